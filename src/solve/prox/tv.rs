//! Weighted anisotropic 3D total variation and its proximal map.
//!
//! `R(v) = tau * ( w_x sum|D_x v| + w_y sum|D_y v| + w_t sum|D_t v| )` with forward
//! differences and no wrap-around; the paper's choice is `w_x = w_y = 1`, `w_t = alpha`.
//!
//! ## The proximal map (parallel proximal method with 1-level Haar shrinkage)
//! Along one axis, the differences split into two families: pairs `(2i, 2i+1)`
//! (shift 0) and pairs `(2i+1, 2i+2)` (shift 1). So
//! `R = sum_{a,s} g_{a,s}` with `g_{a,s}(v) = tau w_a sum_{pairs of (a,s)} |v_1 - v_0|`,
//! `J = 2 x (number of active axes)` terms. Each `g_{a,s}` acts on disjoint pairs, so
//! its prox is exact and separable: with `m = (v_0+v_1)/2`, `d = (v_1-v_0)/2`,
//! `prox_{c |v_1 - v_0|}` maps the pair to `m ∓ soft(d, c)` (the 1-level orthonormal Haar
//! transform shrinks the detail `(v_1-v_0)/sqrt2` by `c sqrt2`, which is the same).
//! The parallel proximal approximation (Kamilov, IEEE TIP 2017) of
//! `prox_{gamma R}` averages the exact maps of `J gamma g_{a,s}`:
//!
//! `prox_{gamma R}(z) ≈ (1/J) sum_{a,s} prox_{J gamma g_{a,s}}(z)`,
//!
//! so the soft threshold on `d` for axis `a` is `c_a = J * gamma * tau * w_a`. The
//! constant `J` is the number of terms averaged, never a fixed 4 or 6: axes of weight 0
//! (e.g. no temporal TV for a static scene) or of length 1 are left out of both the sum
//! and `J`. Samples without a partner (the first sample for shift 1, the last for an
//! odd length) pass through their term unchanged. For two samples and one axis the map
//! is exact (the jump shrinks by `2 gamma tau w`).
//!
//! Non-negativity is applied after the TV map (`max(., 0)`); for TV with the separable
//! constraint `v >= 0` this composition is the exact prox of the sum in 1D.
//!
//! ### Evaluation in one pass
//! Along an axis every sample lies in exactly one pair of each shift: one with its
//! successor, one with its predecessor (or none at an end). With `m ∓ soft(d, c) =
//! v_0 + clip(d, c)`, `v_1 - clip(d, c)` (`clip(d, c) = max(-c, min(c, d))`) the two
//! terms of an axis add up to `2 z_i + clip(Δ⁺_i / 2, c_a) - clip(Δ⁻_i / 2, c_a)`, with
//! `Δ⁺_i = z_{i+1} - z_i`, `Δ⁻_i = z_i - z_{i-1}`, and a missing neighbour contributing
//! 0. Averaging over the `J = 2 x (active axes)` terms:
//!
//! `prox_{gamma R}(z)_i ≈ z_i + (1/J) sum_{active a} [clip(Δ⁺_{a,i}/2, c_a) - clip(Δ⁻_{a,i}/2, c_a)]`,
//!
//! the same map, computed from each sample's six neighbours in one pass over memory
//! (frames in parallel, non-negativity fused). [`TotalVariation::prox_reference`]
//! evaluates the definition term by term and is the reference it is tested against.

use crate::solve::metric::FrameMetric;
use crate::solve::prox::{MetricProx, Prox, TotalVariation};
use rayon::prelude::*;

/// Projection onto `x >= 0` alone (R = indicator).
pub struct NonNegative;

impl Prox for NonNegative {
    fn value(&self, _x: &[f32]) -> f64 {
        0.0
    }
    fn prox(&self, z: &[f32], _gamma: f32, out: &mut [f32]) {
        for (o, &v) in out.iter_mut().zip(z) {
            *o = v.max(0.0);
        }
    }
}

/// Soft threshold: `sign(d) max(|d| - c, 0)`.
#[inline]
pub(crate) fn soft(d: f32, c: f32) -> f32 {
    if d > c {
        d - c
    } else if d < -c {
        d + c
    } else {
        0.0
    }
}

impl TotalVariation {
    /// The paper's TV: spatial weights 1, temporal weight `alpha`, non-negative.
    pub fn new(shape: (usize, usize, usize), tau: f32, alpha: f32) -> Self {
        TotalVariation { shape, tau, weights: [alpha, 1.0, 1.0], nonneg: true }
    }

