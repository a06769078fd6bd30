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
use crate::solve::prox::tv::TotalVariation;
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
}

impl SolverSettings {
    pub fn new(kind: SolverKind, lipschitz: f64, stop: StopRule) -> Self {
        SolverSettings { kind, lipschitz, stop, tv_prox: TvProx::Haar, admm: AdmmParams::default() }
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
            crate::solve::optimize::mfista::MFista { lipschitz: s.lipschitz, stop: s.stop.clone() }.solve(op, b, prox.as_ref(), x0, observer)
        }
        SolverKind::Admm => Admm { lipschitz: s.lipschitz, stop: s.stop.clone(), params: s.admm.clone() }.solve(op, b, tv, x0, observer),
    }
}
