//! Priors: the proximal maps the solvers step with, behind one trait ([`Prox`]), and
//! the one place a prior is built from its description ([`prior::PriorSpec::build`]).
//!
//! The maps: total variation by Haar shrinkage ([`tv`]) or exactly by its dual
//! ([`tv_dual`], on the gradient operator of [`grad3`]), with non-negativity; sparsity
//! (L1) beside them ([`sparse`]); the static + dynamic model's block maps and exact joint
//! non-negativity ([`static_dynamic`]); a rank's block of TV when the frames are split
//! across processes ([`block`]).
//!
//! A new prior is its map (a file here implementing [`Prox`]), a variant of
//! [`prior::PriorSpec`] and its arm in [`prior::PriorSpec::build`]; the solvers, the still start and
//! the tau search take whatever that builds.

pub mod block;
pub mod grad3;
pub mod prior;
pub mod sparse;
pub mod static_dynamic;
pub mod tv;
pub mod tv_dual;

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
