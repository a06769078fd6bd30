//! ADMM with every update in closed form: the DiffuserCam splitting (Antipa et al.,
//! Optica 2018) extended to the rolling-shutter video, for
//! `min D(M A v) + tau sum_a w_a |D_a v|_1 + [v >= 0]` with
//! `A v = sum_k W[:, k] . crop(h * v_k)` ([`ShutterConvolution`]) and `D` the data term
//! (one-sided at clipped pixels).
//!
//! ## The splitting
//! The unknown `v` lives on the padded FFT grid `P x Q` of the convolution (one plane
//! per frame), where `H v_k = h * v_k` is circular and diagonal in Fourier. Three
//! splits, each with a scaled dual and a penalty:
//! - `z_k = H v_k` (penalty `mu_data`): the data term sees `z` through the crop, the
//!   shutter and the mask. Sensor pixel `i` sees the frames through one vector
//!   `a_i = m_i W[row(i), :]`, so its update is the prox of a function of `a_i . z_i`:
//!   `(a_i a_i^T + mu I) z_i = mu r_i + a_i b_i`, solved by Sherman-Morrison
//!   ([`pixel_update`]); at a clipped pixel the loss is one-sided, and `z_i = r_i` when
//!   `a_i . r_i >= b_i`. Every other entry of `z` (outside the crop, or a frame the
//!   pixel's row does not see) has no data term: there `z = H v` after the first
//!   iteration and its dual is zero, so only the entries a row sees are stored.
//! - `u_a = w_a D_a v` (penalty `mu_tv`), shrunk by `tau / mu_tv`. The spatial
//!   differences are periodic on the padded grid (so `D^T D` is diagonal in Fourier);
//!   only the differences between two pixels of the video grid are shrunk, the others
//!   (across its border or the wrap) are left free, so the TV is exactly the other
//!   solvers' (differences stop at the borders). The temporal differences are the
//!   other solvers' (no wrap, none after the last frame).
//! - `w = v` (penalty `mu_nn`): clamped at 0 on the video grid, 0 outside it. So `v`
//!   is the video on its grid at convergence.
//!
//! ## The v-update
//! `(mu_data H^T H + mu_tv D^T D + mu_nn I) v = rhs` is, per spatial frequency `f`, the
//! `K x K` system `(a_f I + mu_tv w_t^2 L_t) vhat_f = rhat_f` with
//! `a_f = mu_data |H_f|^2 + mu_tv (w_y^2 |D_y,f|^2 + w_x^2 |D_x,f|^2) + mu_nn` and `L_t`
//! the path Laplacian of the temporal differences (reflective ends). The DCT-II
//! diagonalises `L_t`; since it is tridiagonal, the same inverse is taken exactly by
//! elimination along time (O(K) per frequency, its pivots stored and refreshed only
//! when a penalty changes). The update is thus two real 2D FFTs per frame, a
//! tridiagonal sweep and one inverse FFT; `H v` is one more inverse FFT, evaluated on
//! the sensor rows each frame's shutter weights touch only ([`VSystem`]).
//!
//! ## Penalties
//! Initial (defaults chosen on the study's captures, `docs/solver-study.md`):
//! `mu_data = 0.01 x max_i |a_i|^2` (the data's weight in the pixel update is
//! `|a_i|^2`),
//! `mu_tv = mu_nn = 30 x mu_data x mean |H_f|^2` (the scale of `mu_data H^T H` in
//! `a_f`). Residual balancing every
//! `balance_every` iterations (Boyd et al. 2011, sec. 3.4.1), per split: with primal
//! residual `r = ||G v - s||` and dual residual `s = mu ||G^T (s - s_prev)||`, the
//! penalty doubles (its scaled dual halves) when `r > 10 s`, halves (dual doubles) when
//! `s > 10 r`. `||G^T d||` is taken as `rms|H_f| ||d||` for `G = H` and `||d||` for the
//! others.
//!
//! ## What it reports
//! The iterate is `x = w` on the video grid: non-negative and zero outside, so a point
//! of the problem every solver minimises; its objective is the data term
//! ([`DataTerm::value`] of `op.forward(x)`, one forward per iteration) plus `tv.value(x)`.
//!
//! Refused ([`crate::solve::optimize::SolverKind`]'s checks): a problem split across
//! ranks, a prior other than TV (L1, the static + dynamic model), an operator that is
//! not one shutter-weighted convolution on its whole grid (a scene's support or static
//! scene, consecutive captures). Clipped pixels and the sensor mask are handled.
//!
//! Memory: about `6 + 2 x (active TV axes)` planes of the padded grid per frame
//! (`v`, `w` and its dual, `u_a` and their duals, the spectrum of `v` as complex
//! `qc x P`, the sweep's pivots) plus `3 x (frames a row sees)` sensor-sized planes.

use crate::model::data::DataTerm;
use crate::model::op::{Operator, ShutterConvolution};
use crate::solve::optimize::common::{rel_change, BLOCK};
use crate::solve::optimize::executor::{run, Accepted, Objective, Step};
use crate::solve::optimize::types::{Observer, SolveResult, StopRule};
use crate::solve::prox::tv::soft;
use crate::solve::prox::Prox as _;
use crate::solve::prox::TotalVariation;
use rayon::prelude::*;
use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};
use rustfft::num_complex::Complex32;
use rustfft::{Fft, FftPlanner};
use serde::Serialize;
use std::sync::{Arc, Mutex};

