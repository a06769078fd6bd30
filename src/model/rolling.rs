//! The imaging model `A v = sum_k W[:, k] . crop(h * v_k)`: a video of `K` frames
//! seen through the diffuser and gated row by row by the shutter. `A` is never formed.
//!
//! Evaluation (the row path of [`Conv2d`]): frame `k` touches only the sensor rows of
//! its shutter weights (about `2 N_l` rows for a dual shutter), so each frame's rows are
//! transformed along `x` only and the `y` direction is a direct sum over the video rows
//! for those sensor rows. The forward sums the weighted row spectra of all frames and
//! transforms each sensor row back once; the adjoint transforms each sensor row once,
//! then builds every frame from the spectra of its rows.
//!
//! Work is split into fixed chunks of consecutive frames (a few per thread); the
//! forward adds the chunks' partial spectra in chunk order, so results do not depend on
//! thread timing. All buffers live in the model and are reused: no allocation per call
//! once the first call has sized them. [`RollingShutterModel::forward_reference`] and
//! [`RollingShutterModel::adjoint_reference`] keep the straightforward 2D-FFT path,
//! against which the fast one is tested.

use crate::model::capture::Fov;
use crate::model::conv::{Conv2d, ConvScratch, RowScratch};
use crate::model::op::{Operator, ShutterConvolution};
use crate::model::shutter::ShutterWeights;
use rayon::prelude::*;
use std::borrow::Cow;
use std::sync::{Arc, Mutex, OnceLock};

/// Sensor rows and weights of every frame, flattened.
struct FramePlan {
    /// `rows[start[k]..start[k+1]]`: sensor rows of frame `k` (ascending).
    rows: Vec<usize>,
    /// The matching weights `W[row, k]`.
    w: Vec<f32>,
    start: Vec<usize>,
    /// Most rows of any frame.
    max_rows: usize,
}

impl FramePlan {
    fn new(weights: &ShutterWeights) -> Self {
        let (mut rows, mut w, mut start) = (Vec::new(), Vec::new(), vec![0]);
        let mut max_rows = 0;
        for k in 0..weights.frames() {
            for r in weights.rows_of_frame(k) {
                for i in r.clone() {
                    rows.push(i);
                    w.push(weights.get(i, k));
                }
            }
            start.push(rows.len());
            max_rows = max_rows.max(start[k + 1] - start[k]);
        }
        FramePlan { rows, w, start, max_rows }
    }
    fn frame(&self, k: usize) -> (&[usize], &[f32]) {
        let r = self.start[k]..self.start[k + 1];
        (&self.rows[r.clone()], &self.w[r])
    }
}

/// One chunk's thread buffers: FFT rows and the spectra of one frame's rows
/// (`max_rows x qcp` each, at least one row).
struct ChunkScratch {
    s: RowScratch,
    fr: Vec<f32>,
    fi: Vec<f32>,
    /// One sensor row times the mask (adjoint of a masked model), `N`.
    masked_row: Vec<f32>,
}

/// One chunk's partial sums of the sensor-row spectra (forward), `M x qcp` each;
/// `touched[i]` marks rows that hold data.
#[derive(Default)]
struct ChunkAcc {
    re: Vec<f32>,
    im: Vec<f32>,
    touched: Vec<bool>,
}

/// Buffers reused across calls.
#[derive(Default)]
struct Work {
    scratch: Vec<ChunkScratch>,
    acc: Vec<ChunkAcc>,
    /// Spectra of every sensor row (adjoint), `M x qcp` each.
    y_re: Vec<f32>,
    y_im: Vec<f32>,
}

/// `A` for one colour channel.
pub struct RollingShutterModel {
    conv: Conv2d,
    weights: ShutterWeights,
    plan: FramePlan,
    work: Mutex<Work>,
    /// Reusable FFT buffers of the reference path.
    pool: Mutex<Vec<ConvScratch>>,
    /// The data term's sensor mask `M` (1 used, 0 left out), row-major on the sensor:
    /// the operator is then `M A` (a defective or clipped pixel explains nothing).
    mask: Option<Arc<[f32]>>,
    /// The still form's row gains ([`RollingShutterModel::still_gains`]), made on
    /// first use.
    still: OnceLock<StillGains>,
}

/// The still form of a shutter convolution ([`crate::model::still`]): `A (1 ⊗ s) = G .
/// crop(h * s)` with `G` the row gain (`g_i = sum_k W[i, k]`) times the mask.
pub(crate) struct StillGains {
    /// Row gain times the mask, per sensor pixel (row-major).
    gain: Vec<f32>,
    /// Sensor rows with a non-zero gain.
    rows: Vec<std::ops::Range<usize>>,
}

