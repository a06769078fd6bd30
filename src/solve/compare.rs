//! Solvers compared on one problem: the runs to compare ([`SolverRun`], parsed from
//! `admm:cg=8:mu=0.01`), running them with a trace observer ([`run_solvers`]), what each
//! run reached and how fast ([`summarize`], [`time_to_error`]), the objective of the
//! truth ([`truth_objective`]) and what a scene declaration saves ([`measure_savings`]).
//! Used by `rollcam compare`; the files it writes are in [`crate::analysis::compare`].

use crate::model::op::Operator;
use crate::model::scene::ScenePlan;
use crate::solve::job::ChannelJob;
use crate::solve::lipschitz::EigenStore;
use crate::solve::metric::Precondition;
use crate::solve::optimize::admm::AdmmParams;
use crate::solve::optimize::{Device, IterInfo, NoObserver, OptimizerSettings, SolveResult, SolverKind, StopRule};
use crate::solve::problem::DeclaredProblem;
use crate::solve::prox::prior::{PriorSpec, TvPrior};
use crate::solve::prox::tv_dual::{TvProx, TvProxChoice};
use crate::solve::prox::Prox;
use crate::solve::start::{video_start, Start, StillReport};
use crate::solve::trace::{compare, TraceRow};
use serde::Serialize;

/// One curve of the comparison: a solver and the settings it runs with (those not
/// given come from [`RunDefaults`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SolverRun {
    /// As written on the command line: the curve's name.
    pub label: String,
    pub kind: SolverKind,
    pub tv_prox: Option<TvProx>,
    pub cg: Option<usize>,
    pub mu: Option<f64>,
    /// Where the run starts ([`Start`]).
    pub start: Option<Start>,
    /// The gradient steps' metric ([`Precondition`]; `None`: plain).
    pub precond: Option<Precondition>,
    /// Where it runs (`None`: the CPU).
    pub device: Option<Device>,
}

impl std::str::FromStr for SolverRun {
    type Err = String;
    fn from_str(text: &str) -> Result<Self, String> {
        let mut parts = text.split(':');
        let kind: SolverKind = parts.next().unwrap_or_default().trim().parse()?;
        let mut run = SolverRun { label: text.trim().to_string(), kind, tv_prox: None, cg: None, mu: None, start: None, precond: None, device: None };
        for setting in parts {
            let (key, value) = setting
                .split_once('=')
                .ok_or_else(|| format!("'{text}': setting '{setting}' is not KEY=VALUE (keys: tv_prox, start, cg, mu, precond, device)"))?;
            let bad = |what: &str| format!("'{text}': {key} = '{value}': expected {what}");
            match key.trim() {
                "tv_prox" => run.tv_prox = Some(value.trim().parse().map_err(|e: String| bad(&e))?),
                "start" => run.start = Some(value.trim().parse().map_err(|e: String| bad(&e))?),
                "precond" => run.precond = Some(value.trim().parse().map_err(|e: String| bad(&e))?),
                "cg" => run.cg = Some(AdmmParams::parse_cg(value).map_err(|e| bad(&e))?),
                "mu" => run.mu = Some(AdmmParams::parse_mu(value).map_err(|e| bad(&e))?),
                "device" => run.device = Some(value.trim().parse().map_err(|e: String| bad(&e))?),
                other => return Err(format!("'{text}': unknown setting '{other}': expected tv_prox, start, cg, mu, precond or device")),
            }
        }
        if run.kind != SolverKind::Admm && run.cg.is_some() {
            return Err(format!("'{text}': cg is ADMM's setting"));
        }
        if !run.kind.shrinks_tv_itself() && run.mu.is_some() {
            return Err(format!("'{text}': mu is a setting of admm and admm-split"));
        }
        if run.precond == Some(Precondition::Frames) && !run.kind.steps_in_frame_metric() {
            return Err(format!("'{text}': precond is a setting of fista and fista-restart"));
        }
        if run.device.is_some_and(|d| !run.kind.runs_on(d)) {
            return Err(format!("'{text}': device is a setting of fista, fista-restart and admm-split (the other solvers run on the CPU)"));
        }
        if run.kind.shrinks_tv_itself() && run.tv_prox.is_some() {
            return Err(format!("'{text}': {} shrinks the TV term exactly; tv_prox is for the gradient methods", run.kind));
        }
        Ok(run)
    }
}

