//! One capture to one video: build the imaging operator per colour channel, measure
//! (or recall) its Lipschitz constant, run the solver (FISTA by default) with TV, record
//! the trace. Channels are solved in parallel, each with its own PSF. A scene
//! declaration (`[scene]` of capture.toml, or [`SolveOptions::scene`]) restricts the
//! problem to what the scene needs (see [`crate::model::scene`]); the undeclared operator
//! then checks the result (residual, and whether the data want light where the
//! declaration allows none).

use crate::model::data::DataTerm;
use crate::model::op::Operator;
use crate::model::scene::{Colour, ScenePlan, SceneSpec};
pub use crate::solve::channel::{ChannelReport, FrameSensitivity, Hooks, ModelChoice, Reconstruction, SceneReport, SolveStats, WEAK_FRAME};
use crate::solve::channel::{ChannelSolve, FullGrid};
use crate::solve::lipschitz::EigenStore;
use crate::solve::optimize::StopRule;
use crate::solve::plan::{Mode, Processes, SolvePlan};
use crate::solve::problem::{reweight_plan, ChannelProblem, PriorRecipe, Problem, ValidSettings};
pub use crate::solve::problem::{ReconstructError, SolveParams};
use crate::solve::start::StillReport;
use crate::solve::support::{Support, SupportReport};
use crate::solve::trace::{motion_error, Baselines};
use ndarray::{Array4, ArrayView4, Axis};
use rayon::prelude::*;
use std::time::Instant;

pub use crate::solve::plan::SolveOptions;

/// Above this [`SceneReport::outside_optimality_ratio`] the declaration is reported as
/// contradicted by the data (see `tests/solve/scene_reconstruct.rs` for measured values).
pub const CONTRADICTION_RATIO: f64 = 3.0;

/// Decide the plan ([`SolvePlan::decide`], one process) and solve it.
pub fn reconstruct(
    problem: &Problem,
    settings: &ValidSettings,
    opts: &SolveOptions,
    truth: Option<(ArrayView4<f32>, &str)>,
    cache: &dyn EigenStore,
    hooks: &Hooks,
) -> Result<(Reconstruction, SolveParams), ReconstructError> {
    let plan = SolvePlan::decide(problem, settings, opts, Processes::One, cache, hooks.stop)?;
    let rec = solve(problem, &plan, truth, cache, hooks)?;
    Ok((rec, plan.params))
}

/// Solve `problem` as `plan` says (decided on this problem): every channel, the error
/// against run time counting the plan's still checks and weight search.
pub fn solve(
    problem: &Problem,
    plan: &SolvePlan,
    truth: Option<(ArrayView4<f32>, &str)>,
    cache: &dyn EigenStore,
    hooks: &Hooks,
) -> Result<Reconstruction, ReconstructError> {
    let mut rec = solve_channels(problem, plan, truth, cache, hooks)?;
    if !plan.params.start.uses_still(plan.frames) {
        // Error against run time: a still start goes on from the checks and counts
        // their seconds; a solve from zero did not use them.
        rec.add_prior_seconds(plan.check_seconds());
    }
    if let Some(s) = &plan.tau_search {
        rec.add_prior_seconds(s.seconds);
    }
    rec.tau_search = plan.tau_search.clone();
    rec.plan = Some(plan.report());
    Ok(rec)
}

/// Solve a built [`Problem`] as `plan` says.
fn solve_channels(
    problem: &Problem,
    plan: &SolvePlan,
    truth: Option<(ArrayView4<f32>, &str)>,
    cache: &dyn EigenStore,
    hooks: &Hooks,
) -> Result<Reconstruction, ReconstructError> {
    let prepared = problem.prepared;
    let params = &plan.params;
    let (spec, declared_in) = (&plan.spec, plan.declared_in);
    if problem.fov != params.fov {
        return Err(ReconstructError::Fov { problem: problem.fov, params: params.fov });
    }
    let captured = prepared.raw.len();
    let grey = spec.colour == Colour::Grey && captured > 1;
    let truth_planes = truth_planes(problem, truth, grey)?;
    let recipe = params.prior(plan.static_dynamic());
    if let Some(chosen_by) = plan.model {
        return crate::solve::static_dynamic::StaticDynamicSolve {
            problem,
            params,
            spec,
            declared_in,
            chosen_by,
            recipe,
            reweight: reweight_plan(params.l1_reweight),
            truth_planes,
            cache,
            hooks,
            still_checks: &plan.still_checks,
            keyframe_noise: (plan.keyframes > 0).then(|| crate::solve::problem::prepared_noise(prepared, plan.frames).map(|n| n.sigma)),
        }
        .reconstruct();
    }
    let plain_stops = (0..problem.channels()).map(|ch| params.stop.clone().with_noise_floor(crate::solve::fit::noise_floor(problem, ch))).collect();
    let solve = ChannelsSolve {
        problem,
        params,
        plain_stops,
        recipe,
        truth_planes: truth_planes.as_deref(),
        cache,
        hooks,
        still_checks: &plan.still_checks,
        support: plan.support.as_ref(),
    };
    let (results, scene) = match plan.mode {
        Mode::Declared => solve.declared(spec, declared_in, plan.measure_full).map(|(r, s)| (r, Some(s)))?,
        Mode::KeyFrames => (solve.with_keyframes()?, None),
        Mode::WholeGrid | Mode::SparseSources | Mode::StaticDynamic => (solve.plain()?, None),
    };
    Ok(solve.assemble(results, scene))
}

