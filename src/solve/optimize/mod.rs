//! The optimisers. [`types`] holds what every solver shares (stopping rules,
//! termination reasons, the per-iteration view its observers see, the result);
//! [`common`] the shared helpers (clock, residual); [`fista`], [`mfista`], [`pgd`] and
//! [`admm`] are the solvers; [`solver`] picks one by name.

pub mod admm;
pub mod common;
pub mod fista;
pub mod mfista;
pub mod pgd;
pub mod solver;
pub mod types;

pub use fista::Fista;
pub use solver::{solve, SolverKind, SolverSettings};
pub use types::{IterInfo, NoObserver, Observer, SolveResult, StopRule, Termination};