/// The first label given twice: each run is one curve, so labels must differ.
pub fn duplicate_label(runs: &[SolverRun]) -> Option<&str> {
    runs.iter().enumerate().find(|(i, r)| runs[..*i].iter().any(|o| o.label == r.label)).map(|(_, r)| r.label.as_str())
}

/// Settings of the runs that name none of their own.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RunDefaults {
    /// TV prox of the gradient methods.
    pub tv_prox: TvProx,
    /// CG steps per ADMM iteration.
    pub admm_cg: usize,
    /// ADMM initial penalties relative to the Lipschitz constant.
    pub admm_mu: f64,
    /// Where the runs start.
    pub start: Start,
}

impl RunDefaults {
    /// The defaults checked as the runs' own settings are (the flag named as on the
    /// command line).
    pub fn check(&self) -> Result<(), String> {
        AdmmParams::check_cg(self.admm_cg).map_err(|e| format!("--admm-cg = {}: expected {e}", self.admm_cg))?;
        AdmmParams::check_mu(self.admm_mu).map_err(|e| format!("--admm-mu = {}: expected {e}", self.admm_mu))?;
        Ok(())
    }
}

impl SolverRun {
    /// The prior of this run on `problem`: its TV with the run's map.
    pub fn prior(&self, defaults: &RunDefaults, problem: &DeclaredProblem) -> PriorSpec {
        PriorSpec::Tv(TvPrior::new(problem.tv().clone(), TvProxChoice::Fixed(self.tv_prox.unwrap_or(defaults.tv_prox)), 0.0))
    }

    /// The solver settings of this run.
    pub fn settings(&self, defaults: &RunDefaults, lipschitz: f64, stop: &StopRule) -> OptimizerSettings {
        let mut s = OptimizerSettings::new(self.kind, lipschitz, stop.clone());
        s.admm.cg_iters = self.cg.unwrap_or(defaults.admm_cg);
        s.admm.mu_tv_rel = self.mu.unwrap_or(defaults.admm_mu);
        s.admm.mu_nn_rel = self.mu.unwrap_or(defaults.admm_mu);
        s.device = self.device.unwrap_or_default();
        if let Some(mu) = self.mu {
            // admm-split: the TV and non-negativity penalties relative to its own scale.
            s.split.mu_tv_rel = mu;
            s.split.mu_nn_rel = mu;
        }
        s
    }

    /// The TV map this run uses ("exact shrinkage" for ADMM).
    pub fn tv_prox_name(&self, defaults: &RunDefaults) -> String {
        if self.kind.shrinks_tv_itself() {
            "exact shrinkage".into()
        } else {
            self.tv_prox.unwrap_or(defaults.tv_prox).name()
        }
    }
}

/// One run done: its trace (one row per iteration) and its result.
#[derive(Clone, Debug)]
pub struct RunTrace {
    pub run: SolverRun,
    pub rows: Vec<TraceRow>,
    pub result: SolveResult,
    /// The still solve the run started from (`None`: from zero).
    pub start: Option<StillReport>,
}

