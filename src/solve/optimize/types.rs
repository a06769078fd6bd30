//! What every solver shares: stopping rules as data ([`StopRule`]), why a run ended
//! ([`Termination`]), what observers see after each iteration ([`IterInfo`],
//! [`Observer`]; the error-against-time trace is one), and the outcome
//! ([`SolveResult`]).

use serde::Serialize;

/// When to stop.
#[derive(Clone, Debug, Serialize)]
pub struct StopRule {
    pub max_iters: usize,
    /// Stop when `||x_k - x_{k-1}|| / ||x_k|| < rel_tol` (0 disables).
    pub rel_tol: f64,
    /// Stop when the solver's own time exceeds this many seconds.
    pub time_budget_s: Option<f64>,
    /// Stop when the run has settled, three ways at once (0 disables the rule):
    /// - the objective's relative change `|F_k - F_{k-1}| / |F_k|` has stayed below
    ///   `obj_tol` for [`OBJ_TOL_PATIENCE`] iterations in a row;
    /// - the iterate's relative change (the method's `rel_change`) has stayed below
    ///   [`ITERATE_PER_OBJ_TOL`] `* obj_tol` for as many iterations;
    /// - the data term fell by less than [`DATA_FALL_PER_OBJ_TOL`] `* obj_tol` of its
    ///   value per iteration, on average over the last [`DATA_WINDOW`] iterations, or
    ///   is at or below [`StopRule::noise_floor`].
    ///
    /// The patience keeps a momentary plateau of an accelerated method from ending the
    /// run. The objective alone stopped runs that were far from done: on an
    /// ill-conditioned still the iterate walks along a nearly flat valley (the error
    /// against the truth fell from 0.19 to 0.11 after the objective "settled"), and
    /// after a still start a video forms its motion by trading TV for data fit while
    /// the sum barely moves (a dense scene "converged" with every frame the same
    /// picture). docs/usage.md, *When a run is done*, has the measurements.
    pub obj_tol: f64,
    /// The data term's value at which the misfit is the noise's (half the sum of the
    /// noise variances over the kept pixels), where the sensor's noise is known: at or
    /// below it the data term counts as settled for the objective rule, since a further
    /// fall fits the noise (a run that went on there lost its video's motion to it).
    pub noise_floor: Option<f64>,
    /// Whether the objective rule waits for the iterate too (its second condition;
    /// true but for the first round of a reweighted-L1 solve, whose reweighting moves the
    /// iterate further than the rest of that round would:
    /// [`crate::solve::static_dynamic`]).
    pub wait_for_iterate: bool,
}

/// Iterations in a row the objective must change by less than `obj_tol`.
pub const OBJ_TOL_PATIENCE: usize = 5;

/// The iterate's relative change, in units of `obj_tol`, below which it counts as
/// settled for the objective rule.
pub const ITERATE_PER_OBJ_TOL: f64 = 2.0;

/// Iterations over which the data term's fall is averaged for the objective rule.
pub const DATA_WINDOW: usize = 20;

/// The data term's average relative fall per iteration over [`DATA_WINDOW`]
/// iterations, in units of `obj_tol`, below which it counts as settled. Chosen on
/// traces of the dense scenes (docs/usage.md, *When a run is done*): from 2 to 5 the
/// stops were the same.
pub const DATA_FALL_PER_OBJ_TOL: f64 = 3.0;

impl StopRule {
    pub fn iterations(n: usize) -> Self {
        StopRule { max_iters: n, rel_tol: 0.0, time_budget_s: None, obj_tol: 0.0, noise_floor: None, wait_for_iterate: true }
    }

    /// This rule with the data term's noise floor ([`StopRule::noise_floor`]).
    pub fn with_noise_floor(mut self, floor: Option<f64>) -> StopRule {
        self.noise_floor = floor.filter(|f| f.is_finite() && *f > 0.0);
        self
    }

    /// Checks the rule's values: at least one iteration, non-negative finite
    /// tolerances, a positive finite time budget. The error is (field, value, expected).
    pub fn check(&self) -> Result<(), (&'static str, String, &'static str)> {
        if self.max_iters == 0 {
            return Err(("iters", "0".into(), "at least one iteration"));
        }
        // Both are relative changes per iteration: at 1 or more every first step
        // "converges".
        if !(self.rel_tol.is_finite() && (0.0..1.0).contains(&self.rel_tol)) {
            return Err(("rel_tol", self.rel_tol.to_string(), "a relative change from 0 (off) to below 1"));
        }
        if !(self.obj_tol.is_finite() && (0.0..1.0).contains(&self.obj_tol)) {
            return Err(("obj_tol", self.obj_tol.to_string(), "a relative change from 0 (off) to below 1"));
        }
        if let Some(b) = self.time_budget_s {
            if !(b.is_finite() && b > 0.0) {
                return Err(("time_budget_s", b.to_string(), "a positive number of seconds"));
            }
        }
        Ok(())
    }
}

/// Why a solve ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case", tag = "reason")]
pub enum Termination {
    MaxIterations,
    Converged,
    TimeBudget,
    /// An observer asked to stop (e.g. Ctrl-C, a target error reached).
    Stopped,
    /// The iterate or objective became NaN/Inf at `iteration`; the last finite iterate
    /// is returned.
    NonFinite {
        iteration: usize,
    },
}

/// What an observer sees after every iteration.
pub struct IterInfo<'a> {
    pub iteration: usize,
    /// Solver seconds since start (observer time excluded).
    pub seconds: f64,
    pub data_term: f64,
    pub reg_term: f64,
    pub rel_change: f64,
    pub x: &'a [f32],
}

impl IterInfo<'_> {
    pub fn objective(&self) -> f64 {
        self.data_term + self.reg_term
    }
}

/// Watches iterations; returns `false` to stop the solver.
pub trait Observer {
    fn observe(&mut self, info: &IterInfo) -> bool;
}

/// An observer that does nothing.
pub struct NoObserver;
impl Observer for NoObserver {
    fn observe(&mut self, _: &IterInfo) -> bool {
        true
    }
}

impl<F: FnMut(&IterInfo) -> bool> Observer for F {
    fn observe(&mut self, info: &IterInfo) -> bool {
        self(info)
    }
}

/// The outcome of a solve.
#[derive(Clone, Debug)]
pub struct SolveResult {
    pub x: Vec<f32>,
    pub iterations: usize,
    pub seconds: f64,
    pub termination: Termination,
    pub data_term: f64,
    pub reg_term: f64,
}