/// The splitting's penalties and their balancing.
#[derive(Clone, Debug, Serialize)]
pub struct SplitParams {
    /// Data split penalty relative to the largest `|a_i|^2` of a sensor pixel.
    pub mu_data_rel: f64,
    /// TV split penalty relative to `mu_data * mean |H_f|^2`.
    pub mu_tv_rel: f64,
    /// Non-negativity split penalty relative to `mu_data * mean |H_f|^2`.
    pub mu_nn_rel: f64,
    /// Residual balancing period (0 disables).
    pub balance_every: usize,
}

impl Default for SplitParams {
    fn default() -> Self {
        SplitParams { mu_data_rel: 0.01, mu_tv_rel: 30.0, mu_nn_rel: 30.0, balance_every: 10 }
    }
}

#[derive(Clone, Debug)]
pub struct AdmmSplit {
    pub stop: StopRule,
    pub params: SplitParams,
}

impl AdmmSplit {
    /// # Panics
    /// On what the checks refuse (a split problem; an operator without the structure).
    pub fn solve<A: Operator + ?Sized>(&self, op: &A, data: &DataTerm, tv: &TotalVariation, x0: Option<Vec<f32>>, observer: &mut dyn Observer) -> SolveResult {
        assert_eq!(data.ranks().size(), 1, "admm-split does not take a split problem");
        let sc = op.shutter_convolution().expect("admm-split needs a shutter-weighted convolution");
        assert_eq!(data.observations().len(), op.output_len(), "measurement size must match the operator's output");
        assert_eq!(tv.shape.0 * tv.shape.1 * tv.shape.2, op.input_len(), "TV shape must match the operator's input");
        run(&self.stop, observer, || SplitStep::new(op, sc, *data, tv, &self.params, x0))
    }
}

/// The z-update of one sensor pixel as the gain `g` of `z = r + a g`:
/// `z = argmin phi(a . z) + mu/2 ||z - r||^2` with `phi(s) = 0.5 (s - b)^2`, one-sided
/// (`0.5 max(0, b - s)^2`) when `lower`, given `ar = a . r` and `aa = |a|^2`. By
/// Sherman-Morrison `(a a^T + mu I)^-1 (mu r + a b) = r + a (b - a.r) / (mu + |a|^2)`;
/// one-sided, `g = 0` when `a . r >= b` (the bound holds at `z = r`), and otherwise
/// the two-sided gain (which lands on `a . z <= b`).
pub fn pixel_gain(ar: f64, aa: f64, b: f32, lower: bool, mu: f32) -> f32 {
    if lower && ar >= b as f64 {
        0.0
    } else {
        ((b as f64 - ar) / (mu as f64 + aa)) as f32
    }
}

/// Real 2D FFTs of `P x Q` planes (row-major), spectra transposed (`qc` columns of
/// length `P`, `qc = Q/2 + 1`), unnormalised forward, inverse scaled by `1/(P Q)`. Rows,
/// transposes and columns each run in parallel, so one plane uses every thread.
struct Fft2 {
    p: usize,
    q: usize,
    qc: usize,
    r2c: Arc<dyn RealToComplex<f32>>,
    c2r: Arc<dyn ComplexToReal<f32>>,
    col_fwd: Arc<dyn Fft<f32>>,
    col_inv: Arc<dyn Fft<f32>>,
    /// One set of buffers per thread (indexed by the rayon thread).
    pool: Vec<Mutex<FftScratch>>,
}

struct FftScratch {
    row: Vec<f32>,
    rfft: Vec<Complex32>,
    cfft: Vec<Complex32>,
}

/// Columns per parallel task of the column passes.
const COLS: usize = 8;

impl Fft2 {
    fn new(p: usize, q: usize) -> Self {
        assert!(q % 2 == 0, "the padded grid's width must be even");
        let mut rp = RealFftPlanner::<f32>::new();
        let (r2c, c2r) = (rp.plan_fft_forward(q), rp.plan_fft_inverse(q));
        let mut cp = FftPlanner::<f32>::new();
        let (col_fwd, col_inv) = (cp.plan_fft_forward(p), cp.plan_fft_inverse(p));
        let rlen = r2c.get_scratch_len().max(c2r.get_scratch_len());
        let clen = col_fwd.get_inplace_scratch_len().max(col_inv.get_inplace_scratch_len());
        let pool = (0..rayon::current_num_threads().max(1))
            .map(|_| Mutex::new(FftScratch { row: vec![0.0; q], rfft: vec![Complex32::default(); rlen], cfft: vec![Complex32::default(); clen] }))
            .collect();
        Fft2 { p, q, qc: q / 2 + 1, r2c, c2r, col_fwd, col_inv, pool }
    }

    fn len(&self) -> usize {
        self.qc * self.p
    }

    fn with_scratch<R>(&self, f: impl FnOnce(&mut FftScratch) -> R) -> R {
        let i = rayon::current_thread_index().unwrap_or(0) % self.pool.len();
        f(&mut self.pool[i].lock().expect("FFT scratch"))
    }

    /// `out = FFT2(x)`; rows where `rows` is false are taken as zero. `tmp`: `P x qc`.
    fn forward(&self, x: &[f32], rows: Option<&[bool]>, tmp: &mut [Complex32], out: &mut [Complex32]) {
        let (p, q, qc) = (self.p, self.q, self.qc);
        tmp.par_chunks_mut(qc).enumerate().for_each(|(r, t)| {
            if rows.is_some_and(|m| !m[r]) {
                t.fill(Complex32::default());
                return;
            }
            self.with_scratch(|s| {
                s.row.copy_from_slice(&x[r * q..(r + 1) * q]);
                self.r2c.process_with_scratch(&mut s.row, t, &mut s.rfft).expect("r2c sizes");
            });
        });
        let tmp = &*tmp;
        out.par_chunks_mut(p * COLS).enumerate().for_each(|(b, o)| {
            let c0 = b * COLS;
            let nc = o.len() / p;
            for r in 0..p {
                for j in 0..nc {
                    o[j * p + r] = tmp[r * qc + c0 + j];
                }
            }
            self.with_scratch(|s| self.col_fwd.process_with_scratch(o, &mut s.cfft));
        });
    }

