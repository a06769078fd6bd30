//! One channel's solve and what it reports: the figures every solve shares
//! ([`SolveStats`]), a channel's report, the observer that records the trace and
//! honours the hooks ([`ChannelSolve`]), how strongly each frame is constrained
//! ([`FrameSensitivity`]), and the [`Reconstruction`] they make up, with the scene
//! declaration's report and the static + dynamic model's parts. Shared by the plain,
//! the declared and the static + dynamic solves.

use crate::model::data::DataTerm;
use crate::model::op::Operator;
use crate::model::prepare::Prepared;
use crate::model::rolling::RollingShutterModel;
use crate::model::scene::ScenePlan;
use crate::solve::fit::{fit_capture, FitReport, SolvedChannel};
use crate::solve::job::{run, ChannelJob};
use crate::solve::optimize::{Device, IterInfo, Observer, OptimizerSettings, SolveResult, SolverKind, StopRule, Termination};
pub use crate::solve::plan::ModelChoice;
use crate::solve::problem::{Problem, SolveParams};
use crate::solve::prox::prior::PriorSpec;
use crate::solve::prox::tv_dual::{TvProx, TvProxChoice, HAAR_STRONG};
use crate::solve::start::{video_start, Start, StillReport};
use crate::solve::trace::{compare, motion_error, Baselines, Error, TraceRow};
use ndarray::{Array3, Array4};
use rayon::prelude::*;
use serde::Serialize;
use std::sync::atomic::{AtomicBool, Ordering};

