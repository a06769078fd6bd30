//! The solvers behind one interface: same minimum, same stopping rules, no NaN escapes.

use crate::support::common;
use common::*;
use rollcam::model::op::Operator;
use rollcam::model::shutter::ShutterMode;
use rollcam::solve::optimize::{solve, SolverKind, SolverSettings};
use rollcam::solve::optimize::{IterInfo, StopRule, Termination};
use rollcam::solve::prox::tv::TotalVariation;
use rollcam::solve::prox::tv_dual::TvProx;

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
        let mut s = settings(kind, l, iters);
        s.tv_prox = TvProx::Dual { inner_iters: 20 };
        let (r, _) = run(&s, &a, &b, &tv);
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
        let mut s = SolverSettings::new(kind, l, StopRule { max_iters: 100_000, rel_tol: 1e-3, time_budget_s: None, obj_tol: 0.0 });
        if kind == SolverKind::Mfista {
            // MFISTA rejects steps that raise the objective: with the approximate Haar
            // map it can reject every step; it is meant for the exact (dual) prox.
            s.tv_prox = TvProx::Dual { inner_iters: 20 };
        }
        let r = solve(&s, &a, &b, &tv, None, &mut |_: &IterInfo| true);
        assert_eq!(r.termination, Termination::Converged, "{kind}");
        assert!(r.iterations < 100_000);
        // Time budget (zero seconds: stops after the first iteration).
        let s = SolverSettings::new(kind, l, StopRule { max_iters: 1000, rel_tol: 0.0, time_budget_s: Some(0.0), obj_tol: 0.0 });
        let r = solve(&s, &a, &b, &tv, None, &mut |_: &IterInfo| true);
        assert_eq!((r.termination, r.iterations), (Termination::TimeBudget, 1), "{kind}");
        // Observer.
        let mut count = 0;
        let r = solve(&settings(kind, l, 100), &a, &b, &tv, None, &mut |_: &IterInfo| {
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
