//! Extreme data: all-zero raw, saturated rows, values near the f32 limits (the result
//! scales with the data when tau does), 16-bit full range.

use crate::support::common;
use common::*;
use rollcam::model::shutter::ShutterMode;
use rollcam::solve::optimize::SolverKind;
use rollcam::solve::prox::tv_dual::TvProx;
use rollcam::solve::prox::TotalVariation;

fn problem() -> (rollcam::model::rolling::RollingShutterModel, Vec<f32>, (usize, usize, usize)) {
    let (m, n) = (8, 7);
    let a = model(&sparse_psf(m, n, 3), m, n, 100.0, 300.0, ShutterMode::Dual);
    let (k, _, _) = a.video_shape();
    let b = forward(&a, &flashing_points(k, m, n, 1.0));
    (a, b, (k, m, n))
}

#[test]
fn all_zero_raw_gives_an_all_zero_video() {
    let (a, b, shape) = problem();
    let zero = vec![0.0f32; b.len()];
    let tv = TotalVariation::new(shape, 0.1, 2.0);
    for kind in SolverKind::ALL {
        let (r, _) = run(&settings(kind, lipschitz(&a), 50), &a, &zero, &tv);
        assert!(r.x.iter().all(|&v| v == 0.0), "{kind}");
    }
}

#[test]
fn values_near_the_f32_limits_give_the_same_result_up_to_scale() {
    let (a, b, shape) = problem();
    let l = lipschitz(&a);
    let solve_scaled = |kind: SolverKind, s: f32| {
        let bs: Vec<f32> = b.iter().map(|v| v * s).collect();
        // tau carries the data's units: it scales with the data.
        let tv = TotalVariation::new(shape, 0.01 * s, 2.0);
        let st = settings(kind, l, 150);
        let map = if kind == SolverKind::Mfista { TvProx::Dual { inner_iters: 20 } } else { TvProx::Haar };
        let (r, objs) = run(&st, &a, &bs, map.build(&tv).as_ref());
        assert!(all_finite(&r.x) && objs.iter().all(|o| o.is_finite()), "{kind} scale {s:e}");
        r.x
    };
    for kind in SolverKind::ALL {
        let x1 = solve_scaled(kind, 1.0);
        let norm: f64 = x1.iter().map(|&v| (v as f64).powi(2)).sum::<f64>().sqrt();
        assert!(norm > 0.0);
        for s in [1e-30f32, 1e30] {
            let xs = solve_scaled(kind, s);
            let err: f64 = xs.iter().zip(&x1).map(|(&p, &q)| (p as f64 / s as f64 - q as f64).powi(2)).sum::<f64>().sqrt() / norm;
            eprintln!("{kind} scale {s:e}: relative difference {err:.2e}");
            // MFISTA's accept/reject decisions compare objectives that differ in the
            // last bits; a flipped decision changes the path (measured 1e-3 at 1e-30).
            let tol = if kind == SolverKind::Mfista { 1e-2 } else { 1e-4 };
            assert!(err < tol, "{kind} scale {s:e}: relative difference {err}");
        }
    }
}

#[test]
fn sixteen_bit_full_range_and_saturated_rows_stay_finite() {
    let (a, b, shape) = problem();
    let peak = b.iter().cloned().fold(0.0f32, f32::max);
    let full: Vec<f32> = b.iter().map(|v| v / peak * 65535.0).collect();
    // Saturate two rows (as a clipped sensor would).
    let n = 7;
    let mut sat = full.clone();
    for r in [2usize, 5] {
        sat[r * n..(r + 1) * n].iter_mut().for_each(|v| *v = 65535.0);
    }
    for data in [&full, &sat] {
        let tv = TotalVariation::new(shape, 1e-3 * 65535.0, 2.0);
        for kind in SolverKind::ALL {
            let (r, objs) = run(&settings(kind, lipschitz(&a), 150), &a, data, &tv);
            assert!(all_finite(&r.x) && r.x.iter().all(|&v| v >= -1e-3 * 65535.0), "{kind}");
            let f0: f64 = 0.5 * data.iter().map(|&v| (v as f64).powi(2)).sum::<f64>();
            assert!(*objs.last().unwrap() < 0.5 * f0, "{kind}: the objective must fall from 0.5||b||^2 = {f0}: {}", objs.last().unwrap());
        }
    }
}
