//! The solvers on one capture, side by side: [`CompareRequest`] -> [`CompareOutcome`],
//! in two steps so that a front-end can say what the problem is before the runs:
//! [`CompareRequest::load`] prepares the capture, resolves the weight as `reconstruct`
//! does and builds the declared problem of one channel with its Lipschitz constant
//! ([`LoadedCompare`]); [`LoadedCompare::run`] runs every solver on it.

use crate::io::budget::check_reconstruction;
use crate::model::prepare::Prepared;
use crate::model::scene::SceneSpec;
use crate::request::capture::CaptureRequest;
use crate::request::RequestError;
use crate::solve::compare::{
    measure_savings, run_solvers, summarize, support_from_truth, truth_objective, truth_on_grid, truth_window, Savings, SolverSummary,
};
pub use crate::solve::compare::{RunDefaults, RunTrace, SolverRun};
use crate::solve::lipschitz::{EigenStore, LIPSCHITZ_MARGIN};
pub use crate::solve::optimize::StopRule;
use crate::solve::plan::{Mode, Processes, SolveOptions, SolvePlan};
use crate::solve::problem::{DeclaredProblem, Problem, SolveParams};
use ndarray::Array4;
use std::sync::atomic::AtomicBool;

// The runs' vocabulary, for a front-end that parses them.
pub use crate::solve::compare::duplicate_label;
pub use crate::solve::prox::tv_dual::TvProx;
use std::time::Instant;

/// Several solver runs on one channel of one capture, each with the same stop rule.
pub struct CompareRequest<'a> {
    /// The capture; its settings give the weight (`tau`, `tau_rel`, `alpha`); its
    /// scene is not read (see `scene`).
    pub capture: CaptureRequest<'a>,
    /// The scene's keys: capture.toml's `[scene]` with the front-end's over it
    /// (`None`: the full grid, nothing declared).
    pub scene: Option<toml::Table>,
    /// Declare `support` as the truth's bounding box grown by this many pixels (an
    /// oracle declaration, to study what a support saves).
    pub support_from_truth: Option<usize>,
    /// The channel compared on (ignored for a grey scene).
    pub channel: usize,
    pub runs: &'a [SolverRun],
    /// Settings of the runs that name none of their own.
    pub defaults: RunDefaults,
    pub stop: StopRule,
    /// Also time a few iterations of the undeclared problem (what the declaration saved).
    pub measure_savings: bool,
}

/// The problem every run solves, built once.
pub struct LoadedCompare<'a> {
    pub request: &'a CompareRequest<'a>,
    pub prepared: Prepared,
    /// The declared problem of the channel.
    pub problem: DeclaredProblem,
    /// The undeclared problem of the channel (its operator shared with `problem`'s
    /// where the declaration leaves it as it is), when the savings are measured.
    undeclared: Option<DeclaredProblem>,
    /// The weight as resolved on the undeclared problem (how it was chosen included).
    pub params: SolveParams,
    /// The TV weight of the declared problem (a static scene's one frame weighs more).
    pub tau: f32,
    /// Lipschitz constant (with margin), the seconds it took (cached per operator) and
    /// the power iterations it took.
    pub lipschitz: f64,
    pub lipschitz_seconds: f64,
    pub power_iterations: usize,
    /// The objective of the truth on the solved grid.
    pub truth_objective: Option<f64>,
    truth_window: Option<Vec<f32>>,
}

/// What the runs gave: each run's trace, the summaries, the savings when measured.
pub struct CompareOutcome {
    pub traces: Vec<RunTrace>,
    pub summaries: Vec<SolverSummary>,
    pub savings: Option<Savings>,
}

