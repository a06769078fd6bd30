//! Linear 2D convolution with a PSF through zero-padded real FFTs, evaluated only on
//! the sensor rows that are asked for.
//!
//! Geometry: the PSF `h` has the sensor's size `M x N` and its centre pixel is
//! `(M/2, N/2)`. A video pixel `(p, q)` of an `Mv x Nv` grid maps to sensor
//! coordinates `(p - off_r, q - off_c)`; a point source there puts the PSF's centre on
//! that sensor pixel:
//!
//! `y[i, j] = sum_{p,q} h[i + off_r - p + M/2, j + off_c - q + N/2] v[p, q]`
//!
//! (terms with the PSF index outside `[0,M) x [0,N)` are zero: linear, not circular,
//! convolution). The circular convolution of size `P x Q` with `P >= Mv + M - 1`,
//! `Q >= Nv + N - 1` computes it exactly.
//!
//! Spectra are stored transposed (`Q/2+1` columns of length `P`) so that the FFTs
//! along rows of the image (the `y` direction) run on contiguous memory.

use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};
use rustfft::num_complex::Complex32;
use rustfft::{Fft, FftPlanner};
use std::ops::Range;
use std::sync::Arc;

/// Smallest `n' >= n` whose only prime factors are 2, 3 and 5 (and even when `even`).
pub fn fft_size(n: usize, even: bool) -> usize {
    let mut m = n.max(1);
    loop {
        let mut r = m;
        for f in [2, 3, 5] {
            while r % f == 0 {
                r /= f;
            }
        }
        if r == 1 && (!even || m % 2 == 0) {
            return m;
        }
        m += 1;
    }
}

/// A planned convolution with one PSF.
pub struct Conv2d {
    m: usize,
    n: usize,
    mv: usize,
    nv: usize,
    off_r: usize,
    off_c: usize,
    p: usize,
    q: usize,
    qc: usize,
    /// PSF spectrum, transposed (qc x p), pre-scaled by 1/(P Q).
    h_t: Vec<Complex32>,
    r2c: Arc<dyn RealToComplex<f32>>,
    c2r: Arc<dyn ComplexToReal<f32>>,
    col_fwd: Arc<dyn Fft<f32>>,
    col_inv: Arc<dyn Fft<f32>>,
}

/// Per-thread buffers for [`Conv2d`]; make one with [`Conv2d::scratch`] and reuse it.
pub struct ConvScratch {
    spec: Vec<Complex32>,
    row: Vec<f32>,
    rowc: Vec<Complex32>,
    fft: Vec<Complex32>,
    rfft: Vec<Complex32>,
}

impl Conv2d {
    /// Plan the convolution of an `Mv x Nv` video grid with `psf` (`M x N`, row-major),
    /// observed on the `M x N` sensor, with the video offset `(off_r, off_c)`.
    pub fn new(psf: &[f32], m: usize, n: usize, mv: usize, nv: usize, off_r: usize, off_c: usize) -> Conv2d {
        assert_eq!(psf.len(), m * n, "PSF must be M x N");
        let p = fft_size(mv + m - 1, false);
        let q = fft_size(nv + n - 1, true);
        let qc = q / 2 + 1;
        let mut rp = RealFftPlanner::<f32>::new();
        let r2c = rp.plan_fft_forward(q);
        let c2r = rp.plan_fft_inverse(q);
        let mut cp = FftPlanner::<f32>::new();
        let col_fwd = cp.plan_fft_forward(p);
        let col_inv = cp.plan_fft_inverse(p);
        assert!(off_r + m <= p && off_c + n <= q, "sensor must lie inside the padded grid");
        let mut conv = Conv2d { m, n, mv, nv, off_r, off_c, p, q, qc, h_t: Vec::new(), r2c, c2r, col_fwd, col_inv };
        // Kernel: hp[a mod P, b mod Q] = h[a + M/2, b + N/2].
        let (cm, cn) = (m / 2, n / 2);
        let mut s = conv.scratch();
        s.spec.fill(Complex32::new(0.0, 0.0));
        for i in 0..m {
            let a = (i as isize - cm as isize).rem_euclid(p as isize) as usize;
            s.row.fill(0.0);
            for j in 0..n {
                let b = (j as isize - cn as isize).rem_euclid(q as isize) as usize;
                s.row[b] = psf[i * n + j];
            }
            conv.r2c.process_with_scratch(&mut s.row, &mut s.rowc, &mut s.rfft).expect("r2c sizes");
            for c in 0..qc {
                s.spec[c * p + a] = s.rowc[c];
            }
        }
        conv.col_fwd.process_with_scratch(&mut s.spec, &mut s.fft);
        let scale = 1.0 / (p * q) as f32;
        conv.h_t = s.spec.iter().map(|z| z * scale).collect();
        conv
    }

