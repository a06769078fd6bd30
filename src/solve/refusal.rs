//! Why a solve plan cannot be solved as asked ([`crate::solve::plan::SolvePlan::decide`]).

use crate::solve::optimize::{Device, SolverKind};

/// Why a plan cannot be solved as asked: each names what to change.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Refusal {
    /// The static + dynamic model with a splitting solver.
    #[error("{model} needs a gradient solver (fista, fista-restart, mfista, pgd): {solver}'s splitting has no static + dynamic map")]
    ModelSolver { model: &'static str, solver: SolverKind },
    /// The static + dynamic model off the CPU.
    #[error("{model} runs on the CPU: the static + dynamic model has no step on --device {device}")]
    ModelDevice { model: &'static str, device: Device },
    /// The solver cannot take the data (its own reason).
    #[error("{0}")]
    Data(String),
    /// Key frames with something they are not solved with.
    #[error("[[keyframes]]: key frames are solved with the static + dynamic model (the default) or on the plain video ([scene] static_background = false), on the CPU; {with} is not taken with them (leave it out, or the key frames)")]
    KeyFrames { with: String },
    /// The L1 weight out of its range (its own reason).
    #[error("{0}")]
    L1(String),
    /// Reweighted L1 without the static + dynamic model.
    #[error("l1_reweight: reweighted L1 applies to the dynamic part of the static + dynamic model ([scene] static_background = true)")]
    L1Reweight,
    /// What a split across MPI ranks cannot solve, and what to do instead.
    #[error("split across MPI ranks: {what}; {instead}")]
    NotSplit { what: String, instead: String },
    /// What consecutive captures solved as one video do not take.
    #[error("{what}: {why}")]
    NotInSequence { what: &'static str, why: &'static str },
}
