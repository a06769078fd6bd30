//! One solve of one channel's problem: a [`ChannelJob`] and [`run`], the only caller of
//! [`crate::solve::optimize::solve`] outside the solvers.

use crate::model::data::DataTerm;
use crate::model::op::Operator;
use crate::solve::optimize::{Observer, OptimizerSettings, SolveResult};
use crate::solve::prox::Prox;

/// What one solve takes: the solver with its step and stop rule, the operator, the
/// data term (the raw, with the key frames' observations stacked when the operator is
/// fused with theirs), the prior and the start.
pub struct ChannelJob<'a, A: ?Sized, R: ?Sized> {
    /// The solver, its Lipschitz constant and its stop rule.
    pub settings: &'a OptimizerSettings,
    pub operator: &'a A,
    pub data: &'a DataTerm<'a>,
    pub prior: &'a R,
    /// Where the solve starts (`None`: zero).
    pub start: Option<Vec<f32>>,
}

/// Run `job`, telling `observer` of every iteration (it returns false to stop).
///
/// # Panics
/// When the solver refuses the job's data, prior, operator or device
/// ([`crate::solve::optimize::solve`]): the plan and the modes check first.
pub fn run<A: Operator + ?Sized, R: Prox + ?Sized>(job: ChannelJob<'_, A, R>, observer: &mut dyn Observer) -> SolveResult {
    crate::solve::optimize::solve(job.settings, job.operator, job.data, job.prior, job.start, observer)
}
