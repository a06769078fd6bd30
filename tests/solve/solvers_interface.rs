//! The solvers behind one interface: same minimum, same stopping rules, no NaN escapes.

use crate::support::common;
use common::*;
use rollcam::model::data::DataTerm;
use rollcam::model::op::{pseudo_random, Operator};
use rollcam::model::shutter::ShutterMode;
use rollcam::solve::optimize::{solve, OptimizerSettings, SolverKind};
use rollcam::solve::optimize::{IterInfo, StopRule, Termination};
use rollcam::solve::problem::SolveSettings;
use rollcam::solve::prox::tv_dual::TvProx;
use rollcam::solve::prox::Prox;
use rollcam::solve::prox::TotalVariation;

#[test]
fn every_solver_reaches_the_same_minimum() {
    let (m, n) = (10, 8);
    let a = model(&sparse_psf(m, n, 3), m, n, 100.0, 300.0, ShutterMode::Dual);
    let (k, _, _) = a.video_shape();
    let truth = flashing_points(k, m, n, 100.0);
    let b = forward(&a, &truth);
    let l = lipschitz(&a);
    let tv = TotalVariation::new((k, m, n), 0.5, 2.0);
    // The gradient methods use the exact (dual) TV prox, so that all minimise the same
    // objective; ADMM shrinks exactly by construction.
    let mut finals = Vec::new();
    for (kind, iters) in
        [(SolverKind::FistaRestart, 3000), (SolverKind::Fista, 3000), (SolverKind::Mfista, 3000), (SolverKind::Admm, 1500), (SolverKind::Pgd, 6000)]
    {
        let s = settings(kind, l, iters);
        let (r, _) = run(&s, &a, &b, TvProx::Dual { inner_iters: 20 }.build(&tv).as_ref());
        assert!(all_finite(&r.x), "{kind}");
        let f = objective(&a, &b, &tv, &r.x.iter().map(|v| v.max(0.0)).collect::<Vec<_>>());
        eprintln!("{kind}: objective {f:.6e} after {} iterations", r.iterations);
        finals.push((kind, f));
    }
    let best = finals.iter().map(|f| f.1).fold(f64::INFINITY, f64::min);
    for (kind, f) in finals {
        assert!(f <= best * 1.01, "{kind}: objective {f} vs best {best}");
    }
}

/// The default stop: it ends a solve whose objective has settled (close to the minimum)
/// and does not end one still moving; the cap ends a run that has not converged, and
/// the run says so.
#[test]
fn the_default_stop_fires_on_a_settled_solve_and_not_on_a_moving_one() {
    let (m, n) = (10, 8);
    let a = model(&sparse_psf(m, n, 3), m, n, 100.0, 300.0, ShutterMode::Dual);
    let (k, _, _) = a.video_shape();
    let b = forward(&a, &flashing_points(k, m, n, 100.0));
    let l = lipschitz(&a);
    let tv = TotalVariation::new((k, m, n), 0.5, 2.0);
    let data = DataTerm::new(&b);
    let stop = SolveSettings::default().stop();
    assert!(stop.obj_tol > 0.0, "the default runs to convergence");
    let kind = SolveSettings::default().solver;
    let reference = solve(&settings(kind, l, 20_000), &a, &data, &tv, None, &mut |_: &IterInfo| true);
    let f_ref = reference.data_term + reference.reg_term;
    // Settled: converged before the cap, within 1% of the minimum.
    let r = solve(&OptimizerSettings::new(kind, l, StopRule { max_iters: 100_000, ..stop.clone() }), &a, &data, &tv, None, &mut |_: &IterInfo| true);
    let f = r.data_term + r.reg_term;
    assert_eq!(r.termination, Termination::Converged);
    assert!(f <= f_ref * 1.01, "stopped at {f} against the minimum {f_ref} after {} iterations", r.iterations);
    // Moving: the objective still changes by more than the tolerance per iteration
    // after 5 iterations; the test does not fire there, the cap ends the run and the
    // run does not claim convergence.
    let mut objs = Vec::new();
    let r = solve(&OptimizerSettings::new(kind, l, StopRule { max_iters: 5, ..stop.clone() }), &a, &data, &tv, None, &mut |i: &IterInfo| {
        objs.push(i.objective());
        true
    });
    assert_eq!((r.termination, r.iterations), (Termination::MaxIterations, 5));
    let moving = objs.windows(2).filter(|w| (w[1] - w[0]).abs() > stop.obj_tol * w[1].abs()).count();
    assert!(moving > 0, "the first 5 iterations were all flat: {objs:?}");
}