/// Truth per output channel, on the full video grid (zero outside the sensor for
/// --fov full; the channel mean for a grey scene).
fn truth_planes(problem: &Problem, truth: Option<(ArrayView4<f32>, &str)>, grey: bool) -> Result<Option<Vec<Vec<f32>>>, ReconstructError> {
    let Some((t, name)) = truth else {
        return Ok(None);
    };
    let model = problem.channel(0).model();
    let (k, mv, nv) = model.video_shape();
    let captured = problem.prepared.raw.len();
    check_truth(&t, name, k, (mv, nv), model.conv().sensor_shape(), captured, grey)?;
    if t.iter().all(|&v| v == 0.0) {
        tracing::warn!("{name}: {}; the error figures are left out", crate::solve::trace::ZERO_TRUTH);
    }
    let channels_out = if grey { 1 } else { captured };
    Ok(Some((0..channels_out).map(|ch| truth_plane(&t, ch, grey, 0..k, (mv, nv), model.conv().offset())).collect()))
}

/// Every output channel's video (on the full grid) and report.
type Solved = Vec<(Vec<f32>, ChannelReport)>;

/// Every channel's solve of a plain or declared video: what each reads.
struct ChannelsSolve<'a> {
    problem: &'a Problem<'a>,
    params: &'a SolveParams,
    /// Each captured channel's stop rule for the plain video: the run's, with the
    /// channel's noise floor ([`crate::solve::fit::noise_floor`]).
    plain_stops: Vec<StopRule>,
    recipe: PriorRecipe,
    truth_planes: Option<&'a [Vec<f32>]>,
    cache: &'a dyn EigenStore,
    hooks: &'a Hooks<'a>,
    /// [`SceneChoice::still_checks`].
    still_checks: &'a [StillReport],
    /// [`SceneChoice::support`].
    support: Option<&'a Support>,
}

/// One channel's key-frame problem, ready to solve ([`ChannelsSolve::keyframe_setup`]).
struct KeyFrameSetup<'p> {
    terms: crate::solve::keyframes::KeyFrameTerms,
    op: crate::model::keyframe::Fused<&'p crate::model::rolling::RollingShutterModel>,
    obs: Vec<f32>,
    lower: Option<Vec<bool>>,
    prior: crate::solve::prox::prior::PriorSpec,
    lipschitz: (f64, bool),
    key: crate::solve::lipschitz::Fingerprint,
}