/// What any one solve reports about itself: the figures shared by a channel's report
/// and a sequence window's (flattened into their JSON).
#[derive(Clone, Debug, Serialize)]
pub struct SolveStats {
    pub iterations: usize,
    pub seconds: f64,
    pub termination: Termination,
    /// Whether the stop rule's convergence test ended the solve (false: the iteration
    /// cap, the time budget or a stop request ended it first).
    pub converged: bool,
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
    pub fn new(
        r: &SolveResult,
        crate::solve::lipschitz::Lipschitz { value: lipschitz, cached: lipschitz_cached }: crate::solve::lipschitz::Lipschitz,
        error: Option<Error>,
    ) -> Self {
        SolveStats {
            iterations: r.iterations,
            seconds: r.seconds,
            termination: r.termination,
            converged: r.termination == Termination::Converged,
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
    /// [`crate::solve::prox::tv_dual::haar_strength`] of this channel's problem.
    pub haar_strength: f64,
    /// An all-zero video's and the truth's temporal mean's figures, when a truth was
    /// given ([`Baselines`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub baseline: Option<Baselines>,
    /// [`crate::solve::trace::motion_error`] of the channel's video against the truth,
    /// when a truth that moves was given: how well the video holds what moves (a
    /// still scores 1, the truth 0), which the relative error does not tell on a dense
    /// scene.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub motion_error: Option<f64>,
    /// The still solve the video solve started from (`None`: from zero). Its seconds
    /// are in `seconds` and in the trace.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub start: Option<StillReport>,
    /// The key frames' terms of this channel's solve (none without key frames).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub keyframes: Vec<crate::solve::keyframes::KeyFrameFit>,
    /// The coarse key-frame solve this solve started from, when one ran.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coarse: Option<crate::solve::keyframes::CoarseStart>,
    /// The key-frame video against the key frames' interpolation, when it was solved
    /// as its departure from it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub interpolation: Option<crate::solve::keyframes::InterpolationReport>,
    /// The sparse scene's support the video was solved on, and whether the data kept
    /// it ([`crate::solve::support`]; `None`: the whole grid, nothing tried).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub support: Option<crate::solve::support::SupportReport>,
    #[serde(skip)]
    pub trace: Vec<TraceRow>,
}

impl ChannelReport {
    /// The error headline for a person, when a truth was given: the relative error
    /// after the best scale first, then the PSNR beside what an all-zero video and the
    /// truth's temporal mean score.
    pub fn error_line(&self) -> Option<String> {
        let e = self.stats.error?;
        let mut s = format!("relative error {:.4} after the best scale ({:.4} as given), PSNR {:.2} dB", e.rel_error_scaled, e.rel_error, e.psnr_db);
        if let Some(b) = self.baseline {
            s.push_str(&format!(" (an all-zero video: {:.2} dB", b.zero_psnr_db));
            if let (Some(db), Some(e)) = (b.temporal_mean_psnr_db, b.temporal_mean_rel_error_scaled) {
                s.push_str(&format!("; the truth's temporal mean: {db:.2} dB, relative error {e:.4}"));
            }
            s.push(')');
        }
        if let Some(me) = self.motion_error {
            s.push_str(&format!("; motion error {me:.4} (a still scores 1)"));
        }
        Some(s)
    }

    /// How the solve ended, for a person: converged, or which limit ended it first.
    pub fn stop_line(&self) -> String {
        let it = self.stats.iterations;
        match self.stats.termination {
            Termination::Converged => format!("converged after {it} iterations"),
            Termination::MaxIterations if self.support.as_ref().is_some_and(|s| s.sources_kept()) => format!(
                "{it} iterations on the support, then the sources' fit in place of the rest of the cap (their shapes and brightness fitted to the data: the sources line below)"
            ),
            Termination::MaxIterations => format!("NOT converged: the iteration cap ended it after {it} iterations (raise --iters to go on)"),
            Termination::TimeBudget => format!("NOT converged: the time budget ended it after {it} iterations"),
            Termination::Stopped => format!("NOT converged: stopped on request after {it} iterations"),
            Termination::NonFinite { iteration } => format!("NOT converged: non-finite at iteration {iteration}; the last finite iterate is kept"),
        }
    }
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
    pub static_background: Option<StaticBackground>,
    /// How the frames were split across MPI ranks (`None`: one process).
    pub split: Option<SplitReport>,
    /// How tau was chosen by held-out pixels (`None`: as given).
    pub tau_search: Option<crate::solve::tau_search::TauSearchReport>,
    /// How well the video explains the data against the noise (`None`: not measured).
    pub fit: Option<FitReport>,
    /// The solve's seconds as estimated before it started
    /// ([`crate::solve::estimate::SolveEstimate::seconds`]; `None`: not estimated).
    pub estimated_seconds: Option<f64>,
    /// The plan solved ([`crate::solve::plan::SolvePlan::report`]; `None`: not planned).
    pub plan: Option<crate::solve::plan::PlanReport>,
}

impl Reconstruction {
    /// Whether every channel's solve converged ([`SolveStats::converged`]).
    pub fn converged(&self) -> bool {
        self.channels.iter().all(|c| c.stats.converged)
    }

    /// Measure the fit report of this video against `problem`'s data
    /// ([`crate::solve::fit::fit_capture`]).
    pub fn add_fit(&mut self, problem: &Problem, params: &SolveParams) {
        let solved: Vec<SolvedChannel> =
            self.channels.iter().map(|c| SolvedChannel { still: c.start.as_ref().and_then(|s| s.image.as_deref()), lipschitz: c.stats.lipschitz }).collect();
        let plain = self.scene.is_none() && self.static_background.is_none();
        self.fit = fit_capture(problem, self.video.view(), &solved, plain, params);
    }

    /// Count `seconds` spent before the solves (the tau search) in every channel's
    /// trace and seconds: error against run time.
    pub fn add_prior_seconds(&mut self, seconds: f64) {
        for c in &mut self.channels {
            c.stats.seconds += seconds;
            c.trace.iter_mut().for_each(|r| r.seconds += seconds);
        }
    }
}

/// One rank's share, as summary.json's `mpi` section lists it.
#[derive(Clone, Debug, Serialize)]
pub struct RankShare {
    pub rank: usize,
    /// Frames `[first, end)` of the video.
    pub frames: [usize; 2],
    /// Share of the estimated work ([`frame_work`]).
    pub work_share: f64,
    /// Peak resident memory of the rank's process, bytes (when the platform says).
    pub peak_memory_bytes: Option<u64>,
    /// Bytes the rank handed to and received from the exchanges per solver iteration
    /// (payloads, over the channels' solves: the scalars and, with a truth, the error's
    /// sums included; the Lipschitz measurement and the final gather not). Collectives
    /// count as a flat pattern would move them (rank 0 to and from each other rank);
    /// MPI's own algorithms may route them differently.
    pub sent_bytes_per_iteration: f64,
    pub received_bytes_per_iteration: f64,
    /// Worker threads of the rank.
    pub threads: usize,
}

/// How a capture was split (summary.json `mpi`).
#[derive(Clone, Debug, Serialize)]
pub struct SplitReport {
    pub ranks: usize,
    pub per_rank: Vec<RankShare>,
    /// Bytes of one video-sized vector of the whole problem and of the largest block
    /// (each rank holds four of its block's, FISTA's).
    pub vector_bytes_whole: usize,
    pub vector_bytes_largest_block: usize,
    /// Sensor rows the forward sums across the ranks (those two blocks' frames touch),
    /// of `sensor_rows`.
    pub sensor_rows_summed: usize,
    pub sensor_rows: usize,
}

/// Frames below this share of the best frame's sensitivity, or of its exposure light,
/// are reported as weak.
pub const WEAK_FRAME: f64 = 0.5;

/// A frame holding under this share of the median frame's light in the reconstruction
/// while its sensitivity is under [`DIM_SENSITIVITY`] is reported as weak too: the data
/// see it less than the middle frames and the video shows it (nearly) dark.
pub const DARK_FRAME: f64 = 0.25;
/// See [`DARK_FRAME`].
pub const DIM_SENSITIVITY: f64 = 0.9;

/// How strongly the data constrain each frame of the video, and which frames are
/// unreliable.
///
/// - `relative`: `||A P_k||_F^2` ([`RollingShutterModel::frame_sensitivity`]) over the
///   largest, averaged over the channels' PSFs: the squared gain from the frame's pixels
///   to the sensor.
/// - `light`: the light a uniform frame `k` puts on the sensor
///   ([`RollingShutterModel::frame_light`]) over the largest: the frame's share of the
///   photons, so of the signal-to-noise.
/// - `video_light`: each frame's light in the reconstruction over the median frame's
///   (set once the video exists).
///
/// A dual shutter's first and last frames are seen by the outer sensor rows only, which
/// catch less of the PSF's light, and the first and last `N_l - 1` frames are partial
/// exposures: their values are small, and what the reconstruction shows there owes more
/// to the regulariser than to the data. `weak_frames` lists every frame below
/// [`WEAK_FRAME`] in `relative` or `light`, or dark in the video ([`DARK_FRAME`]) where
/// the data see it less ([`DIM_SENSITIVITY`]).
#[derive(Clone, Debug, Serialize)]
pub struct FrameSensitivity {
    pub relative: Vec<f64>,
    pub light: Vec<f64>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub video_light: Vec<f64>,
    /// The threshold of `weak_frames` on `relative` and `light` ([`WEAK_FRAME`]).
    pub weak_below: f64,
    /// Runs of weak frames, as `[first, end)`.
    pub weak_frames: Vec<[usize; 2]>,
}

impl FrameSensitivity {
    pub(crate) fn of(models: &[&RollingShutterModel], prepared: &Prepared) -> Self {
        let normalised = |g: Vec<f64>| -> Vec<f64> {
            let max = g.iter().cloned().fold(0.0, f64::max);
            g.iter().map(|v| if max > 0.0 { v / max } else { 0.0 }).collect()
        };
        let per_channel: Vec<(Vec<f64>, Vec<f64>)> = models
            .par_iter()
            .zip(&prepared.psf)
            .map(|(model, psf)| (normalised(model.frame_sensitivity(&psf.data)), normalised(model.frame_light(&psf.data))))
            .collect();
        let k = per_channel[0].0.len();
        // The channels' mean of one measure (0: sensitivity, 1: light).
        let mean = |which: usize| -> Vec<f64> {
            (0..k).map(|f| per_channel.iter().map(|g| if which == 0 { g.0[f] } else { g.1[f] }).sum::<f64>() / per_channel.len() as f64).collect()
        };
        let mut s = FrameSensitivity { relative: mean(0), light: mean(1), video_light: Vec::new(), weak_below: WEAK_FRAME, weak_frames: Vec::new() };
        s.mark_weak();
        s
    }

    /// Adds the reconstruction's light per frame (frame, row, col, channel) and marks
    /// the frames it shows dark where the data see them less.
    pub(crate) fn with_video(mut self, video: &Array4<f32>) -> Self {
        let per_frame: Vec<f64> = video.outer_iter().map(|f| f.iter().map(|&v| v.max(0.0) as f64).sum()).collect();
        let mut sorted = per_frame.clone();
        sorted.sort_by(f64::total_cmp);
        let median = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
        if median > 0.0 && per_frame.len() == self.relative.len() {
            self.video_light = per_frame.iter().map(|v| v / median).collect();
            self.mark_weak();
        }
        self
    }

    /// Whether frame `f` is weak (see [`FrameSensitivity`]).
    pub fn is_weak(&self, f: usize) -> bool {
        let dark = self.video_light.get(f).is_some_and(|&l| l < DARK_FRAME) && self.relative[f] < DIM_SENSITIVITY;
        self.relative[f] < WEAK_FRAME || self.light[f] < WEAK_FRAME || dark
    }

    fn mark_weak(&mut self) {
        self.weak_frames = crate::solve::frames::frame_runs((0..self.relative.len()).map(|f| self.is_weak(f)));
    }

    /// One line for a person: which frames are weak, e.g. "frames 0-11 and 60-65 (18 of
    /// 66)"; `None` when every frame is above the threshold.
    pub fn weak_summary(&self) -> Option<String> {
        (!self.weak_frames.is_empty()).then(|| crate::solve::frames::runs_text(&self.weak_frames, self.relative.len()))
    }

    /// The warning line for a person, when any frame is weak.
    pub fn warning(&self) -> Option<String> {
        let weak = self.weak_summary()?;
        Some(format!(
            "weakly constrained: {weak}: under {} of the best frame's sensitivity or exposure light, or shown under {DARK_FRAME} of the median frame's light where the data see them less; they lean on the regulariser (summary.json: frame_sensitivity)",
            self.weak_below
        ))
    }
}

/// Progress hooks: `on_row(channel, row)` after every iteration; `stop` aborts cleanly.
pub struct Hooks<'a> {
    pub on_row: &'a (dyn Fn(usize, &TraceRow) + Sync),
    pub stop: &'a AtomicBool,
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

/// Where a channel's truth lives: the truth on the full video grid, and the map of the
/// solve's unknowns to that grid.
#[derive(Clone, Copy)]
pub(crate) struct FullGrid<'a> {
    pub truth: Option<&'a [f32]>,
    pub to_full: &'a dyn Fn(&[f32]) -> Vec<f32>,
}

/// The solve of one channel: its solver and trace.
pub(crate) struct ChannelSolve<'a> {
    pub ch: usize,
    pub kind: SolverKind,
    /// Where the solver runs.
    pub device: Device,
    /// Where the video solve starts.
    pub start: Start,
    pub stop: &'a StopRule,
    pub hooks: &'a Hooks<'a>,
    /// The still check made on this channel to choose the scene model
    /// ([`crate::solve::start::check`]), which the still start goes on from.
    pub still_check: Option<&'a StillReport>,
}