    /// Axes (0 = t, 1 = y, 2 = x) that contribute: weight > 0 and length > 1.
    pub fn active_axes(&self) -> Vec<usize> {
        let dims = [self.shape.0, self.shape.1, self.shape.2];
        (0..3).filter(|&a| self.weights[a] > 0.0 && dims[a] > 1 && self.tau > 0.0).collect()
    }

    /// Number of terms J averaged by the parallel proximal map.
    pub fn terms(&self) -> usize {
        2 * self.active_axes().len()
    }

    /// Sums of |D_t|, |D_y|, |D_x| (unweighted), in f64: one pass over memory, fixed
    /// blocks of frames summed in order (the result does not depend on the threads).
    pub fn abs_gradient_sums(&self, x: &[f32]) -> [f64; 3] {
        self.abs_gradient_sums_block(x, None)
    }

    /// [`abs_gradient_sums`](Self::abs_gradient_sums) over a block of consecutive
    /// frames `x` of this TV's video (a rank's block, [`crate::model::split`]), with
    /// `after` the frame just after the block (`None` at the video's end): the temporal
    /// differences from the block's last frame to `after` count here, those into its
    /// first frame on the block before.
    pub fn abs_gradient_sums_block(&self, x: &[f32], after: Option<&[f32]>) -> [f64; 3] {
        const BLOCKS: usize = 64;
        let (_, m, n) = self.shape;
        let fl = m * n;
        assert_eq!(x.len() % fl.max(1), 0);
        let k = x.len() / fl.max(1);
        let nb = k.clamp(1, BLOCKS);
        let per = k.div_ceil(nb);
        let mut parts = [[0.0f64; 3]; BLOCKS];
        parts[..nb].par_iter_mut().enumerate().for_each(|(b, s)| {
            for f in b * per..((b + 1) * per).min(k) {
                let fr = &x[f * fl..(f + 1) * fl];
                for r in 0..m {
                    let row = &fr[r * n..(r + 1) * n];
                    s[2] += abs_diff_sum(&row[..n.saturating_sub(1)], &row[1.min(n)..]);
                    if r + 1 < m {
                        s[1] += abs_diff_sum(row, &fr[(r + 1) * n..(r + 2) * n]);
                    }
                    if f + 1 < k {
                        s[0] += abs_diff_sum(row, &x[(f + 1) * fl + r * n..(f + 1) * fl + (r + 1) * n]);
                    } else if let Some(a) = after {
                        s[0] += abs_diff_sum(row, &a[r * n..(r + 1) * n]);
                    }
                }
            }
        });
        parts[..nb].iter().fold([0.0; 3], |a, p| [a[0] + p[0], a[1] + p[1], a[2] + p[2]])
    }
}

/// `sum |b - a|` over a row: 16 independent f32 lanes (they vectorise; each sums at
/// most len/16 terms), added up in f64.
#[inline]
fn abs_diff_sum(a: &[f32], b: &[f32]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut lanes = [0.0f32; 16];
    let (ac, bc) = (a.chunks_exact(16), b.chunks_exact(16));
    let (ar, br) = (ac.remainder(), bc.remainder());
    for (p, q) in ac.zip(bc) {
        for l in 0..16 {
            lanes[l] += (q[l] - p[l]).abs();
        }
    }
    let tail: f64 = ar.iter().zip(br).map(|(&p, &q)| (q - p).abs() as f64).sum();
    lanes.iter().map(|&v| v as f64).sum::<f64>() + tail
}

impl Prox for TotalVariation {
    fn value(&self, x: &[f32]) -> f64 {
        let s = self.abs_gradient_sums(x);
        self.tau as f64 * (0..3).map(|a| self.weights[a] as f64 * s[a]).sum::<f64>()
    }

    fn prox(&self, z: &[f32], gamma: f32, out: &mut [f32]) {
        assert_eq!(z.len(), self.shape.0 * self.shape.1 * self.shape.2);
        self.prox_block(z, None, None, gamma, out);
    }

    fn total_variation(&self) -> Option<&TotalVariation> {
        Some(self)
    }

    fn haar_tv(&self) -> Option<&TotalVariation> {
        Some(self)
    }

    fn metric_prox(&self) -> Option<&dyn MetricProx> {
        Some(self)
    }
}