impl ChannelsSolve<'_> {
    fn job(&self, ch: usize) -> ChannelSolve<'_> {
        let params = self.params;
        let still_check = self.still_checks.get(ch);
        ChannelSolve { ch, kind: params.solver, device: params.device, start: params.start, stop: &params.stop, hooks: self.hooks, still_check }
    }

    fn truth(&self, ch: usize) -> Option<&[f32]> {
        self.truth_planes.map(|t| t[ch].as_slice())
    }

    /// The undeclared video: every captured channel on its own operator.
    fn plain(&self) -> Result<Solved, ReconstructError> {
        let (problem, params, recipe, cache) = (self.problem, self.params, &self.recipe, self.cache);
        let (prepared, kind, models) = (problem.prepared, params.solver, problem.models());
        let channel = |ch: usize| problem.channel(ch);
        let captured = prepared.raw.len();
        let (k, mv, nv) = models[0].video_shape();
        let lower = prepared.data_mask.lower_bounds.as_deref();
        if let (Some(model), Some(raw)) = (models.first(), prepared.raw.first()) {
            let p = recipe.video((k, mv, nv), channel(0).atb_max() as f64).build(None);
            kind.check_on_device(params.device, model, &DataTerm::new(&raw.data).with_lower_bounds(lower), p.as_ref(), false)
                .and_then(|()| kind.check_device_memory(params.device, model, captured))
                .map_err(ReconstructError::Unsupported)?;
        }
        let identity = |x: &[f32]| x.to_vec();
        let keep = |v: Vec<f32>| v;
        Ok((0..captured)
            .into_par_iter()
            .map(|ch| {
                let lipschitz = channel(ch).lipschitz(cache);
                let prior = recipe.video((k, mv, nv), channel(ch).atb_max() as f64);
                let data = DataTerm::new(&prepared.raw[ch].data).with_lower_bounds(lower);
                let full = FullGrid { truth: self.truth(ch), to_full: &identity };
                let job = ChannelSolve { stop: &self.plain_stops[ch], ..self.job(ch) };
                let supported = prior.clone().with_support(self.support.cloned());
                // On a support, the first solve leaves the probe's iterations of the cap and
                // stops at FIRST_ITERS for the probe and the sources' fit; the rest of the cap
                // goes on only when the sources are refused.
                let max_iters = job.stop.max_iters;
                let probe_iters = self.support.map_or(0, |_| crate::solve::support::probe_iters(max_iters));
                let first_iters = if self.support.is_some() { (max_iters - probe_iters).min(crate::solve::support::FIRST_ITERS) } else { max_iters };
                let first_stop = StopRule { max_iters: first_iters, ..job.stop.clone() };
                let run = |l| ChannelSolve { stop: &first_stop, ..job }.run(models[ch], &data, &supported, l, full, (models[ch], &keep));
                let solved = retry_on_non_finite(run(lipschitz), lipschitz.1, || run((channel(ch).remeasure_lipschitz(cache), false)));
                match self.support {
                    Some(support) => {
                        let run_from = |x0: Vec<f32>, iterations: usize, probe: bool, whole: bool| {
                            // The probe runs its iterations: no settling rule ends it early.
                            let stop = if probe {
                                StopRule { max_iters: iterations, rel_tol: 0.0, obj_tol: 0.0, noise_floor: None, ..job.stop.clone() }
                            } else {
                                StopRule { max_iters: iterations, ..job.stop.clone() }
                            };
                            let on = if whole { &prior } else { &supported };
                            ChannelSolve { stop: &stop, ..job }.run_from(models[ch], &data, on, lipschitz, full, x0)
                        };
                        let capped = solved.1.stats.termination == crate::solve::optimize::Termination::MaxIterations;
                        let solved = keep_or_drop_support(solved, support, (max_iters, probe_iters), &run_from);
                        let fit = |v: &[f32], misfit: f64| crate::solve::sources::fit_sources(models[ch], &data, lipschitz.0, (support, v, misfit), k);
                        let (video, mut report) = sources_or_support(solved, fit, (self.truth(ch), k));
                        let on_support = report.support.as_ref().is_some_and(|s| s.kept && !s.sources_kept());
                        if !(capped && on_support && report.stats.iterations < max_iters) {
                            return (video, report);
                        }
                        // The support's video stands: the solve goes on for the rest of the cap.
                        let (video, rest) = run_from(video, max_iters - report.stats.iterations, false, false);
                        let support = report.support.take();
                        let mut report = chain(report, rest);
                        report.support = support;
                        (video, report)
                    }
                    None => solved,
                }
            })
            .collect())
    }

    /// The undeclared video with the key frames: every captured channel on the stacked
    /// operator of its raw and its key frames ([`crate::solve::keyframes`]), started from
    /// the same solve on a grid coarser in time when the video is long enough
    /// ([`crate::solve::keyframes::coarse_binning`]), else from the key frames.
    fn with_keyframes(&self) -> Result<Solved, ReconstructError> {
        let problem = self.problem;
        let (prepared, models) = (problem.prepared, problem.models());
        let (k, mv, nv) = models[0].video_shape();
        // The coarse twin of the capture: the same raw, frames `binning` times longer.
        let coarse_cfg = crate::solve::keyframes::coarse_binning(k).map(|b| {
            let mut cfg = problem.cfg.clone();
            cfg.binning *= b;
            (b, cfg)
        });
        let coarse = coarse_cfg.as_ref().and_then(|(b, cfg)| match Problem::new(prepared, cfg, problem.fov) {
            Ok(p) => Some((*b, p)),
            Err(e) => {
                tracing::warn!(binning = cfg.binning, "no coarse key-frame solve ({e}): the solve starts from the key frames");
                None
            }
        });
        // The raw's noise (the key frames' weights), measured once for every channel and grid.
        let noise = crate::solve::problem::prepared_noise(prepared, k).map(|n| n.sigma);
        let identity = |x: &[f32]| x.to_vec();
        (0..prepared.raw.len())
            .into_par_iter()
            .map(|ch| {
                let first = match &coarse {
                    Some((b, cp)) => self.coarse_keyframes(cp, *b, ch, (k, mv, nv), noise)?,
                    None => None,
                };
                let setup = self.keyframe_setup(problem, ch, noise)?;
                let data = DataTerm::new(&setup.obs).with_lower_bounds(setup.lower.as_deref());
                let full = FullGrid { truth: self.truth(ch), to_full: &identity };
                let (x0, first) = match first {
                    Some((v, c)) => (v, Some(c)),
                    None => (setup.terms.start(), None),
                };
                let run = |l| self.job(ch).run_from(&setup.op, &data, &setup.prior, l, full, x0.clone());
                let again = || (self.cache.measure(setup.key, &setup.op).lambda_max * crate::solve::lipschitz::LIPSCHITZ_MARGIN, false);
                let (video, mut report) = retry_on_non_finite(run(setup.lipschitz), setup.lipschitz.1, || run(again()));
                let mut terms = setup.terms;
                terms.add_fit(&video);
                report.keyframes = terms.fits;
                if let Some(c) = first {
                    // Error against run time: the coarse solve's seconds come first.
                    report.stats.seconds += c.seconds;
                    report.trace.iter_mut().for_each(|r| r.seconds += c.seconds);
                    report.coarse = Some(c);
                }
                Ok((video, report))
            })
            .collect()
    }

    /// Channel `ch`'s key-frame solve on `problem` (the capture's, or its coarse twin):
    /// the key frames' terms and start, the stacked operator, its observations, the
    /// prior and the measured (or recalled) Lipschitz constant; `noise` is the raw's.
    fn keyframe_setup<'p>(&self, problem: &'p Problem, ch: usize, noise: Option<f32>) -> Result<KeyFrameSetup<'p>, ReconstructError> {
        let (prepared, channel) = (problem.prepared, problem.channel(ch));
        let model = channel.model();
        let (k, mv, nv) = model.video_shape();
        let lower = prepared.data_mask.lower_bounds.as_deref();
        let raw_lipschitz = channel.lipschitz(self.cache).0;
        let prior = self.recipe.video((k, mv, nv), channel.atb_max() as f64);
        let raw_data = DataTerm::new(&prepared.raw[ch].data).with_lower_bounds(lower);
        let still = crate::solve::start::still_fit(model, &raw_data, &prior, 150);
        let terms = crate::solve::keyframes::terms(prepared, ch, model, noise, raw_lipschitz, still.as_deref(), crate::solve::keyframes::STIFFNESS_CAP)
            .map_err(ReconstructError::Unsupported)?;
        let op = terms.fused(model);
        self.params.solver.check_operator(&op).map_err(ReconstructError::Unsupported)?;
        let (obs, lower) = terms.observations(&prepared.raw[ch].data, lower);
        let key = terms.key(channel.key());
        let (e, cached) = self.cache.get_or_measure(key, &op);
        Ok(KeyFrameSetup { terms, op, obs, lower, prior, lipschitz: (e.lambda_max * crate::solve::lipschitz::LIPSCHITZ_MARGIN, cached), key })
    }

    /// The key-frame solve of channel `ch` on the coarse twin `coarse` (frames
    /// `binning` times longer), brought to the capture's `shape` in time
    /// ([`crate::solve::keyframes::refine_in_time`]): the fine solve's start. `None`
    /// when it went non-finite or was stopped.
    fn coarse_keyframes(
        &self,
        coarse: &Problem,
        binning: usize,
        ch: usize,
        shape: (usize, usize, usize),
        noise: Option<f32>,
    ) -> Result<Option<(Vec<f32>, crate::solve::keyframes::CoarseStart)>, ReconstructError> {
        let t0 = Instant::now();
        let setup = self.keyframe_setup(coarse, ch, noise)?;
        let data = DataTerm::new(&setup.obs).with_lower_bounds(setup.lower.as_deref());
        let settings = crate::solve::optimize::OptimizerSettings::new(self.params.solver, setup.lipschitz.0, self.params.stop.clone());
        let reg = setup.prior.build(None);
        let stop = self.hooks.stop;
        let mut observer = |_: &crate::solve::optimize::IterInfo| !stop.load(std::sync::atomic::Ordering::Relaxed);
        let r = crate::solve::optimize::solve(&settings, &setup.op, &data, reg.as_ref(), Some(setup.terms.start()), &mut observer);
        if !r.x.iter().all(|v| v.is_finite()) || stop.load(std::sync::atomic::Ordering::Relaxed) {
            tracing::warn!(channel = ch, "the coarse key-frame solve went non-finite or was stopped: the solve starts from the key frames");
            return Ok(None);
        }
        let frames = setup.prior.video_shape().0;
        let video = crate::solve::keyframes::refine_in_time(&r.x, frames, binning, shape);
        let report = crate::solve::keyframes::CoarseStart { binning, frames, iterations: r.iterations, seconds: t0.elapsed().as_secs_f64() };
        tracing::info!(channel = ch, binning, frames, iterations = r.iterations, seconds = report.seconds, "coarse key-frame solve");
        Ok(Some((video, report)))
    }

    /// The video as `spec` declares it: each output channel on its restricted
    /// operator, checked against the undeclared one.
    fn declared(&self, spec: &SceneSpec, declared_in: &'static str, measure_full: bool) -> Result<(Solved, SceneReport), ReconstructError> {
        let (problem, params, cache) = (self.problem, self.params, self.cache);
        let (prepared, kind) = (problem.prepared, params.solver);
        let captured = prepared.raw.len();
        let channels_out = if spec.colour == Colour::Grey && captured > 1 { 1 } else { captured };
        let (k, mv, nv) = problem.channel(0).model().video_shape();
        let recipe = self.recipe.for_scene(spec, k);
        let problems: Vec<ChannelProblem> = (0..channels_out).map(|ch| problem.declare(spec, recipe.tau, params.alpha, ch)).collect::<Result<_, _>>()?;
        kind.check_operator(&problems[0].op).map_err(ReconstructError::Unsupported)?;
        let p0 = recipe.of_tv(problems[0].tv().clone(), problems[0].atb_max() as f64).build(None);
        kind.check_on_device(params.device, &problems[0].op, &problems[0].data(), p0.as_ref(), false)
            .and_then(|()| kind.check_device_memory(params.device, &problems[0].op, problems.len()))
            .map_err(ReconstructError::Unsupported)?;
        let plan = problems[0].plan().clone();
        for l in &plan.left_out {
            tracing::info!("left out: {l}");
        }
        let out: Vec<(Vec<f32>, ChannelReport, SceneCheck)> = problems
            .par_iter()
            .enumerate()
            .map(|(ch, p)| {
                let lipschitz = p.lipschitz(cache);
                let (k0, _) = p.plan().frames;
                let to_full = |x: &[f32]| {
                    let mut v = vec![0.0f32; k * mv * nv];
                    let w = p.op.embed(x);
                    v[k0 * mv * nv..k0 * mv * nv + w.len()].copy_from_slice(&w);
                    v
                };
                let prior = recipe.of_tv(p.tv().clone(), p.atb_max() as f64);
                let restrict = |v: Vec<f32>| p.op.restrict(&v, false);
                let full = FullGrid { truth: self.truth(ch), to_full: &to_full };
                let run = |l| self.job(ch).run(&p.op, &p.data(), &prior, l, full, (p.model(), &restrict));
                let (full, rep) = retry_on_non_finite(run(lipschitz), lipschitz.1, || run((p.remeasure_lipschitz(cache), false)));
                let check = check_scene(p, &full, params, measure_full);
                (full, rep, check)
            })
            .collect();
        let (reports, checks): (Vec<&ChannelReport>, Vec<&SceneCheck>) = out.iter().map(|(_, r, c)| (r, c)).unzip();
        let report = scene_report(plan, declared_in, &reports, &checks);
        for w in &report.warnings {
            tracing::warn!("{w}");
        }
        Ok((out.into_iter().map(|(v, r, _)| (v, r)).collect(), report))
    }

    /// The video of the channels' results, with its reports.
    fn assemble(&self, results: Solved, scene: Option<SceneReport>) -> Reconstruction {
        let (problem, models) = (self.problem, self.problem.models());
        let (k, mv, nv) = models[0].video_shape();
        let mut video = Array4::<f32>::zeros((k, mv, nv, results.len()));
        let mut reports = Vec::new();
        for (ch, (x, mut rep)) in results.into_iter().enumerate() {
            if rep.baseline.is_none() {
                rep.baseline = self.truth(ch).and_then(|t| Baselines::of(t, k));
            }
            rep.motion_error = self.truth(ch).and_then(|t| motion_error(&x, t, k));
            let plane = ndarray::ArrayView3::from_shape((k, mv, nv), &x).unwrap();
            video.index_axis_mut(Axis(3), ch).assign(&plane);
            reports.push(rep);
        }
        debug_assert_eq!(models[0].input_len(), k * mv * nv);
        let frame_sensitivity = FrameSensitivity::of(&models, problem.prepared).with_video(&video);
        if let Some(weak) = frame_sensitivity.weak_summary() {
            tracing::info!("weakly constrained: {weak}");
        }
        Reconstruction {
            video,
            frame_time_us: problem.cfg.timing().frame_time_us(),
            sensor_offset: models[0].conv().offset(),
            channels: reports,
            scene,
            split: None,
            tau_search: None,
            fit: None,
            estimated_seconds: None,
            plan: None,
            frame_sensitivity,
            static_background: None,
        }
    }
}