#[test]
fn every_solver_obeys_the_shared_stopping_rules() {
    let (m, n) = (8, 6);
    let a = model(&sparse_psf(m, n, 5), m, n, 100.0, 200.0, ShutterMode::Rolling);
    let (k, _, _) = a.video_shape();
    let b = forward(&a, &flashing_points(k, m, n, 10.0));
    let l = lipschitz(&a);
    let tv = TotalVariation::new((k, m, n), 0.05, 1.0);
    for kind in SolverKind::ALL {
        // Iterations.
        let (r, objs) = run(&settings(kind, l, 7), &a, &b, &tv);
        assert_eq!((r.termination, r.iterations, objs.len()), (Termination::MaxIterations, 7, 7), "{kind}");
        // Relative change.
        let s = OptimizerSettings::new(
            kind,
            l,
            StopRule { max_iters: 100_000, rel_tol: 1e-3, time_budget_s: None, obj_tol: 0.0, noise_floor: None, wait_for_iterate: true },
        );
        // MFISTA rejects steps that raise the objective: with the approximate Haar map it
        // can reject every step; it is meant for the exact (dual) prox.
        let map = if kind == SolverKind::Mfista { TvProx::Dual { inner_iters: 20 } } else { TvProx::Haar };
        let data = DataTerm::new(&b);
        let r = solve(&s, &a, &data, map.build(&tv).as_ref(), None, &mut |_: &IterInfo| true);
        assert_eq!(r.termination, Termination::Converged, "{kind}");
        assert!(r.iterations < 100_000);
        // Time budget (zero seconds: stops after the first iteration).
        let s = OptimizerSettings::new(
            kind,
            l,
            StopRule { max_iters: 1000, rel_tol: 0.0, time_budget_s: Some(0.0), obj_tol: 0.0, noise_floor: None, wait_for_iterate: true },
        );
        let r = solve(&s, &a, &data, &tv, None, &mut |_: &IterInfo| true);
        assert_eq!((r.termination, r.iterations), (Termination::TimeBudget, 1), "{kind}");
        // Observer.
        let mut count = 0;
        let r = solve(&settings(kind, l, 100), &a, &data, &tv, None, &mut |_: &IterInfo| {
            count += 1;
            count < 4
        });
        assert_eq!((r.termination, r.iterations), (Termination::Stopped, 4), "{kind}");
        // The reported objective is the objective of the returned iterate.
        let f = objective(&a, &b, &tv, &r.x);
        assert!((r.data_term + r.reg_term - f).abs() <= 1e-4 * f.max(1e-9), "{kind}: {} vs {f}", r.data_term + r.reg_term);
    }
}

#[test]
fn non_finite_data_never_escapes_any_solver() {
    let (m, n) = (6, 5);
    let a = model(&sparse_psf(m, n, 2), m, n, 100.0, 200.0, ShutterMode::Dual);
    let (k, _, _) = a.video_shape();
    let mut b = forward(&a, &flashing_points(k, m, n, 1.0));
    b[7] = f32::NAN;
    let tv = TotalVariation::new((k, m, n), 0.01, 1.0);
    for kind in SolverKind::ALL {
        let (r, _) = run(&settings(kind, lipschitz(&a), 20), &a, &b, &tv);
        assert!(matches!(r.termination, Termination::NonFinite { .. }), "{kind}: {:?}", r.termination);
        assert!(all_finite(&r.x), "{kind}");
        assert_eq!(r.x.len(), a.input_len());
    }
}

