//! Kernel timings (`cargo bench --bench kernels [-- PRESET]`): the imaging operator by
//! the row path and by the 2D-FFT reference path, the TV prox in one pass and term by
//! term, the TV value, and 4 real 2D FFTs of the padded grid. Medians of repeated runs;
//! the whole-iteration benchmark is `rollcam bench`.

use rollcam::model::op::Operator;
use rollcam::perf::bench::{build, fft2d_seconds, load_average, median, preset, scene};
use rollcam::solve::prox::Prox;
use rollcam::solve::prox::TotalVariation;
use std::time::Instant;

fn time(reps: usize, mut f: impl FnMut()) -> f64 {
    f(); // warm-up
    median(
        &(0..reps)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64()
            })
            .collect::<Vec<_>>(),
    )
}

fn main() {
    let name = std::env::args().skip(1).find(|a| !a.starts_with('-')).unwrap_or_else(|| "paper-8x".into());
    let p = preset(&name).unwrap_or_else(|| panic!("unknown preset {name}"));
    let reps = if p.rows > 300 { 3 } else { 9 };
    let a = build(&p, None);
    let (k, m, n) = a.video_shape();
    let x = scene(k, m, n);
    let (mut y, mut g) = (vec![0.0f32; m * n], vec![0.0f32; x.len()]);
    println!("preset {name}: {m} x {n}, K = {k}, {} threads, load {:?}", rayon::current_num_threads(), load_average());
    let row = |label: &str, s: f64| println!("{label:<36} {s:>10.5} s");
    row("forward, row path", time(reps, || a.forward(&x, &mut y)));
    row("forward, 2D-FFT reference", time(reps.min(3), || a.forward_reference(&x, &mut y)));
    row("adjoint, row path", time(reps, || a.adjoint(&y, &mut g)));
    row("adjoint, 2D-FFT reference", time(reps.min(3), || a.adjoint_reference(&y, &mut g)));
    let tv = TotalVariation::new((k, m, n), 0.01, 2.0);
    let mut out = vec![0.0f32; x.len()];
    row("TV prox, one pass", time(reps, || tv.prox(&x, 0.5, &mut out)));
    row("TV prox, term-by-term reference", time(reps.min(3), || tv.prox_reference(&x, 0.5, &mut out)));
    row(
        "TV value",
        time(reps, || {
            std::hint::black_box(tv.value(&x));
        }),
    );
    let (pp, qq) = a.conv().fft_shape();
    row(
        "4 real 2D FFTs of the padded grid",
        time(3, || {
            fft2d_seconds(pp, qq, 4);
        }),
    );
}