    /// `out = IFFT2(spec)` on the rows where `rows` is true (all when `None`); the other
    /// rows of `out` are left as they are. `spec` is destroyed; `tmp`: `P x qc`.
    fn inverse(&self, spec: &mut [Complex32], rows: Option<&[bool]>, tmp: &mut [Complex32], out: &mut [f32]) {
        let (p, q, qc) = (self.p, self.q, self.qc);
        spec.par_chunks_mut(p * COLS).for_each(|o| self.with_scratch(|s| self.col_inv.process_with_scratch(o, &mut s.cfft)));
        let spec = &*spec;
        let scale = 1.0 / (p * q) as f32;
        tmp.par_chunks_mut(qc).zip(out.par_chunks_mut(q)).enumerate().for_each(|(r, (t, o))| {
            if rows.is_some_and(|m| !m[r]) {
                return;
            }
            for (c, tc) in t.iter_mut().enumerate() {
                *tc = spec[c * p + r];
            }
            // DC and Nyquist bins of a real row are real; drop the round-off.
            t[0].im = 0.0;
            t[qc - 1].im = 0.0;
            self.with_scratch(|s| {
                self.c2r.process_with_scratch(t, &mut s.row, &mut s.rfft).expect("c2r sizes");
                for (o, &v) in o.iter_mut().zip(&s.row) {
                    *o = v * scale;
                }
            });
        });
    }
}

/// The v-update's system `mu_data H^T H + mu_tv sum_a w_a^2 D_a^T D_a + mu_nn I` on
/// `K` planes of the padded `P x Q` grid (`H` circular convolution with the PSF, spatial
/// differences periodic, temporal ones without wrap), solved by FFTs and a tridiagonal
/// sweep along time. Public for the tests that compare it with a dense solve.
pub struct VSystem {
    k: usize,
    fft: Fft2,
    /// `FFT2` of the PSF placed with its centre at (0, 0).
    hhat: Vec<Complex32>,
    /// `|H_f|^2`.
    h2: Vec<f32>,
    /// `w_y^2 |D_y,f|^2 + w_x^2 |D_x,f|^2`.
    lap: Vec<f32>,
    /// `w_t^2`.
    wt2: f32,
    /// The sweep's inverse pivots, `K x F`, for `mu`.
    inv_pivot: Vec<f32>,
    mu: [f32; 3],
    /// Scratch: one transposed spectrum and one row-major one.
    spec: Vec<Complex32>,
    tmp: Vec<Complex32>,
}

impl VSystem {
    /// The system of a `m x n` PSF (centre `(m/2, n/2)`) on `k` planes of `p x q` (`q`
    /// even), TV weights `[w_t, w_y, w_x]` (0: axis left out).
    pub fn new(psf: &[f32], (m, n): (usize, usize), (k, p, q): (usize, usize, usize), tv_weights: [f32; 3]) -> Self {
        let fft = Fft2::new(p, q);
        let (qc, f) = (fft.qc, fft.len());
        let hhat = psf_spectrum_with(&fft, psf, (m, n));
        let tmp = vec![Complex32::default(); p * qc];
        let h2 = hhat.iter().map(|z| z.norm_sqr()).collect();
        let [wt, wy, wx] = tv_weights;
        let tau = std::f64::consts::TAU;
        let mut lap = vec![0.0f32; f];
        for c in 0..qc {
            let lx = 2.0 - 2.0 * (tau * c as f64 / q as f64).cos();
            for r in 0..p {
                let ly = 2.0 - 2.0 * (tau * r as f64 / p as f64).cos();
                lap[c * p + r] = ((wy as f64).powi(2) * ly + (wx as f64).powi(2) * lx) as f32;
            }
        }
        VSystem { k, fft, hhat, h2, lap, wt2: wt * wt, inv_pivot: vec![0.0; k * f], mu: [f32::NAN; 3], spec: vec![Complex32::default(); f], tmp }
    }

    fn freqs(&self) -> usize {
        self.fft.len()
    }

    /// The pivots of the sweep for penalties `mu` (only when they changed).
    fn factor(&mut self, mu: [f32; 3]) {
        if mu == self.mu {
            return;
        }
        self.mu = mu;
        let (k, f) = (self.k, self.freqs());
        let e = mu[1] * self.wt2;
        let (h2, lap) = (&self.h2, &self.lap);
        for t in 0..k {
            let deg = if k == 1 {
                0.0
            } else if t == 0 || t + 1 == k {
                1.0
            } else {
                2.0
            };
            let (prev, cur) = self.inv_pivot.split_at_mut(t * f);
            let prev = if t > 0 { &prev[(t - 1) * f..] } else { &[][..] };
            cur[..f].par_chunks_mut(BLOCK).enumerate().for_each(|(bi, c)| {
                let o = bi * BLOCK;
                for (j, cj) in c.iter_mut().enumerate() {
                    let a = mu[0] as f64 * h2[o + j] as f64 + mu[1] as f64 * lap[o + j] as f64 + mu[2] as f64 + e as f64 * deg;
                    let m = if t > 0 { a - (e as f64).powi(2) * prev[o + j] as f64 } else { a };
                    *cj = (1.0 / m) as f32;
                }
            });
        }
    }

