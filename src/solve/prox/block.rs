//! A rank's block of the TV prior when one capture's frames are split across
//! processes ([`crate::solve::split`]): the whole video's TV evaluated on the block
//! with the neighbours' edge frames ([`BlockTv`]), and an L1 term beside it summed over
//! every block.

use crate::model::ranks::Ranks;
use crate::solve::prox::sparse::WithL1;
use crate::solve::prox::tv_dual::{DualTv, TvProx};
use crate::solve::prox::Prox;
use crate::solve::prox::TotalVariation;
use std::sync::Mutex;

/// The TV term of one rank's block: the whole video's TV (`tv.shape` is the whole
/// video's), evaluated on the block with the neighbours' edge frames, by the Haar map
/// or the exact (dual) map.
pub struct BlockTv<'r> {
    pub tv: TotalVariation,
    pub ranks: &'r dyn Ranks,
    /// The dual map (its warm start is the block's), when it is the one used.
    dual: Option<DualTv>,
    /// The frames just before and after the block (halo), refreshed on every call.
    halo: Mutex<(Vec<f32>, Vec<f32>)>,
}

impl<'r> BlockTv<'r> {
    /// The Haar map.
    pub fn new(tv: TotalVariation, ranks: &'r dyn Ranks) -> Self {
        Self::with_map(tv, TvProx::Haar, ranks)
    }

    /// The map `map`.
    pub fn with_map(tv: TotalVariation, map: TvProx, ranks: &'r dyn Ranks) -> Self {
        let fl = tv.shape.1 * tv.shape.2;
        let dual = match map {
            TvProx::Haar => None,
            TvProx::Dual { inner_iters } => Some(DualTv::new(tv.clone(), inner_iters)),
        };
        BlockTv { tv, ranks, dual, halo: Mutex::new((vec![0.0; fl], vec![0.0; fl])) }
    }

    fn temporal(&self) -> bool {
        self.tv.active_axes().contains(&0)
    }

    /// Exchange the block's edge frames of `x` with the neighbours and run `f` with the
    /// frames before and after the block (`None` at the video's ends, or without
    /// temporal TV, where no frame is exchanged). `both`: false exchanges only the
    /// frame after the block (all the TV value needs).
    fn with_halo<R>(&self, x: &[f32], both: bool, f: impl FnOnce(Option<&[f32]>, Option<&[f32]>) -> R) -> R {
        if !self.temporal() || self.ranks.size() == 1 {
            return f(None, None);
        }
        let fl = self.tv.shape.1 * self.tv.shape.2;
        let mut halo = self.halo.lock().unwrap();
        let (before, after) = &mut *halo;
        let (last, before) = if both { (&x[x.len() - fl..], &mut before[..]) } else { (&x[..0], &mut before[..0]) };
        self.ranks.exchange_halo(&x[..fl], last, before, after);
        let (r, end) = (self.ranks.rank(), self.ranks.size() - 1);
        f((both && r > 0).then_some(&before[..]), (r < end).then_some(&after[..]))
    }
}

impl Prox for BlockTv<'_> {
    fn value(&self, x: &[f32]) -> f64 {
        let mut s = self.with_halo(x, false, |_, after| self.tv.abs_gradient_sums_block(x, after));
        self.ranks.sum_f64(&mut s);
        self.tv.tau as f64 * (0..3).map(|a| self.tv.weights[a] as f64 * s[a]).sum::<f64>()
    }

    fn prox(&self, z: &[f32], gamma: f32, out: &mut [f32]) {
        match &self.dual {
            Some(d) => d.prox_block(z, gamma, out, self.ranks),
            None => self.with_halo(z, true, |before, after| self.tv.prox_block(z, before, after, gamma, out)),
        }
    }
}

/// An L1 term beside a block's TV ([`WithL1`]), its sum over every rank's block.
pub(crate) struct SplitL1<'r> {
    pub(crate) with: WithL1<BlockTv<'r>>,
    pub(crate) ranks: &'r dyn Ranks,
}

impl Prox for SplitL1<'_> {
    fn value(&self, x: &[f32]) -> f64 {
        let mut l1 = [self.with.l1_sum(x)];
        self.ranks.sum_f64(&mut l1);
        self.with.inner.value(x) + self.with.l1 as f64 * l1[0]
    }
    fn prox(&self, z: &[f32], gamma: f32, out: &mut [f32]) {
        self.with.prox(z, gamma, out);
    }
}
