//! [`Mode::KeyFrames`](crate::solve::plan::Mode::KeyFrames): the plain video with the
//! key frames as data terms beside the raw ([`crate::solve::keyframes`]), started from
//! the same solve on a grid coarser in time when the video is long enough.

use super::{retry_on_non_finite, ChannelVideos, ModeRun};
use crate::model::data::DataTerm;
use crate::solve::channel::FullGrid;
use crate::solve::job::ChannelJob;
use crate::solve::problem::{Problem, ReconstructError};
use rayon::prelude::*;
use std::time::Instant;

/// One channel's key-frame problem, ready to solve ([`ModeRun::keyframe_setup`]).
struct KeyFrameSetup<'p> {
    terms: crate::solve::keyframes::KeyFrameTerms,
    op: crate::model::keyframe::Fused<&'p crate::model::rolling::RollingShutterModel>,
    obs: Vec<f32>,
    lower: Option<Vec<bool>>,
    prior: crate::solve::prox::prior::PriorSpec,
    lipschitz: (f64, bool),
    key: crate::solve::lipschitz::Fingerprint,
}

impl ModeRun<'_> {
    /// The undeclared video with the key frames: every captured channel on the stacked
    /// operator of its raw and its key frames ([`crate::solve::keyframes`]), started from
    /// the same solve on a grid coarser in time when the video is long enough
    /// ([`crate::solve::keyframes::coarse_binning`]), else from the key frames.
    pub(super) fn with_keyframes(&self) -> Result<ChannelVideos, ReconstructError> {
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
        let r = crate::solve::job::run(
            ChannelJob { settings: &settings, operator: &setup.op, data: &data, prior: reg.as_ref(), start: Some(setup.terms.start()) },
            &mut observer,
        );
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
}
