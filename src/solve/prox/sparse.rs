//! Sparsity beside another regulariser: `R(x) + lambda sum_i |x_i|`.
//!
//! The map is `R`'s own map followed by the soft threshold at `gamma lambda`. For 1D TV
//! (with or without `x >= 0`) this composition is the exact prox of the sum (Friedman,
//! Hastie, Höfling & Tibshirani 2007: soft thresholding commutes with the TV map's
//! fusing); for 3D TV it is the same kind of approximation as the parallel proximal TV
//! map itself. After a non-negative map the threshold is `max(x - gamma lambda, 0)`.

use crate::solve::prox::tv::soft;
use crate::solve::prox::Prox;
use rayon::prelude::*;

/// `inner + l1 sum_i w_i |x_i|` (`w_i = 1` without weights).
pub struct WithL1<P: ?Sized> {
    /// Weight of the L1 term, in the units of the objective (like tau).
    pub l1: f32,
    pub inner: Box<P>,
    /// Per-element weights (reweighted L1), or `None` for all ones.
    pub weights: Option<Vec<f32>>,
}

/// Elements per parallel block.
const BLOCK: usize = 1 << 15;

impl<P: Prox + ?Sized> WithL1<P> {
    /// `sum_i w_i |x_i|` (without the weight `l1`): f32 lanes over runs of 256 values,
    /// f64 beyond.
    pub fn l1_sum(&self, x: &[f32]) -> f64 {
        let parts: Vec<f64> = match &self.weights {
            None => x.par_chunks(BLOCK).map(|c| weighted_abs_sum(c, None)).collect(),
            Some(w) => x.par_chunks(BLOCK).zip(w.par_chunks(BLOCK)).map(|(c, w)| weighted_abs_sum(c, Some(w))).collect(),
        };
        parts.iter().sum()
    }
}

/// `sum_i w_i |x_i|` of one block: each run of 256 values in 16 f32 lanes, the runs
/// added in f64.
fn weighted_abs_sum(x: &[f32], w: Option<&[f32]>) -> f64 {
    let mut sum = 0.0f64;
    for (r, run) in x.chunks(256).enumerate() {
        let mut lanes = [0.0f32; 16];
        match w {
            None => {
                for c in run.chunks(16) {
                    for (l, v) in lanes.iter_mut().zip(c) {
                        *l += v.abs();
                    }
                }
            }
            Some(w) => {
                for (c, w) in run.chunks(16).zip(w[r * 256..].chunks(16)) {
                    for ((l, v), &w) in lanes.iter_mut().zip(c).zip(w) {
                        *l += w * v.abs();
                    }
                }
            }
        }
        sum += lanes.iter().map(|&v| v as f64).sum::<f64>();
    }
    sum
}

impl<P: Prox + ?Sized> Prox for WithL1<P> {
    fn value(&self, x: &[f32]) -> f64 {
        self.inner.value(x) + self.l1 as f64 * self.l1_sum(x)
    }
    fn prox(&self, z: &[f32], gamma: f32, out: &mut [f32]) {
        self.inner.prox(z, gamma, out);
        let c = gamma * self.l1;
        if c > 0.0 {
            match &self.weights {
                None => out.par_chunks_mut(BLOCK).for_each(|o| o.iter_mut().for_each(|v| *v = soft(*v, c))),
                Some(w) => out.par_chunks_mut(BLOCK).zip(w.par_chunks(BLOCK)).for_each(|(o, w)| {
                    for (v, &w) in o.iter_mut().zip(w) {
                        *v = soft(*v, c * w)
                    }
                }),
            }
        }
    }
}

/// Weights of reweighted L1 (Candès, Wakin & Boyd 2008) from a previous estimate `x`:
/// `w_i = eps / (|x_i| + eps)`, 1 where `x` is zero and small where it is large, so the
/// next solve's penalty approaches a count of non-zeros. `eps` is `rel` times the
/// 99.9th percentile of `|x|` (a scale set by the object, not by a few outliers).
pub fn reweight(x: &[f32], rel: f32) -> Vec<f32> {
    let mut mags: Vec<f32> = x.iter().map(|v| v.abs()).filter(|v| v.is_finite()).collect();
    let eps = if mags.is_empty() {
        0.0
    } else {
        let i = ((mags.len() - 1) as f64 * 0.999) as usize;
        let (_, &mut q, _) = mags.select_nth_unstable_by(i, |a, b| a.total_cmp(b));
        rel * q
    };
    if !(eps > 0.0) {
        return vec![1.0; x.len()];
    }
    x.iter().map(|&v| if v.is_finite() { eps / (v.abs() + eps) } else { 1.0 }).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solve::prox::tv::NonNegative;
    use crate::solve::prox::tv_dual::TvProx;
    use crate::solve::prox::TotalVariation;

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
        let p = WithL1 { l1: 0.5, inner: Box::new(NonNegative), weights: None };
        let tv_free = WithL1 { l1: 0.5, inner: Box::new(TotalVariation { shape: (1, 1, 1), tau: 0.0, weights: [0.0; 3], nonneg: false }), weights: None };
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
    fn weights_scale_the_threshold_and_reweighting_spares_large_values() {
        let w = reweight(&[0.0, 0.0, 10.0, -10.0, 1.0], 0.1);
        // eps = 0.1 x the 99.9th percentile magnitude (10) = 1.
        assert_eq!(w[0], 1.0);
        assert!((w[2] - 1.0 / 11.0).abs() < 1e-6 && (w[3] - 1.0 / 11.0).abs() < 1e-6);
        assert!((w[4] - 0.5).abs() < 1e-6);
        let p = WithL1 { l1: 0.5, inner: Box::new(NonNegative), weights: Some(vec![1.0, 0.2]) };
        let mut o = [0.0f32; 2];
        p.prox(&[1.0, 1.0], 1.0, &mut o);
        assert_eq!(o, [0.5, 0.9]);
        assert!((p.value(&[2.0, 2.0]) - (0.5 * 2.0 + 0.5 * 0.2 * 2.0)).abs() < 1e-6);
        assert_eq!(reweight(&[0.0; 4], 0.1), vec![1.0; 4], "no scale: uniform weights");
    }

    #[test]
    fn the_l1_sum_matches_an_f64_sum_over_many_blocks() {
        let n = 2 * BLOCK + 300;
        let x: Vec<f32> = crate::model::op::pseudo_random(n, 8).iter().map(|v| 2.0 * v - 1.0).collect();
        let w: Vec<f32> = crate::model::op::pseudo_random(n, 9);
        let plain: f64 = x.iter().map(|&v| (v as f64).abs()).sum();
        let weighted: f64 = x.iter().zip(&w).map(|(&v, &w)| w as f64 * (v as f64).abs()).sum();
        let p = WithL1 { l1: 1.0, inner: Box::new(NonNegative), weights: None };
        assert!((p.l1_sum(&x) - plain).abs() < 1e-6 * plain, "{} vs {plain}", p.l1_sum(&x));
        let p = WithL1 { weights: Some(w), ..p };
        assert!((p.l1_sum(&x) - weighted).abs() < 1e-6 * weighted, "{} vs {weighted}", p.l1_sum(&x));
    }

    #[test]
    fn two_samples_with_tv_match_brute_force() {
        // 1D TV of two samples plus L1, with the exact (dual) TV map: the composition
        // is exact.
        let tv = TotalVariation { shape: (1, 1, 2), tau: 0.3, weights: [0.0, 0.0, 1.0], nonneg: true };
        let p = WithL1 { l1: 0.4, inner: TvProx::Dual { inner_iters: 500 }.build(&tv), weights: None };
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