impl RollingShutterModel {
    /// The operator of a `rows x cols` PSF (the sensor's size) on the video grid `fov`
    /// under `weights`: the one place the field of view picks the convolution.
    pub fn of_psf(psf: &[f32], rows: usize, cols: usize, fov: Fov, weights: ShutterWeights) -> Self {
        let conv = match fov {
            Fov::Sensor => Conv2d::sensor(psf, rows, cols),
            Fov::Full => Conv2d::full(psf, rows, cols),
        };
        RollingShutterModel::new(conv, weights)
    }

    /// `conv` fixes the PSF and the video grid; `weights` must have the sensor's rows.
    pub fn new(conv: Conv2d, weights: ShutterWeights) -> Self {
        assert_eq!(conv.sensor_shape().0, weights.rows(), "shutter weights must have one row per sensor row");
        let plan = FramePlan::new(&weights);
        RollingShutterModel { conv, weights, plan, work: Mutex::new(Work::default()), pool: Mutex::new(Vec::new()), mask: None, still: OnceLock::new() }
    }

    /// The same shutter, video grid and mask with another PSF of the sensor's size
    /// (row-major, centre pixel `(M/2, N/2)`): the fit report's PSF orientation check.
    ///
    /// # Panics
    /// When `psf` does not have one entry per sensor pixel.
    pub fn with_psf(&self, psf: &[f32]) -> RollingShutterModel {
        let (m, n) = self.conv.sensor_shape();
        let (mv, nv) = self.conv.video_shape();
        let (off_r, off_c) = self.conv.offset();
        let conv = Conv2d::new(psf, m, n, mv, nv, off_r, off_c);
        RollingShutterModel::new(conv, self.weights.clone()).with_mask(self.mask.clone())
    }

    /// The operator `M A`: sensor pixels where `mask` is 0 are left out (forward gives
    /// 0 there, the adjoint ignores them). `None` keeps every pixel.
    ///
    /// # Panics
    /// When the mask does not have one entry per sensor pixel.
    pub fn with_mask(mut self, mask: Option<Arc<[f32]>>) -> Self {
        if let Some(m) = &mask {
            let (r, c) = self.conv.sensor_shape();
            assert_eq!(m.len(), r * c, "the mask must have one entry per sensor pixel");
        }
        self.mask = mask;
        self.still = OnceLock::new();
        self
    }

    /// The row gains of the still form, times the mask.
    fn still_gains(&self) -> &StillGains {
        self.still.get_or_init(|| {
            let (m, n) = self.conv.sensor_shape();
            let mut gain = Vec::with_capacity(m * n);
            for i in 0..m {
                let g = self.weights.row_total(i) as f32;
                match self.mask() {
                    Some(mask) => gain.extend(mask[i * n..(i + 1) * n].iter().map(|&k| g * k)),
                    None => gain.extend(std::iter::repeat(g).take(n)),
                }
            }
            let mut rows: Vec<std::ops::Range<usize>> = Vec::new();
            for i in (0..m).filter(|&i| gain[i * n..(i + 1) * n].iter().any(|&v| v != 0.0)) {
                match rows.last_mut() {
                    Some(r) if r.end == i => r.end = i + 1,
                    _ => rows.push(i..i + 1),
                }
            }
            StillGains { gain, rows }
        })
    }

    /// The operator `M A` of a prepared capture's mask; its clipped pixels are the data
    /// term's ([`crate::model::data::DataTerm::with_lower_bounds`]).
    pub fn with_data_mask(self, m: &crate::model::mask::DataMask) -> Self {
        self.with_mask(m.mask.as_deref().map(Arc::from))
    }

    /// The data term's sensor mask, when pixels are left out.
    pub fn mask(&self) -> Option<&[f32]> {
        self.mask.as_deref()
    }

    /// `y *= M` (the reference paths; the fast ones mask row by row).
    fn apply_mask(&self, y: &mut [f32]) {
        if let Some(m) = &self.mask {
            y.iter_mut().zip(m.iter()).for_each(|(v, &k)| *v *= k);
        }
    }

