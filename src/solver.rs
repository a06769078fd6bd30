//! One interface over the solvers of `min 0.5||A v - b||^2 + tau TV_w(v) + [v >= 0]`:
//! FISTA, FISTA with adaptive restart, monotone FISTA, ADMM (variable splitting) and
//! plain proximal gradient. All take the same operator, data, TV term, stopping rule ([`StopRule`]) and
//! observer (the trace is one), and return the same [`SolveResult`]; the clock excludes
//! observer time in every solver, so their traces compare run time fairly.

use crate::admm::{Admm, AdmmParams};
use crate::fista::{Fista, Observer, SolveResult, StopRule};
use crate::op::Operator;
use crate::pgd::Pgd;
use crate::tv::TotalVariation;
use crate::tv_dual::TvProx;
use serde::Serialize;
use std::time::{Duration, Instant};

/// The solvers behind [`solve`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum SolverKind {
    Fista,
    FistaRestart,
    Admm,
    Pgd,
    /// Monotone FISTA: objective non-increasing by construction.
    Mfista,
}

impl SolverKind {
    pub const ALL: [SolverKind; 5] = [SolverKind::Fista, SolverKind::FistaRestart, SolverKind::Admm, SolverKind::Pgd, SolverKind::Mfista];
    pub fn name(self) -> &'static str {
        match self {
            SolverKind::Fista => "fista",
            SolverKind::FistaRestart => "fista-restart",
            SolverKind::Admm => "admm",
            SolverKind::Pgd => "pgd",
            SolverKind::Mfista => "mfista",
        }
    }
}

impl std::fmt::Display for SolverKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for SolverKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        SolverKind::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| format!("unknown solver '{s}': expected one of fista, fista-restart, admm, pgd, mfista"))
    }
}

/// Everything a solve needs besides the problem.
#[derive(Clone, Debug, Serialize)]
pub struct SolverSettings {
    pub kind: SolverKind,
    /// Largest eigenvalue of `A^T A` (with margin): the step of the gradient methods and
    /// the scale of ADMM's penalties.
    pub lipschitz: f64,
    pub stop: StopRule,
    /// TV proximal map of the gradient methods (ADMM shrinks exactly and ignores it).
    pub tv_prox: TvProx,
    pub admm: AdmmParams,
}

impl SolverSettings {
    pub fn new(kind: SolverKind, lipschitz: f64, stop: StopRule) -> Self {
        SolverSettings { kind, lipschitz, stop, tv_prox: TvProx::Haar, admm: AdmmParams::default() }
    }
}

/// Solve with the chosen solver from `x0` (zeros when `None`).
pub fn solve<A: Operator + ?Sized>(
    s: &SolverSettings,
    op: &A,
    b: &[f32],
    tv: &TotalVariation,
    x0: Option<Vec<f32>>,
    observer: &mut dyn Observer,
) -> SolveResult {
    match s.kind {
        SolverKind::Fista | SolverKind::FistaRestart => {
            let prox = s.tv_prox.build(tv);
            let f = Fista { lipschitz: s.lipschitz, stop: s.stop.clone(), restart: s.kind == SolverKind::FistaRestart };
            f.solve(op, b, prox.as_ref(), x0, observer)
        }
        SolverKind::Pgd => {
            let prox = s.tv_prox.build(tv);
            Pgd { lipschitz: s.lipschitz, stop: s.stop.clone() }.solve(op, b, prox.as_ref(), x0, observer)
        }
        SolverKind::Mfista => {
            let prox = s.tv_prox.build(tv);
            crate::mfista::MFista { lipschitz: s.lipschitz, stop: s.stop.clone() }.solve(op, b, prox.as_ref(), x0, observer)
        }
        SolverKind::Admm => Admm { lipschitz: s.lipschitz, stop: s.stop.clone(), params: s.admm.clone() }.solve(op, b, tv, x0, observer),
    }
}

/// Elements per parallel block of the element-wise passes.
pub(crate) const BLOCK: usize = 1 << 15;

