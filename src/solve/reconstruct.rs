//! One capture to one video: build the imaging operator per colour channel, measure
//! (or recall) its Lipschitz constant, run the solver (FISTA by default) with TV, record
//! the trace. Channels are solved in parallel, each with its own PSF. A scene
//! declaration (`[scene]` of capture.toml, or [`SolveOptions::scene`]) restricts the
//! problem to what the scene needs (see [`crate::model::scene`]); the undeclared operator
//! then checks the result (residual, and whether the data want light where the
//! declaration allows none).

use crate::model::capture::CaptureConfig;
use crate::model::op::Operator;
use crate::model::prepare::Prepared;
use crate::model::rolling::RollingShutterModel;
use crate::model::scene::{Colour, ScenePlan, SceneSpec};
use crate::model::shutter::ShutterWeights;
use crate::solve::lipschitz::EigenStore;
use crate::solve::optimize::{solve, SolverKind, SolverSettings};
use crate::solve::optimize::{IterInfo, Observer, SolveResult, StopRule, Termination};
use crate::solve::problem::{default_l1, Problem};
pub use crate::solve::problem::{Params, ReconstructError};
use crate::solve::prox::tv::TotalVariation;
use crate::solve::prox::tv_dual::{haar_strength, TvProx, TvProxChoice, HAAR_STRONG};
use crate::solve::scene::{build_problem_with, scene_tau, SceneProblem};
use crate::solve::trace::{compare, Error, TraceRow};
use ndarray::{Array4, ArrayView4, Axis};
use rayon::prelude::*;
use serde::Serialize;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// What any one solve reports about itself: the figures shared by a channel's report
/// and a sequence window's (flattened into their JSON).
#[derive(Clone, Debug, Serialize)]
pub struct SolveStats {
    pub iterations: usize,
    pub seconds: f64,
    pub termination: Termination,
    pub lipschitz: f64,
    pub lipschitz_cached: bool,
    /// `data_term + tv_term` at the returned video.
    pub objective: f64,
    pub data_term: f64,
    pub tv_term: f64,
    /// Against the truth, when one was given.
    pub error: Option<Error>,
}

impl SolveStats {
    /// The figures of a finished solve; `lipschitz` is the constant and whether it came
    /// from the cache.
    pub fn new(r: &SolveResult, (lipschitz, lipschitz_cached): (f64, bool), error: Option<Error>) -> Self {
        SolveStats {
            iterations: r.iterations,
            seconds: r.seconds,
            termination: r.termination,
            lipschitz,
            lipschitz_cached,
            objective: r.data_term + r.reg_term,
            data_term: r.data_term,
            tv_term: r.reg_term,
            error,
        }
    }
}

/// What one channel's solve produced.
#[derive(Clone, Debug, Serialize)]
pub struct ChannelReport {
    pub channel: usize,
    #[serde(flatten)]
    pub stats: SolveStats,
    pub solver: SolverKind,
    /// The TV map used (`auto` resolved).
    pub tv_prox: String,
    /// [`haar_strength`] of this channel's problem.
    pub haar_strength: f64,
    #[serde(skip)]
    pub trace: Vec<TraceRow>,
}

/// A reconstructed video (frame, row, col, channel) and how it was obtained.
pub struct Reconstruction {
    pub video: Array4<f32>,
    pub frame_time_us: f64,
    /// Offset of the sensor inside the video grid (non-zero for `--fov full`).
    pub sensor_offset: (usize, usize),
    pub channels: Vec<ChannelReport>,
    /// What a scene declaration left out (`None`: nothing declared).
    pub scene: Option<SceneReport>,
    /// How strongly the data constrain each frame.
    pub frame_sensitivity: FrameSensitivity,
    /// The static image and report of the static + dynamic model (`None`: the plain
    /// video was solved).
    pub static_background: Option<crate::solve::static_dynamic::StaticBackground>,
}