    /// Solve in place along time: `vhat` holds the right-hand side's spectra (`K x F`,
    /// frame-major) and becomes the solution's.
    fn sweep(&self, vhat: &mut [Complex32]) {
        let (k, f) = (self.k, self.freqs());
        let e = self.mu[1] * self.wt2;
        for t in 0..k {
            let (prev, cur) = vhat.split_at_mut(t * f);
            let piv = &self.inv_pivot[t * f..(t + 1) * f];
            if t == 0 {
                cur[..f].par_chunks_mut(BLOCK).zip(piv.par_chunks(BLOCK)).for_each(|(c, p)| c.iter_mut().zip(p).for_each(|(c, &p)| *c *= p));
            } else {
                let prev = &prev[(t - 1) * f..];
                cur[..f].par_chunks_mut(BLOCK).zip(piv.par_chunks(BLOCK)).zip(prev.par_chunks(BLOCK)).for_each(|((c, p), q)| {
                    for ((c, &p), &q) in c.iter_mut().zip(p).zip(q) {
                        *c = (*c + q * e) * p;
                    }
                });
            }
        }
        if e == 0.0 {
            return;
        }
        for t in (0..k.saturating_sub(1)).rev() {
            let (cur, next) = vhat.split_at_mut((t + 1) * f);
            let cur = &mut cur[t * f..];
            let piv = &self.inv_pivot[t * f..(t + 1) * f];
            cur.par_chunks_mut(BLOCK).zip(piv.par_chunks(BLOCK)).zip(next[..f].par_chunks(BLOCK)).for_each(|((c, p), nx)| {
                for ((c, &p), &nx) in c.iter_mut().zip(p).zip(nx) {
                    *c += nx * (e * p);
                }
            });
        }
    }

    /// Solve the system for `rhs` (`K` planes `P x Q`) with penalties
    /// `[mu_data, mu_tv, mu_nn]`: the reference entry point of the tests.
    pub fn solve(&mut self, rhs: &[f32], mu: [f32; 3]) -> Vec<f32> {
        let (pq, f) = (self.fft.p * self.fft.q, self.freqs());
        self.factor(mu);
        let mut vhat = vec![Complex32::default(); self.k * f];
        for (plane, out) in rhs.chunks(pq).zip(vhat.chunks_mut(f)) {
            self.fft.forward(plane, None, &mut self.tmp, out);
        }
        self.sweep(&mut vhat);
        let mut v = vec![0.0f32; rhs.len()];
        for (spec, out) in vhat.chunks(f).zip(v.chunks_mut(pq)) {
            self.spec.copy_from_slice(spec);
            self.fft.inverse(&mut self.spec, None, &mut self.tmp, out);
        }
        v
    }
}

/// `FFT2` of an `m x n` PSF placed with its centre `(m/2, n/2)` at (0, 0) of the
/// padded `p x q` grid, transposed (`q/2 + 1` columns of length `p`): `Conv2d::spectrum`
/// unscaled, for a grid of the test's choosing ([`VSystem::new`] takes a bare PSF).
fn psf_spectrum_with(fft: &Fft2, psf: &[f32], (m, n): (usize, usize)) -> Vec<Complex32> {
    let (p, q) = (fft.p, fft.q);
    let mut kernel = vec![0.0f32; p * q];
    let (cm, cn) = (m / 2, n / 2);
    for i in 0..m {
        let a = (i as isize - cm as isize).rem_euclid(p as isize) as usize;
        for j in 0..n {
            let b = (j as isize - cn as isize).rem_euclid(q as isize) as usize;
            kernel[a * q + b] += psf[i * n + j];
        }
    }
    let mut hhat = vec![Complex32::default(); fft.len()];
    let mut tmp = vec![Complex32::default(); p * fft.qc];
    fft.forward(&kernel, None, &mut tmp, &mut hhat);
    hhat
}

/// Where the grids sit: `K` frames, video `Mv x Nv` at the top left of the padded
/// `P x Q` grid, the sensor (`N` columns) at `(off_r, off_c)`.
#[derive(Clone, Copy)]
pub(crate) struct Grid {
    pub(crate) k: usize,
    pub(crate) p: usize,
    pub(crate) q: usize,
    pub(crate) mv: usize,
    pub(crate) nv: usize,
    pub(crate) n: usize,
    pub(crate) off_r: usize,
    pub(crate) off_c: usize,
}

/// `w (D_a v)` at padded `(r, c)` of frame `vt`: periodic in space, no wrap in time
/// (`next`: the following frame, `None` after the last, where the difference is 0).
#[inline]
fn diff_at(g: &Grid, axis: usize, w: f32, vt: &[f32], next: Option<&[f32]>, r: usize, c: usize) -> f32 {
    let e = r * g.q + c;
    match axis {
        0 => next.map_or(0.0, |nx| w * (nx[e] - vt[e])),
        1 => w * (vt[if r + 1 == g.p { c } else { e + g.q }] - vt[e]),
        _ => w * (vt[if c + 1 == g.q { r * g.q } else { e + 1 }] - vt[e]),
    }
}

/// Whether the difference of `axis` at padded `(r, c)` joins two pixels of the video
/// grid (the differences the TV counts; frame bounds are `diff_frame`'s).
#[inline]
fn inside(g: &Grid, axis: usize, r: usize, c: usize) -> bool {
    match axis {
        0 => r < g.mv && c < g.nv,
        1 => r + 1 < g.mv && c < g.nv,
        _ => r < g.mv && c + 1 < g.nv,
    }
}