/// Run every solver on `problem`, each with the same stop rule, recording every
/// iteration (with its error against `truth_window`, the truth on the full grid of the
/// window's frames, when given). `done` sees each run as it finishes. A run whose
/// solver refuses the problem's data term is refused before any runs
/// ([`SolverKind::check_data`]). A preconditioned run steps in the problem's frame
/// metric ([`DeclaredProblem::frame_metric`]) with its Lipschitz constant from `store`
/// (or measured, not counted in the run's seconds, as the plain one is not).
/// `(runs, defaults)`: the runs and what a run takes where it names nothing.
pub fn run_solvers(
    problem: &DeclaredProblem,
    (runs, defaults): (&[SolverRun], &RunDefaults),
    lipschitz: f64,
    store: &dyn EigenStore,
    stop: &StopRule,
    truth_window: Option<&[f32]>,
    mut done: impl FnMut(&RunTrace),
) -> Result<Vec<RunTrace>, String> {
    for run in runs {
        let device = run.device.unwrap_or_default();
        run.kind
            .check_data(&problem.data())
            .and_then(|()| run.kind.check_operator(&problem.op))
            .and_then(|()| run.kind.check_device(device))
            .map_err(|e| format!("'{}': {e}", run.label))?;
        let prior = run.prior(defaults, problem).build(None);
        if run.precond == Some(Precondition::Frames) {
            run.kind.check_precondition(prior.as_ref()).map_err(|e| format!("'{}': {e}", run.label))?;
        }
        let preconditioned = run.precond == Some(Precondition::Frames);
        run.kind
            .check_on_device(device, &problem.op, &problem.data(), prior.as_ref(), preconditioned)
            .and_then(|()| run.kind.check_device_memory(device, &problem.op, 1))
            .map_err(|e| format!("'{}': {e}", run.label))?;
    }
    let mut traces = Vec::with_capacity(runs.len());
    for run in runs {
        let mut s = run.settings(defaults, lipschitz, stop);
        let prior = run.prior(defaults, problem);
        if run.precond == Some(Precondition::Frames) {
            let metric = problem.frame_metric();
            s.lipschitz = problem.lipschitz_in(&metric, store).value;
            s.metric = Some(metric);
        }
        let mut rows: Vec<TraceRow> = Vec::new();
        let mut rec = |i: &IterInfo| {
            let err = truth_window.and_then(|t| compare(&problem.op.embed(i.x), t));
            rows.push(TraceRow::from_info(i, err));
            true
        };
        // The still start's seconds count in the run's time and trace.
        let restrict = |v: Vec<f32>| problem.op.restrict(&v, false);
        let (x0, start) = video_start(run.start.unwrap_or(defaults.start), problem.model(), &problem.data(), &prior, problem.tv().shape.0, &restrict, None);
        let start_s = start.as_ref().map_or(0.0, |r| r.seconds);
        let mut result = crate::solve::job::run(
            ChannelJob { settings: &s, operator: &problem.op, data: &problem.data(), prior: prior.build(None).as_ref(), start: x0 },
            &mut rec,
        );
        result.seconds += start_s;
        rows.iter_mut().for_each(|r| r.seconds += start_s);
        let trace = RunTrace { run: run.clone(), rows, result, start };
        done(&trace);
        traces.push(trace);
    }
    Ok(traces)
}

/// Seconds at the first row that satisfies `ok` (None: never).
pub fn first_time(rows: &[TraceRow], ok: impl Fn(&TraceRow) -> bool) -> Option<f64> {
    rows.iter().find(|r| ok(r)).map(|r| r.seconds)
}

/// Seconds to first reach a relative error (after the best scale) within each relative
/// tolerance of `best`: `(tolerance, seconds)`. Targets relative to the best any run
/// reached, not absolute PSNRs, which a mostly dark scene meets at the first iteration.
pub fn time_to_error(rows: &[TraceRow], best: f64, tolerances: &[f64]) -> Vec<(f64, Option<f64>)> {
    tolerances.iter().map(|&tol| (tol, first_time(rows, |r| r.rel_error_scaled.is_some_and(|e| e <= best * (1.0 + tol))))).collect()
}