/// Frames below this share of the best frame's sensitivity are reported as weak.
pub const WEAK_FRAME: f64 = 0.5;

/// How strongly the data constrain each frame of the video: `||A P_k||_F^2`
/// ([`RollingShutterModel::frame_sensitivity`]) over the largest, averaged over the
/// channels' PSFs. A dual shutter's first and last frames are seen by the outer sensor
/// rows only, which catch less of the PSF's light, and the first and last
/// `N_l - 1` frames are partial exposures: their values are small, and what the
/// reconstruction shows there owes more to the regulariser than to the data.
#[derive(Clone, Debug, Serialize)]
pub struct FrameSensitivity {
    pub relative: Vec<f64>,
    /// The threshold of `weak_frames` ([`WEAK_FRAME`]).
    pub weak_below: f64,
    /// Runs of frames below `weak_below`, as `[first, end)`.
    pub weak_frames: Vec<[usize; 2]>,
}

impl FrameSensitivity {
    pub(crate) fn of(models: &[RollingShutterModel], prepared: &Prepared) -> Self {
        let per_channel: Vec<Vec<f64>> = models
            .par_iter()
            .zip(&prepared.psf)
            .map(|(model, psf)| {
                let g = model.frame_sensitivity(&psf.data);
                let max = g.iter().cloned().fold(0.0, f64::max);
                g.iter().map(|v| if max > 0.0 { v / max } else { 0.0 }).collect()
            })
            .collect();
        let k = per_channel[0].len();
        let relative: Vec<f64> = (0..k).map(|f| per_channel.iter().map(|g| g[f]).sum::<f64>() / per_channel.len() as f64).collect();
        let mut weak_frames: Vec<[usize; 2]> = Vec::new();
        for (f, &r) in relative.iter().enumerate() {
            if r < WEAK_FRAME {
                match weak_frames.last_mut() {
                    Some(run) if run[1] == f => run[1] = f + 1,
                    _ => weak_frames.push([f, f + 1]),
                }
            }
        }
        FrameSensitivity { relative, weak_below: WEAK_FRAME, weak_frames }
    }

    /// One line for a person: which frames are weak, e.g. "frames 0-11 and 60-65 (18 of
    /// 66)"; `None` when every frame is above the threshold.
    pub fn weak_summary(&self) -> Option<String> {
        if self.weak_frames.is_empty() {
            return None;
        }
        let runs: Vec<String> = self.weak_frames.iter().map(|&[a, b]| if b == a + 1 { format!("{a}") } else { format!("{a}-{}", b - 1) }).collect();
        let count: usize = self.weak_frames.iter().map(|[a, b]| b - a).sum();
        let list = match runs.len() {
            1 => runs[0].clone(),
            _ => format!("{} and {}", runs[..runs.len() - 1].join(", "), runs[runs.len() - 1]),
        };
        Some(format!("frame{} {list} ({count} of {})", if count == 1 { "" } else { "s" }, self.relative.len()))
    }
}

/// Progress hooks: `on_row(channel, row)` after every iteration; `stop` aborts cleanly.
pub struct Hooks<'a> {
    pub on_row: &'a (dyn Fn(usize, &TraceRow) + Sync),
    pub stop: &'a AtomicBool,
}

/// Choices beyond [`Params`]: the scene declaration.
#[derive(Clone, Debug, Serialize)]
pub struct SolveOptions {
    /// Scene declaration; `None`: the typed keys of capture.toml's `[scene]`.
    pub scene: Option<SceneSpec>,
    /// When a declaration leaves something out, time one forward + adjoint of the
    /// undeclared operator to estimate what the full problem would cost per iteration.
    pub measure_full: bool,
}

impl Default for SolveOptions {
    fn default() -> Self {
        SolveOptions { scene: None, measure_full: true }
    }
}