#[test]
fn names_parse_and_unknown_names_say_what_is_expected() {
    for k in SolverKind::ALL {
        assert_eq!(k.name().parse::<SolverKind>().unwrap(), k);
    }
    let e = "newton".parse::<SolverKind>().unwrap_err();
    assert!(e.contains("newton") && e.contains("fista-restart"), "{e}");
}

/// The data term is the solvers' one objective: on a capture with clipped pixels (lower
/// bounds, `A x >= b` there) every gradient method's first step from the same start is
/// the same iterate, each reports the same objective for it, and that objective is the
/// one-sided data term plus TV computed here independently. ADMM, whose data update
/// treats every pixel as an equality, refuses the term and names it.
#[test]
fn every_solver_minimises_the_one_data_term_or_refuses_it() {
    let (m, n) = (10, 8);
    let a = model(&sparse_psf(m, n, 3), m, n, 100.0, 300.0, ShutterMode::Dual);
    let (k, _, _) = a.video_shape();
    let b = forward(&a, &flashing_points(k, m, n, 100.0));
    // Every fifth pixel clipped at half its value: the light was at least that.
    let clip: Vec<bool> = (0..m * n).map(|i| i % 5 == 0).collect();
    let b: Vec<f32> = b.iter().zip(&clip).map(|(&v, &c)| if c { 0.5 * v } else { v }).collect();
    let data = DataTerm::new(&b).with_lower_bounds(Some(&clip));
    let tv = TotalVariation::new((k, m, n), 0.5, 2.0);
    let l = lipschitz(&a);
    let x0: Vec<f32> = pseudo_random(a.input_len(), 7).iter().map(|v| 10.0 * v).collect();
    let one_sided = |x: &[f32]| {
        let ax = forward(&a, x);
        let d: f64 = ax
            .iter()
            .zip(&b)
            .zip(&clip)
            .map(|((&p, &q), &c)| {
                let r = (p - q) as f64;
                if c && r > 0.0 {
                    0.0
                } else {
                    r * r
                }
            })
            .sum();
        0.5 * d + Prox::value(&tv, x)
    };
    let mut first: Option<(Vec<f32>, f64)> = None;
    for kind in [SolverKind::Fista, SolverKind::FistaRestart, SolverKind::Mfista, SolverKind::Pgd] {
        assert!(kind.check_data(&data).is_ok(), "{kind}");
        let mut seen = Vec::new();
        let r = solve(&settings(kind, l, 1), &a, &data, &tv, Some(x0.clone()), &mut |i: &IterInfo| {
            seen.push(i.objective());
            true
        });
        let reported = seen[0];
        let f = one_sided(&r.x);
        assert!((reported - f).abs() <= 1e-5 * f, "{kind}: reported {reported} vs one-sided objective {f}");
        match &first {
            None => first = Some((r.x, reported)),
            Some((x, obj)) => {
                assert_eq!(&r.x, x, "{kind}: the first step from the same start differs");
                assert_eq!(reported, *obj, "{kind}: another objective for the same iterate");
            }
        }
    }
    let refused = SolverKind::Admm.check_data(&data).unwrap_err();
    assert!(refused.starts_with("admm: lower bounds from clipped pixels (16 pixels) are not supported"), "{refused}");
    assert!(SolverKind::Admm.check_data(&DataTerm::new(&b)).is_ok());
    let panic =
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| solve(&settings(SolverKind::Admm, l, 1), &a, &data, &tv, None, &mut |_: &IterInfo| true)));
    assert!(panic.is_err(), "admm must not run on clipped pixels");
}