/// ADMM's state: `v` (padded planes) and its spectrum; the splits `z` (the entries a
/// sensor row sees), `u_a`, `w` with their scaled duals; `H v` on the seen entries;
/// the reported iterate `x` (the video grid) with `A x`.
struct SplitStep<'a, A: ?Sized> {
    op: &'a A,
    data: DataTerm<'a>,
    tv: &'a TotalVariation,
    p: &'a SplitParams,
    s: SplitSetup,
    sys: VSystem,
    /// Per frame, the (sensor row, slot) pairs that see it, and the padded rows as a mask.
    frame_rows: Vec<Vec<(usize, usize)>>,
    frame_mask: Vec<Vec<bool>>,
    mask: Option<&'a [f32]>,
    /// `[mu_data, mu_tv, mu_nn]`.
    mu: [f32; 3],
    /// Seen entries, `M x slots x N`.
    z: Vec<f32>,
    y1: Vec<f32>,
    hv: Vec<f32>,
    vhat: Vec<Complex32>,
    v: Vec<f32>,
    w: Vec<f32>,
    y3: Vec<f32>,
    u: Vec<Vec<f32>>,
    y2: Vec<Vec<f32>>,
    /// One padded plane (rows of `z - y1 - H v` placed, then `H v` rows).
    plane: Vec<f32>,
    spec: Vec<Complex32>,
    x: Vec<f32>,
    x_old: Vec<f32>,
    ax: Vec<f32>,
    /// Squared primal and dual residuals of the three splits, of the last `propose`.
    residuals: [[f64; 2]; 3],
}

/// What the CPU and CUDA steps share: where the grids sit, the TV axes, the frames each
/// sensor row sees and the initial penalties (the rule in the module docs).
pub(crate) struct SplitSetup {
    pub g: Grid,
    /// Active TV axes and their weights; `tvw[a]` the weight of axis `a` (0: left out).
    pub axes: Vec<usize>,
    pub wts: Vec<f32>,
    #[cfg_attr(not(feature = "cuda"), allow(dead_code))]
    pub tvw: [f32; 3],
    /// Frames each sensor row sees, `slots` per row (packed first, padded with
    /// `usize::MAX`), and the weights `W[row, frame]` there (0 in padding).
    pub slots: usize,
    pub row_frames: Vec<usize>,
    pub row_weights: Vec<f32>,
    /// `[mu_data, mu_tv, mu_nn]` at the start.
    pub mu: [f32; 3],
    /// `sqrt(mean |H_f|^2)`: the gain of `H^T` on a broadband residual.
    pub h_rms: f64,
}

impl SplitSetup {
    /// `h2`: `|H_f|^2` over the half spectrum.
    pub(crate) fn new(sc: &ShutterConvolution, tv: &TotalVariation, p: &SplitParams, h2: &[f32]) -> Self {
        let (m, n) = sc.conv.sensor_shape();
        let (mv, nv) = sc.conv.video_shape();
        let (pp, q) = sc.conv.fft_shape();
        let (off_r, off_c) = sc.conv.offset();
        let k = sc.weights.frames();
        let g = Grid { k, p: pp, q, mv, nv, n, off_r, off_c };
        assert_eq!(tv.shape, (k, mv, nv), "TV shape must be the operator's video");
        let (axes, wts, tvw) = Self::tv_weights(tv);
        let h2_mean = h2.iter().map(|&v| v as f64).sum::<f64>() / h2.len() as f64;
        let seen: Vec<Vec<usize>> = (0..m).map(|i| (0..k).filter(|&t| sc.weights.get(i, t) != 0.0).collect()).collect();
        let slots = seen.iter().map(Vec::len).max().unwrap_or(0).max(1);
        let (mut row_frames, mut row_weights) = (vec![usize::MAX; m * slots], vec![0.0f32; m * slots]);
        for (i, fr) in seen.iter().enumerate() {
            for (s, &t) in fr.iter().enumerate() {
                row_frames[i * slots + s] = t;
                row_weights[i * slots + s] = sc.weights.get(i, t);
            }
        }
        let max_a2 = (0..m)
            .map(|i| {
                let w2: f64 = row_weights[i * slots..(i + 1) * slots].iter().map(|&w| (w as f64).powi(2)).sum();
                let m2 = sc.mask.map_or(1.0, |mk| mk[i * n..(i + 1) * n].iter().fold(0.0f64, |a, &v| a.max((v as f64).powi(2))));
                w2 * m2
            })
            .fold(0.0f64, f64::max);
        let mu_data = p.mu_data_rel * if max_a2 > 0.0 { max_a2 } else { 1.0 };
        let scale = mu_data * if h2_mean > 0.0 { h2_mean } else { 1.0 };
        let mu = [mu_data as f32, (p.mu_tv_rel * scale) as f32, (p.mu_nn_rel * scale) as f32];
        SplitSetup { g, axes, wts, tvw, slots, row_frames, row_weights, mu, h_rms: h2_mean.sqrt() }
    }

    /// The active TV axes, their weights, and the weight of every axis (0: left out).
    pub(crate) fn tv_weights(tv: &TotalVariation) -> (Vec<usize>, Vec<f32>, [f32; 3]) {
        let axes = tv.active_axes();
        let wts: Vec<f32> = axes.iter().map(|&a| tv.weights[a]).collect();
        let mut tvw = [0.0f32; 3];
        axes.iter().zip(&wts).for_each(|(&a, &w)| tvw[a] = w);
        (axes, wts, tvw)
    }