/// What a scene declaration left out of a reconstruction, and what that saved.
#[derive(Clone, Debug, Serialize)]
pub struct SceneReport {
    /// `capture.toml` or `options` (given by the caller, e.g. command-line flags).
    pub declared_in: &'static str,
    pub plan: ScenePlan,
    /// Unknowns over all channels: the undeclared problem's and those solved.
    pub unknowns_full: usize,
    pub unknowns_solved: usize,
    /// Bytes of one video-sized vector (FISTA keeps four), full and solved.
    pub vector_bytes_full: usize,
    pub vector_bytes_solved: usize,
    /// Measured solver seconds per iteration, summed over the channels solved.
    pub seconds_per_iteration_solved: f64,
    /// The undeclared problem's, estimated: the solved figure times the measured cost
    /// ratio of one forward + adjoint of the full and the declared operators, times the
    /// channels a grey declaration merged. `None` when not measured.
    pub seconds_per_iteration_full_estimate: Option<f64>,
    /// Optimality of the zeros the declaration imposes, for the undeclared problem:
    /// `max over left-out pixels of A^T (b - A x)` over the largest TV subgradient a
    /// pixel can have, `2 tau sum_a w_a`. Above 1 the full problem would put light
    /// there; well above 1, the data contradict the declaration.
    pub outside_optimality_ratio: Option<f64>,
    /// `||A x - b|| / ||b||` of the solution on the full operator, worst channel.
    pub residual_rel: f64,
    pub warnings: Vec<String>,
}

/// Above this [`SceneReport::outside_optimality_ratio`] the declaration is reported as
/// contradicted by the data (see `tests/scene_reconstruct.rs` for measured values).
pub const CONTRADICTION_RATIO: f64 = 3.0;

/// Reconstruct every channel of a prepared capture, honouring capture.toml's `[scene]`.
pub fn reconstruct(
    prepared: &Prepared,
    cfg: &CaptureConfig,
    params: &Params,
    truth: Option<(ArrayView4<f32>, &str)>,
    cache: &dyn EigenStore,
    hooks: &Hooks,
) -> Result<Reconstruction, ReconstructError> {
    reconstruct_with(prepared, cfg, params, &SolveOptions::default(), truth, cache, hooks)
}

/// Reconstruct with explicit [`SolveOptions`] (the scene declaration): builds the
/// [`Problem`] and solves it.
pub fn reconstruct_with(
    prepared: &Prepared,
    cfg: &CaptureConfig,
    params: &Params,
    opts: &SolveOptions,
    truth: Option<(ArrayView4<f32>, &str)>,
    cache: &dyn EigenStore,
    hooks: &Hooks,
) -> Result<Reconstruction, ReconstructError> {
    let problem = Problem::new(prepared, cfg, params.fov)?;
    reconstruct_problem(&problem, params, opts, truth, cache, hooks)
}

/// The solve of one channel: its solver, prox and trace.
pub(crate) struct ChannelSolve<'a> {
    pub ch: usize,
    pub kind: SolverKind,
    pub tv_prox: TvProxChoice,
    /// Absolute L1 weight beside TV (0: none).
    pub l1: f32,
    pub stop: &'a StopRule,
    pub hooks: &'a Hooks<'a>,
}