/// The lowest relative error (after the best scale) any run reached (None: no truth).
pub fn best_error(traces: &[RunTrace]) -> Option<f64> {
    traces.iter().flat_map(|t| t.rows.iter().filter_map(|r| r.rel_error_scaled)).reduce(f64::min)
}

/// Seconds to reach an objective within each relative tolerance of `best`.
pub fn time_to_objective(rows: &[TraceRow], best: f64, tolerances: &[f64]) -> Vec<(f64, Option<f64>)> {
    tolerances.iter().map(|&tol| (tol, first_time(rows, |r| r.objective <= best * (1.0 + tol)))).collect()
}

/// The lowest objective any run reached.
pub fn best_objective(traces: &[RunTrace]) -> f64 {
    traces.iter().flat_map(|t| t.rows.iter().map(|r| r.objective)).fold(f64::INFINITY, f64::min)
}

/// What one run reached, and how fast.
#[derive(Clone, Debug, Serialize)]
pub struct SolverSummary {
    pub solver: String,
    /// The TV map this run used ("exact shrinkage" for ADMM).
    pub tv_prox: String,
    /// The still solve it started from (its seconds are in `seconds`); `None`: zero.
    pub start: Option<StillReport>,
    pub iterations: usize,
    pub seconds: f64,
    pub seconds_per_iteration: f64,
    pub termination: String,
    pub objective: f64,
    pub objective_gap_vs_truth: Option<f64>,
    pub final_psnr_db: Option<f64>,
    pub best_psnr_db: Option<f64>,
    /// The relative error after the best scale at the end and at its lowest.
    pub final_rel_error_scaled: Option<f64>,
    pub best_rel_error_scaled: Option<f64>,
    /// Seconds to first reach a relative error within each of [`ERROR_TOLERANCES`] of
    /// the best any run reached (None: never).
    pub time_to_error_s: Vec<(f64, Option<f64>)>,
    /// Seconds to reach objective within 1e-2 / 1e-3 of the best final objective.
    pub time_to_objective_s: Vec<(f64, Option<f64>)>,
}

/// The relative objective tolerances of [`SolverSummary::time_to_objective_s`].
pub const OBJECTIVE_TOLERANCES: [f64; 2] = [1e-2, 1e-3];

/// The relative error tolerances of [`SolverSummary::time_to_error_s`]: within 10% and
/// 1% of the best run's error.
pub const ERROR_TOLERANCES: [f64; 2] = [0.1, 0.01];

/// One summary per run. With a truth, the times to reach within [`ERROR_TOLERANCES`]
/// of the best error of all runs; the objective times are against the best objective
/// of all runs.
pub fn summarize(traces: &[RunTrace], defaults: &RunDefaults, truth_objective: Option<f64>) -> Vec<SolverSummary> {
    let best_obj = best_objective(traces);
    let best_err = best_error(traces);
    traces
        .iter()
        .map(|t| {
            let (rows, r) = (&t.rows, &t.result);
            let psnrs: Vec<f64> = rows.iter().filter_map(|r| r.psnr_db).collect();
            let errors: Vec<f64> = rows.iter().filter_map(|r| r.rel_error_scaled).collect();
            let obj = r.data_term + r.reg_term;
            SolverSummary {
                solver: t.run.label.clone(),
                tv_prox: t.run.tv_prox_name(defaults),
                start: t.start.clone(),
                iterations: r.iterations,
                seconds: r.seconds,
                seconds_per_iteration: r.seconds / r.iterations.max(1) as f64,
                termination: format!("{:?}", r.termination),
                objective: obj,
                objective_gap_vs_truth: truth_objective.map(|t| (obj - t) / t.abs().max(1e-300)),
                final_psnr_db: psnrs.last().cloned(),
                best_psnr_db: psnrs.iter().cloned().reduce(f64::max),
                final_rel_error_scaled: errors.last().cloned(),
                best_rel_error_scaled: errors.iter().cloned().reduce(f64::min),
                time_to_error_s: best_err.map(|b| time_to_error(rows, b, &ERROR_TOLERANCES)).unwrap_or_default(),
                time_to_objective_s: time_to_objective(rows, best_obj, &OBJECTIVE_TOLERANCES),
            }
        })
        .collect()
}

