//! One interface over the solvers of `min 0.5||A v - b||^2 + tau TV_w(v) + [v >= 0]`:
//! FISTA, FISTA with adaptive restart, monotone FISTA, ADMM (variable splitting) and
//! plain proximal gradient. All take the same operator, data, TV term, stopping rule ([`StopRule`]) and
//! observer (the trace is one), and return the same [`SolveResult`]; all run in the
//! same executor loop, whose clock excludes observer time, so their traces compare run
//! time fairly.

use crate::model::op::Operator;
use crate::solve::optimize::admm::{Admm, AdmmParams};
use crate::solve::optimize::fista::Fista;
use crate::solve::optimize::pgd::Pgd;
use crate::solve::optimize::types::{Observer, SolveResult, StopRule};
use crate::solve::prox::sparse::WithL1;
use crate::solve::prox::tv::{Prox, TotalVariation};
use crate::solve::prox::tv_dual::TvProx;
use serde::Serialize;

/// The solvers behind [`solve`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, serde::Deserialize)]
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
    /// Absolute weight of an L1 term beside TV (gradient methods; 0: none).
    pub l1: f32,
}

impl SolverSettings {
    pub fn new(kind: SolverKind, lipschitz: f64, stop: StopRule) -> Self {
        SolverSettings { kind, lipschitz, stop, tv_prox: TvProx::Haar, admm: AdmmParams::default(), l1: 0.0 }
    }

    /// The TV map as reports name it: the prox of the gradient methods, or ADMM's own
    /// exact shrinkage (it ignores `tv_prox`).
    pub fn tv_prox_label(&self) -> String {
        if self.kind == SolverKind::Admm {
            "exact shrinkage (admm)".into()
        } else {
            self.tv_prox.name()
        }
    }
}

/// Solve with the chosen solver from `x0` (zeros when `None`): the gradient methods
/// with the TV map of `s.tv_prox` (and L1 when `s.l1 > 0`), ADMM with exact shrinkage.
pub fn solve<A: Operator + ?Sized>(
    s: &SolverSettings,
    op: &A,
    b: &[f32],
    tv: &TotalVariation,
    x0: Option<Vec<f32>>,
    observer: &mut dyn Observer,
) -> SolveResult {
    match s.kind {
        SolverKind::Admm => {
            assert!(s.l1 == 0.0, "ADMM has no L1 term (settings validation refuses it)");
            Admm { lipschitz: s.lipschitz, stop: s.stop.clone(), params: s.admm.clone() }.solve(op, b, tv, x0, observer)
        }
        _ => {
            let prox = s.tv_prox.build(tv);
            if s.l1 > 0.0 {
                solve_prox(s, op, b, &WithL1 { l1: s.l1, inner: prox, weights: None }, x0, observer)
            } else {
                solve_prox(s, op, b, prox.as_ref(), x0, observer)
            }
        }
    }
}

/// Solve with a gradient method (FISTA, FISTA with restart, MFISTA, PGD) and any
/// proximal term `reg` (e.g. the static + dynamic model's). ADMM, which needs the TV
/// term itself, must be refused by the caller first.
pub fn solve_prox<A: Operator + ?Sized, R: Prox + ?Sized>(
    s: &SolverSettings,
    op: &A,
    b: &[f32],
    reg: &R,
    x0: Option<Vec<f32>>,
    observer: &mut dyn Observer,
) -> SolveResult {
    match s.kind {
        SolverKind::Fista | SolverKind::FistaRestart => {
            Fista { lipschitz: s.lipschitz, stop: s.stop.clone(), restart: s.kind == SolverKind::FistaRestart }.solve(op, b, reg, x0, observer)
        }
        SolverKind::Pgd => Pgd { lipschitz: s.lipschitz, stop: s.stop.clone() }.solve(op, b, reg, x0, observer),
        SolverKind::Mfista => crate::solve::optimize::mfista::MFista { lipschitz: s.lipschitz, stop: s.stop.clone() }.solve(op, b, reg, x0, observer),
        SolverKind::Admm => panic!("solve_prox: ADMM needs the TV term itself; callers refuse it first"),
    }
}
