//! Which proximal map of the TV term a solver uses: the fast parallel Haar map of
//! [`crate::solve::prox::TotalVariation`] (an approximation whose fixed-point error grows with
//! `step * tau`, Kamilov 2017) or an iterative map by fast projected gradient on the dual
//! (Beck & Teboulle 2009, FGP) that converges to the exact prox of
//! `gamma tau sum_a w_a |D_a x|_1 + [x >= 0]`.
//!
//! The dual map keeps its dual variable between calls (warm start): inside FISTA the
//! argument changes little from one iteration to the next, so a few inner iterations per
//! call suffice to track the exact prox.

use crate::model::ranks::{One, Ranks};
use crate::solve::metric::FrameMetric;
use crate::solve::prox::grad3::{diff, diff_adjoint_add};
use crate::solve::prox::TotalVariation;
use crate::solve::prox::{MetricProx, Prox};
use rayon::prelude::*;
use serde::Serialize;
use std::sync::Mutex;

/// Choice of TV proximal map.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case", tag = "kind")]
pub enum TvProx {
    /// Parallel proximal Haar shrinkage (one pass, approximate).
    Haar,
    /// FGP on the dual, `inner_iters` iterations per call, warm-started.
    Dual { inner_iters: usize },
}

impl TvProx {
    /// The proximal term for `tv` with this map.
    pub fn build(self, tv: &TotalVariation) -> Box<dyn Prox> {
        match self {
            TvProx::Haar => Box::new(tv.clone()),
            TvProx::Dual { inner_iters } => Box::new(DualTv::new(tv.clone(), inner_iters)),
        }
    }
    pub fn name(self) -> String {
        match self {
            TvProx::Haar => "haar".into(),
            TvProx::Dual { inner_iters } => format!("dual{inner_iters}"),
        }
    }
}

impl std::str::FromStr for TvProx {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "haar" {
            return Ok(TvProx::Haar);
        }
        if let Some(n) = s.strip_prefix("dual") {
            let n = if n.is_empty() { Ok(10) } else { n.parse::<usize>() };
            if let Ok(n) = n {
                if (1..=MAX_DUAL_ITERS).contains(&n) {
                    return Ok(TvProx::Dual { inner_iters: n });
                }
            }
        }
        Err(format!("unknown TV prox '{s}': expected haar, dual or dualN (N inner iterations from 1 to {MAX_DUAL_ITERS})"))
    }
}

/// The TV prox a reconstruction asks for: a fixed map, or `auto` (the default), which
/// takes the exact (dual) map where the Haar map's bias matters ([`haar_strength`]
/// above [`HAAR_STRONG`]) and the Haar map elsewhere.
/// Written and read as its name (`auto`, `haar`, `dual10`), as on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, serde::Deserialize, Default)]
#[serde(into = "String", try_from = "String")]
pub enum TvProxChoice {
    #[default]
    Auto,
    Fixed(TvProx),
}

/// The most inner iterations of the dual map per call: warm-started, it needs tens;
/// more would run past any time budget inside one outer iteration.
pub const MAX_DUAL_ITERS: usize = 1000;

/// Inner iterations of the dual map when `auto` picks it.
pub const AUTO_DUAL_ITERS: usize = 10;

/// Strength of TV for the Haar map, `rho = J w_max tau / max(A^T b)`: the Haar map's
/// threshold per call (`J gamma tau w_max`) relative to the peak of the first gradient
/// step from zero (`gamma max(A^T b)`). It does not depend on the step, and equals
/// `J w_max tau_rel` for a tau given relative to `max(A^T b)` (the paper's weights at
/// the default tau_rel 2e-3, alpha 5: 0.06).
pub fn haar_strength(tv: &TotalVariation, atb_max: f64) -> f64 {
    let w_max = tv.active_axes().iter().map(|&a| tv.weights[a]).fold(0.0f32, f32::max) as f64;
    // No data (or NaN): no scale to compare with, and nothing for TV to bias.
    if atb_max.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return 0.0;
    }
    tv.terms() as f64 * w_max * tv.tau as f64 / atb_max
}

/// Above this [`haar_strength`] the Haar map's fixed point is measurably biased and
/// `auto` takes the exact map. Measured (`tests/solve/solvers_tv_prox.rs`, 16 x 20 flashing
/// points, alpha 5): FISTA-restart's final objective with the Haar map over the
/// minimum was 1.008 at strength 0.03, 1.024 at 0.09, 1.089 at 0.3, 1.29 at 0.9 and
/// 2.25 at 3; with the dual map 1.000 throughout. At 0.1 the excess is about 2.5%.
pub const HAAR_STRONG: f64 = 0.1;

