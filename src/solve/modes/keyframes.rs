//! [`Mode::KeyFrames`](crate::solve::plan::Mode::KeyFrames): the plain video with the
//! key frames as data terms beside the raw ([`crate::solve::keyframes`]), started from
//! the same solve on a grid coarser in time when the video is long enough.

use super::shared::{retry_on_non_finite, ChannelVideos, ModeRun};
use crate::model::data::DataTerm;
use crate::solve::channel::FullGrid;
use crate::solve::job::ChannelJob;
use crate::solve::keyframes::KeyFrameData;
use crate::solve::problem::{Problem, ReconstructError};
use crate::solve::prox::prior::PriorSpec;
use rayon::prelude::*;
use std::time::Instant;

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
                let (setup, prior) = self.keyframe_setup(problem, ch, noise)?;
                let data = setup.data();
                let full = FullGrid { truth: self.truth(ch), to_full: &identity };
                let (x0, first) = match first {
                    Some((v, c)) => (v, Some(c)),
                    None => (setup.terms.start(), None),
                };
                // The key frames' interpolation is where the data say nothing; the
                // solve starts from the coarse solve (else the key frames' still scene).
                let interpolation: std::sync::Arc<[f32]> = setup.terms.interpolation().into();
                let departure = self.recipe.departure(prior.video_shape(), problem.channel(ch).atb_max() as f64, interpolation.clone());
                let departs = self.params.solver.check_prior(departure.build(None).as_ref()).is_ok();
                let prior = if departs { departure } else { prior };
                let run = |l| self.job(ch).run_from(&setup.op, &data, &prior, l, full, x0.clone());
                let again = || {
                    crate::solve::lipschitz::Lipschitz::measured(
                        self.cache.measure(setup.key, &setup.op).lambda_max * crate::solve::lipschitz::LIPSCHITZ_MARGIN,
                    )
                };
                let (video, mut report) = retry_on_non_finite(run(setup.lipschitz), setup.lipschitz.cached, || run(again()));
                let mut terms = setup.terms;
                terms.add_fit(&video);
                report.interpolation = departs.then(|| {
                    let raw = DataTerm::new(&prepared.raw[ch].data).with_lower_bounds(prepared.data_mask.lower_bounds.as_deref());
                    crate::solve::keyframes::InterpolationReport::of(problem.channel(ch).model(), &raw, &video, &interpolation, self.truth(ch))
                });
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

    /// Channel `ch`'s key-frame data term on `problem` (the capture's, or its coarse
    /// twin; `noise` is the raw's) and its video prior.
    fn keyframe_setup<'p>(&self, problem: &'p Problem, ch: usize, noise: Option<f32>) -> Result<(KeyFrameData<'p>, PriorSpec), ReconstructError> {
        let channel = problem.channel(ch);
        let d = KeyFrameData::of(problem, ch, noise, &self.recipe, crate::solve::keyframes::STIFFNESS_CAP, self.params.solver, self.cache)?;
        let prior = self.recipe.video(channel.model().video_shape(), channel.atb_max() as f64);
        Ok((d, prior))
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
        let (setup, prior) = self.keyframe_setup(coarse, ch, noise)?;
        let data = setup.data();
        let settings = crate::solve::optimize::OptimizerSettings::new(self.params.solver, setup.lipschitz.value, self.params.stop.clone());
        let reg = prior.build(None);
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
        let frames = prior.video_shape().0;
        let video = crate::solve::keyframes::refine_in_time(&r.x, frames, binning, shape);
        let report = crate::solve::keyframes::CoarseStart { binning, frames, iterations: r.iterations, seconds: t0.elapsed().as_secs_f64() };
        tracing::info!(channel = ch, binning, frames, iterations = r.iterations, seconds = report.seconds, "coarse key-frame solve");
        Ok(Some((video, report)))
    }
}
