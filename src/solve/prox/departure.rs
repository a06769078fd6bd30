//! A prior on a video's departure from a reference video: `R(x) = P(x - r)` with `x >=
//! 0`, where `P` (TV, and L1 beside it) is taken without its own non-negativity. Its
//! map is `max(r + prox_P(z - r), 0)`: exact for the shift, the bound applied after (as
//! the Haar map applies its own). Where the data say nothing, the video stays at `r`.

use super::Prox;
use std::sync::Arc;

/// `inner` on `x - reference`, then `x >= 0`.
pub struct Departure<'a> {
    pub inner: Box<dyn Prox + 'a>,
    pub reference: Arc<[f32]>,
}

impl Prox for Departure<'_> {
    fn value(&self, x: &[f32]) -> f64 {
        let d: Vec<f32> = x.iter().zip(self.reference.iter()).map(|(&a, &r)| a - r).collect();
        self.inner.value(&d)
    }

    fn prox(&self, z: &[f32], gamma: f32, out: &mut [f32]) {
        let d: Vec<f32> = z.iter().zip(self.reference.iter()).map(|(&a, &r)| a - r).collect();
        self.inner.prox(&d, gamma, out);
        out.iter_mut().zip(self.reference.iter()).for_each(|(o, &r)| *o = (*o + r).max(0.0));
    }
}

#[cfg(test)]
mod tests {
    use crate::solve::prox::prior::{PriorSpec, TvPrior};
    use crate::solve::prox::tv_dual::{TvProx, TvProxChoice};
    use crate::solve::prox::TotalVariation;

    #[test]
    fn the_reference_is_a_fixed_point_and_a_departure_shrinks_toward_it() {
        let shape = (4, 3, 3);
        let n = 36;
        let reference: Vec<f32> = (0..n).map(|i| 1.0 + (i % 7) as f32).collect();
        let mut tv = TotalVariation::new(shape, 0.5, 1.0);
        tv.nonneg = false;
        let spec = PriorSpec::Departure { part: TvPrior::new(tv, TvProxChoice::Fixed(TvProx::Haar), 1.0).with_l1(0.5), reference: reference.clone().into() };
        let p = spec.build(None);
        let mut out = vec![0.0; n];
        p.prox(&reference, 1.0, &mut out);
        assert!(out.iter().zip(&reference).all(|(a, b)| (a - b).abs() < 1e-5), "{out:?}");
        assert!(p.value(&reference).abs() < 1e-9);
        // A small departure in one pixel is shrunk back (L1 beside TV), never below zero.
        let mut z = reference.clone();
        z[5] += 0.2;
        z[7] = -3.0;
        p.prox(&z, 1.0, &mut out);
        assert!((out[5] - reference[5]).abs() < 0.2, "{} against {}", out[5], reference[5]);
        assert!(out.iter().all(|&v| v >= 0.0));
    }
}
