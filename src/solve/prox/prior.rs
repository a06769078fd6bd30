//! A prior as a problem declares it ([`PriorSpec`]) and the one place it becomes the
//! proximal map the solvers step with ([`PriorSpec::build`]).

use crate::model::ranks::Ranks;
use crate::solve::prox::block::{BlockTv, SplitL1};
use crate::solve::prox::departure::Departure;
use crate::solve::prox::sparse::WithL1;
use crate::solve::prox::static_dynamic::StaticDynamicProx;
use crate::solve::prox::tv_dual::{haar_strength, TvProx, TvProxChoice};
use crate::solve::prox::{Prox, TotalVariation};
use crate::solve::support::{Support, Supported};
use std::sync::Arc;

/// TV with its map, and L1 beside it: one block of a prior.
#[derive(Clone, Debug)]
pub struct TvPrior {
    /// Shape, absolute weight tau, axis weights and non-negativity.
    pub tv: TotalVariation,
    /// The map of the gradient methods (`auto`: judged against `scale`).
    pub map: TvProxChoice,
    /// `max(A^T b)` of the problem the prior is for, the scale `auto` judges the TV
    /// strength against ([`TvProxChoice::resolve`]; a fixed map ignores it).
    pub scale: f64,
    /// Absolute weight of `sum_i w_i |x_i|` beside TV (0: none).
    pub l1: f32,
    /// The L1 term's per-element weights (reweighted L1); `None`: all ones.
    pub l1_weights: Option<Vec<f32>>,
    /// Pixels outside which the video is zero in every frame (a sparse scene's,
    /// [`crate::solve::support`]); `None`: the whole grid.
    pub support: Option<Support>,
}

impl TvPrior {
    /// TV alone with the map `map`, judged on `scale`.
    pub fn new(tv: TotalVariation, map: TvProxChoice, scale: f64) -> Self {
        TvPrior { tv, map, scale, l1: 0.0, l1_weights: None, support: None }
    }

    /// With an L1 term of absolute weight `l1` (0: none) beside TV.
    pub fn with_l1(self, l1: f32) -> Self {
        TvPrior { l1, ..self }
    }

    /// Restricted to `support` (`None`: the whole grid).
    pub fn with_support(self, support: Option<Support>) -> Self {
        TvPrior { support, ..self }
    }

    /// The TV map the gradient methods use (`auto` resolved).
    pub fn tv_map(&self) -> TvProx {
        self.map.resolve(&self.tv, self.scale)
    }

    /// [`haar_strength`] of this TV on its scale.
    pub fn haar_strength(&self) -> f64 {
        haar_strength(&self.tv, self.scale)
    }

    fn boxed(&self) -> Box<dyn Prox> {
        let tv = self.tv_map().build(&self.tv);
        let inner: Box<dyn Prox> = if self.l1 > 0.0 { Box::new(WithL1 { l1: self.l1, inner: tv, weights: self.l1_weights.clone() }) } else { tv };
        self.restricted(inner)
    }

    /// `inner` restricted to the support, when there is one.
    fn restricted<'a>(&self, inner: Box<dyn Prox + 'a>) -> Box<dyn Prox + 'a> {
        match &self.support {
            Some(support) => Box::new(Supported { inner, support: support.clone() }),
            None => inner,
        }
    }
}

/// A prior as a problem declares it; [`PriorSpec::build`] makes the map.
#[derive(Clone, Debug)]
pub enum PriorSpec {
    /// TV with non-negativity (and L1) on the video.
    Tv(TvPrior),
    /// The static + dynamic model's ([`StaticDynamicProx`]): TV of the static image and
    /// TV (and L1) of the dynamic video, on the unknowns scaled by `scale`, `pixels` per
    /// frame, with the joint non-negativity.
    StaticDynamic { static_part: TvPrior, dynamic_part: TvPrior, scale: [f32; 2], pixels: usize },
    /// TV (and L1) of the video's departure from `reference` (the key frames'
    /// interpolation), with the video's non-negativity ([`Departure`]); `part`'s own
    /// non-negativity is off.
    Departure { part: TvPrior, reference: Arc<[f32]> },
}