/// The Haar map in the per-frame metric: every pair term's prox is exact in the
/// metric and the terms are averaged as in the plain map. A pair within frame `k`
/// (both weights `d_k`) has its threshold scaled by `1/d_k`; a temporal pair `(a, b)`
/// moves `a` by `clip((z_b - z_a) / (1/d_a + 1/d_b), c) / d_a` (and `b` the other way),
/// which keeps `d_a x_a + d_b x_b` and with `d = 1` is the plain `clip(Δ/2, c)`.
impl MetricProx for TotalVariation {
    fn prox_in(&self, z: &[f32], gamma: f32, metric: &FrameMetric, out: &mut [f32]) {
        let (k, m, n) = self.shape;
        let fl = m * n;
        assert_eq!((metric.frames(), metric.frame_len()), (k, fl), "the metric's frames must be the TV's");
        assert_eq!((z.len(), out.len()), (k * fl, k * fl));
        let active = self.active();
        let terms = 2 * active.iter().filter(|&&a| a).count();
        if terms == 0 {
            // Non-negativity alone: the same projection in any diagonal metric.
            return self.prox_block(z, None, None, gamma, out);
        }
        let j = terms as f32;
        let thr = |a: usize| j * gamma * self.tau * self.weights[a];
        let (ct, cy, cx) = (thr(0), thr(1), thr(2));
        let (inv, nonneg, w) = (1.0 / j, self.nonneg, metric.inverse());
        out.par_chunks_mut(fl).enumerate().for_each(|(f, o)| {
            let s = w[f];
            let scale_prev = if f > 0 { 1.0 / (w[f - 1] + s) } else { 0.0 };
            let scale_next = if f + 1 < k { 1.0 / (s + w[f + 1]) } else { 0.0 };
            let frame = FrameProx { m, n, active, c: [ct, cy * s, cx * s], inv, nonneg, t_metric: Some([s, scale_prev, scale_next]) };
            let zf = &z[f * fl..(f + 1) * fl];
            let prev = if f > 0 { Some(&z[(f - 1) * fl..f * fl]) } else { None };
            let next = if f + 1 < k { Some(&z[(f + 1) * fl..(f + 2) * fl]) } else { None };
            frame.run(zf, prev.filter(|_| active[0]), next.filter(|_| active[0]), o);
        });
    }
}

impl TotalVariation {
    /// [`Prox::prox`] of a block of consecutive frames `z` of this TV's video (a rank's
    /// block, [`crate::model::split`]; `shape` stays the whole video's, which sets the
    /// active axes and the number of terms), given the frames just before and after the
    /// block (`None` at the video's ends). Each output frame depends only on its own
    /// frame and its two neighbours, so the blocks' outputs are the whole map's frames,
    /// to the bit.
    pub fn prox_block(&self, z: &[f32], before: Option<&[f32]>, after: Option<&[f32]>, gamma: f32, out: &mut [f32]) {
        let (_, m, n) = self.shape;
        let fl = m * n;
        assert_eq!(z.len() % fl.max(1), 0);
        let k = z.len() / fl.max(1);
        assert_eq!(out.len(), z.len());
        let active = self.active();
        let terms = 2 * active.iter().filter(|&&a| a).count();
        if terms == 0 {
            let nonneg = self.nonneg;
            out.par_chunks_mut(1 << 14).zip(z.par_chunks(1 << 14)).for_each(|(o, z)| {
                o.copy_from_slice(z);
                if nonneg {
                    o.iter_mut().for_each(|v| *v = v.max(0.0));
                }
            });
            return;
        }
        let j = terms as f32;
        let thr = |a: usize| j * gamma * self.tau * self.weights[a];
        let (ct, cy, cx) = (thr(0), thr(1), thr(2));
        let inv = 1.0 / j;
        let nonneg = self.nonneg;
        let frame = FrameProx { m, n, active, c: [ct, cy, cx], inv, nonneg, t_metric: None };
        out.par_chunks_mut(fl).enumerate().for_each(|(f, o)| {
            let zf = &z[f * fl..(f + 1) * fl];
            let prev = if f > 0 { Some(&z[(f - 1) * fl..f * fl]) } else { before };
            let next = if f + 1 < k { Some(&z[(f + 1) * fl..(f + 2) * fl]) } else { after };
            frame.run(zf, prev.filter(|_| active[0]), next.filter(|_| active[0]), o);
        });
    }
}

/// The one-pass prox of one frame.
struct FrameProx {
    m: usize,
    n: usize,
    active: [bool; 3],
    /// Thresholds (t, y, x).
    c: [f32; 3],
    inv: f32,
    nonneg: bool,
    /// In a per-frame metric: `[1/d_k, 1/(1/d_{k-1} + 1/d_k), 1/(1/d_k + 1/d_{k+1})]`
    /// for the temporal pairs; `None`: the plain map.
    t_metric: Option<[f32; 3]>,
}

