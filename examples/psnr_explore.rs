//! Explore the time-to-PSNR run of `rollcam bench --psnr`: PSNR against iterations for
//! several TV weights, per-frame PSNR at the end, and each frame's sensitivity
//! (`||A P_k||_F^2`, relative) on a benchmark preset.
//!
//! ```sh
//! cargo run --release --example psnr_explore -- paper-8x 3000 2e-4,1 1e-4,1   # tau_rel,alpha[,r|n]
//! SCENE=edge cargo run --release --example psnr_explore -- paper-8x 2000 5e-5,1  # disc edge to edge
//! ```
use rollcam::model::data::DataTerm;
use rollcam::model::op::Operator;
use rollcam::perf::bench::{build, preset, scene};
use rollcam::solve::lipschitz::{power_iteration, LIPSCHITZ_MARGIN};
use rollcam::solve::optimize::{Fista, IterInfo, RestartTest, StopRule};
use rollcam::solve::prox::TotalVariation;
use rollcam::solve::trace::compare;

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let p = preset(&a[1]).unwrap();
    let iters: usize = a[2].parse().unwrap();
    let model = build(&p, None);
    let (k, m, n) = model.video_shape();
    let truth = if std::env::var("SCENE").as_deref() == Ok("edge") { edge_to_edge(k, m, n) } else { scene(k, m, n) };
    let mut b = vec![0.0f32; m * n];
    model.forward(&truth, &mut b);
    let eig = power_iteration(&model, 300, 1e-5, 0x5eed);
    let mut atb = vec![0.0f32; model.input_len()];
    model.adjoint(&b, &mut atb);
    let amax = atb.iter().fold(0.0f32, |a, &v| a.max(v));
    {
        let psf = rollcam::perf::bench::psf(m, n);
        let sq: Vec<f32> = psf.iter().map(|v| v * v).collect();
        let c = rollcam::model::conv::Conv2d::sensor(&sq, m, n);
        let mut s = c.scratch();
        let e = c.apply(&vec![1.0f32; m * n], &mut s);
        let rowe: Vec<f64> = (0..m).map(|i| e[i * n..(i + 1) * n].iter().map(|&v| v as f64).sum()).collect();
        let w = model.weights();
        let g: Vec<f64> = (0..k).map(|f| (0..m).map(|i| (w.get(i, f) as f64).powi(2) * rowe[i]).sum()).collect();
        let gm = g.iter().cloned().fold(0.0, f64::max);
        println!("frame sensitivity: {}", g.iter().map(|v| format!("{:.2}", v / gm)).collect::<Vec<_>>().join(" "));
        println!(
            "row energy: {}",
            rowe.iter().step_by((m / 16).max(1)).map(|v| format!("{:.2}", v / rowe.iter().cloned().fold(0.0, f64::max))).collect::<Vec<_>>().join(" ")
        );
    }
    for spec in &a[3..] {
        let mut it = spec.split(',');
        let tau_rel: f32 = it.next().unwrap().parse().unwrap();
        let alpha: f32 = it.next().unwrap().parse().unwrap();
        let restart = it.next().map(|s| s == "r").unwrap_or(true);
        let tv = TotalVariation::new((k, m, n), tau_rel * amax, alpha);
        let fista =
            Fista { lipschitz: eig.lambda_max * LIPSCHITZ_MARGIN, stop: StopRule::iterations(iters), restart: restart.then_some(RestartTest::Objective) };
        let mut best = (f64::NEG_INFINITY, 0, 0.0);
        let mut line = String::new();
        let mut obs = |i: &IterInfo| {
            let e = compare(i.x, &truth).expect("a simulated truth has light");
            if e.psnr_db > best.0 {
                best = (e.psnr_db, i.iteration, i.seconds);
            }
            if i.iteration % (iters / 8).max(1) == 0 {
                line += &format!(" {}:{:.1}", i.iteration, e.psnr_db);
            }
            true
        };
        let r = fista.solve(&model, &DataTerm::new(&b), &tv, None, &mut obs);
        let fr = m * n;
        let per: Vec<String> = (0..k)
            .map(|f| {
                let se: f64 = r.x[f * fr..(f + 1) * fr].iter().zip(&truth[f * fr..(f + 1) * fr]).map(|(a, b)| ((a - b) as f64).powi(2)).sum();
                format!("{:.0}", 10.0 * (4.0 / (se / fr as f64)).log10())
            })
            .collect();
        println!("per-frame psnr: {}", per.join(" "));
        let inner = &r.x[8 * fr..(k - 8) * fr];
        let tin = &truth[8 * fr..(k - 8) * fr];
        println!("inner frames 8..k-8: {:.2} dB", compare(inner, tin).expect("a simulated truth has light").psnr_db);
        println!(
            "tau_rel {tau_rel:e} alpha {alpha} restart {restart}: best {:.2} dB at it {} ({:.1}s) | {line} | {:.1}s total",
            best.0, best.1, best.2, r.seconds
        );
    }
}

/// The benchmark scene with the disc sweeping the whole width (edge to edge), as the
/// benchmark had it before: the border frames show the cost of the PSF crop.
fn edge_to_edge(frames: usize, rows: usize, cols: usize) -> Vec<f32> {
    let mut v = scene(frames, rows, cols);
    let rad = (rows as f32 / 8.0).max(1.5);
    for (f, fr) in v.chunks_mut(rows * cols).enumerate() {
        let t = f as f32 / frames.max(2).saturating_sub(1) as f32;
        let (cy, old_cx, cx) = (rows as f32 * 0.55, cols as f32 * (0.25 + 0.5 * t), rad + t * (cols as f32 - 2.0 * rad));
        for r in 0..rows {
            for c in 0..cols {
                let band = if r > rows / 5 && r < rows / 4 + rows / 10 { 0.1 } else { 0.0 };
                let (dy, dxo, dx) = (r as f32 - cy, c as f32 - old_cx, c as f32 - cx);
                if dy * dy + dxo * dxo <= rad * rad && fr[r * cols + c] == 1.0 {
                    fr[r * cols + c] = band;
                }
                if dy * dy + dx * dx <= rad * rad {
                    fr[r * cols + c] = 1.0;
                }
            }
        }
    }
    v
}