impl TvProxChoice {
    /// The map to use for `tv` on data whose `A^T b` peaks at `atb_max`.
    pub fn resolve(self, tv: &TotalVariation, atb_max: f64) -> TvProx {
        match self {
            TvProxChoice::Fixed(p) => p,
            TvProxChoice::Auto => {
                if haar_strength(tv, atb_max) > HAAR_STRONG {
                    TvProx::Dual { inner_iters: AUTO_DUAL_ITERS }
                } else {
                    TvProx::Haar
                }
            }
        }
    }
    pub fn name(self) -> String {
        match self {
            TvProxChoice::Auto => "auto".into(),
            TvProxChoice::Fixed(p) => p.name(),
        }
    }
}

impl std::str::FromStr for TvProxChoice {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "auto" {
            return Ok(TvProxChoice::Auto);
        }
        s.parse::<TvProx>()
            .map(TvProxChoice::Fixed)
            .map_err(|_| format!("unknown TV prox '{s}': expected auto, haar, dual or dualN (N inner iterations from 1 to {MAX_DUAL_ITERS})"))
    }
}

impl From<TvProxChoice> for String {
    fn from(c: TvProxChoice) -> String {
        c.name()
    }
}

impl TryFrom<String> for TvProxChoice {
    type Error = String;
    fn try_from(s: String) -> Result<Self, String> {
        s.parse()
    }
}

impl std::fmt::Display for TvProxChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.name())
    }
}

/// TV prox by warm-started FGP on the dual.
///
/// Each inner iteration is two kinds of pass over the volume, frames in parallel: the
/// primal `x = P(z - lambda sum_a w_a D_a^T q_a)` (one pass, all axes fused, the frame
/// in cache) and, per active axis, the projected dual step with its momentum. The
/// buffers live in the map and are reused between calls. [`DualTv::prox_reference`]
/// keeps the plain whole-volume version the fast one is tested against.
pub struct DualTv {
    pub tv: TotalVariation,
    pub inner_iters: usize,
    /// Dual variables and their momentum iterates, one volume per active axis (kept
    /// between calls: the warm start).
    state: Mutex<DualState>,
}

#[derive(Default)]
struct DualState {
    p: Vec<Vec<f32>>,
    q: Vec<Vec<f32>>,
}

impl DualState {
    fn ensure(&mut self, axes: usize, n: usize) {
        if self.p.len() != axes || self.p.iter().any(|p| p.len() != n) {
            self.p = vec![vec![0.0f32; n]; axes];
            self.q = vec![vec![0.0f32; n]; axes];
        }
    }
}

impl DualTv {
    pub fn new(tv: TotalVariation, inner_iters: usize) -> Self {
        DualTv { tv, inner_iters: inner_iters.max(1), state: Mutex::new(DualState::default()) }
    }

    /// `lambda`, the active axes, and the dual step `1 / (lambda ||D_w||^2)`.
    fn setup(&self, gamma: f32) -> (f32, Vec<usize>, f32) {
        let tv = &self.tv;
        let lambda = gamma * tv.tau;
        let axes = tv.active_axes();
        let lip: f32 = 4.0 * axes.iter().map(|&a| tv.weights[a] * tv.weights[a]).sum::<f32>();
        (lambda, axes, 1.0 / (lambda * lip))
    }

