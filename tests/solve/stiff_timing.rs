//! Extreme timing: exposure of one line time, exposure as long as the whole readout
//! (temporally unresolvable), 1-row and 2-row sensors, odd sizes.

use crate::support::common;
use common::*;
use rollcam::model::op::Operator;
use rollcam::model::shutter::ShutterMode;
use rollcam::solve::optimize::SolverKind;
use rollcam::solve::prox::TotalVariation;

#[test]
fn exposure_of_one_line_time_is_solved() {
    let (m, n) = (9, 7);
    for mode in [ShutterMode::Rolling, ShutterMode::Dual] {
        let a = model(&sparse_psf(m, n, 1), m, n, 100.0, 100.0, mode);
        let (k, _, _) = a.video_shape();
        let truth = flashing_points(k, m, n, 50.0);
        let b = forward(&a, &truth);
        let tv = TotalVariation::new((k, m, n), 0.01, 1.0);
        let f_truth = objective(&a, &b, &tv, &truth);
        for kind in SolverKind::ALL {
            let (r, objs) = run(&settings(kind, lipschitz(&a), iters_for(kind, 500)), &a, &b, &tv);
            assert!(all_finite(&r.x), "{mode} {kind}");
            let last = *objs.last().unwrap();
            eprintln!("{mode} {kind}: {last:.4e}, truth's {f_truth:.4e}");
            assert!(near_truth_objective(last, f_truth), "{mode} {kind}: {last} vs truth's {f_truth}");
        }
    }
}

#[test]
fn global_shutter_like_exposure_invents_no_motion() {
    // Every row exposed over the same long window (all rows starting together, from a
    // per-row table: a global shutter alone is a one-frame still), exposure of the
    // whole readout: the data say nothing about when light arrived, every frame is
    // seen identically, and a static solution must come back: no invented motion.
    let (m, n) = (8, 6);
    let frame: Vec<f32> = rollcam::model::op::pseudo_random(m * n, 4).iter().map(|v| 10.0 * v).collect();
    let mut timing = rollcam::model::shutter::Timing::new(m, 100.0, 100.0 * m as f64, ShutterMode::Global);
    timing.row_start_us = Some(vec![0.0; m]);
    let a = rollcam::model::rolling::RollingShutterModel::new(rollcam::model::conv::Conv2d::sensor(&sparse_psf(m, n, 2), m, n), timing.weights().unwrap());
    let (k, _, _) = a.video_shape();
    assert!(k > 1);
    let truth: Vec<f32> = (0..k).flat_map(|_| frame.iter().cloned()).collect();
    let b = forward(&a, &truth);
    let tv = TotalVariation::new((k, m, n), 0.01, 5.0);
    for kind in SolverKind::ALL {
        let (r, _) = run(&settings(kind, lipschitz(&a), 300), &a, &b, &tv);
        assert!(all_finite(&r.x));
        let [st, sy, sx] = tv.abs_gradient_sums(&r.x);
        eprintln!("global, {kind}: temporal {st:.3e} spatial {:.3e}", sy + sx);
        assert!(sy + sx > 0.0);
        assert!(st <= 1e-5 * (sy + sx), "{kind}: temporal variation {st} vs spatial {}", sy + sx);
    }
    // Rolling shutter with an exposure of the whole readout: only the middle frame is
    // seen by every row; time is barely resolved, and the solution must stay close to
    // static (temporal variation a small fraction of the spatial structure).
    let a = model(&sparse_psf(m, n, 2), m, n, 100.0, 100.0 * m as f64, ShutterMode::Rolling);
    let (k, _, _) = a.video_shape();
    let truth: Vec<f32> = (0..k).flat_map(|_| frame.iter().cloned()).collect();
    let b = forward(&a, &truth);
    let tv = TotalVariation::new((k, m, n), 0.01, 5.0);
    for kind in SolverKind::ALL {
        let (r, _) = run(&settings(kind, lipschitz(&a), iters_for(kind, 300)), &a, &b, &tv);
        assert!(all_finite(&r.x));
        let [st, sy, sx] = tv.abs_gradient_sums(&r.x);
        eprintln!("rolling, exposure = readout, {kind}: temporal {st:.3e} spatial {:.3e}", sy + sx);
        assert!(st < 0.1 * (sy + sx), "{kind}: temporal variation {st} vs spatial {}", sy + sx);
    }
}

#[test]
fn one_and_two_row_sensors_and_odd_sizes() {
    for (m, n) in [(1, 5), (2, 3), (1, 1), (5, 3), (7, 9)] {
        for mode in [ShutterMode::Rolling, ShutterMode::Dual, ShutterMode::DualCenterOut] {
            let a = model(&sparse_psf(m, n, 7), m, n, 100.0, 200.0, mode);
            let (k, _, _) = a.video_shape();
            let truth: Vec<f32> = rollcam::model::op::pseudo_random(k * m * n, 8);
            let b = forward(&a, &truth);
            let tv = TotalVariation::new((k, m, n), 1e-3, 1.0);
            for kind in SolverKind::ALL {
                let (r, objs) = run(&settings(kind, lipschitz(&a), 200), &a, &b, &tv);
                assert!(all_finite(&r.x), "{m}x{n} {mode} {kind}");
                assert_eq!(r.x.len(), a.input_len());
                let f0: f64 = 0.5 * b.iter().map(|&v| (v as f64).powi(2)).sum::<f64>();
                assert!(*objs.last().unwrap() < 0.1 * f0 + 1e-9, "{m}x{n} {mode} {kind}: {} vs {f0}", objs.last().unwrap());
            }
        }
    }
}
