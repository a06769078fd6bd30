//! Recovery of a known video through the reconstruction's own operator: point sources
//! flashing square waves behind a sparse random PSF, dual shutter. The waveform at each
//! source must come back (correlation with the truth), and the solver must converge.

use rollcam::io::cache::LipschitzCache;
use rollcam::model::capture::{CaptureConfig, Fov};
use rollcam::model::op::{pseudo_random, Operator};
use rollcam::model::prepare::{Plane, Prepared};
use rollcam::model::shutter::ShutterMode;
use rollcam::solve::problem::build_operator;
use rollcam::solve::problem::{Problem, SolveSettings};
use rollcam::solve::reconstruct::{reconstruct, Hooks, SolveOptions};
use std::sync::atomic::AtomicBool;

use crate::support::common::correlation;

#[test]
fn flashing_points_are_recovered_through_the_model() {
    let (m, n) = (32, 40);
    // Sparse caustic-like PSF: a few dozen bright random points.
    let r = pseudo_random(m * n, 3);
    let psf: Vec<f32> = r.iter().map(|&v| if v > 0.85 { v } else { 0.0 }).collect();
    let sum: f32 = psf.iter().sum();
    let psf: Vec<f32> = psf.iter().map(|v| v / sum).collect();
    let cfg = CaptureConfig::new(m, n, 100.0, 300.0, ShutterMode::Dual);
    let mut prepared = Prepared {
        raw: vec![Plane { rows: m, cols: n, data: vec![0.0; m * n] }],
        psf: vec![Plane { rows: m, cols: n, data: psf }],
        raw_dark: 0.0,
        psf_dark: 0.0,
        dark_estimated: false,
        ..Prepared::default()
    };
    let model = build_operator(&prepared.psf[0], &cfg.timing().weights().unwrap(), Fov::Sensor, &Default::default());
    let (k, _, _) = model.video_shape();
    // Two sources with different periods (in frames): 8 and 12.
    let sources = [((12usize, 14usize), 8usize), ((20, 27), 12)];
    let mut truth = vec![0.0f32; k * m * n];
    for f in 0..k {
        for &((r, c), p) in &sources {
            if (f % p) < p / 2 {
                truth[(f * m + r) * n + c] = 1000.0;
            }
        }
    }
    let mut b = vec![0.0; m * n];
    model.forward(&truth, &mut b);
    prepared.raw[0].data = b;
    let settings = SolveSettings { tau: rollcam::solve::tau::Tau::Absolute(0.02), alpha: 3.0, iters: 800, ..SolveSettings::default() }.validate().unwrap();
    let stop = AtomicBool::new(false);
    let hooks = Hooks { on_row: &|_, _| {}, stop: &stop };
    let t = ndarray::Array4::from_shape_vec((k, m, n, 1), truth.clone()).unwrap();
    let problem = Problem::new(&prepared, &cfg, Fov::Sensor).unwrap();
    let (rec, params) = reconstruct(&problem, &settings, &SolveOptions::default(), Some((t.view(), "truth")), &LipschitzCache::disabled(), &hooks).unwrap();
    let ch = &rec.channels[0];
    // The truth is feasible, so the minimum is no higher than the truth's objective.
    let tv = rollcam::solve::prox::TotalVariation::new((k, m, n), params.tau, params.alpha);
    let truth_objective = rollcam::solve::prox::Prox::value(&tv, &truth); // data term of the truth is 0
    assert!(ch.stats.objective <= 1.01 * truth_objective, "objective {} vs truth's {truth_objective}", ch.stats.objective);
    eprintln!("objective {} (truth {truth_objective}), PSNR {:?}", ch.stats.objective, ch.stats.error);
    for &((r, c), p) in &sources {
        // Sum a 3x3 neighbourhood: TV may spread a point by a pixel.
        let got: Vec<f64> = (0..k)
            .map(|f| {
                let mut s = 0.0;
                for dr in 0..3 {
                    for dc in 0..3 {
                        s += rec.video[[f, r + dr - 1, c + dc - 1, 0]] as f64;
                    }
                }
                s
            })
            .collect();
        let want: Vec<f64> = (0..k).map(|f| truth[(f * m + r) * n + c] as f64).collect();
        let corr = correlation(&got, &want);
        eprintln!("corr {corr}");
        assert!(corr > 0.9, "source at ({r},{c}) period {p}: correlation {corr}");
    }
    assert!(rec.video.iter().all(|v| v.is_finite() && *v >= 0.0));
}
