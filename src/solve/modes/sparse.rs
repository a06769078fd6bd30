//! [`Mode::SparseSources`](crate::solve::plan::Mode::SparseSources): a sparse scene's
//! plain video solved on its still image's support ([`crate::solve::support`]), probed
//! against the whole grid, then fitted as sources that change only in brightness
//! ([`crate::solve::sources`]) when the data confirm them.

use super::shared::{chain, retry_on_non_finite, ChannelVideos, ModeRun};
use crate::solve::channel::{ChannelReport, ChannelSolve};
use crate::solve::optimize::{StopRule, Termination};
use crate::solve::problem::ReconstructError;
use crate::solve::support::{Support, SupportReport};
use rayon::prelude::*;

/// Where a solve after the first goes on, and under which stop.
#[derive(Clone, Copy)]
enum Then {
    /// The probe on the support: all its iterations, no settling rule.
    ProbeSupport,
    /// The probe on the whole grid: all its iterations, no settling rule.
    ProbeWholeGrid,
    /// On the support, under the run's stop rule.
    OnSupport,
    /// On the whole grid, under the run's stop rule.
    OnWholeGrid,
}

impl ModeRun<'_> {
    /// Every captured channel's video on the plan's support, kept, dropped for the whole
    /// grid, or replaced by its sources' as the data say.
    pub(super) fn sparse(&self, support: &Support) -> Result<ChannelVideos, ReconstructError> {
        self.check_plain_on_device()?;
        let k = self.problem.channel(0).model().video_shape().0;
        Ok((0..self.problem.channels())
            .into_par_iter()
            .map(|ch| {
                let c = self.plain_channel(ch);
                let (model, lipschitz, full) = (c.model, c.lipschitz, c.full());
                let supported = c.prior.clone().with_support(Some(support.clone()));
                // The first solve leaves the probe's iterations of the cap and stops at
                // FIRST_ITERS for the probe and the sources' fit; the rest of the cap goes
                // on only when the sources are refused.
                let max_iters = c.job.stop.max_iters;
                let probe_iters = crate::solve::support::probe_iters(max_iters);
                let first_iters = (max_iters - probe_iters).min(crate::solve::support::FIRST_ITERS);
                let first_stop = StopRule { max_iters: first_iters, ..c.job.stop.clone() };
                let run = |l| ChannelSolve { stop: &first_stop, ..c.job }.run(model, &c.data, &supported, l, full, (model, &|v| v));
                let solved = retry_on_non_finite(run(lipschitz), lipschitz.cached, || {
                    run(crate::solve::lipschitz::Lipschitz::measured(self.problem.channel(ch).remeasure_lipschitz(self.cache)))
                });
                let run_from = |x0: Vec<f32>, iterations: usize, then: Then| {
                    let stop = match then {
                        Then::ProbeSupport | Then::ProbeWholeGrid => {
                            StopRule { max_iters: iterations, rel_tol: 0.0, obj_tol: 0.0, noise_floor: None, ..c.job.stop.clone() }
                        }
                        Then::OnSupport | Then::OnWholeGrid => StopRule { max_iters: iterations, ..c.job.stop.clone() },
                    };
                    let on = match then {
                        Then::ProbeWholeGrid | Then::OnWholeGrid => &c.prior,
                        Then::ProbeSupport | Then::OnSupport => &supported,
                    };
                    ChannelSolve { stop: &stop, ..c.job }.run_from(model, &c.data, on, lipschitz, full, x0)
                };
                let capped = solved.1.stats.termination == Termination::MaxIterations;
                let solved = keep_or_drop_support(solved, support, (max_iters, probe_iters), &run_from);
                let fit = |v: &[f32], misfit: f64| crate::solve::sources::fit_sources(model, &c.data, lipschitz.value, (support, v, misfit), k);
                let (video, mut report) = sources_or_support(solved, fit, (self.truth(ch), k));
                let on_support = report.support.as_ref().is_some_and(|s| s.kept && !s.sources_kept());
                if !(capped && on_support && report.stats.iterations < max_iters) {
                    return (video, report);
                }
                // The support's video stands: the solve goes on for the rest of the cap.
                let (video, rest) = run_from(video, max_iters - report.stats.iterations, Then::OnSupport);
                let support = report.support.take();
                let mut report = chain(report, rest);
                report.support = support;
                (video, report)
            })
            .collect())
    }
}

/// The video solved on a sparse scene's `support` (for `max_iters` less the probe's
/// iterations) kept unless the data hold light outside it. `run_from(x0, iterations,
/// then)` solves from `x0` for at most `iterations`, where [`Then`] says. The probe runs `probe_iters`
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
    run_from: &impl Fn(Vec<f32>, usize, Then) -> (Vec<f32>, ChannelReport),
) -> (Vec<f32>, ChannelReport) {
    let ch = report.channel;
    if probe_iters == 0 || matches!(report.stats.termination, Termination::Stopped | Termination::NonFinite { .. }) {
        // A stopped or failed solve, or a cap under two iterations, is returned as it
        // is: the probe would judge nothing.
        report.support = Some(SupportReport::unprobed(support));
        return (video, report);
    }
    let (on, on_report) = run_from(video.clone(), probe_iters, Then::ProbeSupport);
    let (probe, probe_report) = run_from(video, probe_iters, Then::ProbeWholeGrid);
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
        let (video, rest) = run_from(probe, max_iters - chained.stats.iterations, Then::OnWholeGrid);
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
