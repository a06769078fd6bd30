//! Sparsity beside another regulariser: `R(x) + lambda sum_i |x_i|`.
//!
//! The map is `R`'s own map followed by the soft threshold at `gamma lambda`. For 1D TV
//! (with or without `x >= 0`) this composition is the exact prox of the sum (Friedman,
//! Hastie, Höfling & Tibshirani 2007: soft thresholding commutes with the TV map's
//! fusing); for 3D TV it is the same kind of approximation as the parallel proximal TV
//! map itself. After a non-negative map the threshold is `max(x - gamma lambda, 0)`.

use crate::solve::prox::tv::{soft, Prox};
use rayon::prelude::*;

/// `inner + l1 ||x||_1`.
pub struct WithL1<P: ?Sized> {
    /// Weight of the L1 term, in the units of the objective (like tau).
    pub l1: f32,
    pub inner: Box<P>,
}

impl<P: Prox + ?Sized> Prox for WithL1<P> {
    fn value(&self, x: &[f32]) -> f64 {
        let l1: f64 = x.par_chunks(1 << 15).map(|c| c.iter().map(|&v| (v as f64).abs()).sum::<f64>()).collect::<Vec<_>>().iter().sum();
        self.inner.value(x) + self.l1 as f64 * l1
    }
    fn prox(&self, z: &[f32], gamma: f32, out: &mut [f32]) {
        self.inner.prox(z, gamma, out);
        let c = gamma * self.l1;
        if c > 0.0 {
            out.par_chunks_mut(1 << 15).for_each(|o| o.iter_mut().for_each(|v| *v = soft(*v, c)));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solve::prox::tv::{NonNegative, TotalVariation};
    use crate::solve::prox::tv_dual::TvProx;

    /// Brute force: argmin over a fine grid of gamma R(x) + 0.5 (x - z)^2 for one sample.
    fn brute_1(z: f32, gamma: f32, l1: f32, nonneg: bool) -> f32 {
        let mut best = (f64::INFINITY, 0.0f32);
        for i in -40000..=40000 {
            let x = i as f32 * 1e-4;
            if nonneg && x < 0.0 {
                continue;
            }
            let f = gamma as f64 * l1 as f64 * (x as f64).abs() + 0.5 * ((x - z) as f64).powi(2);
            if f < best.0 {
                best = (f, x);
            }
        }
        best.1
    }

    #[test]
    fn one_sample_is_the_exact_soft_threshold() {
        let p = WithL1 { l1: 0.5, inner: Box::new(NonNegative) };
        let tv_free = WithL1 { l1: 0.5, inner: Box::new(TotalVariation { shape: (1, 1, 1), tau: 0.0, weights: [0.0; 3], nonneg: false }) };
        for z in [-2.0f32, -0.3, 0.1, 0.2, 0.7, 3.0] {
            let mut o = [0.0f32];
            p.prox(&[z], 0.6, &mut o);
            assert!((o[0] - brute_1(z, 0.6, 0.5, true)).abs() < 2e-4, "z = {z}: {}", o[0]);
            tv_free.prox(&[z], 0.6, &mut o);
            assert!((o[0] - brute_1(z, 0.6, 0.5, false)).abs() < 2e-4, "z = {z}: {}", o[0]);
        }
        assert!((p.value(&[1.0, -2.0]) - 1.5).abs() < 1e-12);
    }

    #[test]
    fn two_samples_with_tv_match_brute_force() {
        // 1D TV of two samples plus L1, with the exact (dual) TV map: the composition
        // is exact.
        let tv = TotalVariation { shape: (1, 1, 2), tau: 0.3, weights: [0.0, 0.0, 1.0], nonneg: true };
        let p = WithL1 { l1: 0.4, inner: TvProx::Dual { inner_iters: 500 }.build(&tv) };
        for z in [[1.0f32, 0.2], [0.1, 0.15], [2.0, 1.9], [0.5, -0.5]] {
            let mut o = [0.0f32; 2];
            p.prox(&z, 1.0, &mut o);
            let f = |x: [f32; 2]| p.value(&x) + 0.5 * x.iter().zip(&z).map(|(a, b)| ((a - b) as f64).powi(2)).sum::<f64>();
            let mut best = (f64::INFINITY, [0.0f32; 2]);
            for i in 0..=300 {
                for j in 0..=300 {
                    let x = [i as f32 * 0.01, j as f32 * 0.01];
                    let v = f(x);
                    if v < best.0 {
                        best = (v, x);
                    }
                }
            }
            assert!(f(o) <= best.0 + 1e-5, "z = {z:?}: map {o:?} ({}) vs grid {:?} ({})", f(o), best.1, best.0);
        }
    }
}