/// The start shared by the gradient methods (FISTA, MFISTA, PGD): checks the sizes and
/// the Lipschitz constant, returns the step `1/L`, the start `x0` (zeros when `None`)
/// and `A x0`.
pub(crate) fn gradient_start<A: Operator + ?Sized>(op: &A, b: &[f32], lipschitz: f64, x0: Option<Vec<f32>>) -> (f32, Vec<f32>, Vec<f32>) {
    let (n, m) = (op.input_len(), op.output_len());
    assert_eq!(b.len(), m, "measurement size must match the operator's output");
    assert!(lipschitz.is_finite() && lipschitz > 0.0, "Lipschitz constant must be positive");
    let x = x0.unwrap_or_else(|| vec![0.0; n]);
    assert_eq!(x.len(), n);
    let mut ax = vec![0.0f32; m];
    op.forward(&x, &mut ax);
    ((1.0 / lipschitz) as f32, x, ax)
}

/// The gradient step of the data term at `y`, given `A y`:
/// `out = y - step A^T (A y - b)`; `resid` is scratch of the measurement's size.
/// Element-wise passes in parallel blocks; no allocation.
pub(crate) fn gradient_step<A: Operator + ?Sized>(op: &A, b: &[f32], y: &[f32], ay: &[f32], step: f32, resid: &mut [f32], out: &mut [f32]) {
    use rayon::prelude::*;
    for ((r, &p), &q) in resid.iter_mut().zip(ay).zip(b) {
        *r = p - q;
    }
    op.adjoint(resid, out);
    out.par_chunks_mut(BLOCK).zip(y.par_chunks(BLOCK)).for_each(|(g, y)| {
        for (g, &y) in g.iter_mut().zip(y) {
            *g = y - step * *g;
        }
    });
}

/// Solver clock that excludes the time spent in observers.
pub(crate) struct Clock {
    start: Instant,
    paused: Duration,
}

impl Clock {
    pub(crate) fn start() -> Self {
        Clock { start: Instant::now(), paused: Duration::ZERO }
    }
    pub(crate) fn seconds(&self) -> f64 {
        (self.start.elapsed() - self.paused).as_secs_f64()
    }
    /// Run `f` (an observer call) off the clock.
    pub(crate) fn off<R>(&mut self, f: impl FnOnce() -> R) -> R {
        let t = Instant::now();
        let r = f();
        self.paused += t.elapsed();
        r
    }
}

/// `0.5 ||a - b||^2` in f64.
pub(crate) fn half_residual_sq(a: &[f32], b: &[f32]) -> f64 {
    0.5 * a.iter().zip(b).map(|(&p, &q)| ((p - q) as f64).powi(2)).sum::<f64>()
}

/// `||a - b|| / ||a||` in f64.
pub(crate) fn rel_change(new: &[f32], old: &[f32]) -> f64 {
    let mut d = 0.0f64;
    let mut n = 0.0f64;
    for (&a, &b) in new.iter().zip(old) {
        d += ((a - b) as f64).powi(2);
        n += (a as f64).powi(2);
    }
    (d / n.max(1e-300)).sqrt()
}

/// After an iteration: ask the observer (off the clock), then the shared stopping rule.
/// `info.seconds` is the solver's clock at the end of the iteration.
pub(crate) fn after_iteration(clock: &mut Clock, observer: &mut dyn crate::fista::Observer, stop: &StopRule, info: crate::fista::IterInfo) -> Option<crate::fista::Termination> {
    if !clock.off(|| observer.observe(&info)) {
        return Some(crate::fista::Termination::Stopped);
    }
    stop_reason(stop, info.rel_change, info.seconds)
}

/// What the shared stopping rule says after an iteration (observer already asked).
pub(crate) fn stop_reason(stop: &StopRule, rel: f64, seconds: f64) -> Option<crate::fista::Termination> {
    use crate::fista::Termination;
    if stop.rel_tol > 0.0 && rel < stop.rel_tol {
        return Some(Termination::Converged);
    }
    match stop.time_budget_s {
        Some(b) if seconds >= b => Some(Termination::TimeBudget),
        _ => None,
    }
}