/// The report of a declared solve from its channels' reports and checks (the plain
/// and the split solves').
pub(crate) fn scene_report(
    plan: ScenePlan,
    declared_in: &'static str,
    reports: &[impl std::borrow::Borrow<ChannelReport>],
    checks: &[impl std::borrow::Borrow<SceneCheck>],
) -> SceneReport {
    let per_iteration = |r: &ChannelReport| r.stats.seconds / r.stats.iterations.max(1) as f64;
    let (fu, su) = plan.unknowns();
    let solved_s: f64 = reports.iter().map(|r| per_iteration(r.borrow())).sum();
    let merged = (plan.channels_captured / plan.channels_solved) as f64;
    let full_est = reports.iter().zip(checks).map(|(r, c)| c.borrow().cost_ratio.map(|q| q * per_iteration(r.borrow()) * merged)).sum::<Option<f64>>();
    let ratio = checks.iter().filter_map(|c| c.borrow().outside_ratio).reduce(f64::max);
    let residual_rel = checks.iter().map(|c| c.borrow().residual_rel).fold(0.0, f64::max);
    let mut warnings = Vec::new();
    if let Some(q) = ratio.filter(|&q| q > CONTRADICTION_RATIO) {
        warnings.push(format!(
            "the data contradict the scene declaration: light is wanted where it declares none (A^T residual there is {q:.1} x the largest TV subgradient); the declared solve leaves that light unexplained (residual {residual_rel:.3} of the data)"
        ));
    }
    SceneReport {
        declared_in,
        plan,
        unknowns_full: fu,
        unknowns_solved: su,
        vector_bytes_full: fu * 4,
        vector_bytes_solved: su * 4,
        seconds_per_iteration_solved: solved_s,
        seconds_per_iteration_full_estimate: full_est,
        outside_optimality_ratio: ratio,
        residual_rel,
        warnings,
    }
}

