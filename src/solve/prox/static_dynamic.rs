//! The regulariser of the static + dynamic scene model
//! ([`crate::model::static_dynamic`]), on the scaled unknowns `z = [z_s; z_d]` with
//! `s = c_s z_s`, `d = c_d z_d`:
//!
//! `R(z) = R_s(c_s z_s) + R_d(c_d z_d) + [s >= 0, s + d_k >= 0 for every k]`,
//!
//! `R_s` the static image's TV, `R_d` the dynamic video's TV (and L1). Both are
//! positively homogeneous (`R(c x) = c R(x)`), so the value is `c_s R_s(z_s) + c_d
//! R_d(z_d)` and the block maps are `prox_{gamma c R}` on `z` itself: no scaled copies.
//!
//! The constraint keeps the video `v_k = s + d_k` non-negative (a moving object may be
//! darker than what it covers, so `d` may be negative) and the static image too. Its
//! projection is exact, per pixel ([`project_static_dynamic`]); the map applies the two
//! block maps and then the projection, the same composition as TV followed by
//! `max(., 0)` in the plain problem.

use crate::solve::prox::Prox;
use rayon::prelude::*;

/// `R_s`, `R_d` and the non-negativity of the static + dynamic model.
pub struct StaticDynamicProx {
    pub static_reg: Box<dyn Prox>,
    pub dynamic_reg: Box<dyn Prox>,
    /// `[c_s, c_d]`, both positive.
    pub scale: [f32; 2],
    /// Pixels per frame (the length of `z_s`).
    pub pixels: usize,
}

impl Prox for StaticDynamicProx {
    fn value(&self, z: &[f32]) -> f64 {
        let (zs, zd) = z.split_at(self.pixels);
        self.scale[0] as f64 * self.static_reg.value(zs) + self.scale[1] as f64 * self.dynamic_reg.value(zd)
    }
    fn prox(&self, z: &[f32], gamma: f32, out: &mut [f32]) {
        let (zs, zd) = z.split_at(self.pixels);
        let (os, od) = out.split_at_mut(self.pixels);
        let [cs, cd] = self.scale;
        self.static_reg.prox(zs, gamma * cs, os);
        self.dynamic_reg.prox(zd, gamma * cd, od);
        project_static_dynamic(os, od, cs / cd);
    }
}

/// Pixels per parallel block of the projection.
const CHUNK: usize = 256;