    /// `M y` (the reference paths).
    fn masked<'y>(&self, y: &'y [f32]) -> Cow<'y, [f32]> {
        match &self.mask {
            None => Cow::Borrowed(y),
            Some(m) => Cow::Owned(y.iter().zip(m.iter()).map(|(&v, &k)| v * k).collect()),
        }
    }

    pub fn frames(&self) -> usize {
        self.weights.frames()
    }
    pub fn weights(&self) -> &ShutterWeights {
        &self.weights
    }
    pub fn conv(&self) -> &Conv2d {
        &self.conv
    }
    /// (frames, rows, cols) of the video.
    pub fn video_shape(&self) -> (usize, usize, usize) {
        let (mv, nv) = self.conv.video_shape();
        (self.weights.frames(), mv, nv)
    }

    /// Each frame's sensitivity `||A P_k||_F^2`, `P_k` the embedding of frame `k`: the
    /// total squared gain from the frame's pixels to the sensor. It is
    /// `sum_i W[i, k]^2 E_i`, with `E_i` the energy sensor row `i` receives from a video
    /// of ones through the squared PSF (`|h|^2 * 1`, cropped), so one convolution gives
    /// every frame's. Frames that only the outer rows of a dual shutter see, or that a
    /// partial exposure cuts short, have a small value: the data constrain them less and
    /// their reconstruction leans on the regulariser. `psf` must be the `M x N` PSF the
    /// model's convolution was planned with.
    pub fn frame_sensitivity(&self, psf: &[f32]) -> Vec<f64> {
        let squared: Vec<f32> = psf.iter().map(|v| v * v).collect();
        self.rows_through_frames(&squared, 2)
    }

    /// Each frame's exposure light `||A P_k 1||_1`: the light a uniform frame `k` of ones
    /// puts on the sensor, `sum_i W[i, k] L_i` with `L_i` what sensor row `i` receives
    /// from a video of ones through the PSF (`h * 1`, cropped; negative PSF values count
    /// as zero). A frame few rows see, or see briefly, collects few photons: its share
    /// of the signal, where [`Self::frame_sensitivity`] is its share of the squared gain.
    pub fn frame_light(&self, psf: &[f32]) -> Vec<f64> {
        let positive: Vec<f32> = psf.iter().map(|v| v.max(0.0)).collect();
        self.rows_through_frames(&positive, 1)
    }

    /// `sum_i W[i, k]^power R_i` per frame `k`, with `R_i` what sensor row `i` receives
    /// from a video of ones through `kernel` (cropped; negative sums count as zero).
    fn rows_through_frames(&self, kernel: &[f32], power: i32) -> Vec<f64> {
        let (m, n) = self.conv.sensor_shape();
        let (mv, nv) = self.conv.video_shape();
        let (off_r, off_c) = self.conv.offset();
        let conv = Conv2d::new(kernel, m, n, mv, nv, off_r, off_c);
        let through = conv.apply(&vec![1.0f32; mv * nv], &mut conv.scratch());
        let per_row: Vec<f64> = through.chunks(n).map(|row| row.iter().map(|&v| (v as f64).max(0.0)).sum()).collect();
        (0..self.frames())
            .map(|k| self.weights.rows_of_frame(k).iter().flat_map(|r| r.clone()).map(|i| (self.weights.get(i, k) as f64).powi(power) * per_row[i]).sum())
            .collect()
    }

    /// Bytes of the buffers the fast path keeps between calls (for `threads` threads).
    pub fn work_bytes(&self, threads: usize) -> usize {
        let (m, _) = self.conv.sensor_shape();
        let w = self.conv.spectrum_width();
        let chunks = Self::chunk_count(self.frames(), threads);
        let per_chunk = 4 * (2 * self.plan.max_rows * w + 2 * m * w) + m;
        chunks * per_chunk + 4 * 2 * m * w
    }

    /// Chunks of consecutive frames: a few per thread, for balance.
    fn chunk_count(frames: usize, threads: usize) -> usize {
        (4 * threads.max(1)).clamp(1, frames.max(1))
    }

    /// Run `f` on the reusable buffers, with at least `chunks` chunk scratches (a
    /// second concurrent caller gets fresh buffers rather than waiting).
    fn with_work<R>(&self, chunks: usize, f: impl FnOnce(&mut Work) -> R) -> R {
        let w = self.conv.spectrum_width();
        let mut local;
        let mut guard = self.work.try_lock().ok();
        let work: &mut Work = match guard.as_deref_mut() {
            Some(wk) => wk,
            None => {
                local = Work::default();
                &mut local
            }
        };
        while work.scratch.len() < chunks {
            let rows = self.plan.max_rows.max(1);
            let n = self.conv.sensor_shape().1;
            work.scratch.push(ChunkScratch { s: self.conv.row_scratch(), fr: vec![0.0; rows * w], fi: vec![0.0; rows * w], masked_row: vec![0.0; n] });
        }
        f(work)
    }

    fn with_scratch<R>(&self, f: impl FnOnce(&mut ConvScratch) -> R) -> R {
        let mut s = self.pool.lock().unwrap().pop().unwrap_or_else(|| self.conv.scratch());
        let r = f(&mut s);
        self.pool.lock().unwrap().push(s);
        r
    }

    /// `y = A x` by the straightforward path: a full 2D FFT convolution per frame
    /// (reference for tests and benchmarks).
    pub fn forward_reference(&self, x: &[f32], y: &mut [f32]) {
        let (k, mv, nv) = self.video_shape();
        let (_, n) = self.conv.sensor_shape();
        let frame_len = mv * nv;
        assert_eq!(x.len(), k * frame_len);
        let chunks = rayon::current_num_threads().clamp(1, k);
        let per = k.div_ceil(chunks);
        let partials: Vec<Vec<f32>> = (0..chunks)
            .into_par_iter()
            .map(|c| {
                let mut acc = vec![0.0f32; y.len()];
                self.with_scratch(|s| {
                    for f in c * per..((c + 1) * per).min(k) {
                        let rows = self.weights.rows_of_frame(f);
                        if rows.is_empty() {
                            continue;
                        }
                        self.conv.forward_rows(&x[f * frame_len..(f + 1) * frame_len], rows, s, |i, row| {
                            let w = self.weights.get(i, f);
                            for (a, &v) in acc[i * n..(i + 1) * n].iter_mut().zip(row) {
                                *a += w * v;
                            }
                        });
                    }
                });
                acc
            })
            .collect();
        y.fill(0.0);
        for p in &partials {
            for (a, b) in y.iter_mut().zip(p) {
                *a += b;
            }
        }
        self.apply_mask(y);
    }

    /// `x = A^T y` by the straightforward path (reference for tests and benchmarks).
    pub fn adjoint_reference(&self, y: &[f32], x: &mut [f32]) {
        let (k, mv, nv) = self.video_shape();
        let (_, n) = self.conv.sensor_shape();
        assert_eq!(x.len(), k * mv * nv);
        let y = &*self.masked(y);
        x.par_chunks_mut(mv * nv).enumerate().for_each(|(f, xf)| {
            let rows = self.weights.rows_of_frame(f);
            if rows.is_empty() {
                xf.fill(0.0);
                return;
            }
            self.with_scratch(|s| {
                self.conv.adjoint_rows(
                    rows,
                    s,
                    |i, row| {
                        let w = self.weights.get(i, f);
                        for (r, &v) in row.iter_mut().zip(&y[i * n..(i + 1) * n]) {
                            *r = w * v;
                        }
                    },
                    xf,
                );
            });
        });
    }
}