impl<'a> CompareRequest<'a> {
    /// Prepare the capture, declare the scene, resolve the weight from the undeclared
    /// problem's scale (as `reconstruct` does, so that a declaration changes the
    /// unknowns, not the objective), build the declared problem and its Lipschitz
    /// constant (cached per operator in `cache`).
    pub fn load(&'a self, cache: &dyn EigenStore) -> Result<LoadedCompare<'a>, RequestError> {
        let r = &self.capture;
        let cfg = r.cfg;
        check_reconstruction(cfg, cfg.fov, 1, 1).map_err(Box::new)?;
        let prepared = r.prepare_data()?;
        (r.on_sensor)(&prepared.sensor);
        let full = Problem::new(&prepared, cfg, cfg.fov).map_err(RequestError::Solve)?;
        // The plan `reconstruct` would run on the plain video of the whole grid (or the
        // declaration; the static + dynamic model only where declared): its weight, its
        // refusals.
        let spec = self.spec()?;
        let plain = SceneSpec { whole_grid: spec.is_plain(), static_background: spec.static_background.or(Some(false)), ..spec };
        let options = SolveOptions { scene: Some(plain), measure_full: false };
        let plan = SolvePlan::decide(&full, r.settings, &options, Processes::One, cache, &AtomicBool::new(false))?;
        let not_compared = match plan.mode {
            Mode::StaticDynamic(_) => Some("static_background = true: compare runs the solvers on the plain (or declared) video; the static + dynamic model is solved by `rollcam reconstruct` (judge it with `rollcam analyze --truth`), or give --full-grid"),
            Mode::KeyFrames => Some("[[keyframes]]: compare runs the solvers on the raw's plain (or declared) video; key frames are solved by `rollcam reconstruct`"),
            Mode::WholeGrid | Mode::Declared | Mode::SparseSources => None,
        };
        if let Some(why) = not_compared {
            return Err(RequestError::Invalid(why.into()));
        }
        let (spec, params) = (plan.spec, plan.params);
        let tau = params.prior(false).for_scene(&spec, full.weights().frames()).tau;
        let problem = full.declare(&spec, tau, params.alpha, self.channel)?;
        let undeclared = (self.measure_savings && !problem.plan().left_out.is_empty())
            .then(|| full.declare(&SceneSpec::default(), tau, params.alpha, self.channel))
            .transpose()?;
        drop(full);
        let truth_full = match r.truth {
            Some((t, name)) => Some(truth_on_grid(problem.plan(), t, self.channel).map_err(|e| RequestError::Invalid(format!("{name}: {e}")))?),
            None => None,
        };
        let truth = truth_full.as_ref().map(|t| problem.restrict_truth(t));
        let truth_window = truth_full.as_ref().map(|t| truth_window(problem.plan(), t));
        let t_l = Instant::now();
        let (eig, _) = problem.eigen(cache);
        let lipschitz = eig.lambda_max * LIPSCHITZ_MARGIN;
        let lipschitz_seconds = t_l.elapsed().as_secs_f64();
        let truth_objective = truth.as_ref().map(|t| truth_objective(&problem, t));
        Ok(LoadedCompare {
            request: self,
            prepared,
            problem,
            undeclared,
            params,
            tau,
            lipschitz,
            lipschitz_seconds,
            power_iterations: eig.iterations,
            truth_objective,
            truth_window,
        })
    }

    /// The declaration: the scene's keys, and the truth's support when asked.
    fn spec(&self) -> Result<SceneSpec, RequestError> {
        let Some(table) = &self.scene else { return Ok(SceneSpec::default()) };
        let mut table = table.clone();
        if let (Some(margin), Some((t, _))) = (self.support_from_truth, self.capture.truth) {
            if let Some(sup) = support_from_truth(t, margin) {
                table.insert("support".into(), toml::Value::Array(sup.iter().map(|&x| toml::Value::Integer(x as i64)).collect()));
            }
        }
        let config = self.capture.config_name.unwrap_or("the scene declaration");
        SceneSpec::from_table(Some(&table)).map_err(|e| RequestError::Invalid(format!("{config}: {e}")))
    }
}

impl LoadedCompare<'_> {
    /// Run every solver (`done` sees each run as it finishes), summarise, and measure
    /// the savings when asked.
    pub fn run(&self, cache: &dyn EigenStore, done: impl FnMut(&RunTrace)) -> Result<CompareOutcome, RequestError> {
        let r = self.request;
        let traces = run_solvers(&self.problem, (r.runs, &r.defaults), self.lipschitz, cache, &r.stop, self.truth_window.as_deref(), done)
            .map_err(RequestError::Invalid)?;
        let summaries = summarize(&traces, &r.defaults, self.truth_objective);
        // What the declaration saved: a few FISTA iterations on the full problem.
        let savings = self.undeclared.as_ref().map(|full| measure_savings(full, &self.problem, self.lipschitz));
        Ok(CompareOutcome { traces, summaries, savings })
    }

    /// A run's last iterate as a video (frames, rows, cols, 1) on the full grid: zero
    /// outside a declared window or support.
    pub fn full_video(&self, trace: &RunTrace) -> Array4<f32> {
        let plan = self.problem.plan();
        let (k, mv, nv) = plan.full_shape;
        let (k0, _) = plan.frames;
        let window = self.problem.op.embed(&trace.result.x);
        let mut video = vec![0.0f32; k * mv * nv];
        video[k0 * mv * nv..k0 * mv * nv + window.len()].copy_from_slice(&window);
        Array4::from_shape_vec((k, mv, nv, 1), video).expect("the full grid's size")
    }
}
