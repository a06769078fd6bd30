//! Probe: choosing tau by holding out part of the sensor. For each `tau_rel`, the
//! video is solved from the sensor minus a held-out set (still start, FISTA with
//! restart, the default map), and the held-out pixels are predicted by the forward
//! model. Prints the held-out residual beside the truth error of that solve, per
//! hold-out design, on a folder written by `rollcam simulate`.
//!
//!     cargo run --release --example tau_cv_probe -- DIR ITERS TAU,TAU,.. DESIGN,..
//!
//! DESIGN: `pixels` (a random 10% of the pixels), `rows` (a random 10% of the rows),
//! `bands` (8 rows in every 80), `bands4` (4 in every 40), `bands2` (2 in every 20).
use ndarray::Axis;
use rollcam::io::cache::LipschitzCache;
use rollcam::model::capture::CaptureOverrides;
use rollcam::model::data::DataTerm;
use rollcam::model::op::Operator;
use rollcam::model::prepare::{prepare, DataMask, SensorInput};
use rollcam::solve::optimize::{solve, NoObserver, OptimizerSettings, SolverKind, StopRule};
use rollcam::solve::problem::{build_operator, Problem, ValidSettings};
use rollcam::solve::prox::prior::{PriorSpec, TvPrior};
use rollcam::solve::prox::TotalVariation;
use rollcam::solve::start::{video_start, Start};
use rollcam::solve::tau::TauScale;
use rollcam::solve::trace::compare;
use std::path::Path;

fn hash(i: u64) -> f64 {
    let mut x = i.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0x2545_F491_4F6C_DD1D;
    x ^= x >> 31;
    x = x.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x ^= x >> 29;
    (x >> 11) as f64 / (1u64 << 53) as f64
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let dir = Path::new(&args[1]);
    let iters: usize = args[2].parse().unwrap();
    let taus: Vec<f32> = args[3].split(',').map(|v| v.parse().unwrap()).collect();
    let designs: Vec<String> = args[4].split(',').map(String::from).collect();
    let raw = rollcam::io::read_image(dir.join("raw.tiff")).unwrap();
    let psf = rollcam::io::read_image(dir.join("psf.tiff")).unwrap();
    let (rows, cols, _) = raw.dim();
    let cfg = rollcam::io::capture_file::resolve_capture(Some(&dir.join("capture.toml")), &CaptureOverrides::default(), (rows, cols)).unwrap();
    let truth4 = rollcam::io::read_truth(dir.join("truth.npy")).unwrap();
    let truth: Vec<f32> = truth4.index_axis(Axis(3), 0).iter().cloned().collect();
    let prepared = prepare(raw.view(), "raw", psf.view(), "psf", &cfg, &SensorInput::default()).unwrap();
    let problem = Problem::new(&prepared, &cfg, cfg.fov).unwrap();
    let settings = ValidSettings::default();
    let full = problem.channel(0).model();
    let (k, m, n) = full.video_shape();
    let b = &prepared.raw[0].data;
    let l = problem.channel(0).lipschitz(&LipschitzCache::disabled()).value;
    let scale = problem.tau_scale();
    let (orows, ocols) = (full.output_shape()[0], full.output_shape()[1]);
    println!("{} {k}x{m}x{n} L {l:.4e} scale {scale:.4}", dir.display());
    for design in &designs {
        let held: Vec<bool> = (0..orows * ocols)
            .map(|i| {
                let (r, _c) = (i / ocols, i % ocols);
                match design.as_str() {
                    "pixels" => hash(i as u64) < 0.1,
                    "rows" => hash(r as u64 + 7_777_777) < 0.1,
                    "bands" => r % 80 >= 36 && r % 80 < 44,
                    "bands4" => r % 40 >= 18 && r % 40 < 22,
                    "bands2" => r % 20 >= 9 && r % 20 < 11,
                    other => panic!("design {other}"),
                }
            })
            .collect();
        let mask: Vec<f32> = held.iter().map(|&h| if h { 0.0 } else { 1.0 }).collect();
        let train = build_operator(&prepared.psf[0], problem.weights(), cfg.fov, &DataMask { mask: Some(mask), lower_bounds: None });
        for &tr in &taus {
            let tau = settings.with_tau_rel(tr).resolve(&problem, problem.fov).tau;
            let tv = TotalVariation::new((k, m, n), tau, settings.alpha);
            let prox = settings.tv_prox;
            let spec = PriorSpec::Tv(TvPrior::new(tv.clone(), prox, scale as f64));
            let (x0, _) = video_start(Start::Still, &train, &DataTerm::new(b), &spec, k, &|v| v, None);
            let st = OptimizerSettings::new(SolverKind::FistaRestart, l, StopRule::iterations(iters));
            let prior = prox.resolve(&tv, scale as f64).build(&tv);
            let r = solve(&st, &train, &DataTerm::new(b), prior.as_ref(), x0, &mut NoObserver);
            let mut y = vec![0.0f32; orows * ocols];
            full.forward(&r.x, &mut y);
            let (mut eo, mut bo, mut et, mut bt) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
            for i in 0..y.len() {
                let d = (y[i] - b[i]) as f64;
                if held[i] {
                    eo += d * d;
                    bo += (b[i] as f64).powi(2);
                } else {
                    et += d * d;
                    bt += (b[i] as f64).powi(2);
                }
            }
            let err = compare(&r.x, &truth).expect("a simulated truth has light").rel_error;
            println!("{design:>7} tau_rel {tr:.2e}  held-out {:.5e}  train {:.5e}  truth err {err:.4}  ({:.1} s)", eo / bo, et / bt, r.seconds);
        }
    }
}