impl ChannelSolve<'_> {
    /// Minimise `data` on `op` plus `prior`; `full` maps the unknowns to the full
    /// video grid, where the truth lives. `still` is the model whose still image starts
    /// the solve ([`Start`], with the same data term and prior) and the map from its
    /// video to the unknowns.
    pub(crate) fn run<A: Operator + ?Sized>(
        &self,
        op: &A,
        data: &DataTerm,
        prior: &PriorSpec,
        lipschitz: crate::solve::lipschitz::Lipschitz,
        full: FullGrid,
        still: (&RollingShutterModel, &dyn Fn(Vec<f32>) -> Vec<f32>),
    ) -> (Vec<f32>, ChannelReport) {
        let (x0, start) = video_start(self.start, still.0, data, prior, prior.video_shape().0, still.1, self.still_check);
        self.solve_from(op, data, prior, lipschitz, full, (x0, start))
    }

    /// [`Self::run`] from the video `x0` (the key frames' start) instead of a still.
    pub(crate) fn run_from<A: Operator + ?Sized>(
        &self,
        op: &A,
        data: &DataTerm,
        prior: &PriorSpec,
        lipschitz: crate::solve::lipschitz::Lipschitz,
        full: FullGrid,
        x0: Vec<f32>,
    ) -> (Vec<f32>, ChannelReport) {
        self.solve_from(op, data, prior, lipschitz, full, (Some(x0), None))
    }

    /// The solve of [`Self::run`] and [`Self::run_from`] from `x0` (`None`: zero), with
    /// the still start's report when it came from one.
    fn solve_from<A: Operator + ?Sized>(
        &self,
        op: &A,
        data: &DataTerm,
        prior: &PriorSpec,
        lipschitz: crate::solve::lipschitz::Lipschitz,
        full: FullGrid,
        (x0, start): (Option<Vec<f32>>, Option<StillReport>),
    ) -> (Vec<f32>, ChannelReport) {
        let strength = prior.haar_strength();
        warn_strong_haar(self.ch, self.kind, prior.tv_choice(), strength);
        let mut settings = OptimizerSettings::new(self.kind, lipschitz.value, self.stop.clone());
        settings.device = self.device;
        let label = self.kind.tv_map_label(prior);
        let reg = prior.build(None);
        self.observed(prior.video_shape(), (&label, strength), lipschitz, full, start, |observer| {
            run(ChannelJob { settings: &settings, operator: op, data, prior: reg.as_ref(), start: x0 }, observer)
        })
    }

    /// Run `solve` with this channel's observer (trace rows, hooks, the stop flag) and
    /// report it: the iterate mapped to the full grid, the stats against the truth.
    /// `(prox_label, strength)`: the TV map as reports name it and its Haar strength.
    pub(crate) fn observed(
        &self,
        shape: (usize, usize, usize),
        (prox_label, strength): (&str, f64),
        lipschitz: crate::solve::lipschitz::Lipschitz,
        full: FullGrid,
        start: Option<StillReport>,
        solve: impl FnOnce(&mut dyn Observer) -> SolveResult,
    ) -> (Vec<f32>, ChannelReport) {
        let mut rows: Vec<TraceRow> = Vec::new();
        let (ch, hooks) = (self.ch, self.hooks);
        let FullGrid { truth, to_full } = full;
        // The trace's clock includes the start's solve: error against run time.
        let start_s = start.as_ref().map_or(0.0, |s| s.seconds);
        let (k, m, n) = shape;
        let mut observer = |i: &IterInfo| {
            let x_full = truth.map(|_| to_full(i.x));
            let err = truth.zip(x_full.as_deref()).and_then(|(t, x)| compare(x, t));
            // The motion error where the truth is on the solved grid (a plain video).
            let motion = truth.zip(x_full.as_deref()).filter(|(t, _)| t.len() == k * m * n).and_then(|(t, x)| motion_error(x, t, k));
            let row = TraceRow::from_info(&IterInfo { seconds: i.seconds + start_s, ..*i }, err).with_motion(motion);
            (hooks.on_row)(ch, &row);
            rows.push(row);
            !hooks.stop.load(Ordering::Relaxed)
        };
        let span = tracing::info_span!("solve", channel = ch, frames = k, rows = m, cols = n, solver = %self.kind, tv_prox = %prox_label);
        let _g = span.enter();
        let mut r = solve(&mut observer);
        r.seconds += start_s;
        tracing::info!(iterations = r.iterations, seconds = r.seconds, termination = ?r.termination, "channel solved");
        let full = to_full(&r.x);
        let error = truth.and_then(|t| compare(&full, t));
        let report = ChannelReport {
            channel: ch,
            stats: SolveStats::new(&r, lipschitz, error),
            // On the solved grid only; a declared scene's solve (fewer frames, a
            // support) gets its baselines from the caller, on the full grid.
            baseline: truth.filter(|t| t.len() == k * m * n).and_then(|t| Baselines::of(t, k)),
            // The caller's, on the full grid with all its frames.
            motion_error: None,
            solver: self.kind,
            tv_prox: prox_label.to_string(),
            haar_strength: strength,
            start,
            keyframes: Vec::new(),
            coarse: None,
            interpolation: None,
            support: None,
            trace: rows,
        };
        (full, report)
    }
}