impl Operator for RollingShutterModel {
    fn shutter_convolution(&self) -> Option<ShutterConvolution<'_>> {
        Some(ShutterConvolution { conv: &self.conv, weights: &self.weights, mask: self.mask() })
    }
    /// One convolution of `s`, scaled per row by the row gain (and the mask).
    fn forward_still(&self, s: &[f32], y: &mut [f32]) -> bool {
        let n = self.conv.sensor_shape().1;
        let g = self.still_gains();
        y.fill(0.0);
        self.with_scratch(|sc| {
            self.conv.forward_rows(s, &g.rows, sc, |i, row| {
                for ((o, &v), &w) in y[i * n..(i + 1) * n].iter_mut().zip(row).zip(&g.gain[i * n..(i + 1) * n]) {
                    *o = w * v;
                }
            })
        });
        true
    }
    fn adjoint_still(&self, y: &[f32], s: &mut [f32]) -> bool {
        let n = self.conv.sensor_shape().1;
        let g = self.still_gains();
        self.with_scratch(|sc| {
            self.conv.adjoint_rows(
                &g.rows,
                sc,
                |i, row| {
                    for ((o, &v), &w) in row.iter_mut().zip(&y[i * n..(i + 1) * n]).zip(&g.gain[i * n..(i + 1) * n]) {
                        *o = w * v;
                    }
                },
                s,
            )
        });
        true
    }
    fn input_shape(&self) -> Vec<usize> {
        let (k, mv, nv) = self.video_shape();
        vec![k, mv, nv]
    }
    fn output_shape(&self) -> Vec<usize> {
        let (m, n) = self.conv.sensor_shape();
        vec![m, n]
    }

    fn forward(&self, x: &[f32], y: &mut [f32]) {
        let (k, mv, nv) = self.video_shape();
        let (m, n) = self.conv.sensor_shape();
        let frame_len = mv * nv;
        assert_eq!(x.len(), k * frame_len);
        assert_eq!(y.len(), m * n);
        let mask = self.mask.as_deref();
        let w = self.conv.spectrum_width();
        let nch = Self::chunk_count(k, rayon::current_num_threads());
        let per = k.div_ceil(nch);
        let (conv, plan) = (&self.conv, &self.plan);
        self.with_work(nch, |work| {
            while work.acc.len() < nch {
                work.acc.push(ChunkAcc::default());
            }
            let (accs, scratch) = (&mut work.acc[..nch], &mut work.scratch[..nch]);
            // 1. Each chunk sums the weighted row spectra of its frames.
            accs.par_iter_mut().zip(scratch.par_iter_mut()).enumerate().for_each(|(c, (acc, sc))| {
                if acc.re.len() < m * w {
                    acc.re = vec![0.0; m * w];
                    acc.im = vec![0.0; m * w];
                    acc.touched = vec![false; m];
                }
                for i in 0..m {
                    if acc.touched[i] {
                        acc.re[i * w..(i + 1) * w].fill(0.0);
                        acc.im[i * w..(i + 1) * w].fill(0.0);
                        acc.touched[i] = false;
                    }
                }
                for f in c * per..((c + 1) * per).min(k) {
                    let (rows, wts) = plan.frame(f);
                    if rows.is_empty() {
                        continue;
                    }
                    conv.forward_spectra(&x[f * frame_len..(f + 1) * frame_len], rows, &mut sc.s, &mut sc.fr, &mut sc.fi);
                    for (j, (&i, &wt)) in rows.iter().zip(wts).enumerate() {
                        axpy(&mut acc.re[i * w..(i + 1) * w], wt, &sc.fr[j * w..(j + 1) * w]);
                        axpy(&mut acc.im[i * w..(i + 1) * w], wt, &sc.fi[j * w..(j + 1) * w]);
                        acc.touched[i] = true;
                    }
                }
            });
            // 2. Per sensor row, the chunks' sums in chunk order, then back to space.
            let accs = &*accs;
            let band = m.div_ceil(nch);
            y.par_chunks_mut(band * n).zip(scratch.par_iter_mut()).enumerate().for_each(|(b, (yb, sc))| {
                for (r, yrow) in yb.chunks_mut(n).enumerate() {
                    let i = b * band + r;
                    let (sr, si) = (&mut sc.fr[..w], &mut sc.fi[..w]);
                    let mut any = false;
                    for acc in accs.iter().filter(|a| a.touched[i]) {
                        if any {
                            axpy(sr, 1.0, &acc.re[i * w..(i + 1) * w]);
                            axpy(si, 1.0, &acc.im[i * w..(i + 1) * w]);
                        } else {
                            sr.copy_from_slice(&acc.re[i * w..(i + 1) * w]);
                            si.copy_from_slice(&acc.im[i * w..(i + 1) * w]);
                            any = true;
                        }
                    }
                    if any {
                        conv.sensor_row_from_spectrum(sr, si, &mut sc.s, yrow);
                        if let Some(mk) = mask {
                            yrow.iter_mut().zip(&mk[i * n..(i + 1) * n]).for_each(|(v, &k)| *v *= k);
                        }
                    } else {
                        yrow.fill(0.0);
                    }
                }
            });
        });
    }

    fn adjoint(&self, y: &[f32], x: &mut [f32]) {
        let (k, mv, nv) = self.video_shape();
        let (m, n) = self.conv.sensor_shape();
        let frame_len = mv * nv;
        assert_eq!(x.len(), k * frame_len);
        assert_eq!(y.len(), m * n);
        let mask = self.mask.as_deref();
        let w = self.conv.spectrum_width();
        let nch = Self::chunk_count(k, rayon::current_num_threads());
        let per = k.div_ceil(nch);
        let (conv, plan) = (&self.conv, &self.plan);
        self.with_work(nch, |work| {
            if work.y_re.len() < m * w {
                work.y_re = vec![0.0; m * w];
                work.y_im = vec![0.0; m * w];
            }
            let scratch = &mut work.scratch[..nch];
            // 1. The x-spectrum of every sensor row, rows in bands.
            let band = m.div_ceil(nch);
            work.y_re[..m * w].par_chunks_mut(band * w).zip(work.y_im[..m * w].par_chunks_mut(band * w)).zip(scratch.par_iter_mut()).enumerate().for_each(
                |(b, ((re, im), sc))| {
                    for (r, (re, im)) in re.chunks_mut(w).zip(im.chunks_mut(w)).enumerate() {
                        let i = b * band + r;
                        let row = &y[i * n..(i + 1) * n];
                        let row = match mask {
                            None => row,
                            Some(mk) => {
                                sc.masked_row.iter_mut().zip(row).zip(&mk[i * n..(i + 1) * n]).for_each(|((o, &v), &k)| *o = v * k);
                                &sc.masked_row[..]
                            }
                        };
                        conv.sensor_row_spectrum(row, &mut sc.s, re, im);
                    }
                },
            );
            // 2. Every frame from the weighted spectra of its rows.
            let (y_re, y_im) = (&work.y_re[..], &work.y_im[..]);
            x.par_chunks_mut(per * frame_len).zip(scratch.par_iter_mut()).enumerate().for_each(|(c, (xc, sc))| {
                for (fl, xf) in xc.chunks_mut(frame_len).enumerate() {
                    let f = c * per + fl;
                    let (rows, wts) = plan.frame(f);
                    if rows.is_empty() {
                        xf.fill(0.0);
                        continue;
                    }
                    for (j, (&i, &wt)) in rows.iter().zip(wts).enumerate() {
                        scale_into(&mut sc.fr[j * w..(j + 1) * w], wt, &y_re[i * w..(i + 1) * w]);
                        scale_into(&mut sc.fi[j * w..(j + 1) * w], wt, &y_im[i * w..(i + 1) * w]);
                    }
                    conv.adjoint_from_spectra(rows, &sc.fr, &sc.fi, &mut sc.s, xf);
                }
            });
        });
    }
}