    /// Sensor-sized video grid (`Mv = M`, `Nv = N`, no offset).
    pub fn sensor(psf: &[f32], m: usize, n: usize) -> Conv2d {
        Conv2d::new(psf, m, n, m, n, 0, 0)
    }

    /// Full field of view: every scene point whose PSF reaches the sensor,
    /// `(2M-1) x (2N-1)`.
    pub fn full(psf: &[f32], m: usize, n: usize) -> Conv2d {
        Conv2d::new(psf, m, n, 2 * m - 1, 2 * n - 1, m - 1 - m / 2, n - 1 - n / 2)
    }

    pub fn scratch(&self) -> ConvScratch {
        ConvScratch {
            spec: vec![Complex32::new(0.0, 0.0); self.qc * self.p],
            row: vec![0.0; self.q],
            rowc: vec![Complex32::new(0.0, 0.0); self.qc],
            fft: vec![Complex32::new(0.0, 0.0); self.col_fwd.get_inplace_scratch_len().max(self.col_inv.get_inplace_scratch_len())],
            rfft: vec![
                Complex32::new(0.0, 0.0);
                self.r2c.get_scratch_len().max(self.c2r.get_scratch_len())
            ],
        }
    }

    pub fn sensor_shape(&self) -> (usize, usize) {
        (self.m, self.n)
    }
    pub fn video_shape(&self) -> (usize, usize) {
        (self.mv, self.nv)
    }
    pub fn fft_shape(&self) -> (usize, usize) {
        (self.p, self.q)
    }
    /// Offset of the sensor inside the video grid.
    pub fn offset(&self) -> (usize, usize) {
        (self.off_r, self.off_c)
    }

    /// Compute the sensor rows in `rows` of `h * v` (`v` is `Mv x Nv`); `emit(i, row)`
    /// receives each sensor row `i` with its `N` values.
    pub fn forward_rows(&self, v: &[f32], rows: &[Range<usize>], s: &mut ConvScratch, mut emit: impl FnMut(usize, &[f32])) {
        debug_assert_eq!(v.len(), self.mv * self.nv);
        let (p, qc) = (self.p, self.qc);
        s.spec.fill(Complex32::new(0.0, 0.0));
        for r in 0..self.mv {
            let src = &v[r * self.nv..(r + 1) * self.nv];
            s.row[..self.nv].copy_from_slice(src);
            s.row[self.nv..].fill(0.0);
            self.r2c.process_with_scratch(&mut s.row, &mut s.rowc, &mut s.rfft).expect("r2c sizes");
            for c in 0..qc {
                s.spec[c * p + r] = s.rowc[c];
            }
        }
        self.col_fwd.process_with_scratch(&mut s.spec, &mut s.fft);
        for (z, h) in s.spec.iter_mut().zip(&self.h_t) {
            *z *= h;
        }
        self.col_inv.process_with_scratch(&mut s.spec, &mut s.fft);
        for range in rows {
            for i in range.clone() {
                let a = i + self.off_r;
                for c in 0..qc {
                    s.rowc[c] = s.spec[c * p + a];
                }
                self.real_row(s);
                emit(i, &s.row[self.off_c..self.off_c + self.n]);
            }
        }
    }

    /// Adjoint: `x = h ⋆ y` where `y` is non-zero only on the sensor rows in `rows`;
    /// `fill(i, row)` writes sensor row `i` (`N` values). Writes all of `x` (`Mv x Nv`).
    pub fn adjoint_rows(&self, rows: &[Range<usize>], s: &mut ConvScratch, mut fill: impl FnMut(usize, &mut [f32]), x: &mut [f32]) {
        debug_assert_eq!(x.len(), self.mv * self.nv);
        let (p, qc) = (self.p, self.qc);
        s.spec.fill(Complex32::new(0.0, 0.0));
        for range in rows {
            for i in range.clone() {
                s.row.fill(0.0);
                fill(i, &mut s.row[self.off_c..self.off_c + self.n]);
                self.r2c.process_with_scratch(&mut s.row, &mut s.rowc, &mut s.rfft).expect("r2c sizes");
                let a = i + self.off_r;
                for c in 0..qc {
                    s.spec[c * p + a] = s.rowc[c];
                }
            }
        }
        self.col_fwd.process_with_scratch(&mut s.spec, &mut s.fft);
        for (z, h) in s.spec.iter_mut().zip(&self.h_t) {
            *z *= h.conj();
        }
        self.col_inv.process_with_scratch(&mut s.spec, &mut s.fft);
        for r in 0..self.mv {
            for c in 0..qc {
                s.rowc[c] = s.spec[c * p + r];
            }
            self.real_row(s);
            x[r * self.nv..(r + 1) * self.nv].copy_from_slice(&s.row[..self.nv]);
        }
    }