impl PriorSpec {
    /// The prior's map: the one place a prior is built. `ranks`: the processes the
    /// frames are split across, when the map is a rank's block of the whole problem's
    /// ([`BlockTv`], the L1 sum over every block); `None`: one process.
    ///
    /// # Panics
    /// For a split static + dynamic prior (the split refuses that model first).
    pub fn build<'r>(&self, ranks: Option<&'r dyn Ranks>) -> Box<dyn Prox + 'r> {
        match (self, ranks) {
            (PriorSpec::Tv(p), None) => p.boxed(),
            (PriorSpec::Tv(p), Some(ranks)) => {
                let block = BlockTv::with_map(p.tv.clone(), p.tv_map(), ranks);
                p.restricted(if p.l1 > 0.0 {
                    Box::new(SplitL1 { with: WithL1 { l1: p.l1, inner: Box::new(block), weights: p.l1_weights.clone() }, ranks })
                } else {
                    Box::new(block)
                })
            }
            (PriorSpec::StaticDynamic { static_part, dynamic_part, scale, pixels }, None) => {
                Box::new(StaticDynamicProx { static_reg: static_part.boxed(), dynamic_reg: dynamic_part.boxed(), scale: *scale, pixels: *pixels })
            }
            (PriorSpec::StaticDynamic { .. }, Some(_)) => panic!("the static + dynamic prior is not split across ranks"),
            (PriorSpec::Departure { part, reference }, None) => Box::new(Departure { inner: part.boxed(), reference: reference.clone() }),
            (PriorSpec::Departure { .. }, Some(_)) => panic!("the departure prior is not split across ranks"),
        }
    }

    /// The prior of the still problem of a video of `frames` frames whose still image
    /// is `(rows, cols)` and whose still operator's `max(A^T b)` is `scale`
    /// ([`crate::solve::start`]): the video's spatial TV on one image, weighted by
    /// `frames` (a still video costs the same in both problems), with non-negativity
    /// and the same map choice, without L1. For the static + dynamic model, the static
    /// image's TV (non-negative).
    pub fn still(&self, frames: usize, (rows, cols): (usize, usize), scale: f64) -> TvPrior {
        let tv = match self {
            PriorSpec::Tv(p) => TotalVariation {
                shape: (1, rows, cols),
                tau: crate::solve::tau::static_frame_tau(p.tv.tau, frames),
                weights: p.tv.weights,
                nonneg: p.tv.nonneg,
            },
            PriorSpec::StaticDynamic { static_part, .. } => TotalVariation { shape: (1, rows, cols), nonneg: true, ..static_part.tv.clone() },
            PriorSpec::Departure { part, .. } => {
                TotalVariation { shape: (1, rows, cols), tau: crate::solve::tau::static_frame_tau(part.tv.tau, frames), weights: part.tv.weights, nonneg: true }
            }
        };
        TvPrior::new(tv, self.tv_choice(), scale)
    }

    /// The prior restricted to `support` (the plain video's TV; the static + dynamic
    /// model's prior is returned as it is: it is never restricted).
    pub fn with_support(self, support: Option<Support>) -> PriorSpec {
        match self {
            PriorSpec::Tv(p) => PriorSpec::Tv(p.with_support(support)),
            other => other,
        }
    }

    /// (frames, rows, cols) of the video the prior is on (the dynamic part's for the
    /// static + dynamic model).
    pub fn video_shape(&self) -> (usize, usize, usize) {
        match self {
            PriorSpec::Tv(p) => p.tv.shape,
            PriorSpec::StaticDynamic { dynamic_part, .. } => dynamic_part.tv.shape,
            PriorSpec::Departure { part, .. } => part.tv.shape,
        }
    }

    /// The TV maps the gradient methods use, as reports name them: `haar`, `dual10`,
    /// `static haar + dynamic dual10`.
    pub fn tv_map_name(&self) -> String {
        match self {
            PriorSpec::Tv(p) => p.tv_map().name(),
            PriorSpec::StaticDynamic { static_part, dynamic_part, .. } => {
                format!("static {} + dynamic {}", static_part.tv_map().name(), dynamic_part.tv_map().name())
            }
            PriorSpec::Departure { part, .. } => format!("{} of the departure from the key frames", part.tv_map().name()),
        }
    }

    /// The largest [`haar_strength`] of the prior's TV terms.
    pub fn haar_strength(&self) -> f64 {
        match self {
            PriorSpec::Tv(p) => p.haar_strength(),
            PriorSpec::StaticDynamic { static_part, dynamic_part, .. } => static_part.haar_strength().max(dynamic_part.haar_strength()),
            PriorSpec::Departure { part, .. } => part.haar_strength(),
        }
    }

    /// The map choice of the prior's TV.
    pub fn tv_choice(&self) -> TvProxChoice {
        match self {
            PriorSpec::Tv(p) => p.map,
            PriorSpec::StaticDynamic { static_part, .. } => static_part.map,
            PriorSpec::Departure { part, .. } => part.map,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::op::pseudo_random;

    #[test]
    fn a_tv_prior_with_l1_is_tv_plus_the_weighted_l1_sum_and_its_still_form_drops_l1() {
        let tv = TotalVariation::new((3, 4, 5), 0.2, 2.0);
        let x: Vec<f32> = pseudo_random(60, 1).iter().map(|v| v - 0.3).collect();
        let spec = PriorSpec::Tv(TvPrior::new(tv.clone(), TvProxChoice::Fixed(TvProx::Haar), 1.0).with_l1(0.5));
        let l1: f64 = x.iter().map(|&v| (v as f64).abs()).sum();
        let built = spec.build(None);
        // The L1 sum is taken in f32 lanes: agreement to f32's precision.
        let want = tv.value(&x) + 0.5 * l1;
        assert!((built.value(&x) - want).abs() < 1e-6 * want, "{} vs {want}", built.value(&x));
        // ADMM shrinks TV itself: only a TV prior alone offers it.
        assert!(built.total_variation().is_none());
        assert!(PriorSpec::Tv(TvPrior::new(tv.clone(), TvProxChoice::Auto, 1.0)).build(None).total_variation().is_some());
        // The still problem: one image, the spatial TV weighted by the frames, no L1.
        let still = spec.still(3, (4, 5), 7.0);
        assert_eq!((still.tv.shape, still.tv.tau, still.tv.weights, still.l1, still.scale), ((1, 4, 5), 0.2 * 3.0, tv.weights, 0.0, 7.0));
    }
}
