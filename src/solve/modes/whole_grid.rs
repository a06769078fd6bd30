//! [`Mode::WholeGrid`](crate::solve::plan::Mode::WholeGrid): the plain video, every
//! captured channel on its own operator over the whole grid.

use super::shared::{retry_on_non_finite, ChannelVideos, ModeRun};
use crate::solve::problem::ReconstructError;
use rayon::prelude::*;

impl ModeRun<'_> {
    /// Every captured channel's plain video on the whole grid.
    pub(super) fn whole_grid(&self) -> Result<ChannelVideos, ReconstructError> {
        self.check_plain_on_device()?;
        Ok((0..self.problem.channels())
            .into_par_iter()
            .map(|ch| {
                let c = self.plain_channel(ch);
                let run = |l| c.job.run(c.model, &c.data, &c.prior, l, c.full(), (c.model, &|v| v));
                retry_on_non_finite(run(c.lipschitz), c.lipschitz.cached, || {
                    run(crate::solve::lipschitz::Lipschitz::measured(self.problem.channel(ch).remeasure_lipschitz(self.cache)))
                })
            })
            .collect())
    }
}