/// Say when a user fixed the Haar map at a TV strength where its fixed point is
/// biased ([`HAAR_STRONG`]; `auto` would take the exact map there).
pub(crate) fn warn_strong_haar(ch: usize, kind: SolverKind, choice: TvProxChoice, strength: f64) {
    if !kind.shrinks_tv_itself() && choice == TvProxChoice::Fixed(TvProx::Haar) && strength > HAAR_STRONG {
        tracing::warn!(
            channel = ch,
            strength,
            "strong TV for the Haar map (J w tau / max A^T b = {strength:.3} > {HAAR_STRONG}): its fixed point is biased; --tv-prox auto or dualN solves the exact problem"
        );
    }
}

/// What the static + dynamic model changed, per channel (in summary.json as
/// `static_background`).
#[derive(Clone, Debug, Serialize)]
pub struct StaticDynamicReport {
    /// Why the model was solved.
    pub chosen_by: ModelChoice,
    /// Unknowns per channel: the plain video's `K m n`, and this model's `(K + 1) m n`.
    pub unknowns_plain: usize,
    pub unknowns_solved: usize,
    pub channels: Vec<StaticDynamicChannel>,
}

/// One channel of [`StaticDynamicReport`].
#[derive(Clone, Debug, Serialize)]
pub struct StaticDynamicChannel {
    pub channel: usize,
    /// Lipschitz constants (with margin) of the static block, the dynamic block, and the
    /// scaled operator the solver steps on.
    pub lipschitz_static: f64,
    pub lipschitz_dynamic: f64,
    pub lipschitz_scaled: f64,
    /// The steps taken on `s` and `d`: `share / (L_s L_z)` and `1 / (L_d L_z)`
    /// ([`crate::solve::static_dynamic::STATIC_STEP_SHARE`]).
    pub step_static: f64,
    pub step_dynamic: f64,
    /// The weights: TV of the static image (`tau K`, with key frames `tau sqrt(K)`),
    /// TV of the dynamic part (`tau`),
    /// L1 of the dynamic part.
    pub tau_static: f32,
    pub tau_dynamic: f32,
    pub l1_dynamic: f32,
    /// Share of the video's light in the static image: `K sum(s) / sum(v)`.
    pub static_share: f64,
    /// `||A v - b|| / ||b||` at the returned video.
    pub residual_rel: f64,
    /// The iterations of each round: the first (uniform L1), then each reweighted one.
    pub round_iterations: Vec<usize>,
    /// The gains the dynamic part got from its scale refitted to the data after each
    /// round (1: none; [`crate::solve::static_dynamic::MAX_DYNAMIC_GAIN`] at most); none
    /// after a round a stop, the time budget or a non-finite iterate ended, nor after
    /// a gain past the bound was refused.
    pub dynamic_gains: Vec<f64>,
}