    /// The same map as [`Prox::prox`], evaluated the plain way (whole-volume passes per
    /// axis, one thread): the reference of the fast path's tests. It shares the warm
    /// start with the fast path.
    pub fn prox_reference(&self, z: &[f32], gamma: f32, out: &mut [f32]) {
        let tv = &self.tv;
        let shape = tv.shape;
        let n = z.len();
        let (lambda, axes, step) = self.setup(gamma);
        let clamp = |v: f32| if tv.nonneg { v.max(0.0) } else { v };
        if axes.is_empty() || lambda <= 0.0 {
            for (o, &v) in out.iter_mut().zip(z) {
                *o = clamp(v);
            }
            return;
        }
        let mut guard = self.state.lock().unwrap();
        guard.ensure(axes.len(), n);
        let st = &mut guard.p;
        let mut q: Vec<Vec<f32>> = st.clone();
        let mut t = 1.0f32;
        let mut d = vec![0.0f32; n];
        let primal = |q: &[Vec<f32>], out: &mut [f32]| {
            out.copy_from_slice(z);
            for (ai, &a) in axes.iter().enumerate() {
                diff_adjoint_add(shape, a, &q[ai], -lambda * tv.weights[a], out);
            }
            for o in out.iter_mut() {
                *o = clamp(*o);
            }
        };
        for _ in 0..self.inner_iters {
            primal(&q, out);
            let t_new = 0.5 * (1.0 + (1.0 + 4.0 * t * t).sqrt());
            let beta = (t - 1.0) / t_new;
            for (ai, &a) in axes.iter().enumerate() {
                diff(shape, a, out, &mut d);
                let w = tv.weights[a];
                let (p_old, qa) = (&mut st[ai], &mut q[ai]);
                for i in 0..n {
                    let p_new = (qa[i] + step * w * d[i]).clamp(-1.0, 1.0);
                    qa[i] = p_new + beta * (p_new - p_old[i]);
                    p_old[i] = p_new;
                }
            }
            t = t_new;
        }
        primal(st, out);
    }
}

/// `o += s * a`.
#[inline]
fn axpy(o: &mut [f32], s: f32, a: &[f32]) {
    for (o, &a) in o.iter_mut().zip(a) {
        *o += s * a;
    }
}

/// The dual variables' axes, each axis's coefficient and the projection of the primal
/// ([`primal_frame`]).
struct PrimalTerms<'a> {
    axes: &'a [usize],
    coef: &'a [f32],
    nonneg: bool,
}

/// Frame `f` (of the block `q` holds) of the primal: `out_f = P(z_f + sum_a coef_a
/// (D_a^T q_a)_f)`, with `(D^T q)[i] = q[i - s] (if not first along the axis) - q[i]
/// (if not last)`. Along time the frame before is `prev_t` (the temporal dual
/// variable's previous frame, `None` at the video's start) and `last_t` says whether
/// this is the video's last frame.
fn primal_frame(
    (m, n): (usize, usize),
    f: usize,
    z_f: &[f32],
    q: &[Vec<f32>],
    terms: &PrimalTerms,
    out_f: &mut [f32],
    (prev_t, last_t): (Option<&[f32]>, bool),
) {
    let PrimalTerms { axes, coef, nonneg } = *terms;
    let fl = m * n;
    out_f.copy_from_slice(z_f);
    for (ai, &a) in axes.iter().enumerate() {
        let (s, qa) = (coef[ai], &q[ai]);
        let qf = &qa[f * fl..(f + 1) * fl];
        match a {
            0 => {
                if let Some(prev) = prev_t {
                    axpy(out_f, s, prev);
                }
                if !last_t {
                    axpy(out_f, -s, qf);
                }
            }
            1 => {
                for r in 0..m {
                    let o = &mut out_f[r * n..(r + 1) * n];
                    if r > 0 {
                        axpy(o, s, &qf[(r - 1) * n..r * n]);
                    }
                    if r + 1 < m {
                        axpy(o, -s, &qf[r * n..(r + 1) * n]);
                    }
                }
            }
            _ => {
                for (o, qr) in out_f.chunks_mut(n).zip(qf.chunks(n)) {
                    for c in 1..n {
                        o[c] += s * qr[c - 1];
                    }
                    for c in 0..n - 1 {
                        o[c] -= s * qr[c];
                    }
                }
            }
        }
    }
    if nonneg {
        for o in out_f.iter_mut() {
            *o = o.max(0.0);
        }
    }
}

/// The projected dual step with momentum on frame `f` (of the block `x` holds) of one
/// axis: `p_new = clip(q + sw D_a x, -1, 1)`, `q = p_new + beta (p_new - p)`,
/// `p = p_new`. Along time the next frame is `next_t` (`None` at the video's end).
fn dual_frame((m, n): (usize, usize), axis: usize, f: usize, x: &[f32], (sw, beta): (f32, f32), (p_f, q_f): (&mut [f32], &mut [f32]), next_t: Option<&[f32]>) {
    let fl = m * n;
    let x_f = &x[f * fl..(f + 1) * fl];
    let update = |p: &mut f32, q: &mut f32, d: f32| {
        let p_new = (*q + sw * d).clamp(-1.0, 1.0);
        *q = p_new + beta * (p_new - *p);
        *p = p_new;
    };
    match axis {
        0 => {
            if let Some(x_next) = next_t {
                for i in 0..fl {
                    update(&mut p_f[i], &mut q_f[i], x_next[i] - x_f[i]);
                }
            } else {
                for i in 0..fl {
                    update(&mut p_f[i], &mut q_f[i], 0.0);
                }
            }
        }
        1 => {
            for i in 0..fl {
                let d = if i + n < fl { x_f[i + n] - x_f[i] } else { 0.0 };
                update(&mut p_f[i], &mut q_f[i], d);
            }
        }
        _ => {
            for ((xr, pr), qr) in x_f.chunks(n).zip(p_f.chunks_mut(n)).zip(q_f.chunks_mut(n)) {
                for c in 0..n {
                    let d = if c + 1 < n { xr[c + 1] - xr[c] } else { 0.0 };
                    update(&mut pr[c], &mut qr[c], d);
                }
            }
        }
    }
}

