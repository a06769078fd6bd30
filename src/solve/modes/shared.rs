//! What every mode's channel solves share: [`ModeRun`] (the problem, the plan, the
//! prior's recipe, the truth, the cache and the hooks), a plain channel's setup, the
//! assembly of the channels' videos, and the chaining and retrying of solves.

use crate::model::data::DataTerm;
use crate::model::op::Operator;
use crate::model::rolling::RollingShutterModel;
use crate::solve::channel::{ChannelReport, ChannelSolve, FrameSensitivity, FullGrid, Hooks, Reconstruction, SceneReport};
use crate::solve::lipschitz::EigenStore;
use crate::solve::optimize::StopRule;
use crate::solve::plan::SolvePlan;
use crate::solve::problem::{PriorRecipe, Problem, ReconstructError, SolveParams};
use crate::solve::prox::prior::PriorSpec;
use crate::solve::trace::{motion_error, Baselines};
use ndarray::{Array4, Axis};
use std::sync::OnceLock;

/// Every output channel's video (on the full grid) and report.
pub(crate) type ChannelVideos = Vec<(Vec<f32>, ChannelReport)>;

/// What every mode's channel solves read: the problem, the plan and its parameters,
/// the prior's recipe, the truth, the cache and the hooks.
pub(crate) struct ModeRun<'a> {
    pub(super) problem: &'a Problem<'a>,
    pub(super) plan: &'a SolvePlan,
    pub(super) params: &'a SolveParams,
    pub(super) recipe: PriorRecipe,
    pub(super) truth_planes: Option<&'a [Vec<f32>]>,
    pub(super) cache: &'a dyn EigenStore,
    pub(super) hooks: &'a Hooks<'a>,
    /// Each captured channel's stop rule for the plain video: the run's, with the
    /// channel's noise floor ([`crate::solve::fit::noise_floor`]); made on first use.
    pub(super) plain_stops: OnceLock<Vec<StopRule>>,
}

/// One captured channel's plain video ([`ModeRun::plain_channel`]): its operator, data,
/// prior, stored (or measured) Lipschitz constant, truth and solve under the plain
/// video's stop rule.
pub(super) struct PlainChannel<'r> {
    pub(super) model: &'r RollingShutterModel,
    pub(super) data: DataTerm<'r>,
    pub(super) prior: PriorSpec,
    pub(super) lipschitz: crate::solve::lipschitz::Lipschitz,
    pub(super) truth: Option<&'r [f32]>,
    pub(super) job: ChannelSolve<'r>,
}

impl PlainChannel<'_> {
    pub(super) fn full(&self) -> FullGrid<'_> {
        FullGrid { truth: self.truth, to_full: &|x: &[f32]| x.to_vec() }
    }
}

impl<'a> ModeRun<'a> {
    pub(super) fn job(&self, ch: usize) -> ChannelSolve<'_> {
        let params = self.params;
        let still_check = self.plan.still_checks.get(ch);
        ChannelSolve { ch, kind: params.solver, device: params.device, start: params.start, stop: &params.stop, hooks: self.hooks, still_check }
    }

    pub(super) fn truth(&self, ch: usize) -> Option<&[f32]> {
        self.truth_planes.map(|t| t[ch].as_slice())
    }

    /// Channel `ch`'s plain video, under [`ModeRun::plain_stops`].
    pub(super) fn plain_channel(&self, ch: usize) -> PlainChannel<'_> {
        let (problem, prepared) = (self.problem, self.problem.prepared);
        let c = problem.channel(ch);
        let model = c.model();
        let stop = &self
            .plain_stops
            .get_or_init(|| (0..problem.channels()).map(|ch| self.params.stop.clone().with_noise_floor(crate::solve::fit::noise_floor(problem, ch))).collect())
            [ch];
        PlainChannel {
            model,
            data: DataTerm::new(&prepared.raw[ch].data).with_lower_bounds(prepared.data_mask.lower_bounds.as_deref()),
            prior: self.recipe.video(model.video_shape(), c.atb_max() as f64),
            lipschitz: c.lipschitz(self.cache),
            truth: self.truth(ch),
            job: ChannelSolve { stop, ..self.job(ch) },
        }
    }

    /// Whether the plain video's solver runs on its device with this capture (checked
    /// on the first channel, the device's memory for all).
    pub(super) fn check_plain_on_device(&self) -> Result<(), ReconstructError> {
        let (problem, params) = (self.problem, self.params);
        let (prepared, kind, models) = (problem.prepared, params.solver, problem.models());
        let lower = prepared.data_mask.lower_bounds.as_deref();
        if let (Some(model), Some(raw)) = (models.first(), prepared.raw.first()) {
            let p = self.recipe.video(model.video_shape(), problem.channel(0).atb_max() as f64).build(None);
            kind.check_on_device(params.device, *model, &DataTerm::new(&raw.data).with_lower_bounds(lower), p.as_ref(), false)
                .and_then(|()| kind.check_device_memory(params.device, *model, prepared.raw.len()))
                .map_err(ReconstructError::Unsupported)?;
        }
        Ok(())
    }

    /// The video of the channels' results, with its reports.
    pub(super) fn assemble(&self, results: ChannelVideos, scene: Option<SceneReport>) -> Reconstruction {
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

/// `first` then `then` as one solve: iterations and seconds added, `then`'s rows after
/// `first`'s (numbered and timed on from them), the rest (the stop, the error at the
/// returned video) `then`'s; the start `first`'s.
pub(super) fn chain(first: ChannelReport, mut then: ChannelReport) -> ChannelReport {
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
pub(super) fn retry_on_non_finite(
    first: (Vec<f32>, ChannelReport),
    cached: bool,
    again: impl FnOnce() -> (Vec<f32>, ChannelReport),
) -> (Vec<f32>, ChannelReport) {
    if cached && matches!(first.1.stats.termination, crate::solve::optimize::Termination::NonFinite { .. }) {
        tracing::warn!(channel = first.1.channel, "the solve went non-finite with the stored Lipschitz constant: measuring it again and solving anew");
        return again();
    }
    first
}