/// The static image of a static + dynamic solve and what the model changed.
pub struct StaticBackground {
    /// `s`, (rows, cols, channels) on the video grid.
    pub image: Array3<f32>,
    pub report: StaticDynamicReport,
}

impl StaticBackground {
    /// The dynamic video `d_k = v_k - s` of `video` (frames, rows, cols, channels).
    pub fn dynamic(&self, video: &Array4<f32>) -> Array4<f32> {
        let mut d = video.clone();
        for mut frame in d.outer_iter_mut() {
            frame -= &self.image;
        }
        d
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sens(relative: Vec<f64>, light: Vec<f64>) -> FrameSensitivity {
        let mut s = FrameSensitivity { relative, light, video_light: Vec::new(), weak_below: WEAK_FRAME, weak_frames: Vec::new() };
        s.mark_weak();
        s
    }

    #[test]
    fn frames_weak_by_sensitivity_by_light_or_dark_where_the_data_see_them_less() {
        // Frame 0 by sensitivity, frame 1 by exposure light alone.
        let s = sens(vec![0.3, 0.8, 1.0, 1.0, 0.95, 0.85], vec![0.6, 0.4, 1.0, 1.0, 1.0, 0.9]);
        assert_eq!(s.weak_frames, vec![[0, 2]]);
        // The video shows frames 4 and 5 nearly dark: frame 5 is seen less (0.85 < 0.9)
        // and is weak; frame 4 is seen well, so dark there is the scene's doing.
        let mut video = Array4::<f32>::from_elem((6, 2, 2, 1), 1.0);
        video.index_axis_mut(ndarray::Axis(0), 4).fill(0.1);
        video.index_axis_mut(ndarray::Axis(0), 5).fill(0.1);
        let s = s.with_video(&video);
        assert_eq!(s.video_light.len(), 6);
        assert!((s.video_light[5] - 0.1).abs() < 1e-6);
        assert_eq!(s.weak_frames, vec![[0, 2], [5, 6]]);
        assert_eq!(s.weak_summary().unwrap(), "frames 0-1 and 5 (3 of 6)");
        assert!(s.warning().unwrap().starts_with("weakly constrained: frames 0-1 and 5"));
        // Nothing weak: no line.
        assert!(sens(vec![1.0, 0.9], vec![1.0, 0.7]).warning().is_none());
    }
}