impl Prox for DualTv {
    fn value(&self, x: &[f32]) -> f64 {
        self.tv.value(x)
    }

    fn prox(&self, z: &[f32], gamma: f32, out: &mut [f32]) {
        self.prox_block(z, gamma, out, &One);
    }

    fn total_variation(&self) -> Option<&TotalVariation> {
        Some(&self.tv)
    }

    fn metric_prox(&self) -> Option<&dyn MetricProx> {
        Some(self)
    }
}

/// The dual map in the per-frame metric: `x(p) = P(z - lambda D^{-1} sum_a w_a D_a^T
/// p_a)` (each frame's correction divided by its weight `d_k`), the dual step bound
/// `1 / (lambda ||D_w||^2 max_k 1/d_k)`.
impl MetricProx for DualTv {
    fn prox_in(&self, z: &[f32], gamma: f32, metric: &FrameMetric, out: &mut [f32]) {
        let (k, m, n) = self.tv.shape;
        assert_eq!((metric.frames(), metric.frame_len()), (k, m * n), "the metric's frames must be the TV's");
        self.prox_frames(z, gamma, out, &One, Some(metric));
    }
}

impl DualTv {
    /// [`Prox::prox`] of a block of consecutive frames `z` of this TV's video (a rank's
    /// block, [`crate::model::split`]; `tv.shape` stays the whole video's). Each inner
    /// iteration needs two edge frames from the neighbouring ranks: the previous
    /// rank's last frame of the temporal dual variable (for the primal) and the next
    /// rank's first frame of the primal (for the dual step). Every per-frame update
    /// depends only on those neighbours, so the blocks compute the whole map's frames,
    /// to the bit. With [`One`] it is the whole map.
    pub fn prox_block(&self, z: &[f32], gamma: f32, out: &mut [f32], ranks: &dyn Ranks) {
        self.prox_frames(z, gamma, out, ranks, None);
    }