impl FrameProx {
    fn run(&self, zf: &[f32], prev: Option<&[f32]>, next: Option<&[f32]>, o: &mut [f32]) {
        #[cfg(target_arch = "x86_64")]
        {
            if crate::model::conv::simd::has_avx2_fma() {
                // SAFETY: the CPU supports AVX2 and FMA (checked above).
                unsafe { self.run_avx2(zf, prev, next, o) };
                return;
            }
        }
        self.body(zf, prev, next, o)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn run_avx2(&self, zf: &[f32], prev: Option<&[f32]>, next: Option<&[f32]>, o: &mut [f32]) {
        self.body(zf, prev, next, o)
    }

    #[inline(always)]
    fn body(&self, zf: &[f32], prev: Option<&[f32]>, next: Option<&[f32]>, o: &mut [f32]) {
        let (m, n) = (self.m, self.n);
        let [ct, cy, cx] = self.c;
        for r in 0..m {
            let row = r * n..(r + 1) * n;
            let (orow, zr) = (&mut o[row.clone()], &zf[row.clone()]);
            if self.active[2] {
                x_terms(zr, orow, cx);
            } else {
                orow.fill(0.0);
            }
            if self.active[1] {
                if r > 0 {
                    backward_term(orow, zr, &zf[(r - 1) * n..r * n], cy);
                }
                if r + 1 < m {
                    forward_term(orow, zr, &zf[(r + 1) * n..(r + 2) * n], cy);
                }
            }
            match self.t_metric {
                None => {
                    if let Some(p) = prev {
                        backward_term(orow, zr, &p[row.clone()], ct);
                    }
                    if let Some(nx) = next {
                        forward_term(orow, zr, &nx[row.clone()], ct);
                    }
                }
                Some([w, scale_prev, scale_next]) => {
                    if let Some(p) = prev {
                        weighted_term(orow, zr, &p[row.clone()], ct, -w, -scale_prev);
                    }
                    if let Some(nx) = next {
                        weighted_term(orow, zr, &nx[row.clone()], ct, w, scale_next);
                    }
                }
            }
            finish(orow, zr, self.inv, self.nonneg);
        }
    }
}

impl TotalVariation {
    /// Active axes as flags (t, y, x), without allocating.
    fn active(&self) -> [bool; 3] {
        let dims = [self.shape.0, self.shape.1, self.shape.2];
        [0, 1, 2].map(|a| self.weights[a] > 0.0 && dims[a] > 1 && self.tau > 0.0)
    }

