//! Priors: the proximal maps the solvers step with, behind one trait ([`Prox`]), and
//! the one place a prior is built from its description ([`prior::PriorSpec::build`]).
//!
//! The maps: total variation by Haar shrinkage ([`tv`]) or exactly by its dual
//! ([`tv_dual`], on the gradient operator of [`grad3`]), with non-negativity; sparsity
//! (L1) beside them ([`sparse`]); the static + dynamic model's block maps and exact joint
//! non-negativity ([`static_dynamic`]); a rank's block of TV when the frames are split
//! across processes ([`block`]). Both TV maps also step in a per-frame diagonal metric
//! ([`MetricProx`], for the preconditioned gradient methods of [`crate::solve::metric`]).
//!
//! A new prior is its map (a file here implementing [`Prox`]), a variant of
//! [`prior::PriorSpec`] and its arm in [`prior::PriorSpec::build`]; the solvers, the still start and
//! the tau search take whatever that builds.

pub mod block;
pub mod departure;
pub mod grad3;
pub mod prior;
pub mod sparse;
pub mod static_dynamic;
pub mod tv;
pub mod tv_dual;

use crate::solve::metric::FrameMetric;

/// Something with a value and a proximal map: `prox(z, gamma) = argmin_x gamma R(x) +
/// 0.5 ||x - z||^2` (possibly approximate, as documented by the implementation).
pub trait Prox: Send + Sync {
    /// `R(x)`, accumulated in f64.
    fn value(&self, x: &[f32]) -> f64;
    /// Writes `prox_{gamma R}(z)` into `out`.
    fn prox(&self, z: &[f32], gamma: f32, out: &mut [f32]);
    /// The TV term (with its non-negativity) when this prior is that term alone, by
    /// whichever map: what a solver that shrinks TV itself (ADMM) needs. `None`: any
    /// other prior.
    fn total_variation(&self) -> Option<&TotalVariation> {
        None
    }
    /// The TV term when this prior is that term alone through the Haar map (the map the
    /// CUDA FISTA step evaluates); `None`: any other prior or map.
    fn haar_tv(&self) -> Option<&TotalVariation> {
        None
    }
    /// The map in a per-frame metric ([`MetricProx`]), when this prior has one (TV with
    /// non-negativity by either map); `None`: any other prior, which the preconditioned
    /// solvers refuse.
    fn metric_prox(&self) -> Option<&dyn MetricProx> {
        None
    }
}

/// The proximal map in a per-frame diagonal metric: `prox_in(z, gamma, P) = argmin_x
/// gamma R(x) + 0.5 sum_k d_k ||x_k - z_k||^2` (as exact as the map's plain form). With
/// every `d_k = 1` it is [`Prox::prox`], to the bit; with every `d_k = d`, the plain map
/// at `gamma / d`.
pub trait MetricProx: Send + Sync {
    fn prox_in(&self, z: &[f32], gamma: f32, metric: &FrameMetric, out: &mut [f32]);
}

/// Weighted anisotropic TV on a `(frames, rows, cols)` volume: the term every TV map
/// ([`tv`]'s Haar shrinkage, [`tv_dual`]'s exact map) and ADMM minimise.
#[derive(Clone, Debug)]
pub struct TotalVariation {
    pub shape: (usize, usize, usize),
    pub tau: f32,
    /// Weights of the (t, y, x) differences.
    pub weights: [f32; 3],
    pub nonneg: bool,
}