impl ChannelSolve<'_> {
    /// Solve `op x = b` with `tv`; `to_full` maps the unknowns to the full video grid,
    /// where the truth lives.
    #[allow(clippy::too_many_arguments)]
    fn run<A: Operator + ?Sized>(
        &self,
        op: &A,
        b: &[f32],
        tv: &TotalVariation,
        lipschitz: (f64, bool),
        atb_max: f64,
        truth: Option<&[f32]>,
        to_full: &dyn Fn(&[f32]) -> Vec<f32>,
    ) -> (Vec<f32>, ChannelReport) {
        let strength = haar_strength(tv, atb_max);
        let prox = self.tv_prox.resolve(tv, atb_max);
        let uses_prox = self.kind != SolverKind::Admm;
        if uses_prox && self.tv_prox == TvProxChoice::Fixed(TvProx::Haar) && strength > HAAR_STRONG {
            tracing::warn!(
                channel = self.ch,
                strength,
                "strong TV for the Haar map (J w tau / max A^T b = {strength:.3} > {HAAR_STRONG}): its fixed point is biased; --tv-prox auto or dualN solves the exact problem"
            );
        }
        let mut settings = SolverSettings::new(self.kind, lipschitz.0, self.stop.clone());
        settings.tv_prox = prox;
        settings.l1 = self.l1;
        let label = settings.tv_prox_label();
        self.observed(tv.shape, &label, strength, lipschitz, truth, to_full, |observer| solve(&settings, op, b, tv, None, observer))
    }

    /// Run `solve` with this channel's observer (trace rows, hooks, the stop flag) and
    /// report it: the iterate mapped by `to_full`, the stats against the truth.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn observed(
        &self,
        shape: (usize, usize, usize),
        prox_label: &str,
        strength: f64,
        lipschitz: (f64, bool),
        truth: Option<&[f32]>,
        to_full: &dyn Fn(&[f32]) -> Vec<f32>,
        solve: impl FnOnce(&mut dyn Observer) -> SolveResult,
    ) -> (Vec<f32>, ChannelReport) {
        let mut rows: Vec<TraceRow> = Vec::new();
        let (ch, hooks) = (self.ch, self.hooks);
        let mut observer = |i: &IterInfo| {
            let err = truth.map(|t| compare(&to_full(i.x), t));
            let row = TraceRow::from_info(i, err);
            (hooks.on_row)(ch, &row);
            rows.push(row);
            !hooks.stop.load(Ordering::Relaxed)
        };
        let (k, m, n) = shape;
        let span = tracing::info_span!("solve", channel = ch, frames = k, rows = m, cols = n, solver = %self.kind, tv_prox = %prox_label);
        let _g = span.enter();
        let r = solve(&mut observer);
        tracing::info!(iterations = r.iterations, seconds = r.seconds, termination = ?r.termination, "channel solved");
        let full = to_full(&r.x);
        let error = truth.map(|t| compare(&full, t));
        let report = ChannelReport {
            channel: ch,
            stats: SolveStats::new(&r, lipschitz, error),
            solver: self.kind,
            tv_prox: prox_label.to_string(),
            haar_strength: strength,
            trace: rows,
        };
        (full, report)
    }
}