/// Euclidean projection of `(a, b)` (`a` one value per pixel, `b` frames of pixels)
/// onto `{a >= 0, rho a + b_k >= 0 for every k}`, in place; `rho = c_s / c_d > 0`.
///
/// Per pixel: for a given `a` the best `b_k` is `max(b_k, -rho a)`, which leaves a
/// convex, piecewise quadratic function of `a` alone,
/// `(a - a_0)^2 + sum_{k: b_k < -rho a} (rho a + b_k)^2`. Its minimiser over `a >= 0`
/// is found exactly by letting the active frames go one by one in the order they
/// would leave the set (smallest `-b_k / rho` first). Pixels whose frames are all
/// feasible at `max(a_0, 0)` (most of them) cost one pass.
pub fn project_static_dynamic(a: &mut [f32], b: &mut [f32], rho: f32) {
    let p = a.len();
    assert!(p > 0 && b.len() % p == 0, "the dynamic part must be whole frames of the static image's size");
    assert!(rho.is_finite() && rho > 0.0);
    // The static value of each pixel.
    let b_ro: &[f32] = b;
    a.par_chunks_mut(CHUNK).enumerate().for_each(|(ci, a)| {
        let p0 = ci * CHUNK;
        let mut active: Vec<f32> = Vec::new();
        for (i, av) in a.iter_mut().enumerate() {
            let a0 = *av;
            let s0 = a0.max(0.0);
            // The frames infeasible at s0, if any.
            active.clear();
            for frame in b_ro.chunks(p) {
                let bk = frame[p0 + i];
                if bk < -rho * s0 {
                    active.push(bk);
                }
            }
            if active.is_empty() {
                *av = s0;
                continue;
            }
            // Thresholds t_k = -b_k / rho: frame k is active while a < t_k. Leave in
            // ascending order of t_k, i.e. descending b_k.
            active.sort_by(|x, y| y.partial_cmp(x).unwrap_or(std::cmp::Ordering::Equal));
            let (rho64, a064) = (rho as f64, a0 as f64);
            let mut sum: f64 = active.iter().map(|&v| v as f64).sum();
            let mut n = active.len();
            let mut first = 0;
            let value = loop {
                let cand = ((a064 - rho64 * sum) / (1.0 + rho64 * rho64 * n as f64)).max(0.0);
                // Frame `first` has the smallest threshold among those still active.
                let t_min = -(active[first] as f64) / rho64;
                if cand <= t_min {
                    break cand;
                }
                sum -= active[first] as f64;
                n -= 1;
                first += 1;
                if n == 0 {
                    break a064.max(0.0);
                }
            };
            *av = value as f32;
        }
    });
    let a_ro: &[f32] = a;
    b.par_chunks_mut(p).for_each(|frame| {
        for (bv, &av) in frame.iter_mut().zip(a_ro) {
            *bv = bv.max(-rho * av);
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::op::pseudo_random;

    /// The projection's cost for one pixel at static value `a` (the `b_k` follow in
    /// closed form), in f64.
    fn cost(a: f64, a0: f32, b0: &[f32], rho: f32) -> f64 {
        let rho = rho as f64;
        (a - a0 as f64).powi(2) + b0.iter().map(|&b| (b as f64).max(-rho * a) - b as f64).map(|d| d * d).sum::<f64>()
    }

    /// Brute force: the least cost over a fine grid of `a >= 0`.
    fn brute(a0: f32, b0: &[f32], rho: f32) -> f64 {
        (0..=400_000).map(|i| cost(i as f64 * 1e-5, a0, b0, rho)).fold(f64::INFINITY, f64::min)
    }

    #[test]
    fn projection_matches_brute_force_and_is_feasible() {
        let frames = 6;
        let pixels = 40;
        let r = pseudo_random(pixels * (frames + 1), 11);
        let mut a: Vec<f32> = r[..pixels].iter().map(|v| 2.0 * v - 0.7).collect();
        let mut b: Vec<f32> = r[pixels..].iter().map(|v| 3.0 * v - 2.0).collect();
        let (a0, b0) = (a.clone(), b.clone());
        for rho in [0.3f32, 1.0, 2.5] {
            a.copy_from_slice(&a0);
            b.copy_from_slice(&b0);
            project_static_dynamic(&mut a, &mut b, rho);
            for i in 0..pixels {
                let bi: Vec<f32> = (0..frames).map(|k| b0[k * pixels + i]).collect();
                let (got, best) = (cost(a[i] as f64, a0[i], &bi, rho), brute(a0[i], &bi, rho));
                assert!(got <= best + 1e-9, "pixel {i}, rho {rho}: cost {got} at {} vs {best} on the grid", a[i]);
                assert!(a[i] >= 0.0);
                for k in 0..frames {
                    let v = b[k * pixels + i];
                    assert!(rho * a[i] + v >= -1e-6, "infeasible: {} + {v}", rho * a[i]);
                    assert_eq!(v, b0[k * pixels + i].max(-rho * a[i]));
                }
            }
        }
    }

    #[test]
    fn feasible_points_are_kept() {
        let mut a = vec![1.0f32, 0.0, 2.0];
        let mut b = vec![0.5f32, 0.0, -1.0, -1.0, 3.0, -2.0];
        let (a0, b0) = (a.clone(), b.clone());
        project_static_dynamic(&mut a, &mut b, 1.0);
        assert_eq!((a, b), (a0, b0));
    }
}