/// Whether a truth `t` (frames, rows, cols, channels) fits a video of `k` frames on
/// the `(mv, nv)` grid of a `(m, n)` sensor (either grid) with `captured` channels (one
/// for a grey scene).
pub(crate) fn check_truth(
    t: &ArrayView4<f32>,
    name: &str,
    k: usize,
    (mv, nv): (usize, usize),
    (m, n): (usize, usize),
    captured: usize,
    grey: bool,
) -> Result<(), ReconstructError> {
    let (tk, tm, tn, tc) = t.dim();
    let ok_grid = (tm, tn) == (mv, nv) || (tm, tn) == (m, n);
    let ok_channels = tc == captured || (grey && tc == 1);
    if tk != k || !ok_grid || !ok_channels {
        return Err(ReconstructError::TruthShape { what: name.into(), got: vec![tk, tm, tn, tc], expected: vec![k, mv, nv, captured] });
    }
    Ok(())
}

/// Frames `frames` of channel `ch` of the truth (or the channel mean for a grey scene)
/// on the video grid (`offset`: the sensor's place in it when the truth is given on the
/// sensor's grid).
pub(crate) fn truth_plane(
    t: &ArrayView4<f32>,
    ch: usize,
    grey: bool,
    frames: std::ops::Range<usize>,
    (mv, nv): (usize, usize),
    offset: (usize, usize),
) -> Vec<f32> {
    let (_, tm, tn, tc) = t.dim();
    let (or, oc) = if (tm, tn) == (mv, nv) { (0, 0) } else { offset };
    let srcs: Vec<usize> = if grey { (0..tc).collect() } else { vec![ch] };
    let inv = 1.0 / srcs.len() as f64;
    let mut v = vec![0.0f32; frames.len() * mv * nv];
    for (i, f) in frames.enumerate() {
        for r in 0..tm {
            for c in 0..tn {
                let s: f64 = srcs.iter().map(|&sc| t[[f, r, c, sc]] as f64).sum();
                v[(i * mv + r + or) * nv + c + oc] = (s * inv) as f32;
            }
        }
    }
    v
}

