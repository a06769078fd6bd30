//! One capture split across MPI ranks: [`SplitRequest`] -> [`SplitCapture`]. Every rank
//! builds the same request and runs it; rank 0 gets the gathered video.

use crate::io::budget::check_split_reconstruction;
use crate::model::ranks::Ranks;
use crate::request::capture::{CaptureOutcome, CaptureRequest};
use crate::request::RequestError;
use crate::solve::channel::SplitReport;
use crate::solve::lipschitz::EigenStore;
use crate::solve::plan::SolvePlan;
use crate::solve::reconstruct::Hooks;
use std::time::Instant;

/// A capture request solved by `ranks` together ([`crate::solve::split`]).
pub struct SplitRequest<'a> {
    pub capture: &'a CaptureRequest<'a>,
    pub ranks: &'a dyn Ranks,
    /// Ranks on this machine (they share its memory budget).
    pub ranks_here: usize,
    /// This process's peak resident memory, for the split's report.
    pub peak_memory: &'a dyn Fn() -> Option<u64>,
    /// Told the plan before the solve (every rank); false declines it.
    pub on_plan: &'a dyn Fn(&SolvePlan) -> bool,
}

/// What a split gave each rank: the outcome on rank 0 (`None` elsewhere) and the
/// split's report on every rank (`None` from [`SplitRequest::run`]: the plan was declined).
pub struct SplitCapture {
    pub outcome: Option<CaptureOutcome>,
    pub report: SplitReport,
}

impl SplitRequest<'_> {
    /// Channels the solve runs (for progress totals).
    pub fn solved_channels(&self) -> usize {
        self.capture.solved_channels()
    }

    /// Prepare the capture (every rank holds the whole raw), check this machine's
    /// memory for its ranks' shares, report the sensor on rank 0, and solve.
    pub fn run(&self, cache: &dyn EigenStore, hooks: &Hooks) -> Result<Option<SplitCapture>, RequestError> {
        let r = self.capture;
        let prepared = r.prepare_data()?;
        check_split_reconstruction(r.cfg, r.cfg.fov, prepared.raw.len(), self.ranks.size(), self.ranks_here).map_err(Box::new)?;
        if self.ranks.rank() == 0 {
            (r.on_sensor)(&prepared.sensor);
        }
        let t0 = Instant::now();
        let split = crate::solve::split::reconstruct(
            (&prepared, r.cfg),
            r.settings,
            r.scene.clone(),
            r.truth,
            cache,
            hooks,
            crate::solve::split::RankContext { ranks: self.ranks, peak_memory: self.peak_memory, on_plan: self.on_plan },
        )?;
        let Some(split) = split else { return Ok(None) };
        let seconds = t0.elapsed().as_secs_f64();
        let outcome = split.reconstruction.map(|reconstruction| CaptureOutcome { reconstruction, params: split.params, prepared, seconds });
        Ok(Some(SplitCapture { outcome, report: split.report }))
    }
}