    /// [`Self::prox_block`], in the per-frame `metric` when given (frames of the block).
    fn prox_frames(&self, z: &[f32], gamma: f32, out: &mut [f32], ranks: &dyn Ranks, metric: Option<&FrameMetric>) {
        let tv = &self.tv;
        let (_, m, nc) = tv.shape;
        let fl = (m * nc).max(1);
        let n = z.len();
        let kb = n / fl;
        let (lambda, axes, step) = self.setup(gamma);
        if axes.is_empty() || lambda <= 0.0 {
            for (o, &v) in out.iter_mut().zip(z) {
                *o = if tv.nonneg { v.max(0.0) } else { v };
            }
            return;
        }
        // In a metric: each frame's correction over its weight, the step over the largest.
        let inv_d = metric.map(|d| d.inverse());
        let step = metric.map_or(step, |d| step / d.max_inverse());
        // Dual of min 0.5||x - z||^2 + lambda sum_a w_a |D_a x| + [x >= 0]:
        // x(p) = P(z - lambda sum_a w_a D_a^T p_a), |p_a| <= 1, step 1 / (lambda ||D_w||^2).
        let coef: Vec<f32> = axes.iter().map(|&a| -lambda * tv.weights[a]).collect();
        let mut guard = self.state.lock().unwrap();
        guard.ensure(axes.len(), n);
        let DualState { p, q } = &mut *guard;
        for (qa, pa) in q.iter_mut().zip(p.iter()) {
            qa.par_chunks_mut(fl).zip(pa.par_chunks(fl)).for_each(|(qf, pf)| qf.copy_from_slice(pf));
        }
        // The block's place: whether frames lie before and after it (other ranks').
        let split = ranks.size() > 1;
        let (has_before, has_after) = (split && ranks.rank() > 0, split && ranks.rank() + 1 < ranks.size());
        let t_axis = axes.iter().position(|&a| a == 0);
        let mut halo_q = vec![0.0f32; if t_axis.is_some() && has_before { fl } else { 0 }];
        let mut halo_x = vec![0.0f32; if t_axis.is_some() && has_after { fl } else { 0 }];
        // The previous rank's last frame of the temporal dual variable `v`.
        let fetch_before = |v: &[Vec<f32>], halo: &mut [f32]| {
            if let (Some(ai), true) = (t_axis, split) {
                let last = &v[ai][n - fl..];
                ranks.exchange_halo(&[], if has_after { last } else { &[] }, halo, &mut []);
            }
        };
        let primal = |q: &[Vec<f32>], halo: &[f32], out: &mut [f32]| {
            out.par_chunks_mut(fl).zip(z.par_chunks(fl)).enumerate().for_each(|(f, (o, zf))| {
                let prev = match t_axis {
                    Some(ai) if f > 0 => Some(&q[ai][(f - 1) * fl..f * fl]),
                    Some(_) if has_before => Some(halo),
                    _ => None,
                };
                let s = inv_d.map_or(1.0, |w| w[f]);
                let mut cf = [0.0f32; 3];
                cf.iter_mut().zip(&coef).for_each(|(c, &v)| *c = v * s);
                let terms = PrimalTerms { axes: &axes, coef: &cf[..coef.len()], nonneg: tv.nonneg };
                primal_frame((m, nc), f, zf, q, &terms, o, (prev, f + 1 == kb && !has_after))
            });
        };
        let mut t = 1.0f32;
        for _ in 0..self.inner_iters {
            fetch_before(q, &mut halo_q);
            primal(q, &halo_q, out);
            let t_new = 0.5 * (1.0 + (1.0 + 4.0 * t * t).sqrt());
            let beta = (t - 1.0) / t_new;
            let x: &[f32] = out;
            if t_axis.is_some() && split {
                // The next rank's first frame of the primal.
                ranks.exchange_halo(if has_before { &x[..fl] } else { &[] }, &[], &mut [], &mut halo_x);
            }
            for (ai, &a) in axes.iter().enumerate() {
                let sw = step * tv.weights[a];
                let halo_x = &halo_x[..];
                p[ai].par_chunks_mut(fl).zip(q[ai].par_chunks_mut(fl)).enumerate().for_each(|(f, (pf, qf))| {
                    let next = if f + 1 < kb {
                        Some(&x[(f + 1) * fl..(f + 2) * fl])
                    } else if has_after {
                        Some(halo_x)
                    } else {
                        None
                    };
                    dual_frame((m, nc), a, f, x, (sw, beta), (pf, qf), next)
                });
            }
            t = t_new;
        }
        fetch_before(p, &mut halo_q);
        primal(p, &halo_q, out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::op::pseudo_random;
    use crate::solve::prox::tv::tv1d_prox_exact;

    #[test]
    fn dual_prox_matches_the_exact_1d_prox() {
        let n = 40;
        let y: Vec<f32> = pseudo_random(n, 3).iter().enumerate().map(|(i, v)| v + if i > 15 { 2.0 } else { 0.0 }).collect();
        let tv = TotalVariation { shape: (1, 1, n), tau: 0.4, weights: [0.0, 0.0, 1.0], nonneg: false };
        let exact = tv1d_prox_exact(&y.iter().map(|&v| v as f64).collect::<Vec<_>>(), 0.4 * 0.5);
        let d = DualTv::new(tv.clone(), 3000);
        let mut out = vec![0.0; n];
        d.prox(&y, 0.5, &mut out);
        let err = out.iter().zip(&exact).map(|(a, b)| (*a as f64 - b).abs()).fold(0.0, f64::max);
        // The Haar map is the faster approximation: it must be further off.
        let mut haar = vec![0.0; n];
        tv.prox(&y, 0.5, &mut haar);
        let herr = haar.iter().zip(&exact).map(|(a, b)| (*a as f64 - b).abs()).fold(0.0, f64::max);
        assert!(err < 1e-4, "dual prox error {err}");
        assert!(herr > 10.0 * err, "haar {herr} vs dual {err}");
    }

    #[test]
    fn fast_dual_prox_matches_the_plain_reference_call_after_call() {
        // Frames in parallel, axes fused, buffers reused: the same map as the plain
        // whole-volume passes, warm start included (five calls on drifting input).
        for (shape, weights, nonneg) in [
            ((5, 7, 9), [2.0, 1.0, 1.0], true),
            ((4, 6, 5), [0.0, 1.0, 1.0], true),
            ((6, 1, 8), [3.0, 1.0, 0.5], false),
            ((3, 5, 1), [1.0, 1.0, 1.0], true),
            ((1, 8, 6), [5.0, 1.0, 2.0], true),
        ] {
            let (k, m, n) = shape;
            let tv = TotalVariation { shape, tau: 0.3, weights, nonneg };
            let (fast, plain) = (DualTv::new(tv.clone(), 7), DualTv::new(tv, 7));
            let (mut a, mut b) = (vec![0.0f32; k * m * n], vec![0.0f32; k * m * n]);
            for call in 0..5 {
                let z: Vec<f32> = pseudo_random(k * m * n, 10 + call).iter().map(|v| v + 0.1 * call as f32).collect();
                fast.prox(&z, 0.8, &mut a);
                plain.prox_reference(&z, 0.8, &mut b);
                let scale = b.iter().fold(0.0f32, |s, v| s.max(v.abs())).max(1e-6);
                let diff = a.iter().zip(&b).fold(0.0f32, |d, (x, y)| d.max((x - y).abs()));
                assert!(diff / scale < 1e-5, "{shape:?} {weights:?} call {call}: {diff} of {scale}");
            }
            // And the warm starts stayed in step.
            let (sf, sp) = (fast.state.lock().unwrap(), plain.state.lock().unwrap());
            for (x, y) in sf.p.iter().flatten().zip(sp.p.iter().flatten()) {
                assert!((x - y).abs() < 1e-5, "dual variables drifted apart: {x} vs {y}");
            }
        }
    }

    #[test]
    fn blocks_of_the_dual_map_on_ranks_give_the_whole_map_exactly() {
        // Three calls (the warm start carries over), blocks of uneven size, one frame
        // blocks included.
        let (k, m, n) = (7, 4, 5);
        let fl = m * n;
        for weights in [[4.0, 1.0, 1.0], [0.0, 1.0, 2.0], [2.0, 0.0, 0.0]] {
            let tv = TotalVariation { shape: (k, m, n), tau: 0.3, weights, nonneg: true };
            let whole = DualTv::new(tv.clone(), 6);
            let calls: Vec<Vec<f32>> = (0..3).map(|c| pseudo_random(k * fl, 20 + c).iter().map(|v| v - 0.2 + 0.1 * c as f32).collect()).collect();
            let expected: Vec<Vec<f32>> = calls
                .iter()
                .map(|z| {
                    let mut o = vec![0.0f32; z.len()];
                    whole.prox(z, 0.9, &mut o);
                    o
                })
                .collect();
            for cuts in [vec![0, 3, 7], vec![0, 1, 2, 6, 7]] {
                let ranks = crate::model::ranks::threads::ThreadRanks::chain(cuts.len() - 1);
                let pieces: Vec<Vec<Vec<f32>>> = std::thread::scope(|s| {
                    let handles: Vec<_> = ranks
                        .iter()
                        .zip(cuts.windows(2))
                        .map(|(r, w)| {
                            let (tv, calls) = (tv.clone(), &calls);
                            s.spawn(move || {
                                let block = DualTv::new(tv, 6);
                                calls
                                    .iter()
                                    .map(|z| {
                                        let mut o = vec![0.0f32; (w[1] - w[0]) * fl];
                                        block.prox_block(&z[w[0] * fl..w[1] * fl], 0.9, &mut o, r);
                                        o
                                    })
                                    .collect()
                            })
                        })
                        .collect();
                    handles.into_iter().map(|h| h.join().unwrap()).collect()
                });
                for (c, want) in expected.iter().enumerate() {
                    let got: Vec<f32> = pieces.iter().flat_map(|p| p[c].iter().copied()).collect();
                    assert_eq!(&got, want, "{weights:?} {cuts:?} call {c}");
                }
            }
        }
    }

    #[test]
    fn parses_names() {
        assert_eq!("haar".parse::<TvProx>().unwrap(), TvProx::Haar);
        assert_eq!("dual".parse::<TvProx>().unwrap(), TvProx::Dual { inner_iters: 10 });
        assert_eq!("dual25".parse::<TvProx>().unwrap(), TvProx::Dual { inner_iters: 25 });
        assert!("dual0".parse::<TvProx>().unwrap_err().contains("expected"));
    }
}