/// What the undeclared operator says about a declared solution.
pub(crate) struct SceneCheck {
    /// Cost of one forward + adjoint, full over declared.
    cost_ratio: Option<f64>,
    outside_ratio: Option<f64>,
    residual_rel: f64,
}

/// Apply the undeclared operator (all frames, the whole grid; the declared problem's
/// PSF) to the declared solution `full` (on the full grid): the residual, the
/// optimality of the imposed zeros, and the cost of one forward + adjoint against the
/// declared operator's.
pub(crate) fn check_scene(p: &ChannelProblem, full: &[f32], params: &SolveParams, measure: bool) -> SceneCheck {
    let model = &*p.declaration().full;
    let (k, mv, nv) = model.video_shape();
    let t0 = Instant::now();
    let mut ax = vec![0.0f32; model.output_len()];
    model.forward(full, &mut ax);
    let resid: Vec<f32> = p.b.iter().zip(&ax).map(|(&b, &a)| b - a).collect();
    let mut g = vec![0.0f32; model.input_len()];
    model.adjoint(&resid, &mut g);
    let t_full = t0.elapsed().as_secs_f64();
    let nb: f64 = p.b.iter().map(|&v| (v as f64).powi(2)).sum::<f64>().sqrt();
    let nr: f64 = resid.iter().map(|&v| (v as f64).powi(2)).sum::<f64>().sqrt();
    let residual_rel = nr / nb.max(1e-300);
    // Pixels the declaration sets to zero: outside the support box or the frame window.
    let (k0, k1) = p.plan().frames;
    let (rr, cr) = (p.op.rows.clone(), p.op.cols.clone());
    let restricted_space = (k0, k1) != (0, k) || rr != (0..mv) || cr != (0..nv);
    let outside_ratio = restricted_space.then(|| {
        let mut worst = f32::NEG_INFINITY;
        for f in 0..k {
            for r in 0..mv {
                let row = &g[(f * mv + r) * nv..(f * mv + r + 1) * nv];
                for (c, &v) in row.iter().enumerate() {
                    let inside = (k0..k1).contains(&f) && rr.contains(&r) && cr.contains(&c);
                    if !inside && v.is_finite() {
                        worst = worst.max(v);
                    }
                }
            }
        }
        let w = p.plan().spec.tv_weights.unwrap_or([params.alpha, 1.0, 1.0]);
        let dims = [k, mv, nv];
        let bound = 2.0 * params.tau as f64 * (0..3).filter(|&a| dims[a] > 1).map(|a| w[a] as f64).sum::<f64>();
        worst.max(0.0) as f64 / bound.max(1e-30)
    });
    let cost_ratio = measure.then(|| {
        let x = vec![0.0f32; p.op.input_len()];
        let mut y = vec![0.0f32; p.op.output_len()];
        let mut xa = vec![0.0f32; p.op.input_len()];
        let t0 = Instant::now();
        p.op.forward(&x, &mut y);
        p.op.adjoint(&y, &mut xa);
        t_full / t0.elapsed().as_secs_f64().max(1e-9)
    });
    SceneCheck { cost_ratio, outside_ratio, residual_rel }
}