#[inline]
fn axpy(y: &mut [f32], a: f32, x: &[f32]) {
    for (p, &q) in y.iter_mut().zip(x) {
        *p += a * q;
    }
}

#[inline]
fn scale_into(y: &mut [f32], a: f32, x: &[f32]) {
    for (p, &q) in y.iter_mut().zip(x) {
        *p = a * q;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::op::{adjoint_mismatch, pseudo_random, Dense};
    use crate::model::shutter::{ShutterMode, Timing};

    fn model(m: usize, n: usize, mode: ShutterMode, full: bool) -> RollingShutterModel {
        let psf = pseudo_random(m * n, 11);
        let t = Timing::new(m, 10.0, 25.0, mode);
        let conv = if full { Conv2d::full(&psf, m, n) } else { Conv2d::sensor(&psf, m, n) };
        RollingShutterModel::new(conv, t.weights().unwrap())
    }

    #[test]
    fn a_masked_operator_is_m_a_and_its_adjoint_holds() {
        for mode in [ShutterMode::Dual, ShutterMode::Rolling] {
            let (m, n) = (9, 8);
            let mask: Vec<f32> = (0..m * n).map(|i| if i % 7 == 3 || i / n == 4 { 0.0 } else { 1.0 }).collect();
            let plain = model(m, n, mode, false);
            let a = model(m, n, mode, true).with_mask(Some(mask.clone().into()));
            let b = model(m, n, mode, false).with_mask(Some(mask.clone().into()));
            for op in [&a, &b] {
                let x = pseudo_random(op.input_len(), 3);
                let y = pseudo_random(op.output_len(), 4);
                assert!(adjoint_mismatch(op, &x, &y) < 1e-5);
                let mut r1 = vec![0.0; op.output_len()];
                let mut r2 = vec![0.0; op.output_len()];
                op.forward(&x, &mut r1);
                op.forward_reference(&x, &mut r2);
                assert!(r1.iter().zip(&r2).all(|(p, q)| (p - q).abs() < 1e-4));
                let (mut a1, mut a2) = (vec![0.0; op.input_len()], vec![0.0; op.input_len()]);
                op.adjoint(&y, &mut a1);
                op.adjoint_reference(&y, &mut a2);
                assert!(a1.iter().zip(&a2).all(|(p, q)| (p - q).abs() < 1e-4));
            }
            // M A x is A x with the masked pixels zeroed; A^T M y ignores them.
            let x = pseudo_random(b.input_len(), 5);
            let (mut full, mut masked) = (vec![0.0; m * n], vec![0.0; m * n]);
            plain.forward(&x, &mut full);
            b.forward(&x, &mut masked);
            for i in 0..m * n {
                assert_eq!(masked[i], full[i] * mask[i]);
            }
            let mut y = pseudo_random(m * n, 6);
            let mut at1 = vec![0.0; b.input_len()];
            b.adjoint(&y, &mut at1);
            for (v, &k) in y.iter_mut().zip(&mask) {
                if k == 0.0 {
                    *v = 1e6;
                }
            }
            let mut at2 = vec![0.0; b.input_len()];
            b.adjoint(&y, &mut at2);
            assert_eq!(at1, at2, "values under the mask never reach the adjoint");
            // The Lipschitz constant of M A is at most A's (a sub-operator).
            let (la, lm) = (Dense::from_operator(&plain).gram_lambda_max(), Dense::from_operator(&b).gram_lambda_max());
            assert!(lm <= la * (1.0 + 1e-9) && lm > 0.5 * la, "{lm} vs {la}");
        }
    }

    #[test]
    fn adjoint_dot_product_every_mode_odd_and_even_sizes() {
        for mode in ShutterMode::ALL {
            for (m, n) in [(8, 6), (7, 9), (1, 4), (2, 3)] {
                for full in [false, true] {
                    let a = model(m, n, mode, full);
                    let x = pseudo_random(a.input_len(), 1);
                    let y = pseudo_random(a.output_len(), 2);
                    let e = adjoint_mismatch(&a, &x, &y);
                    assert!(e < 1e-5, "{mode} {m}x{n} full={full}: {e}");
                }
            }
        }
    }

    #[test]
    fn frame_sensitivity_is_the_squared_norm_of_each_frames_columns() {
        // ||A P_k||_F^2 = sum over frame k's pixels p of ||A e_p||^2, column by column.
        for mode in ShutterMode::ALL {
            for (m, n) in [(8, 6), (7, 9), (2, 3)] {
                for full in [false, true] {
                    let psf = pseudo_random(m * n, 11);
                    let a = model(m, n, mode, full);
                    let (k, mv, nv) = a.video_shape();
                    let got = a.frame_sensitivity(&psf);
                    assert_eq!(got.len(), k);
                    let (mut e, mut y) = (vec![0.0f32; a.input_len()], vec![0.0f32; a.output_len()]);
                    for f in 0..k {
                        let mut want = 0.0f64;
                        for p in 0..mv * nv {
                            e[f * mv * nv + p] = 1.0;
                            a.forward_reference(&e, &mut y);
                            e[f * mv * nv + p] = 0.0;
                            want += y.iter().map(|&v| (v as f64).powi(2)).sum::<f64>();
                        }
                        let rel = (got[f] - want).abs() / want.max(1e-12);
                        assert!(rel < 1e-4, "{mode} {m}x{n} full={full} frame {f}: {} against {want}", got[f]);
                    }
                }
            }
        }
    }

    #[test]
    fn static_scene_gives_exposure_ratio_times_convolution() {
        let (m, n) = (6, 5);
        let a = model(m, n, ShutterMode::Dual, false);
        let (k, _, _) = a.video_shape();
        let frame = pseudo_random(m * n, 3);
        let x: Vec<f32> = (0..k).flat_map(|_| frame.iter().cloned()).collect();
        let mut y = vec![0.0; m * n];
        a.forward(&x, &mut y);
        let c = a.conv().apply(&frame, &mut a.conv().scratch());
        for (yi, ci) in y.iter().zip(&c) {
            assert!((yi - 2.5 * ci).abs() < 1e-4 * ci.abs().max(1.0), "{yi} vs {}", 2.5 * ci);
        }
    }

    #[test]
    fn forward_matches_dense_reference_built_from_weights() {
        // Build A from its definition: sum_k W[:,k] . conv(v_k), column by column.
        let (m, n) = (4, 3);
        let a = model(m, n, ShutterMode::Rolling, false);
        let dense = Dense::from_operator(&a);
        let psf = pseudo_random(m * n, 11);
        let w = a.weights();
        let (k, _, _) = a.video_shape();
        for f in 0..k {
            for p in 0..m * n {
                let mut v = vec![0.0; m * n];
                v[p] = 1.0;
                let c = crate::model::conv::conv_direct(&psf, m, n, &v, m, n, (0, 0));
                for i in 0..m {
                    for j in 0..n {
                        let expect = w.get(i, f) * c[i * n + j];
                        let got = dense.a[(i * n + j) * dense.cols + f * m * n + p];
                        assert!((got - expect).abs() < 1e-5, "frame {f} pixel {p} -> ({i},{j})");
                    }
                }
            }
        }
    }

    fn max_rel(a: &[f32], b: &[f32]) -> f32 {
        let scale = b.iter().fold(0.0f32, |m, x| m.max(x.abs()));
        a.iter().zip(b).fold(0.0f32, |m, (x, y)| m.max((x - y).abs())) / scale
    }

    fn timing(m: usize, mode: ShutterMode, lt: f64, ex: f64, d: usize, b: usize) -> Timing {
        let mut t = Timing::new(m * d, lt, ex, mode);
        t.downsample = d;
        t.binning = b;
        t
    }

    #[test]
    fn fast_path_equals_the_2d_fft_reference() {
        // Every shutter mode, odd and even sizes, sensor and full field of view,
        // fractional weights (downsampling, binning, non-integer exposure).
        let cases = [(8, 6, 1, 1, 25.0), (7, 9, 1, 1, 30.0), (12, 10, 2, 1, 35.0), (9, 5, 1, 2, 40.0), (16, 20, 1, 1, 10.0), (1, 4, 1, 1, 20.0)];
        for mode in ShutterMode::ALL {
            for &(m, n, d, b, ex) in &cases {
                for full in [false, true] {
                    let psf = pseudo_random(m * n, 13);
                    let conv = if full { Conv2d::full(&psf, m, n) } else { Conv2d::sensor(&psf, m, n) };
                    let a = RollingShutterModel::new(conv, timing(m, mode, 10.0, ex, d, b).weights().unwrap());
                    let x = pseudo_random(a.input_len(), 5);
                    let (mut fast, mut slow) = (vec![f32::NAN; a.output_len()], vec![0.0; a.output_len()]);
                    a.forward(&x, &mut fast);
                    a.forward_reference(&x, &mut slow);
                    let e = max_rel(&fast, &slow);
                    assert!(e < 1e-5, "forward {mode} {m}x{n} d={d} b={b} full={full}: {e}");
                    let y = pseudo_random(a.output_len(), 6);
                    let (mut fast, mut slow) = (vec![f32::NAN; a.input_len()], vec![0.0; a.input_len()]);
                    a.adjoint(&y, &mut fast);
                    a.adjoint_reference(&y, &mut slow);
                    let e = max_rel(&fast, &slow);
                    assert!(e < 1e-5, "adjoint {mode} {m}x{n} d={d} b={b} full={full}: {e}");
                }
            }
        }
    }

    #[test]
    fn repeated_calls_reuse_buffers_without_stale_data() {
        // A second call with different data must not see the first call's sums, and
        // the same input must give the same output bit for bit.
        let a = model(10, 7, ShutterMode::Dual, true);
        let x1 = pseudo_random(a.input_len(), 1);
        let x2: Vec<f32> = pseudo_random(a.input_len(), 2).iter().map(|v| v * 3.0 - 1.0).collect();
        let (mut y1, mut y2, mut y1b, mut r2) = (vec![0.0; a.output_len()], vec![0.0; a.output_len()], vec![0.0; a.output_len()], vec![0.0; a.output_len()]);
        a.forward(&x1, &mut y1);
        a.forward(&x2, &mut y2);
        a.forward(&x1, &mut y1b);
        a.forward_reference(&x2, &mut r2);
        assert_eq!(y1, y1b);
        assert!(max_rel(&y2, &r2) < 1e-5);
        let (mut g1, mut g2) = (vec![0.0; a.input_len()], vec![0.0; a.input_len()]);
        a.adjoint(&y2, &mut g1);
        a.adjoint(&y1, &mut g2);
        a.adjoint(&y2, &mut g2);
        assert_eq!(g1, g2);
    }

    #[test]
    fn results_do_not_depend_on_the_thread_count() {
        let a = model(12, 9, ShutterMode::Dual, false);
        let x = pseudo_random(a.input_len(), 3);
        let y = pseudo_random(a.output_len(), 4);
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| {
                let (mut ax, mut aty) = (vec![0.0; a.output_len()], vec![0.0; a.input_len()]);
                a.forward(&x, &mut ax);
                a.adjoint(&y, &mut aty);
                (ax, aty)
            })
        };
        let (f1, b1) = run(1);
        let (f3, b3) = run(3);
        assert!(max_rel(&f1, &f3) < 1e-6 && max_rel(&b1, &b3) < 1e-6);
        // The adjoint is per frame: identical whatever the split.
        assert_eq!(b1, b3);
    }
}
