//! The optimisers. [`types`] holds what every solver shares (stopping rules,
//! termination reasons, the per-iteration view its observers see, the result);
//! [`executor`] the one loop every solver runs in (clock, stopping rules, the
//! non-finite check, observers, the result), around a solver's `Step`; [`common`] the
//! helpers the steps share (gradient start and step, residual and change norms);
//! [`fista`] (with adaptive restart), [`mfista`], [`pgd`], [`admm`] and [`admm_split`] are the solvers,
//! each a step; [`solver`] picks one by name.
//!
//! Imports run one way: the solver files use `types`, `common` and `executor`;
//! `solver` uses the solvers; this file only declares and re-exports.

pub mod admm;
pub mod admm_split;
pub mod common;
#[cfg(feature = "cuda")]
pub mod cuda;
pub mod device;
pub mod executor;
pub mod fista;
pub mod mfista;
pub mod pgd;
pub mod solver;
pub mod types;

pub use device::Device;
pub use fista::{Fista, RestartTest};
pub use solver::{solve, OptimizerSettings, SolverKind};
pub use types::{
    IterInfo, NoObserver, Observer, SolveResult, StopRule, Termination, DATA_FALL_PER_OBJ_TOL, DATA_WINDOW, ITERATE_PER_OBJ_TOL, OBJ_TOL_PATIENCE,
};