/// Solve a built [`Problem`] with `params`, honouring the scene declaration of `opts`
/// (else capture.toml's `[scene]`).
pub fn reconstruct_problem(
    problem: &Problem,
    params: &Params,
    opts: &SolveOptions,
    truth: Option<(ArrayView4<f32>, &str)>,
    cache: &dyn EigenStore,
    hooks: &Hooks,
) -> Result<Reconstruction, ReconstructError> {
    let (prepared, cfg) = (problem.prepared, problem.cfg);
    if !(params.tau.is_finite() && params.tau >= 0.0) {
        return Err(ReconstructError::Tau(params.tau));
    }
    if !(params.alpha.is_finite() && params.alpha >= 0.0) {
        return Err(ReconstructError::Alpha(params.alpha));
    }
    let (spec, declared_in) = match &opts.scene {
        Some(s) => (s.clone(), "options"),
        None => (SceneSpec::from_table(cfg.scene.as_ref())?, "capture.toml"),
    };
    if problem.fov != params.fov {
        return Err(ReconstructError::Fov { problem: problem.fov, params: params.fov });
    }
    let kind = params.solver;
    let captured = prepared.raw.len();
    let models = problem.models();
    let (k, mv, nv) = models[0].video_shape();
    let offset = models[0].conv().offset();
    let (m, n) = models[0].conv().sensor_shape();
    let grey = spec.colour == Colour::Grey && captured > 1;
    let channels_out = if grey { 1 } else { captured };

    // Truth per output channel, on the full video grid (zero outside the sensor for
    // --fov full; the channel mean for a grey scene).
    let truth_planes: Option<Vec<Vec<f32>>> = match truth {
        None => None,
        Some((t, name)) => {
            let (tk, tm, tn, tc) = t.dim();
            let ok_grid = (tm, tn) == (mv, nv) || (tm, tn) == (m, n);
            let ok_channels = tc == captured || (grey && tc == 1);
            if tk != k || !ok_grid || !ok_channels {
                return Err(ReconstructError::TruthShape { what: name.into(), got: vec![tk, tm, tn, tc], expected: vec![k, mv, nv, captured] });
            }
            let (or, oc) = if (tm, tn) == (mv, nv) { (0, 0) } else { offset };
            Some(
                (0..channels_out)
                    .map(|ch| {
                        let mut v = vec![0.0f32; k * mv * nv];
                        let srcs: Vec<usize> = if grey { (0..tc).collect() } else { vec![ch] };
                        let inv = 1.0 / srcs.len() as f64;
                        for f in 0..k {
                            for r in 0..tm {
                                for c in 0..tn {
                                    let s: f64 = srcs.iter().map(|&sc| t[[f, r, c, sc]] as f64).sum();
                                    v[(f * mv + r + or) * nv + c + oc] = (s * inv) as f32;
                                }
                            }
                        }
                        v
                    })
                    .collect(),
            )
        }
    };

    if spec.static_background && kind == SolverKind::Admm {
        return Err(ReconstructError::Unsupported(
            "[scene] static_background = true needs a gradient solver (fista, fista-restart, mfista, pgd): ADMM's splitting has no static + dynamic map".into(),
        ));
    }
    let l1_rel = params.l1.unwrap_or(default_l1(spec.static_background));
    if !(l1_rel.is_finite() && l1_rel >= 0.0) || (l1_rel > 0.0 && kind == SolverKind::Admm) {
        return Err(ReconstructError::L1(l1_rel));
    }
    if spec.static_background {
        return crate::solve::static_dynamic::reconstruct(problem, params, &spec, declared_in, l1_rel, truth_planes, cache, hooks);
    }
    let job = |ch: usize, tau: f32| ChannelSolve { ch, kind, tv_prox: params.tv_prox, l1: l1_rel * tau, stop: &params.stop, hooks };
    let identity = |x: &[f32]| x.to_vec();
    let mut scene_report = None;
    let results: Vec<(Vec<f32>, ChannelReport)> = if spec == SceneSpec::default() {
        (0..captured)
            .into_par_iter()
            .map(|ch| {
                let lipschitz = problem.lipschitz(ch, cache);
                let tv = TotalVariation::new((k, mv, nv), params.tau, params.alpha);
                let truth_ch = truth_planes.as_ref().map(|t| t[ch].as_slice());
                job(ch, params.tau).run(&models[ch], &prepared.raw[ch].data, &tv, lipschitz, problem.atb_max(ch) as f64, truth_ch, &identity)
            })
            .collect()
    } else {
        // A static scene's one frame stands for every frame of the window: its TV counts
        // once per frame it replaces, so the objective is the full problem's on static
        // videos.
        let tau = scene_tau(&spec, params.tau, k);
        let problems: Vec<SceneProblem> =
            (0..channels_out).map(|ch| build_problem_with(prepared, problem.weights(), params.fov, &spec, tau, params.alpha, ch)).collect::<Result<_, _>>()?;
        let plan = problems[0].plan.clone();
        for l in &plan.left_out {
            tracing::info!("left out: {l}");
        }
        let out: Vec<(Vec<f32>, ChannelReport, SceneCheck)> = problems
            .par_iter()
            .enumerate()
            .map(|(ch, p)| {
                let lipschitz = p.lipschitz(cache);
                let truth_ch = truth_planes.as_ref().map(|t| t[ch].as_slice());
                let (k0, _) = p.plan.frames;
                let to_full = |x: &[f32]| {
                    let mut v = vec![0.0f32; k * mv * nv];
                    let w = p.op.embed(x);
                    v[k0 * mv * nv..k0 * mv * nv + w.len()].copy_from_slice(&w);
                    v
                };
                let atb_max = p.atb_max() as f64;
                let (full, rep) = job(ch, tau).run(&p.op, &p.b, &p.tv, lipschitz, atb_max, truth_ch, &to_full);
                let check = check_scene(p, &full, params, problem.weights(), opts.measure_full);
                (full, rep, check)
            })
            .collect();
        let (fu, su) = plan.unknowns();
        let solved_s: f64 = out.iter().map(|(_, r, _)| r.stats.seconds / r.stats.iterations.max(1) as f64).sum();
        let merged = (plan.channels_captured / plan.channels_solved) as f64;
        let full_est = out.iter().map(|(_, r, c)| c.cost_ratio.map(|q| q * r.stats.seconds / r.stats.iterations.max(1) as f64 * merged)).sum::<Option<f64>>();
        let ratio = out.iter().filter_map(|(_, _, c)| c.outside_ratio).reduce(f64::max);
        let residual_rel = out.iter().map(|(_, _, c)| c.residual_rel).fold(0.0, f64::max);
        let mut warnings = Vec::new();
        if let Some(q) = ratio.filter(|&q| q > CONTRADICTION_RATIO) {
            let w = format!(
                "the data contradict the scene declaration: light is wanted where it declares none (A^T residual there is {q:.1} x the largest TV subgradient); the declared solve leaves that light unexplained (residual {residual_rel:.3} of the data)"
            );
            tracing::warn!("{w}");
            warnings.push(w);
        }
        scene_report = Some(SceneReport {
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
        });
        out.into_iter().map(|(v, r, _)| (v, r)).collect()
    };

    let mut video = Array4::<f32>::zeros((k, mv, nv, channels_out));
    let mut reports = Vec::new();
    for (ch, (x, rep)) in results.into_iter().enumerate() {
        let plane = ndarray::ArrayView3::from_shape((k, mv, nv), &x).unwrap();
        video.index_axis_mut(Axis(3), ch).assign(&plane);
        reports.push(rep);
    }
    debug_assert_eq!(models[0].input_len(), k * mv * nv);
    let frame_sensitivity = FrameSensitivity::of(models, prepared);
    if let Some(weak) = frame_sensitivity.weak_summary() {
        tracing::info!("weakly constrained (under {WEAK_FRAME} of the best frame's sensitivity): {weak}");
    }
    Ok(Reconstruction {
        video,
        frame_time_us: cfg.timing().frame_time_us(),
        sensor_offset: offset,
        channels: reports,
        scene: scene_report,
        frame_sensitivity,
        static_background: None,
    })
}

/// What the undeclared operator says about a declared solution.
struct SceneCheck {
    /// Cost of one forward + adjoint, full over declared.
    cost_ratio: Option<f64>,
    outside_ratio: Option<f64>,
    residual_rel: f64,
}

/// Apply the undeclared operator (all frames, the whole grid; the declared problem's
/// PSF) to the declared solution `full` (on the full grid): the residual, the
/// optimality of the imposed zeros, and the cost of one forward + adjoint against the
/// declared operator's.
fn check_scene(p: &SceneProblem, full: &[f32], params: &Params, weights: &ShutterWeights, measure: bool) -> SceneCheck {
    let (rows, cols) = p.op.inner.conv().sensor_shape();
    let model = RollingShutterModel::of_psf(&p.psf, rows, cols, params.fov, weights.clone())
        .with_mask(p.op.inner.mask().map(std::sync::Arc::from))
        .with_lower_bounds(p.op.inner.lower_bounds().map(std::sync::Arc::from));
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
    let (k0, k1) = p.plan.frames;
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
        let w = p.plan.spec.tv_weights.unwrap_or([params.alpha, 1.0, 1.0]);
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