/// The objective `0.5 ||A t - b||^2 + TV(t)` of the truth restricted to the solved grid.
pub fn truth_objective(problem: &DeclaredProblem, truth: &[f32]) -> f64 {
    let mut at = vec![0.0f32; problem.op.output_len()];
    problem.op.forward(truth, &mut at);
    problem.data().value(&at) + problem.tv().value(truth)
}

/// The truth of one channel on the video grid, flattened (frames, rows, cols), from a
/// video (frames, rows, cols, channels): the channels averaged for a grey scene. The
/// error names the grid the truth must have.
pub fn truth_on_grid(plan: &ScenePlan, truth: ndarray::ArrayView4<f32>, channel: usize) -> Result<Vec<f32>, String> {
    use ndarray::Axis;
    let (tk, tm, tn, tc) = truth.dim();
    let (k, m, n) = plan.full_shape;
    if (tk, tm, tn) != (k, m, n) {
        return Err(format!("truth is {tk} x {tm} x {tn}: expected the video grid (frames, rows, cols) = {k} x {m} x {n}"));
    }
    let ch = if plan.channels_solved == 1 && plan.channels_captured > 1 {
        // Grey scene: the truth's channels averaged, as the raw is.
        truth.mean_axis(Axis(3)).expect("the truth has channels")
    } else {
        truth.index_axis(Axis(3), channel.min(tc - 1)).to_owned()
    };
    Ok(ch.iter().cloned().collect())
}

/// The frames of the window of `plan` out of a full-grid truth from [`truth_on_grid`]:
/// errors are measured there (an estimate restricted to a support is zero outside it,
/// as the scene is declared to be).
pub fn truth_window(plan: &ScenePlan, truth_full: &[f32]) -> Vec<f32> {
    let (_, m, n) = plan.full_shape;
    let (k0, k1) = plan.frames;
    truth_full[k0 * m * n..k1 * m * n].to_vec()
}

/// The bounding box `[r0, r1, c0, c1]` (ends excluded) of the light in any frame of a
/// video (frames, rows, cols, channels), grown by `margin` pixels within the frame; None
/// for a dark video.
pub fn support_from_truth(truth: ndarray::ArrayView4<f32>, margin: usize) -> Option<[usize; 4]> {
    let (_, tm, tn, _) = truth.dim();
    let (mut r0, mut r1, mut c0, mut c1) = (usize::MAX, 0, usize::MAX, 0);
    for ((_, r, c, _), &v) in truth.indexed_iter() {
        if v > 0.0 {
            (r0, r1, c0, c1) = (r0.min(r), r1.max(r + 1), c0.min(c), c1.max(c + 1));
        }
    }
    (r0 < r1).then(|| [r0.saturating_sub(margin), (r1 + margin).min(tm), c0.saturating_sub(margin), (c1 + margin).min(tn)])
}

/// What a scene declaration saved: unknowns, iterate memory, time per iteration.
#[derive(Clone, Debug, Serialize)]
pub struct Savings {
    pub full_unknowns: usize,
    pub solved_unknowns: usize,
    pub full_seconds_per_iteration: f64,
    pub solved_seconds_per_iteration: f64,
    pub full_iterate_bytes: usize,
    pub solved_iterate_bytes: usize,
}

