//! Strong regularisation (large tau, alpha up to 100), and the known bias of the
//! parallel-proximal Haar TV map at large `step * tau`, against the exact (dual) map.

use crate::support::common;
use common::*;
use rollcam::model::shutter::ShutterMode;
use rollcam::solve::optimize::SolverKind;
use rollcam::solve::prox::tv_dual::TvProx;
use rollcam::solve::prox::Prox;
use rollcam::solve::prox::TotalVariation;

#[test]
fn strong_tv_monotone_fista_never_rises_and_restart_settles() {
    let (m, n) = (10, 8);
    let a = model(&sparse_psf(m, n, 4), m, n, 100.0, 300.0, ShutterMode::Dual);
    let (k, _, _) = a.video_shape();
    let b = forward(&a, &flashing_points(k, m, n, 1000.0));
    let l = lipschitz(&a);
    for (tau, alpha) in [(5.0f32, 10.0f32), (20.0, 100.0)] {
        let tv = TotalVariation::new((k, m, n), tau, alpha);
        for prox in [TvProx::Haar, TvProx::Dual { inner_iters: 20 }] {
            // Monotone FISTA: the objective never rises, whatever the prox.
            let mut s = settings(SolverKind::Mfista, l, 400);
            let (r, objs) = run(&s, &a, &b, prox.build(&tv).as_ref());
            assert!(all_finite(&r.x));
            assert!(objs.windows(2).all(|w| w[1] <= w[0]), "mfista tau {tau} alpha {alpha} {prox:?}: the objective rose");
            let f_mono = *objs.last().unwrap();
            // FISTA with function-value restart keeps the step that rose (momentum is
            // reset after it), so its objective is not monotone: with the Haar map at
            // large step*tau it rises often (the map is not the exact prox) yet still
            // settles; the level it settles on is reported, not asserted.
            s.kind = SolverKind::FistaRestart;
            let (r, objs) = run(&s, &a, &b, prox.build(&tv).as_ref());
            assert!(all_finite(&r.x));
            let ups: Vec<f64> = objs.windows(2).filter(|w| w[1] > w[0]).map(|w| (w[1] - w[0]) / w[0]).collect();
            let worst = ups.iter().cloned().fold(0.0, f64::max);
            let tail = &objs[objs.len() - 50..];
            let (lo, hi) = tail.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &v| (lo.min(v), hi.max(v)));
            eprintln!(
                "tau {tau} alpha {alpha} {prox:?}: restart rose {} times in {} iterations (worst {worst:.1e}), tail spread {:.1e}; final {:.6e} vs monotone {f_mono:.6e}",
                ups.len(),
                objs.len(),
                (hi - lo) / lo,
                objs.last().unwrap()
            );
            assert!((hi - lo) / lo < 1e-2, "restart tau {tau} {prox:?}: tail spread {}", (hi - lo) / lo);
        }
    }
}

#[test]
fn huge_temporal_weight_gives_a_video_constant_in_time() {
    // Light that flashes is, under alpha = 100 and a strong tau, explained by a video
    // that does not change in time: temporal variation vanishes, spatial remains.
    let (m, n) = (10, 8);
    let a = model(&sparse_psf(m, n, 6), m, n, 100.0, 300.0, ShutterMode::Dual);
    let (k, _, _) = a.video_shape();
    let b = forward(&a, &flashing_points(k, m, n, 1000.0));
    let tv = TotalVariation::new((k, m, n), 20.0, 100.0);
    let s = settings(SolverKind::FistaRestart, lipschitz(&a), 600);
    let (r, _) = run(&s, &a, &b, TvProx::Dual { inner_iters: 20 }.build(&tv).as_ref());
    let [st, sy, sx] = tv.abs_gradient_sums(&r.x);
    let mass: f64 = r.x.iter().map(|&v| v as f64).sum();
    eprintln!("temporal {st:.3e}, spatial {:.3e}, mass {mass:.3e}", sy + sx);
    assert!(mass > 0.0, "the light must remain");
    assert!(st < 1e-3 * (sy + sx), "temporal variation {st} vs spatial {}", sy + sx);
}

#[test]
fn haar_map_bias_at_large_step_times_tau_and_the_dual_remedy() {
    // The flashing-points case of tests/solve/recovery_model.rs, smaller: tau 1, alpha 10.
    // The truth is feasible, so the exact minimum is at most the truth's objective.
    // FISTA with the parallel Haar map settles on a fixed point whose objective can
    // exceed it; the exact (dual) map removes the gap.
    let (m, n) = (16, 20);
    let a = model(&sparse_psf(m, n, 3), m, n, 100.0, 300.0, ShutterMode::Dual);
    let (k, _, _) = a.video_shape();
    let truth = flashing_points(k, m, n, 1000.0);
    let b = forward(&a, &truth);
    let tv = TotalVariation::new((k, m, n), 1.0, 10.0);
    let f_truth = objective(&a, &b, &tv, &truth);
    let l = lipschitz(&a);
    let gap = |prox: TvProx| {
        let s = settings(SolverKind::FistaRestart, l, 800);
        let (r, _) = run(&s, &a, &b, prox.build(&tv).as_ref());
        assert!(all_finite(&r.x));
        (objective(&a, &b, &tv, &r.x) - f_truth) / f_truth
    };
    let (haar, dual) = (gap(TvProx::Haar), gap(TvProx::Dual { inner_iters: 10 }));
    eprintln!("step*tau = {:.3e}; objective gap vs truth: haar {haar:+.4}, dual {dual:+.4}", tv.tau as f64 / l);
    assert!(dual <= 0.01, "the exact prox must reach the truth's objective or below: gap {dual}");
    assert!(haar > dual, "haar gap {haar} must exceed the exact prox's {dual}");
    let _ = tv.value(&truth);
}