/// The video solved on a sparse scene's `support` (for `max_iters` less the probe's
/// iterations) kept unless the data hold light outside it. `run_from(x0, iterations,
/// probe, whole)` solves from `x0` for at most `iterations` (`probe`: all of them, no
/// settling rule), on the whole grid or on the support. The probe runs `probe_iters`
/// ([`crate::solve::support::probe_iters`]) from the support's video twice, on the
/// support and on the whole grid, and compares their data misfits: what the whole grid
/// gains beyond going on is light outside. Kept, the video is the one gone on with on
/// the support (its iterations chained to the first solve's: `max_iters` in all when
/// the cap ends both); dropped, the whole grid's probe and then the whole grid solved
/// on from it for what is left of `max_iters`. The other branch's seconds count too.
fn keep_or_drop_support(
    (video, mut report): (Vec<f32>, ChannelReport),
    support: &Support,
    (max_iters, probe_iters): (usize, usize),
    run_from: &impl Fn(Vec<f32>, usize, bool, bool) -> (Vec<f32>, ChannelReport),
) -> (Vec<f32>, ChannelReport) {
    use crate::solve::optimize::Termination;
    let ch = report.channel;
    if probe_iters == 0 || matches!(report.stats.termination, Termination::Stopped | Termination::NonFinite { .. }) {
        // A stopped or failed solve, or a cap under two iterations, is returned as it
        // is: the probe would judge nothing.
        report.support = Some(SupportReport::unprobed(support));
        return (video, report);
    }
    let (on, on_report) = run_from(video.clone(), probe_iters, true, false);
    let (probe, probe_report) = run_from(video, probe_iters, true, true);
    // Each solve's data term at the video it returns: the misfits compared.
    let (on_support, on_grid) = (on_report.stats.data_term, probe_report.stats.data_term);
    let check = SupportReport::new(support, on_support, (on_grid, probe_report.stats.iterations, probe_report.stats.seconds));
    if check.kept {
        tracing::info!(channel = ch, pixels = check.pixels, misfit_ratio = check.probe_misfit_ratio, "solved on the sparse scene's support");
        let mut kept = chain(report, on_report);
        kept.stats.seconds += check.probe_seconds;
        kept.support = Some(check);
        return (on, kept);
    }
    tracing::warn!("{}", check.line(ch));
    let side_s = on_report.stats.seconds;
    let mut chained = chain(report, probe_report);
    chained.stats.seconds += side_s;
    let video = if max_iters > chained.stats.iterations {
        let (video, rest) = run_from(probe, max_iters - chained.stats.iterations, false, true);
        chained = chain(chained, rest);
        video
    } else {
        probe
    };
    chained.support = Some(check);
    (video, chained)
}

