//! How long a solve will take, estimated before it starts: one forward and one adjoint
//! application of a channel's operator are timed (the FFT work of one iteration of
//! every solver here) and multiplied by the iterations and channels to come.

use crate::model::op::Operator;
use crate::solve::problem::Problem;
use serde::Serialize;
use std::time::Instant;

/// Above this many estimated seconds a front-end warns before it starts.
pub const LONG_SOLVE_S: f64 = 60.0;

/// The estimate of a solve, before it starts.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SolveEstimate {
    /// Seconds of one forward plus one adjoint application of a channel's operator, as
    /// timed.
    pub seconds_per_iteration: f64,
    pub iterations: usize,
    pub channels: usize,
    /// `iterations x channels x seconds_per_iteration`: an order of magnitude, not a
    /// bound: the timed application is the first (plans and memory touched for the
    /// first time make it slower than the solver's), while the TV step, the step size's
    /// power iteration when not cached and the still start add to the solve.
    pub seconds: f64,
}

impl SolveEstimate {
    /// Whether the solve is long enough to warn before it starts ([`LONG_SOLVE_S`]).
    pub fn is_long(&self) -> bool {
        self.seconds > LONG_SOLVE_S
    }
}

/// Time one forward and one adjoint of `problem`'s first channel (on an iterate of
/// ones) and scale it to `iterations` on `channels` channels.
pub fn estimate(problem: &Problem, iterations: usize, channels: usize) -> SolveEstimate {
    let op = &problem.models()[0];
    let x = vec![1.0f32; op.input_len()];
    let mut y = vec![0.0f32; op.output_len()];
    let mut back = vec![0.0f32; op.input_len()];
    let t0 = Instant::now();
    op.forward(&x, &mut y);
    op.adjoint(&y, &mut back);
    let seconds_per_iteration = t0.elapsed().as_secs_f64();
    SolveEstimate { seconds_per_iteration, iterations, channels, seconds: seconds_per_iteration * (iterations * channels) as f64 }
}
