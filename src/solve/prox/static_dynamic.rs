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
/// would leave the set (smallest `-b_k / rho` first).
///
/// Most pixels are feasible at `max(a_0, 0)`: a block of pixels first takes the least
/// `b_k` of each pixel in one pass over the frames in memory order, and only the
/// pixels it finds infeasible are solved and have their frames changed (a second pass
/// that touches those pixels alone).
pub fn project_static_dynamic(a: &mut [f32], b: &mut [f32], rho: f32) {
    let p = a.len();
    assert!(p > 0 && b.len() % p == 0, "the dynamic part must be whole frames of the static image's size");
    assert!(rho.is_finite() && rho > 0.0);
    let b_ro: &[f32] = b;
    // The static value of each pixel; the pixels whose frames change.
    let changed: Vec<Vec<usize>> = a
        .par_chunks_mut(CHUNK)
        .enumerate()
        .map(|(ci, a)| {
            let (p0, len) = (ci * CHUNK, a.len());
            let mut least = [f32::INFINITY; CHUNK];
            let least = &mut least[..len];
            for frame in b_ro.chunks(p) {
                for (m, &v) in least.iter_mut().zip(&frame[p0..p0 + len]) {
                    *m = m.min(v);
                }
            }
            let mut changed = Vec::new();
            let mut active: Vec<f32> = Vec::new();
            for (i, (av, &m)) in a.iter_mut().zip(least.iter()).enumerate() {
                let s0 = av.max(0.0);
                // NaN frames compare false here and below, as they are left alone.
                if !(m < -rho * s0) {
                    *av = s0;
                    continue;
                }
                active.clear();
                active.extend(b_ro.chunks(p).map(|frame| frame[p0 + i]).filter(|&bk| bk < -rho * s0));
                *av = pixel_static_value(*av, &mut active, rho);
                changed.push(p0 + i);
            }
            changed
        })
        .collect();
    let changed: Vec<usize> = changed.concat();
    if changed.is_empty() {
        return;
    }
    let a_ro: &[f32] = a;
    b.par_chunks_mut(p).for_each(|frame| {
        for &i in &changed {
            frame[i] = frame[i].max(-rho * a_ro[i]);
        }
    });
}

/// One pixel's static value: the minimiser over `a >= 0` of `(a - a0)^2 + sum_k (rho a
/// + b_k)^2` over the frames still active, `active` holding the `b_k` infeasible at
/// `max(a0, 0)` (reordered here).
fn pixel_static_value(a0: f32, active: &mut [f32], rho: f32) -> f32 {
    // Thresholds t_k = -b_k / rho: frame k is active while a < t_k. Leave in ascending
    // order of t_k, i.e. descending b_k.
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
    value as f32
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
    fn blocks_of_pixels_project_as_each_pixel_alone() {
        // More pixels than a block, about half of them infeasible: every pixel must
        // come out as its own one-pixel projection, frames of feasible pixels untouched.
        let (frames, pixels, rho) = (9, 3 * CHUNK + 17, 0.8f32);
        let r = pseudo_random(pixels * (frames + 1), 5);
        let mut a: Vec<f32> = r[..pixels].iter().map(|v| 2.0 * v - 0.5).collect();
        let mut b: Vec<f32> = r[pixels..].iter().map(|v| 2.0 * v - 0.6).collect();
        let (a0, b0) = (a.clone(), b.clone());
        project_static_dynamic(&mut a, &mut b, rho);
        let mut infeasible = 0;
        for i in 0..pixels {
            let mut ai = [a0[i]];
            let mut bi: Vec<f32> = (0..frames).map(|k| b0[k * pixels + i]).collect();
            infeasible += usize::from(bi.iter().any(|&v| v < -rho * a0[i].max(0.0)));
            project_static_dynamic(&mut ai, &mut bi, rho);
            assert_eq!(a[i], ai[0], "pixel {i}");
            for k in 0..frames {
                assert_eq!(b[k * pixels + i], bi[k], "pixel {i}, frame {k}");
            }
        }
        assert!(infeasible > pixels / 4 && infeasible < pixels, "{infeasible} of {pixels} infeasible: the test needs both kinds");
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