/// A kept support's video replaced by its sources' when they fit the data
/// ([`crate::solve::sources`]). `fit(video, misfit)` fits the sources of the support's
/// video. Kept, the sources' video is returned (its misfit, and its error against
/// `truth`, a video of `frames` frames, in the report and the trace's last row, which
/// is the returned video's); else the support's. The fit's seconds count either way
/// (the trace's last row ends with it). A dropped or unprobed support is returned as
/// it is.
fn sources_or_support(
    (video, mut report): (Vec<f32>, ChannelReport),
    fit: impl Fn(&[f32], f64) -> Option<crate::solve::sources::SourcesFit>,
    (truth, frames): (Option<&[f32]>, usize),
) -> (Vec<f32>, ChannelReport) {
    let probed = report.support.as_ref().is_some_and(|s| s.kept && s.probe_iterations > 0);
    let Some(f) = probed.then(|| fit(&video, report.stats.data_term)).flatten() else {
        return (video, report);
    };
    let s = f.report(report.stats.data_term);
    tracing::info!(channel = report.channel, regions = s.regions, misfit_ratio = s.misfit_ratio, kept = s.kept, "sources fitted");
    report.stats.seconds += f.seconds;
    if let Some(last) = report.trace.last_mut() {
        last.seconds += f.seconds;
    }
    let kept = s.kept && f.video.iter().all(|v| v.is_finite());
    if let Some(sup) = report.support.as_mut() {
        sup.sources = Some(crate::solve::support::SourcesReport { kept, ..s });
    }
    if !kept {
        return (video, report);
    }
    let error = truth.and_then(|t| crate::solve::trace::compare(&f.video, t));
    report.stats.data_term = f.misfit;
    report.stats.objective = f.misfit + report.stats.tv_term;
    report.stats.error = error;
    if let Some(last) = report.trace.last_mut() {
        last.data_term = f.misfit;
        last.objective = f.misfit + last.tv_term;
        (last.psnr_db, last.rel_error, last.rel_error_scaled) = (error.map(|e| e.psnr_db), error.map(|e| e.rel_error), error.map(|e| e.rel_error_scaled));
        if last.motion_error.is_some() {
            last.motion_error = truth.and_then(|t| crate::solve::trace::motion_error(&f.video, t, frames));
        }
    }
    (f.video, report)
}

/// `first` then `then` as one solve: iterations and seconds added, `then`'s rows after
/// `first`'s (numbered and timed on from them), the rest (the stop, the error at the
/// returned video) `then`'s; the start `first`'s.
fn chain(first: ChannelReport, mut then: ChannelReport) -> ChannelReport {
    let (its, secs) = (first.stats.iterations, first.stats.seconds);
    then.trace.iter_mut().for_each(|r| {
        r.iteration += its;
        r.seconds += secs;
    });
    let mut trace = first.trace;
    trace.append(&mut then.trace);
    then.stats.iterations += its;
    then.stats.seconds += secs;
    ChannelReport { trace, start: first.start, ..then }
}

/// A solve that went non-finite with a stored Lipschitz constant is run again with the
/// constant measured anew (the store may hold a wrong value that passed its checks).
fn retry_on_non_finite(first: (Vec<f32>, ChannelReport), cached: bool, again: impl FnOnce() -> (Vec<f32>, ChannelReport)) -> (Vec<f32>, ChannelReport) {
    if cached && matches!(first.1.stats.termination, crate::solve::optimize::Termination::NonFinite { .. }) {
        tracing::warn!(channel = first.1.channel, "the solve went non-finite with the stored Lipschitz constant: measuring it again and solving anew");
        return again();
    }
    first
}