    /// `x` (the video grid) placed on the padded planes.
    pub(crate) fn place(&self, x: &[f32]) -> Vec<f32> {
        let g = self.g;
        let pq = g.p * g.q;
        assert_eq!(x.len(), g.k * g.mv * g.nv);
        let mut v = vec![0.0f32; g.k * pq];
        for t in 0..g.k {
            for r in 0..g.mv {
                v[t * pq + r * g.q..t * pq + r * g.q + g.nv].copy_from_slice(&x[(t * g.mv + r) * g.nv..(t * g.mv + r + 1) * g.nv]);
            }
        }
        v
    }

    /// The residual balancing rule (module docs) for split `j` given its squared primal
    /// and dual residuals: the factor its penalty is multiplied by (its scaled dual is
    /// divided by it), `None` when it stays.
    pub(crate) fn balance(&self, j: usize, mu: f32, [prim, dual]: [f64; 2]) -> Option<f32> {
        if j == 1 && self.axes.is_empty() {
            return None;
        }
        let gain = if j == 0 { self.h_rms } else { 1.0 };
        let (r, s) = (prim.sqrt(), mu as f64 * gain * dual.sqrt());
        if r > 10.0 * s {
            Some(2.0)
        } else if s > 10.0 * r {
            Some(0.5)
        } else {
            None
        }
    }
}

impl<'a, A: Operator + ?Sized> SplitStep<'a, A> {
    fn new(op: &'a A, sc: ShutterConvolution<'a>, data: DataTerm<'a>, tv: &'a TotalVariation, p: &'a SplitParams, x0: Option<Vec<f32>>) -> (Self, Objective) {
        let (m, n) = sc.conv.sensor_shape();
        let (pp, q) = sc.conv.fft_shape();
        let k = sc.weights.frames();
        let (mv, nv) = sc.conv.video_shape();
        let sys = VSystem::new(sc.conv.psf(), (m, n), (k, pp, q), SplitSetup::tv_weights(tv).2);
        let setup = SplitSetup::new(&sc, tv, p, &sys.h2);
        let (g, slots, mu) = (setup.g, setup.slots, setup.mu);
        let mut frame_rows = vec![Vec::new(); k];
        let mut frame_mask = vec![vec![false; pp]; k];
        for i in 0..m {
            for s in 0..slots {
                let t = setup.row_frames[i * slots + s];
                if t != usize::MAX {
                    frame_rows[t].push((i, s));
                    frame_mask[t][i + g.off_r] = true;
                }
            }
        }
        let (pq, f) = (pp * q, sys.freqs());
        let x = x0.unwrap_or_else(|| vec![0.0; k * mv * nv]);
        let v = setup.place(&x);
        let seen_len = m * slots * n;
        let mut step = SplitStep {
            op,
            data,
            tv,
            p,
            sys,
            frame_rows,
            frame_mask,
            mask: sc.mask,
            mu,
            z: vec![0.0; seen_len],
            y1: vec![0.0; seen_len],
            hv: vec![0.0; seen_len],
            vhat: vec![Complex32::default(); k * f],
            w: v.clone(),
            y3: vec![0.0; k * pq],
            u: Vec::new(),
            y2: vec![vec![0.0; k * pq]; setup.axes.len()],
            s: setup,
            v,
            plane: vec![0.0; pq],
            spec: vec![Complex32::default(); f],
            x_old: x.clone(),
            ax: vec![0.0; op.output_len()],
            x,
            residuals: [[0.0; 2]; 3],
        };
        // Splits at the start point: u = D v, z = H v (duals zero).
        step.u = step.s.axes.iter().zip(&step.s.wts).map(|(&a, &w)| step.diff(a, w)).collect();
        for t in 0..k {
            let vt = &step.v[t * pq..(t + 1) * pq];
            step.sys.fft.forward(vt, None, &mut step.sys.tmp, &mut step.vhat[t * f..(t + 1) * f]);
        }
        step.seen_h_v();
        step.z.copy_from_slice(&step.hv);
        op.forward(&step.x, &mut step.ax);
        let objective = Objective { data_term: data.value(&step.ax), reg_term: tv.value(&step.x) };
        (step, objective)
    }

    /// `w D_a v` over every frame.
    fn diff(&self, axis: usize, w: f32) -> Vec<f32> {
        let (g, pq) = (self.s.g, self.s.g.p * self.s.g.q);
        let mut d = vec![0.0f32; self.v.len()];
        d.par_chunks_mut(pq).enumerate().for_each(|(t, dt)| {
            let next = (t + 1 < g.k).then(|| &self.v[(t + 1) * pq..(t + 2) * pq]);
            let vt = &self.v[t * pq..(t + 1) * pq];
            for r in 0..g.p {
                for c in 0..g.q {
                    dt[r * g.q + c] = diff_at(&g, axis, w, vt, next, r, c);
                }
            }
        });
        d
    }

    /// `hv = H v` on the seen entries, from `vhat`.
    fn seen_h_v(&mut self) {
        let (g, f, pq) = (self.s.g, self.sys.freqs(), self.s.g.p * self.s.g.q);
        for t in 0..g.k {
            if self.frame_rows[t].is_empty() {
                continue;
            }
            let vh = &self.vhat[t * f..(t + 1) * f];
            self.spec.par_chunks_mut(BLOCK).zip(vh.par_chunks(BLOCK)).zip(self.sys.hhat.par_chunks(BLOCK)).for_each(|((s, v), h)| {
                for ((s, &v), &h) in s.iter_mut().zip(v).zip(h) {
                    *s = v * h;
                }
            });
            self.sys.fft.inverse(&mut self.spec, Some(&self.frame_mask[t]), &mut self.sys.tmp, &mut self.plane);
            for &(i, s) in &self.frame_rows[t] {
                let src = &self.plane[(i + g.off_r) * g.q + g.off_c..(i + g.off_r) * g.q + g.off_c + g.n];
                let o = (i * self.s.slots + s) * g.n;
                self.hv[o..o + g.n].copy_from_slice(src);
            }
            debug_assert_eq!(self.plane.len(), pq);
        }
    }
}