    /// The parallel proximal map evaluated term by term (pairs of shift 0 and 1 per
    /// axis, summed, then averaged): the plain reference for [`Prox::prox`].
    pub fn prox_reference(&self, z: &[f32], gamma: f32, out: &mut [f32]) {
        let (k, m, n) = self.shape;
        let fl = m * n;
        assert_eq!(z.len(), k * fl);
        assert_eq!(out.len(), z.len());
        let axes = self.active_axes();
        let j = (2 * axes.len()) as f32;
        if axes.is_empty() {
            out.copy_from_slice(z);
        } else {
            let thr = |a: usize| j * gamma * self.tau * self.weights[a];
            let (do_y, do_x, do_t) = (axes.contains(&1), axes.contains(&2), axes.contains(&0));
            let (cy, cx, ct) = (thr(1), thr(2), thr(0));
            // Spatial terms, frame by frame (cache-friendly): out = sum of y and x terms.
            out.par_chunks_mut(fl).zip(z.par_chunks(fl)).for_each(|(o, f)| {
                o.fill(0.0);
                if do_x {
                    for r in 0..m {
                        let (orow, frow) = (&mut o[r * n..(r + 1) * n], &f[r * n..(r + 1) * n]);
                        for s in 0..2 {
                            haar_pairs_contiguous(frow, orow, s, cx);
                        }
                    }
                }
                if do_y {
                    for s in 0..2 {
                        if s == 1 {
                            add(&mut o[..n], &f[..n]);
                        }
                        let mut r = s;
                        while r + 1 < m {
                            let (a, b) = (&f[r * n..(r + 1) * n], &f[(r + 1) * n..(r + 2) * n]);
                            let (oa, ob) = o[r * n..(r + 2) * n].split_at_mut(n);
                            haar_pair_rows(a, b, oa, ob, cy);
                            r += 2;
                        }
                        if r < m {
                            add(&mut o[r * n..(r + 1) * n], &f[r * n..(r + 1) * n]);
                        }
                    }
                }
            });
            if do_t {
                for s in 0..2 {
                    // Unpaired frames pass through.
                    if s == 1 {
                        add(&mut out[..fl], &z[..fl]);
                    }
                    let paired = (k - s) / 2;
                    let start = s * fl;
                    let (body, _) = out[start..].split_at_mut(paired * 2 * fl);
                    body.par_chunks_mut(2 * fl).enumerate().for_each(|(p, o2)| {
                        let f0 = start + 2 * p * fl;
                        let (oa, ob) = o2.split_at_mut(fl);
                        haar_pair_rows(&z[f0..f0 + fl], &z[f0 + fl..f0 + 2 * fl], oa, ob, ct);
                    });
                    let last = s + 2 * paired;
                    if last < k {
                        add(&mut out[last * fl..(last + 1) * fl], &z[last * fl..(last + 1) * fl]);
                    }
                }
            }
            let inv = 1.0 / j;
            out.par_iter_mut().for_each(|v| *v *= inv);
        }
        if self.nonneg {
            out.par_iter_mut().for_each(|v| *v = v.max(0.0));
        }
    }
}

/// `clip(d / 2, c)` (comparisons, so that it compiles to vector min/max).
#[inline(always)]
fn clip_half(d: f32, c: f32) -> f32 {
    let h = 0.5 * d;
    let h = if h > c { c } else { h };
    if h < -c {
        -c
    } else {
        h
    }
}

/// The x terms of a row: `o_i = clip(Δ⁺_i/2) - clip(Δ⁻_i/2)` (overwrites `o`).
#[inline(always)]
fn x_terms(z: &[f32], o: &mut [f32], c: f32) {
    let n = z.len();
    if n < 2 {
        o.fill(0.0);
        return;
    }
    o[0] = clip_half(z[1] - z[0], c);
    let (a, b, d) = (&z[..n - 2], &z[1..n - 1], &z[2..]);
    for (((o, &a), &b), &d) in o[1..n - 1].iter_mut().zip(a).zip(b).zip(d) {
        *o = clip_half(d - b, c) - clip_half(b - a, c);
    }
    o[n - 1] = -clip_half(z[n - 1] - z[n - 2], c);
}

/// `o += clip((next - z)/2)`: the pair with the successor along an axis.
#[inline(always)]
fn forward_term(o: &mut [f32], z: &[f32], next: &[f32], c: f32) {
    for ((o, &z), &nx) in o.iter_mut().zip(z).zip(next) {
        *o += clip_half(nx - z, c);
    }
}

/// `o -= clip((z - prev)/2)`: the pair with the predecessor along an axis.
#[inline(always)]
fn backward_term(o: &mut [f32], z: &[f32], prev: &[f32], c: f32) {
    for ((o, &z), &p) in o.iter_mut().zip(z).zip(prev) {
        *o -= clip_half(z - p, c);
    }
}

/// `o += w clip((other - z) scale, c)`: a temporal pair in the per-frame metric (`w`,
/// `scale` negated for the pair with the predecessor: `o -= w clip((z - prev) scale, c)`).
#[inline(always)]
fn weighted_term(o: &mut [f32], z: &[f32], other: &[f32], c: f32, w: f32, scale: f32) {
    for ((o, &z), &x) in o.iter_mut().zip(z).zip(other) {
        let h = (x - z) * scale;
        let h = if h > c { c } else { h };
        *o += w * if h < -c { -c } else { h };
    }
}

/// `o = z + o / J`, then `max(o, 0)` when asked (NaN becomes 0, as with `f32::max`).
#[inline(always)]
fn finish(o: &mut [f32], z: &[f32], inv: f32, nonneg: bool) {
    if nonneg {
        for (o, &z) in o.iter_mut().zip(z) {
            let v = z + *o * inv;
            *o = if v > 0.0 { v } else { 0.0 };
        }
    } else {
        for (o, &z) in o.iter_mut().zip(z) {
            *o = z + *o * inv;
        }
    }
}

#[inline]
fn add(o: &mut [f32], f: &[f32]) {
    for (a, b) in o.iter_mut().zip(f) {
        *a += b;
    }
}

/// Exact prox of `c |b - a|` per element pair, accumulated into `oa`, `ob`.
#[inline]
fn haar_pair_rows(a: &[f32], b: &[f32], oa: &mut [f32], ob: &mut [f32], c: f32) {
    for i in 0..a.len() {
        let m = 0.5 * (a[i] + b[i]);
        let d = soft(0.5 * (b[i] - a[i]), c);
        oa[i] += m - d;
        ob[i] += m + d;
    }
}

/// Pairs along a contiguous row with the given shift, accumulated into `o`.
#[inline]
fn haar_pairs_contiguous(f: &[f32], o: &mut [f32], shift: usize, c: f32) {
    let n = f.len();
    if shift == 1 {
        o[0] += f[0];
    }
    let mut i = shift;
    while i + 1 < n {
        let m = 0.5 * (f[i] + f[i + 1]);
        let d = soft(0.5 * (f[i + 1] - f[i]), c);
        o[i] += m - d;
        o[i + 1] += m + d;
        i += 2;
    }
    if i < n {
        o[i] += f[i];
    }
}

/// Exact 1D TV prox `argmin_x 0.5||x - y||^2 + lambda sum|x_{i+1} - x_i|`, by
/// accelerated projected gradient on the dual (`|u_i| <= lambda`), run to a tolerance
/// far below f32 precision. A slow, trusted reference for tests and studies.
pub fn tv1d_prox_exact(y: &[f64], lambda: f64) -> Vec<f64> {
    let n = y.len();
    if n < 2 {
        return y.to_vec();
    }
    // x = y - D^T u with (D x)_i = x_{i+1} - x_i; D^T u: (D^T u)_i = u_{i-1} - u_i.
    let dt = |u: &[f64]| -> Vec<f64> {
        (0..n)
            .map(|i| {
                let left = if i > 0 { u[i - 1] } else { 0.0 };
                let right = if i < n - 1 { u[i] } else { 0.0 };
                left - right
            })
            .collect()
    };
    let mut u = vec![0.0; n - 1];
    let mut w = u.clone();
    let mut t = 1.0f64;
    let step = 0.25;
    for _ in 0..200_000 {
        let x: Vec<f64> = y.iter().zip(dt(&w)).map(|(a, b)| a - b).collect();
        // gradient of 0.5||y - D^T u||^2 w.r.t. u is -D x
        let mut un = vec![0.0; n - 1];
        for i in 0..n - 1 {
            un[i] = (w[i] + step * (x[i + 1] - x[i])).clamp(-lambda, lambda);
        }
        let tn = 0.5 * (1.0 + (1.0 + 4.0 * t * t).sqrt());
        let change: f64 = un.iter().zip(&u).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        for i in 0..n - 1 {
            w[i] = un[i] + (t - 1.0) / tn * (un[i] - u[i]);
        }
        u = un;
        t = tn;
        if change < 1e-13 * (1.0 + lambda) {
            break;
        }
    }
    y.iter().zip(dt(&u)).map(|(a, b)| a - b).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::op::pseudo_random;

    fn tv1(len: usize, tau: f32) -> TotalVariation {
        TotalVariation { shape: (1, 1, len), tau, weights: [0.0, 0.0, 1.0], nonneg: false }
    }

    /// The whole video's map and TV sums, computed block by block with the frames just
    /// outside each block (as split ranks do), equal the whole computation to the bit.
    #[test]
    fn blocks_with_their_edge_frames_give_the_whole_map_exactly() {
        let (k, m, n) = (7, 5, 6);
        let z: Vec<f32> = crate::model::op::pseudo_random(k * m * n, 11).iter().map(|v| v - 0.3).collect();
        let fl = m * n;
        for weights in [[5.0, 1.0, 1.0], [0.0, 1.0, 1.0]] {
            let tv = TotalVariation { shape: (k, m, n), tau: 0.05, weights, nonneg: true };
            let mut whole = vec![0.0f32; z.len()];
            tv.prox(&z, 0.7, &mut whole);
            let sums = tv.abs_gradient_sums(&z);
            for cuts in [vec![0, 3, 7], vec![0, 1, 2, 6, 7], vec![0, 7]] {
                let mut pieced = vec![0.0f32; z.len()];
                let mut pieced_sums = [0.0f64; 3];
                for w in cuts.windows(2) {
                    let (a, b) = (w[0], w[1]);
                    let before = (a > 0).then(|| &z[(a - 1) * fl..a * fl]);
                    let after = (b < k).then(|| &z[b * fl..(b + 1) * fl]);
                    tv.prox_block(&z[a * fl..b * fl], before, after, 0.7, &mut pieced[a * fl..b * fl]);
                    let s = tv.abs_gradient_sums_block(&z[a * fl..b * fl], after);
                    (0..3).for_each(|i| pieced_sums[i] += s[i]);
                }
                assert_eq!(pieced, whole, "{weights:?} {cuts:?}");
                for i in 0..3 {
                    assert!((pieced_sums[i] - sums[i]).abs() <= 1e-9 * sums[i].max(1.0), "{weights:?} {cuts:?} axis {i}");
                }
            }
        }
    }

    #[test]
    fn two_samples_match_exact_prox() {
        let tv = tv1(2, 1.0);
        let mut out = vec![0.0; 2];
        tv.prox(&[0.0, 3.0], 0.5, &mut out);
        let exact = tv1d_prox_exact(&[0.0, 3.0], 0.5);
        assert!((out[0] as f64 - exact[0]).abs() < 1e-6 && (out[1] as f64 - exact[1]).abs() < 1e-6, "{out:?} vs {exact:?}");
        assert!((out[1] - out[0] - 2.0).abs() < 1e-6);
    }

    #[test]
    fn temporal_jump_uses_the_true_term_count() {
        // Two constant frames differing by 10: spatial terms are inactive in value but
        // still counted (J = 6). The exact prox moves each frame by gamma*tau*alpha
        // towards the other; a wrong J (e.g. 4 for 6 terms) would not.
        let (m, n) = (3, 4);
        let tv = TotalVariation::new((2, m, n), 0.5, 2.0);
        assert_eq!(tv.terms(), 6);
        let mut z = vec![1.0f32; 2 * m * n];
        z[m * n..].iter_mut().for_each(|v| *v = 11.0);
        let mut out = vec![0.0; z.len()];
        tv.prox(&z, 0.3, &mut out);
        let shift = 0.3 * 0.5 * 2.0;
        for v in &out[..m * n] {
            assert!((v - (1.0 + shift)).abs() < 1e-5, "{v}");
        }
        for v in &out[m * n..] {
            assert!((v - (11.0 - shift)).abs() < 1e-5, "{v}");
        }
    }

    #[test]
    fn zero_weight_axis_is_left_out() {
        let tv = TotalVariation { shape: (3, 4, 5), tau: 1.0, weights: [0.0, 1.0, 1.0], nonneg: false };
        assert_eq!(tv.active_axes(), vec![1, 2]);
        assert_eq!(tv.terms(), 4);
        // A video constant in space but varying in time passes through unchanged.
        let z: Vec<f32> = (0..60).map(|i| (i / 20) as f32).collect();
        let mut out = vec![0.0; 60];
        tv.prox(&z, 1.0, &mut out);
        assert_eq!(out, z);
    }

    #[test]
    fn preserves_the_mean_without_positivity() {
        let tv = TotalVariation { shape: (5, 6, 7), tau: 0.7, weights: [3.0, 1.0, 1.0], nonneg: false };
        let z = pseudo_random(5 * 6 * 7, 9);
        let mut out = vec![0.0; z.len()];
        tv.prox(&z, 0.2, &mut out);
        let (a, b): (f64, f64) = (z.iter().map(|&v| v as f64).sum(), out.iter().map(|&v| v as f64).sum());
        assert!((a - b).abs() < 1e-4, "{a} vs {b}");
        assert!(tv.value(&out) < tv.value(&z));
    }

    #[test]
    fn proximal_gradient_with_haar_map_reaches_the_exact_tv_solution() {
        // Kamilov: proximal gradient with the parallel Haar map converges to the true
        // TV-regularised solution as the step shrinks. Denoising (A = I) of small
        // signals; compare the fixed point with the exact 1D prox.
        for seed in 0..4u64 {
            let n = 17 + seed as usize;
            let y: Vec<f32> = pseudo_random(n, seed + 20).iter().enumerate().map(|(i, v)| v + if i > n / 2 { 2.0 } else { 0.0 }).collect();
            let lambda = 0.3f32;
            let exact = tv1d_prox_exact(&y.iter().map(|&v| v as f64).collect::<Vec<_>>(), lambda as f64);
            let tv = tv1(n, lambda);
            let norm: f64 = exact.iter().map(|b| b * b).sum::<f64>().sqrt();
            let fixed_point_error = |mu: f32| {
                let mut x = y.clone();
                let mut z = vec![0.0; n];
                for _ in 0..(400.0 / mu) as usize {
                    for i in 0..n {
                        z[i] = x[i] - mu * (x[i] - y[i]);
                    }
                    tv.prox(&z, mu, &mut x);
                }
                x.iter().zip(&exact).map(|(a, b)| (*a as f64 - b).powi(2)).sum::<f64>().sqrt() / norm
            };
            let (coarse, fine) = (fixed_point_error(0.04), fixed_point_error(0.005));
            eprintln!("seed {seed}: error {coarse:.2e} at step 0.04, {fine:.2e} at step 0.005");
            assert!(fine < 0.5 * coarse || fine < 1e-5, "seed {seed}: error must shrink with the step");
            let err = fine * norm;
            assert!(err / norm < 2e-3, "seed {seed}: relative error {}", err / norm);
        }
    }

    #[test]
    fn exact_reference_satisfies_optimality() {
        // Check the reference itself: for y with one jump of height 4 and lambda 0.5,
        // the exact prox of a two-level step on [a|b] of lengths 3 and 5 moves the left
        // level up by lambda/3 and the right level down by lambda/5.
        let y = [0.0, 0.0, 0.0, 4.0, 4.0, 4.0, 4.0, 4.0];
        let x = tv1d_prox_exact(&y, 0.5);
        for v in &x[..3] {
            assert!((v - 0.5 / 3.0).abs() < 1e-9, "{x:?}");
        }
        for v in &x[3..] {
            assert!((v - (4.0 - 0.5 / 5.0)).abs() < 1e-9, "{x:?}");
        }
    }

    #[test]
    fn value_counts_each_axis_with_its_weight() {
        let tv = TotalVariation { shape: (2, 2, 2), tau: 2.0, weights: [10.0, 1.0, 0.5], nonneg: true };
        // frame 0 = [[0,1],[0,1]], frame 1 = frame 0 + 3
        let x = [0.0, 1.0, 0.0, 1.0, 3.0, 4.0, 3.0, 4.0];
        let s = tv.abs_gradient_sums(&x);
        assert_eq!(s, [12.0, 0.0, 4.0]);
        assert!((tv.value(&x) - 2.0 * (10.0 * 12.0 + 0.5 * 4.0)).abs() < 1e-9);
    }

    #[test]
    fn nonnegativity_clamps() {
        let tv = TotalVariation::new((2, 2, 2), 0.0, 1.0);
        let mut out = vec![0.0; 8];
        tv.prox(&[-1.0, 2.0, -3.0, 4.0, 0.0, -0.5, 1.0, 1.0], 1.0, &mut out);
        assert_eq!(out, vec![0.0, 2.0, 0.0, 4.0, 0.0, 0.0, 1.0, 1.0]);
    }

    #[test]
    fn one_pass_prox_equals_the_term_by_term_reference() {
        let shapes = [(5, 6, 7), (4, 9, 8), (1, 5, 6), (3, 1, 9), (6, 4, 1), (2, 2, 2), (1, 1, 1), (7, 3, 17)];
        let weights = [[2.0, 1.0, 1.0], [0.0, 1.0, 0.5], [3.0, 0.0, 1.0], [1.0, 1.0, 0.0], [0.0, 0.0, 0.0]];
        for &shape in &shapes {
            for w in weights {
                for nonneg in [false, true] {
                    for (tau, gamma) in [(0.7f32, 0.2f32), (0.05, 0.1), (0.0, 1.0), (5.0, 1.0)] {
                        let tv = TotalVariation { shape, tau, weights: w, nonneg };
                        let len = shape.0 * shape.1 * shape.2;
                        let z: Vec<f32> = pseudo_random(len, 3).iter().map(|v| 4.0 * v - 1.0).collect();
                        let (mut fast, mut slow) = (vec![f32::NAN; len], vec![f32::NAN; len]);
                        tv.prox(&z, gamma, &mut fast);
                        tv.prox_reference(&z, gamma, &mut slow);
                        let scale = slow.iter().fold(1e-30f32, |m, v| m.max(v.abs()));
                        let err = fast.iter().zip(&slow).fold(0.0f32, |m, (a, b)| m.max((a - b).abs())) / scale;
                        assert!(err < 1e-5, "{shape:?} {w:?} nonneg={nonneg} tau={tau}: {err}");
                    }
                }
            }
        }
    }

    #[test]
    fn gradient_sums_match_a_plain_triple_loop() {
        for shape in [(3, 4, 5), (1, 1, 40), (70, 3, 33), (2, 17, 1)] {
            let (k, m, n) = shape;
            let x: Vec<f32> = pseudo_random(k * m * n, 8).iter().map(|v| 10.0 * v - 3.0).collect();
            let tv = TotalVariation::new(shape, 1.0, 1.0);
            let at = |f: usize, r: usize, c: usize| x[(f * m + r) * n + c] as f64;
            let mut want = [0.0f64; 3];
            for f in 0..k {
                for r in 0..m {
                    for c in 0..n {
                        if f + 1 < k {
                            want[0] += (at(f + 1, r, c) - at(f, r, c)).abs();
                        }
                        if r + 1 < m {
                            want[1] += (at(f, r + 1, c) - at(f, r, c)).abs();
                        }
                        if c + 1 < n {
                            want[2] += (at(f, r, c + 1) - at(f, r, c)).abs();
                        }
                    }
                }
            }
            let got = tv.abs_gradient_sums(&x);
            for a in 0..3 {
                assert!((got[a] - want[a]).abs() <= 1e-5 * want[a].max(1.0), "{shape:?} axis {a}: {} vs {}", got[a], want[a]);
            }
        }
    }
}