/// Time a few FISTA (restart) iterations on the undeclared problem `full` and the
/// declared `problem` (the full problem's time scaled to every captured channel).
pub fn measure_savings(full: &DeclaredProblem, problem: &DeclaredProblem, lipschitz: f64) -> Savings {
    let it = 10;
    let time = |p: &DeclaredProblem| {
        let s = OptimizerSettings::new(SolverKind::FistaRestart, lipschitz, StopRule::iterations(it));
        crate::solve::job::run(ChannelJob { settings: &s, operator: &p.op, data: &p.data(), prior: p.tv(), start: None }, &mut NoObserver).seconds / it as f64
    };
    let plan = problem.plan();
    let (fu, su) = plan.unknowns();
    let per_channel = plan.channels_captured as f64 / plan.channels_solved as f64;
    Savings {
        full_unknowns: fu,
        solved_unknowns: su,
        full_seconds_per_iteration: time(full) * per_channel,
        solved_seconds_per_iteration: time(problem),
        full_iterate_bytes: fu * 4,
        solved_iterate_bytes: su * 4,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(seconds: f64, objective: f64, err: Option<f64>) -> TraceRow {
        TraceRow {
            iteration: 0,
            seconds,
            objective,
            data_term: 0.0,
            tv_term: 0.0,
            rel_change: 0.0,
            psnr_db: None,
            rel_error: None,
            rel_error_scaled: err,
            motion_error: None,
        }
    }

    #[test]
    fn runs_parse_with_their_settings() {
        let r: SolverRun = "admm:cg=8:mu=0.01".parse().unwrap();
        assert_eq!((r.kind, r.cg, r.mu, r.label.as_str()), (SolverKind::Admm, Some(8), Some(0.01), "admm:cg=8:mu=0.01"));
        let r: SolverRun = "fista".parse().unwrap();
        assert_eq!((r.kind, r.cg, r.mu, r.tv_prox, r.precond), (SolverKind::Fista, None, None, None, None));
        assert_eq!("fista-restart:precond=frames".parse::<SolverRun>().unwrap().precond, Some(Precondition::Frames));
        assert!("fista:tv_prox=dual10".parse::<SolverRun>().unwrap().tv_prox.is_some());
        for (text, what) in [
            ("fista:cg=3", "ADMM's setting"),
            ("admm-split:cg=3", "ADMM's setting"),
            ("fista:mu=0.1", "admm and admm-split"),
            ("admm:tv_prox=haar", "exactly"),
            ("admm:cg=0", "from 1 to 1000"),
            ("admm:cg=18446744073709551615", "from 1 to 1000"),
            ("admm:mu=-1", "positive penalty"),
            ("fista:x=1", "unknown setting 'x'"),
            ("fista:cg", "not KEY=VALUE"),
            ("admm-split:precond=frames", "fista and fista-restart"),
            ("fista:precond=rows", "none or frames"),
        ] {
            let e = text.parse::<SolverRun>().unwrap_err();
            assert!(e.contains(what), "{text}: {e}");
        }
        let runs: Vec<SolverRun> = ["fista", "admm", "fista"].iter().map(|s| s.parse().unwrap()).collect();
        assert_eq!(duplicate_label(&runs), Some("fista"));
        assert_eq!(duplicate_label(&runs[..2]), None);
    }

    #[test]
    fn time_to_error_is_the_first_row_within_the_tolerance_of_the_best() {
        let rows = [row(0.1, 10.0, Some(0.5)), row(0.2, 5.0, Some(0.21)), row(0.3, 4.0, Some(0.25)), row(0.4, 3.0, Some(0.2))];
        assert_eq!(time_to_error(&rows, 0.2, &[0.1, 0.01, 0.0]), vec![(0.1, Some(0.2)), (0.01, Some(0.4)), (0.0, Some(0.4))]);
        assert_eq!(time_to_error(&rows, 0.1, &[0.1]), vec![(0.1, None)]);
        assert_eq!(time_to_objective(&rows, 3.0, &[0.5, 1e-3]), vec![(0.5, Some(0.3)), (1e-3, Some(0.4))]);
        assert_eq!(time_to_error(&[row(0.1, 1.0, None)], 1.0, &[1.0]), vec![(1.0, None)]);
    }
}