    /// Inverse real FFT of `s.rowc` into `s.row`.
    fn real_row(&self, s: &mut ConvScratch) {
        // The DC (and Nyquist) bins of a real signal are real; round-off leaves a tiny
        // imaginary part that the inverse transform must not see.
        s.rowc[0].im = 0.0;
        s.rowc[self.qc - 1].im = 0.0;
        self.c2r.process_with_scratch(&mut s.rowc, &mut s.row, &mut s.rfft).expect("c2r sizes");
    }

    /// Whole-image convolution (all sensor rows), convenience for simulation and tests.
    pub fn apply(&self, v: &[f32], s: &mut ConvScratch) -> Vec<f32> {
        let mut out = vec![0.0; self.m * self.n];
        self.forward_rows(v, &[0..self.m], s, |i, row| out[i * self.n..(i + 1) * self.n].copy_from_slice(row));
        out
    }
}

/// Direct evaluation of the same linear convolution (reference for tests).
pub fn conv_direct(psf: &[f32], m: usize, n: usize, v: &[f32], mv: usize, nv: usize, off: (usize, usize)) -> Vec<f32> {
    let (cm, cn) = ((m / 2) as isize, (n / 2) as isize);
    let mut y = vec![0.0f32; m * n];
    for i in 0..m {
        for j in 0..n {
            let mut acc = 0.0f64;
            for p in 0..mv {
                let a = i as isize + off.0 as isize - p as isize + cm;
                if a < 0 || a >= m as isize {
                    continue;
                }
                for q in 0..nv {
                    let b = j as isize + off.1 as isize - q as isize + cn;
                    if b < 0 || b >= n as isize {
                        continue;
                    }
                    acc += psf[a as usize * n + b as usize] as f64 * v[p * nv + q] as f64;
                }
            }
            y[i * n + j] = acc as f32;
        }
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::op::pseudo_random;

    fn max_rel(a: &[f32], b: &[f32]) -> f32 {
        let scale = b.iter().fold(0.0f32, |m, x| m.max(x.abs()));
        a.iter().zip(b).fold(0.0f32, |m, (x, y)| m.max((x - y).abs())) / scale
    }

    #[test]
    fn fft_sizes_are_smooth() {
        assert_eq!(fft_size(7, false), 8);
        assert_eq!(fft_size(11, false), 12);
        assert_eq!(fft_size(539, false), 540);
        assert_eq!(fft_size(15, true), 16);
        assert_eq!(fft_size(1, true), 2);
    }

    #[test]
    fn matches_direct_convolution_sensor_and_full() {
        for (m, n) in [(5, 7), (6, 4), (1, 5), (2, 2), (9, 8)] {
            let psf = pseudo_random(m * n, 1);
            let v = pseudo_random(m * n, 2);
            let c = Conv2d::sensor(&psf, m, n);
            let fast = c.apply(&v, &mut c.scratch());
            let slow = conv_direct(&psf, m, n, &v, m, n, (0, 0));
            assert!(max_rel(&fast, &slow) < 1e-5, "{m}x{n}: {}", max_rel(&fast, &slow));

            let c = Conv2d::full(&psf, m, n);
            let (mv, nv) = c.video_shape();
            let v = pseudo_random(mv * nv, 3);
            let fast = c.apply(&v, &mut c.scratch());
            let slow = conv_direct(&psf, m, n, &v, mv, nv, c.offset());
            assert!(max_rel(&fast, &slow) < 1e-5, "full {m}x{n}");
        }
    }

    #[test]
    fn point_source_lands_psf_centre_on_its_pixel() {
        let (m, n) = (6, 5);
        let psf: Vec<f32> = (0..m * n).map(|i| i as f32).collect();
        let mut v = vec![0.0; m * n];
        v[3 * n + 2] = 1.0; // (3, 2) == (M/2, N/2): the PSF itself
        let c = Conv2d::sensor(&psf, m, n);
        let y = c.apply(&v, &mut c.scratch());
        assert!(max_rel(&y, &psf) < 1e-5);
    }

    #[test]
    fn rows_subset_equals_full_rows() {
        let (m, n) = (8, 6);
        let psf = pseudo_random(m * n, 4);
        let v = pseudo_random(m * n, 5);
        let c = Conv2d::sensor(&psf, m, n);
        let mut s = c.scratch();
        let full = c.apply(&v, &mut s);
        let mut got = Vec::new();
        c.forward_rows(&v, &[1..3, 6..7], &mut s, |i, row| got.push((i, row.to_vec())));
        assert_eq!(got.iter().map(|g| g.0).collect::<Vec<_>>(), vec![1, 2, 6]);
        for (i, row) in got {
            assert_eq!(row, full[i * n..(i + 1) * n].to_vec());
        }
    }
}