impl<A: Operator + ?Sized> Step for SplitStep<'_, A> {
    fn propose(&mut self, _: usize) -> Objective {
        let g = self.s.g;
        let (pq, f, n, slots) = (g.p * g.q, self.sys.freqs(), g.n, self.s.slots);
        let [mu1, mu2, mu3] = self.mu;
        self.x_old.copy_from_slice(&self.x);
        self.sys.factor(self.mu);

        // Right-hand side in space: mu_nn (w - y3) + mu_tv sum_a w_a D_a^T (u_a - y2_a).
        {
            let (w, y3, u, y2, axes, wts) = (&self.w, &self.y3, &self.u, &self.y2, &self.s.axes, &self.s.wts);
            self.v.par_chunks_mut(pq).enumerate().for_each(|(t, out)| {
                let o = t * pq;
                for ((r, &wv), &yv) in out.iter_mut().zip(&w[o..o + pq]).zip(&y3[o..o + pq]) {
                    *r = mu3 * (wv - yv);
                }
                for ((&a, &wa), (ua, ya)) in axes.iter().zip(wts).zip(u.iter().zip(y2)) {
                    let s = mu2 * wa;
                    let gd = |j: usize| ua[j] - ya[j];
                    match a {
                        0 => {
                            // (D_t^T d)_t = d_{t-1} - d_t (d after the last frame is 0).
                            for (j, oj) in out.iter_mut().enumerate() {
                                let before = if t > 0 { gd(o - pq + j) } else { 0.0 };
                                let here = if t + 1 < g.k { gd(o + j) } else { 0.0 };
                                *oj += s * (before - here);
                            }
                        }
                        1 => {
                            for r in 0..g.p {
                                let rp = (r + g.p - 1) % g.p;
                                for c in 0..g.q {
                                    out[r * g.q + c] += s * (gd(o + rp * g.q + c) - gd(o + r * g.q + c));
                                }
                            }
                        }
                        _ => {
                            for r in 0..g.p {
                                let row = o + r * g.q;
                                for c in 0..g.q {
                                    let cp = if c == 0 { g.q - 1 } else { c - 1 };
                                    out[r * g.q + c] += s * (gd(row + cp) - gd(row + c));
                                }
                            }
                        }
                    }
                }
            });
        }
        // Its spectrum plus mu_data H^T (z - y1): H^T H v_prev + H^T (z - y1 - H v_prev).
        for t in 0..g.k {
            let vh = &mut self.vhat[t * f..(t + 1) * f];
            self.sys.fft.forward(&self.v[t * pq..(t + 1) * pq], None, &mut self.sys.tmp, &mut self.spec);
            let (spec, h2) = (&self.spec, &self.sys.h2);
            vh.par_chunks_mut(BLOCK).zip(spec.par_chunks(BLOCK)).zip(h2.par_chunks(BLOCK)).for_each(|((v, s), h)| {
                for ((v, &s), &h) in v.iter_mut().zip(s).zip(h) {
                    *v = s + *v * (mu1 * h);
                }
            });
            if self.frame_rows[t].is_empty() {
                continue;
            }
            for &(i, s) in &self.frame_rows[t] {
                let o = (i * slots + s) * n;
                let row = &mut self.plane[(i + g.off_r) * g.q..(i + g.off_r + 1) * g.q];
                row.fill(0.0);
                for j in 0..n {
                    row[g.off_c + j] = self.z[o + j] - self.y1[o + j] - self.hv[o + j];
                }
            }
            self.sys.fft.forward(&self.plane, Some(&self.frame_mask[t]), &mut self.sys.tmp, &mut self.spec);
            let (spec, hh) = (&self.spec, &self.sys.hhat);
            vh.par_chunks_mut(BLOCK).zip(spec.par_chunks(BLOCK)).zip(hh.par_chunks(BLOCK)).for_each(|((v, s), h)| {
                for ((v, &s), &h) in v.iter_mut().zip(s).zip(h) {
                    *v += h.conj() * s * mu1;
                }
            });
        }
        // Solve along time, back to space; H v on the seen entries.
        self.sys.sweep(&mut self.vhat);
        for t in 0..g.k {
            self.spec.copy_from_slice(&self.vhat[t * f..(t + 1) * f]);
            self.sys.fft.inverse(&mut self.spec, None, &mut self.sys.tmp, &mut self.v[t * pq..(t + 1) * pq]);
        }
        self.seen_h_v();

        // z: per sensor pixel, Sherman-Morrison; y1 += H v - z.
        let (data, mask) = (self.data, self.mask);
        let (b, lower) = (data.observations(), data.lower_bounds());
        let (row_weights, row_frames) = (&self.s.row_weights, &self.s.row_frames);
        let r1 = self
            .z
            .par_chunks_mut(slots * n)
            .zip(self.y1.par_chunks_mut(slots * n))
            .zip(self.hv.par_chunks(slots * n))
            .enumerate()
            .map(|(i, ((z, y1), hv))| {
                let wr = &row_weights[i * slots..(i + 1) * slots];
                let used = row_frames[i * slots..(i + 1) * slots].iter().filter(|&&t| t != usize::MAX).count();
                let mut acc = [0.0f64; 2];
                for j in 0..n {
                    let px = i * n + j;
                    let mk = mask.map_or(1.0, |mk| mk[px]);
                    let lb = lower.is_some_and(|l| l[px]);
                    // a . r and |a|^2 over the frames this row sees.
                    let (mut ar, mut aa) = (0.0f64, 0.0f64);
                    for s in 0..used {
                        let a = (mk * wr[s]) as f64;
                        ar += a * (hv[s * n + j] + y1[s * n + j]) as f64;
                        aa += a * a;
                    }
                    let gain = pixel_gain(ar, aa, b[px], lb, mu1);
                    for (s, &ws) in wr[..used].iter().enumerate() {
                        let e = s * n + j;
                        let zn = hv[e] + y1[e] + mk * ws * gain;
                        let prim = hv[e] - zn;
                        acc[1] += ((zn - z[e]) as f64).powi(2);
                        acc[0] += (prim as f64).powi(2);
                        z[e] = zn;
                        y1[e] += prim;
                    }
                }
                acc
            })
            .reduce(|| [0.0; 2], |a, b| [a[0] + b[0], a[1] + b[1]]);

        // u: shrink the differences inside the video grid; y2 += D v - u.
        let thr = self.tv.tau / mu2;
        let mut r2 = [0.0f64; 2];
        for ai in 0..self.s.axes.len() {
            let (a, wa) = (self.s.axes[ai], self.s.wts[ai]);
            let v = &self.v;
            let part = self.u[ai]
                .par_chunks_mut(pq)
                .zip(self.y2[ai].par_chunks_mut(pq))
                .enumerate()
                .map(|(t, (u, y))| {
                    let mut acc = [0.0f64; 2];
                    let next = (t + 1 < g.k).then(|| &v[(t + 1) * pq..(t + 2) * pq]);
                    let vt = &v[t * pq..(t + 1) * pq];
                    for r in 0..g.p {
                        for c in 0..g.q {
                            let e = r * g.q + c;
                            let d = diff_at(&g, a, wa, vt, next, r, c);
                            let s = d + y[e];
                            let un = if inside(&g, a, r, c) { soft(s, thr) } else { s };
                            acc[1] += ((un - u[e]) as f64).powi(2);
                            acc[0] += ((d - un) as f64).powi(2);
                            u[e] = un;
                            y[e] += d - un;
                        }
                    }
                    acc
                })
                .reduce(|| [0.0; 2], |a, b| [a[0] + b[0], a[1] + b[1]]);
            r2 = [r2[0] + part[0], r2[1] + part[1]];
        }

        // w: clamp on the video grid, 0 outside; y3 += v - w.
        let nonneg = self.tv.nonneg;
        let v = &self.v;
        let r3 = self
            .w
            .par_chunks_mut(pq)
            .zip(self.y3.par_chunks_mut(pq))
            .enumerate()
            .map(|(t, (w, y))| {
                let mut acc = [0.0f64; 2];
                let vt = &v[t * pq..(t + 1) * pq];
                for r in 0..g.p {
                    for c in 0..g.q {
                        let e = r * g.q + c;
                        let s = vt[e] + y[e];
                        let wn = if r < g.mv && c < g.nv {
                            if nonneg {
                                s.max(0.0)
                            } else {
                                s
                            }
                        } else {
                            0.0
                        };
                        acc[1] += ((wn - w[e]) as f64).powi(2);
                        acc[0] += ((vt[e] - wn) as f64).powi(2);
                        w[e] = wn;
                        y[e] += vt[e] - wn;
                    }
                }
                acc
            })
            .reduce(|| [0.0; 2], |a, b| [a[0] + b[0], a[1] + b[1]]);
        self.residuals = [r1, r2, r3];

        // The iterate: w on the video grid.
        let (mv, nv) = (g.mv, g.nv);
        let w = &self.w;
        self.x.par_chunks_mut(mv * nv).enumerate().for_each(|(t, xt)| {
            for r in 0..mv {
                xt[r * nv..(r + 1) * nv].copy_from_slice(&w[t * pq + r * g.q..t * pq + r * g.q + nv]);
            }
        });
        self.op.forward(&self.x, &mut self.ax);
        Objective { data_term: self.data.value(&self.ax), reg_term: self.tv.value(&self.x) }
    }

    fn proposal(&self) -> &[f32] {
        &self.x
    }

    fn accept(&mut self, it: usize, _: Objective, proposed: Objective) -> Accepted {
        if self.p.balance_every > 0 && it % self.p.balance_every == 0 {
            for (j, res) in self.residuals.into_iter().enumerate() {
                let Some(factor) = self.s.balance(j, self.mu[j], res) else { continue };
                self.mu[j] *= factor;
                let scale_dual = |y: &mut [f32]| y.par_chunks_mut(BLOCK).for_each(|c| c.iter_mut().for_each(|v| *v /= factor));
                match j {
                    0 => scale_dual(&mut self.y1),
                    1 => self.y2.iter_mut().for_each(|y| scale_dual(y)),
                    _ => scale_dual(&mut self.y3),
                }
            }
        }
        Accepted { objective: proposed, rel_change: rel_change(&self.x, &self.x_old, &crate::model::ranks::One) }
    }

    fn abandon(&mut self) {
        self.x.copy_from_slice(&self.x_old);
    }

    fn x(&self) -> &[f32] {
        &self.x
    }

    fn into_x(self) -> Vec<f32> {
        self.x
    }
}
