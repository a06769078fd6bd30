//! Probe: how many still iterations the still start needs, for FISTA with restart
//! on a capture folder written by `rollcam simulate` (raw.tiff, psf.tiff, capture.toml,
//! truth.npy). Prints iterations and seconds to within 1% / 0.1% of the best objective
//! and to the best relative error + 1%. (The per-frame preconditioner this probe once
//! tried is the library's now: `compare --solvers fista-restart:precond=frames`.)
//!
//!     cargo run --release --example still_start_probe -- DIR [ITERS] [STILL_ITERS,..]
use ndarray::Axis;
use rollcam::io::cache::LipschitzCache;
use rollcam::model::capture::CaptureOverrides;
use rollcam::model::data::DataTerm;
use rollcam::model::prepare::{prepare, SensorInput};
use rollcam::solve::lipschitz::power_iteration;
use rollcam::solve::optimize::{solve, IterInfo, OptimizerSettings, SolverKind, StopRule};
use rollcam::solve::problem::{Problem, ValidSettings};
use rollcam::solve::prox::TotalVariation;
use rollcam::solve::trace::compare;
use std::path::Path;

type Row = (f64, f64, f64, usize); // seconds, objective, rel error, iteration

fn report(label: &str, rows: &[Row], best_obj: f64, best_err: f64) {
    let at = |f: &dyn Fn(&Row) -> bool| rows.iter().find(|r| f(r)).map(|r| format!("{} it / {:.1} s", r.3, r.0)).unwrap_or("-".into());
    println!(
        "{label:>28}: obj 1%: {:>16}  obj 0.1%: {:>16}  err+1%: {:>16}  final err {:.4} obj {:.5e}",
        at(&|r| r.1 <= best_obj * 1.01),
        at(&|r| r.1 <= best_obj * 1.001),
        at(&|r| r.2 <= best_err * 1.01),
        rows.last().unwrap().2,
        rows.last().unwrap().1
    );
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let dir = Path::new(&args[1]);
    let iters: usize = args.get(2).map(|s| s.parse().unwrap()).unwrap_or(300);
    let still_iters: Vec<usize> = args.get(3).map(|s| s.split(',').map(|v| v.parse().unwrap()).collect()).unwrap_or(vec![30, 100]);
    let raw = rollcam::io::read_image(dir.join("raw.tiff")).unwrap();
    let psf = rollcam::io::read_image(dir.join("psf.tiff")).unwrap();
    let (rows, cols, _) = raw.dim();
    let cfg = rollcam::io::capture_file::resolve_capture(Some(&dir.join("capture.toml")), &CaptureOverrides::default(), (rows, cols)).unwrap();
    let truth4 = rollcam::io::read_truth(dir.join("truth.npy")).unwrap();
    let truth: Vec<f32> = truth4.index_axis(Axis(3), 0).iter().cloned().collect();
    let prepared = prepare(raw.view(), "raw", psf.view(), "psf", &cfg, &SensorInput::default()).unwrap();
    let cache = LipschitzCache::disabled();
    let problem = Problem::new(&prepared, &cfg, cfg.fov).unwrap();
    let params = ValidSettings::default().resolve(&problem, problem.fov);
    let model = problem.channel(0).model();
    let (k, m, n) = model.video_shape();
    assert_eq!(truth.len(), k * m * n, "truth shape");
    let b = &prepared.raw[0].data;
    let tv = TotalVariation::new((k, m, n), params.tau, params.alpha);
    let l = problem.channel(0).lipschitz(&cache).value;
    println!("{k} x {m} x {n}, tau {:.4}, L {l:.4e}, tv_prox {:?}", params.tau, params.tv_prox.resolve(&tv, problem.channel(0).atb_max() as f64));
    let mut all: Vec<(String, Vec<Row>)> = Vec::new();

    // Baseline: the library's fista-restart with the default map.
    let run_lib = |x0: Option<Vec<f32>>, t0: f64| {
        let st = OptimizerSettings::new(SolverKind::FistaRestart, l, StopRule::iterations(iters));
        let prior = params.tv_prox.resolve(&tv, problem.channel(0).atb_max() as f64).build(&tv);
        let mut rows = Vec::new();
        let mut obs = |i: &IterInfo| {
            rows.push((t0 + i.seconds, i.objective(), compare(i.x, &truth).expect("a simulated truth has light").rel_error, i.iteration));
            true
        };
        solve(&st, model, &DataTerm::new(b), prior.as_ref(), x0, &mut obs);
        rows
    };
    all.push(("fista-restart".into(), run_lib(None, 0.0)));

    // Still warm start: the still image solved (one convolution per call), repeated.
    let still = rollcam::model::still::Still::new(model);
    let still_tv = TotalVariation::new((1, m, n), rollcam::solve::tau::static_frame_tau(params.tau, k), params.alpha);
    let t = std::time::Instant::now();
    let ls = power_iteration(&still, 60, 1e-4, 1).lambda_max * 1.01;
    let tl = t.elapsed().as_secs_f64();
    for s_iters in still_iters.clone() {
        let st = OptimizerSettings::new(SolverKind::FistaRestart, ls, StopRule::iterations(s_iters));
        let prior = params.tv_prox.resolve(&still_tv, problem.channel(0).atb_max() as f64).build(&still_tv);
        let r = solve(&st, &still, &DataTerm::new(b), prior.as_ref(), None, &mut rollcam::solve::optimize::NoObserver);
        let x0 = r.x.repeat(k);
        println!(
            "still: {} iterations, {:.2} s (+{tl:.2} s Lipschitz), start rel error {:.4}",
            r.iterations,
            r.seconds,
            compare(&x0, &truth).expect("a simulated truth has light").rel_error
        );
        all.push((format!("still {s_iters} + fista-restart"), run_lib(Some(x0), r.seconds + tl)));
    }
    finish(all)
}

fn finish(all: Vec<(String, Vec<Row>)>) {
    let best_obj = all.iter().flat_map(|(_, r)| r.iter().map(|r| r.1)).fold(f64::MAX, f64::min);
    let best_err = all.iter().flat_map(|(_, r)| r.iter().map(|r| r.2)).fold(f64::MAX, f64::min);
    println!("best objective {best_obj:.5e}, best rel error {best_err:.4}");
    for (label, rows) in &all {
        report(label, rows, best_obj, best_err);
    }
}
