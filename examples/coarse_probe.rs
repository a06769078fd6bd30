//! Does a coarse temporal solve (frames binned by F) make a good warm start for the fine
//! solve? Error against solver time, plain FISTA with restart against coarse + fine, on
//! a simulated 128 x 160 dual-shutter capture (synthetic diffuser, Poisson and read
//! noise). The measurement behind docs/dense-scenes.md's "Coarse-to-fine warm start".
//!
//!     cargo run --release --example coarse_probe -- [SCENE] [FACTOR] [COARSE_ITERS]
//!
//! SCENE: led-array, moving-disc, disc-over-texture (default); FACTOR: temporal
//! binning of the coarse solve (2); COARSE_ITERS: its iterations (60).
use ndarray::Axis;
use rollcam::io::cache::LipschitzCache;
use rollcam::model::data::DataTerm;
use rollcam::model::prepare::{prepare, SensorInput};
use rollcam::sim::setup::SceneKind;
use rollcam::sim::{psf_counts, SimParams, SimSetup};
use rollcam::solve::optimize::{solve, IterInfo, OptimizerSettings, SolverKind, StopRule};
use rollcam::solve::problem::{Problem, ValidSettings};
use rollcam::solve::prox::TotalVariation;
use rollcam::solve::trace::compare;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let scene: SceneKind = args.get(1).map(|s| s.parse().unwrap()).unwrap_or(SceneKind::DiscOverTexture);
    let factor: usize = args.get(2).map(|s| s.parse().unwrap()).unwrap_or(2);
    let coarse_iters: usize = args.get(3).map(|s| s.parse().unwrap()).unwrap_or(60);
    let (rows, cols) = (128, 160);
    let p = SimParams { rows, cols, disc_radius_px: 6.0, disc_px_per_ms: 6.0, disc_contrast: 10.0, seed: 1, ..SimParams::default() };
    let psf = p.synthetic_psf().unwrap();
    let cfg = p.capture_config(rows, cols).unwrap();
    let sc = p.scene(scene, rows, cols, None).unwrap();
    let setup = SimSetup::new(&p, cfg, psf, sc);
    let (cfg, s) = setup.simulate().unwrap();
    let raw = s.raw.insert_axis(Axis(2));
    let psfc = psf_counts(setup.psf.view(), setup.noise.dark_level_adu);
    let prepared = prepare(raw.view(), "raw", psfc.view(), "psf", &cfg, &SensorInput::default()).unwrap();
    let cache = LipschitzCache::disabled();
    let fine = Problem::new(&prepared, &cfg, cfg.fov).unwrap();
    let params = ValidSettings::default().resolve(&fine, fine.fov);
    let (k, m, n) = fine.channel(0).model().video_shape();
    let truth: Vec<f32> = s.truth.iter().cloned().collect();
    let tv = TotalVariation::new((k, m, n), params.tau, params.alpha);
    let lf = fine.channel(0).lipschitz(&cache).value;
    let run = |iters: usize, x0: Option<Vec<f32>>, t0: f64, label: &str| {
        let st = OptimizerSettings::new(SolverKind::FistaRestart, lf, StopRule::iterations(iters));
        let prior = params.tv_prox.resolve(&tv, fine.channel(0).atb_max() as f64).build(&tv);
        let mut rows = Vec::new();
        let mut obs = |i: &IterInfo| {
            rows.push((t0 + i.seconds, compare(i.x, &truth).expect("a simulated truth has light").rel_error, i.iteration));
            true
        };
        solve(&st, fine.channel(0).model(), &DataTerm::new(&prepared.raw[0].data), prior.as_ref(), x0, &mut obs);
        println!("{label}: {} iterations, last rel error {:.4} at {:.2} s", rows.len(), rows.last().unwrap().1, rows.last().unwrap().0);
        rows
    };
    let plain = run(600, None, 0.0, "plain");
    // Coarse.
    let mut cc = cfg.clone();
    cc.binning *= factor;
    let coarse = Problem::new(&prepared, &cc, cc.fov).unwrap();
    let (kc, _, _) = coarse.channel(0).model().video_shape();
    let tvc = TotalVariation::new((kc, m, n), params.tau, params.alpha);
    let lc = coarse.channel(0).lipschitz(&cache).value;
    let st = OptimizerSettings::new(SolverKind::FistaRestart, lc, StopRule::iterations(coarse_iters));
    let prior = params.tv_prox.resolve(&tvc, coarse.channel(0).atb_max() as f64).build(&tvc);
    let r = solve(&st, coarse.channel(0).model(), &DataTerm::new(&prepared.raw[0].data), prior.as_ref(), None, &mut rollcam::solve::optimize::NoObserver);
    let tc = r.seconds;
    let mut x0 = vec![0.0f32; k * m * n];
    for f in 0..k {
        let j = (f / factor).min(kc - 1);
        for i in 0..m * n {
            x0[f * m * n + i] = r.x[j * m * n + i] / factor as f32;
        }
    }
    println!(
        "coarse: {kc} frames (fine {k}), {} iterations in {tc:.2} s, start rel error {:.4}",
        r.iterations,
        compare(&x0, &truth).expect("a simulated truth has light").rel_error
    );
    let warm = run(600, Some(x0), tc, "coarse+fine");
    let best = plain.iter().chain(&warm).map(|r| r.1).fold(f64::MAX, f64::min);
    for slack in [1.10, 1.05, 1.02, 1.01] {
        let t = |rows: &Vec<(f64, f64, usize)>| rows.iter().find(|r| r.1 <= best * slack).map(|r| (r.0, r.2));
        println!("within {:.0}% of the best error {best:.4}: plain {:?}, coarse+fine {:?}", (slack - 1.0) * 100.0, t(&plain), t(&warm));
    }
}
