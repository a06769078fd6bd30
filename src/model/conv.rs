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
//! Two evaluations of the same convolution:
//!
//! - the **2D path** ([`Conv2d::forward_rows`], [`Conv2d::adjoint_rows`], [`Conv2d::apply`]):
//!   full `P x Q` transforms per call. Spectra are stored transposed (`Q/2+1` columns of
//!   length `P`) so that the FFTs along the `y` direction run on contiguous memory. It is
//!   the straightforward reference.
//! - the **row path** ([`Conv2d::forward_spectra`], [`Conv2d::adjoint_from_spectra`]):
//!   transforms along `x` only (real FFTs of length `Q`), and the `y` direction as a
//!   direct sum over video rows, evaluated only for the sensor rows that are needed.
//!   With `Hx[a] = FFT_x(h[a, .])` (scaled by `1/Q`) and `Vx[p] = FFT_x(v[p, .])`,
//!
//!   `FFT_x(y[i, .]) = sum_p Hx[i + off_r - p + M/2] . Vx[p]`  (terms with the PSF row
//!   outside `[0, M)` are zero),
//!
//!   and the adjoint, for sensor rows `i` with spectra `Yx[i]`,
//!
//!   `FFT_x(x[p, .]) = sum_i conj(Hx[i + off_r - p + M/2]) . Yx[i]`.
//!
//!   A frame of the imaging model touches a few sensor rows only, so a few dense
//!   complex products per video row replace the column FFTs. Spectra are kept as split
//!   real / imaginary arrays of width `qcp` (`Q/2+1` rounded up to a multiple of 8, the
//!   tail zero) so that the products vectorise.

use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};
use rustfft::num_complex::Complex32;
use rustfft::{Fft, FftPlanner};
use std::ops::Range;
use std::sync::{Arc, OnceLock};

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

/// Length of the row path's FFTs along x: the smallest even 2,3,5-smooth length at which
/// the circular convolution is exact on the sensor columns. Only the `N` columns
/// `off_c .. off_c + N` are read, so wrap-around may land elsewhere: with PSF offsets
/// `b` in `[-N/2, N - N/2)` and differences `d = t - q` (`t` a sensor column + `off_c`,
/// `q` a video column) in `[off_c - Nv + 1, off_c + N - 1]`, no `d ± Q` may fall in the
/// PSF's range: `Q >= max(Nv + N - N/2 - off_c - 1, off_c + N + N/2)`. For the sensor
/// field of view that is `3N/2` instead of `2N - 1`; for the full one, `2N - 1`.
pub fn row_fft_size(n: usize, nv: usize, off_c: usize) -> usize {
    let cn = n / 2;
    let need = (nv + n - cn).saturating_sub(off_c + 1).max(off_c + n + cn).max(n).max(nv);
    fft_size(need, true)
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
    /// Row path: length of the real FFTs along x (see [`row_fft_size`]), its spectrum
    /// length `qr/2+1`, and the width of split spectra (rounded up to a multiple of 8).
    qr: usize,
    qrc: usize,
    qcp: usize,
    /// PSF rows transformed along x, pre-scaled by 1/qr: `M x qcp`, real and imaginary
    /// parts (zero beyond `qrc`).
    hx_re: Vec<f32>,
    hx_im: Vec<f32>,
    r2c_row: Arc<dyn RealToComplex<f32>>,
    c2r_row: Arc<dyn ComplexToReal<f32>>,
    /// The PSF (for the 2D path's spectrum).
    psf: Vec<f32>,
    /// PSF spectrum for the 2D path, transposed (qc x p), pre-scaled by 1/(P Q); made on
    /// first use.
    h_t: OnceLock<Vec<Complex32>>,
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
        let qr = row_fft_size(n, nv, off_c);
        let qrc = qr / 2 + 1;
        let qcp = qrc.div_ceil(8) * 8;
        let mut rp = RealFftPlanner::<f32>::new();
        let r2c = rp.plan_fft_forward(q);
        let c2r = rp.plan_fft_inverse(q);
        let r2c_row = rp.plan_fft_forward(qr);
        let c2r_row = rp.plan_fft_inverse(qr);
        let mut cp = FftPlanner::<f32>::new();
        let col_fwd = cp.plan_fft_forward(p);
        let col_inv = cp.plan_fft_inverse(p);
        assert!(off_r + m <= p && off_c + n <= q, "sensor must lie inside the padded grid");
        let mut conv = Conv2d {
            m,
            n,
            mv,
            nv,
            off_r,
            off_c,
            p,
            q,
            qc,
            qr,
            qrc,
            qcp,
            hx_re: vec![0.0; m * qcp],
            hx_im: vec![0.0; m * qcp],
            r2c_row,
            c2r_row,
            psf: psf.to_vec(),
            h_t: OnceLock::new(),
            r2c,
            c2r,
            col_fwd,
            col_inv,
        };
        // Kernel along x: hp[b mod qr] = h[., b + N/2].
        let cn = n / 2;
        let mut s = conv.row_scratch();
        let scale = 1.0 / qr as f32;
        for i in 0..m {
            s.row.fill(0.0);
            for j in 0..n {
                let b = (j as isize - cn as isize).rem_euclid(qr as isize) as usize;
                s.row[b] = psf[i * n + j];
            }
            conv.r2c_row.process_with_scratch(&mut s.row, &mut s.rowc, &mut s.rfft).expect("r2c sizes");
            for (c, z) in s.rowc.iter().enumerate() {
                conv.hx_re[i * qcp + c] = z.re * scale;
                conv.hx_im[i * qcp + c] = z.im * scale;
            }
        }
        conv
    }

    /// The 2D PSF spectrum (transposed: `Q/2 + 1` columns of length `P`, scaled by
    /// 1/(P Q)): kernel `hp[a mod P, b mod Q] = h[a + M/2, b + N/2]`, made on first use.
    /// Also the CUDA steps' `H` (`crate::solve::optimize::cuda`).
    pub(crate) fn spectrum(&self) -> &[Complex32] {
        self.h_t.get_or_init(|| {
            let (m, n, p, q, qc) = (self.m, self.n, self.p, self.q, self.qc);
            let (cm, cn) = (m / 2, n / 2);
            let mut s = self.scratch();
            s.spec.fill(Complex32::new(0.0, 0.0));
            for i in 0..m {
                let a = (i as isize - cm as isize).rem_euclid(p as isize) as usize;
                s.row.fill(0.0);
                for j in 0..n {
                    let b = (j as isize - cn as isize).rem_euclid(q as isize) as usize;
                    s.row[b] = self.psf[i * n + j];
                }
                self.r2c.process_with_scratch(&mut s.row, &mut s.rowc, &mut s.rfft).expect("r2c sizes");
                for c in 0..qc {
                    s.spec[c * p + a] = s.rowc[c];
                }
            }
            self.col_fwd.process_with_scratch(&mut s.spec, &mut s.fft);
            let scale = 1.0 / (p * q) as f32;
            s.spec.iter().map(|z| z * scale).collect()
        })
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
            rfft: vec![Complex32::new(0.0, 0.0); self.r2c.get_scratch_len().max(self.c2r.get_scratch_len())],
        }
    }

    pub fn sensor_shape(&self) -> (usize, usize) {
        (self.m, self.n)
    }
    /// The `M x N` PSF, row-major, centre pixel `(M/2, N/2)`.
    pub fn psf(&self) -> &[f32] {
        &self.psf
    }
    /// `sum |h|`: a bound of the convolution's operator norm (Young's inequality), so
    /// `||crop(h * v)|| <= psf_l1 ||v||` on any grid.
    pub fn psf_l1(&self) -> f64 {
        self.psf.iter().map(|v| v.abs() as f64).sum()
    }
    /// `max_w sum_a |FFT(h_a)(w)|^2` over the PSF rows `a`, the FFTs of the row path's
    /// length: a bound of `||y_i||^2 / ||v||^2` for any one sensor row `y_i` of `h * v`
    /// (the row is `sum_p h_a(p) * v_p` with distinct PSF rows; Cauchy-Schwarz at each
    /// frequency, then Parseval). At most `sum_a (sum |h_a|)^2`.
    pub fn row_gain_sq(&self) -> f64 {
        let scale = self.qr as f64;
        (0..self.qrc)
            .map(|c| {
                (0..self.m).map(|a| (self.hx_re[a * self.qcp + c] as f64).powi(2) + (self.hx_im[a * self.qcp + c] as f64).powi(2)).sum::<f64>() * scale * scale
            })
            .fold(0.0, f64::max)
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
        for (z, h) in s.spec.iter_mut().zip(self.spectrum()) {
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
        for (z, h) in s.spec.iter_mut().zip(self.spectrum()) {
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
        self.forward_rows(v, std::slice::from_ref(&(0..self.m)), s, |i, row| out[i * self.n..(i + 1) * self.n].copy_from_slice(row));
        out
    }
}

/// Per-thread buffers for the row path of [`Conv2d`]; make one with
/// [`Conv2d::row_scratch`] and reuse it (it grows to the largest row count seen).
pub struct RowScratch {
    row: Vec<f32>,
    rowc: Vec<Complex32>,
    rfft: Vec<Complex32>,
    /// One split spectrum (`qcp` each).
    vr: Vec<f32>,
    vi: Vec<f32>,
    /// Per-output-row split spectra (`rows x qcp` each).
    acc_r: Vec<f32>,
    acc_i: Vec<f32>,
}

/// The row path (see the module documentation).
impl Conv2d {
    pub fn row_scratch(&self) -> RowScratch {
        RowScratch {
            row: vec![0.0; self.qr],
            rowc: vec![Complex32::new(0.0, 0.0); self.qrc],
            rfft: vec![Complex32::new(0.0, 0.0); self.r2c_row.get_scratch_len().max(self.c2r_row.get_scratch_len())],
            vr: vec![0.0; self.qcp],
            vi: vec![0.0; self.qcp],
            acc_r: Vec::new(),
            acc_i: Vec::new(),
        }
    }

    /// Width of the split row spectra used by the row path.
    pub fn spectrum_width(&self) -> usize {
        self.qcp
    }

    /// Length of the row path's real FFTs along x.
    pub fn row_fft_len(&self) -> usize {
        self.qr
    }

    /// Range of video rows `p` whose PSF row `i + off_r - p + M/2` lies in `[0, M)` for
    /// at least one sensor row `i` in `rows` (the hull of the per-row ranges).
    fn video_rows_needed(&self, rows: &[usize]) -> Range<usize> {
        let shift = self.off_r + self.m / 2;
        let (mut lo, mut hi) = (usize::MAX, 0usize);
        for &i in rows {
            // a = i + shift - p in [0, M)  <=>  p in (i + shift - M, i + shift]
            let top = i + shift; // p <= top
            let bottom = (top + 1).saturating_sub(self.m); // p >= top - M + 1
            lo = lo.min(bottom);
            hi = hi.max(top + 1);
        }
        lo.min(self.mv)..hi.min(self.mv)
    }

    /// Real FFT along x of `src` placed at `at` inside a zero row of length `qr`; the
    /// split spectrum goes to `s.vr`, `s.vi`.
    fn row_fft_into_v(&self, src: &[f32], at: usize, s: &mut RowScratch) {
        s.row[..at].fill(0.0);
        s.row[at..at + src.len()].copy_from_slice(src);
        s.row[at + src.len()..].fill(0.0);
        self.r2c_row.process_with_scratch(&mut s.row, &mut s.rowc, &mut s.rfft).expect("r2c sizes");
        for ((r, i), z) in s.vr.iter_mut().zip(s.vi.iter_mut()).zip(&s.rowc) {
            *r = z.re;
            *i = z.im;
        }
    }

    /// Inverse real FFT of a split spectrum (`qcp` wide) into `s.row` (length `qr`).
    fn row_ifft(&self, re: &[f32], im: &[f32], s: &mut RowScratch) {
        for (c, z) in s.rowc.iter_mut().enumerate() {
            *z = Complex32::new(re[c], im[c]);
        }
        // DC and Nyquist of a real signal are real (round-off leaves a trace).
        s.rowc[0].im = 0.0;
        s.rowc[self.qrc - 1].im = 0.0;
        self.c2r_row.process_with_scratch(&mut s.rowc, &mut s.row, &mut s.rfft).expect("c2r sizes");
    }

    /// Row path, forward: the x-spectra of the (distinct) sensor rows `rows` of `h * v` (`v` is
    /// `Mv x Nv`), written as split spectra `out_re[j*qcp..]`, `out_im[j*qcp..]` for
    /// `rows[j]` (`out_*` hold at least `rows.len() * qcp` values). The inverse row FFT
    /// of a spectrum, columns `off_c .. off_c + N`, is the sensor row.
    pub fn forward_spectra(&self, v: &[f32], rows: &[usize], s: &mut RowScratch, out_re: &mut [f32], out_im: &mut [f32]) {
        debug_assert_eq!(v.len(), self.mv * self.nv);
        let (qcp, shift) = (self.qcp, self.off_r + self.m / 2);
        let len = rows.len() * qcp;
        let (out_re, out_im) = (&mut out_re[..len], &mut out_im[..len]);
        out_re.fill(0.0);
        out_im.fill(0.0);
        for p in self.video_rows_needed(rows) {
            self.row_fft_into_v(&v[p * self.nv..(p + 1) * self.nv], 0, s);
            for (j, &i) in rows.iter().enumerate() {
                let a = i + shift;
                if a < p || a - p >= self.m {
                    continue;
                }
                let a = a - p;
                let h = a * qcp..(a + 1) * qcp;
                let o = j * qcp..(j + 1) * qcp;
                cmac(&mut out_re[o.clone()], &mut out_im[o], &self.hx_re[h.clone()], &self.hx_im[h], &s.vr, &s.vi, false);
            }
        }
    }

    /// Row path, adjoint: `x = h ⋆ y` for `y` non-zero only on the (distinct) sensor rows `rows`,
    /// given their x-spectra (`y_re[j*qcp..]`, `y_im[j*qcp..]` for `rows[j]`, each the
    /// FFT of the sensor row placed at `off_c` in a zero row of length `Q`). Writes all
    /// of `x` (`Mv x Nv`).
    pub fn adjoint_from_spectra(&self, rows: &[usize], y_re: &[f32], y_im: &[f32], s: &mut RowScratch, x: &mut [f32]) {
        debug_assert_eq!(x.len(), self.mv * self.nv);
        let (qcp, shift) = (self.qcp, self.off_r + self.m / 2);
        let need = self.video_rows_needed(rows);
        for p in 0..self.mv {
            let xrow = &mut x[p * self.nv..(p + 1) * self.nv];
            if !need.contains(&p) {
                xrow.fill(0.0);
                continue;
            }
            s.vr.fill(0.0);
            s.vi.fill(0.0);
            for (j, &i) in rows.iter().enumerate() {
                let a = i + shift;
                if a < p || a - p >= self.m {
                    continue;
                }
                let a = a - p;
                let h = a * qcp..(a + 1) * qcp;
                let o = j * qcp..(j + 1) * qcp;
                cmac(&mut s.vr, &mut s.vi, &self.hx_re[h.clone()], &self.hx_im[h], &y_re[o.clone()], &y_im[o], true);
            }
            let (vr, vi) = (std::mem::take(&mut s.vr), std::mem::take(&mut s.vi));
            self.row_ifft(&vr, &vi, s);
            s.vr = vr;
            s.vi = vi;
            xrow.copy_from_slice(&s.row[..self.nv]);
        }
    }

    /// The x-spectrum of one sensor row (`N` values), placed at `off_c`: what
    /// [`Conv2d::adjoint_from_spectra`] takes. `re`, `im` receive `qcp` values.
    pub fn sensor_row_spectrum(&self, row: &[f32], s: &mut RowScratch, re: &mut [f32], im: &mut [f32]) {
        debug_assert_eq!(row.len(), self.n);
        self.row_fft_into_v(row, self.off_c, s);
        re[..self.qcp].copy_from_slice(&s.vr);
        im[..self.qcp].copy_from_slice(&s.vi);
    }

    /// The sensor row (`N` values) of an x-spectrum from [`Conv2d::forward_spectra`].
    pub fn sensor_row_from_spectrum(&self, re: &[f32], im: &[f32], s: &mut RowScratch, out: &mut [f32]) {
        self.row_ifft(re, im, s);
        out.copy_from_slice(&s.row[self.off_c..self.off_c + self.n]);
    }

    /// [`Conv2d::forward_rows`] evaluated by the row path (same arguments, same result
    /// up to round-off).
    pub fn forward_rows_fast(&self, v: &[f32], rows: &[Range<usize>], s: &mut RowScratch, mut emit: impl FnMut(usize, &[f32])) {
        let list: Vec<usize> = rows.iter().flat_map(|r| r.clone()).collect();
        let len = list.len() * self.qcp;
        let (mut re, mut im) = (std::mem::take(&mut s.acc_r), std::mem::take(&mut s.acc_i));
        re.resize(re.len().max(len), 0.0);
        im.resize(im.len().max(len), 0.0);
        self.forward_spectra(v, &list, s, &mut re, &mut im);
        let mut out = vec![0.0; self.n];
        for (j, &i) in list.iter().enumerate() {
            let sp = j * self.qcp..(j + 1) * self.qcp;
            self.sensor_row_from_spectrum(&re[sp.clone()], &im[sp], s, &mut out);
            emit(i, &out);
        }
        s.acc_r = re;
        s.acc_i = im;
    }

    /// [`Conv2d::adjoint_rows`] evaluated by the row path.
    pub fn adjoint_rows_fast(&self, rows: &[Range<usize>], s: &mut RowScratch, mut fill: impl FnMut(usize, &mut [f32]), x: &mut [f32]) {
        let list: Vec<usize> = rows.iter().flat_map(|r| r.clone()).collect();
        let len = list.len() * self.qcp;
        let (mut re, mut im) = (vec![0.0; len], vec![0.0; len]);
        let mut row = vec![0.0; self.n];
        for (j, &i) in list.iter().enumerate() {
            row.fill(0.0);
            fill(i, &mut row);
            let sp = j * self.qcp..(j + 1) * self.qcp;
            self.sensor_row_spectrum(&row, s, &mut re[sp.clone()], &mut im[sp]);
        }
        self.adjoint_from_spectra(&list, &re, &im, s, x);
    }
}

/// `acc += h . v` (or `conj(h) . v` when `conj`) over split complex arrays, with the
/// widest vector instructions the CPU has (checked once at run time).
#[inline]
pub fn cmac(acc_r: &mut [f32], acc_i: &mut [f32], hr: &[f32], hi: &[f32], vr: &[f32], vi: &[f32], conj: bool) {
    #[cfg(target_arch = "x86_64")]
    {
        if simd::has_avx2_fma() {
            // SAFETY: the CPU supports AVX2 and FMA (checked above).
            unsafe { simd::cmac_avx2(acc_r, acc_i, hr, hi, vr, vi, conj) };
            return;
        }
    }
    cmac_body::<false>(acc_r, acc_i, hr, hi, vr, vi, conj)
}

#[inline(always)]
fn cmac_body<const FMA: bool>(acc_r: &mut [f32], acc_i: &mut [f32], hr: &[f32], hi: &[f32], vr: &[f32], vi: &[f32], conj: bool) {
    let n = acc_r.len();
    let (acc_i, hr, hi, vr, vi) = (&mut acc_i[..n], &hr[..n], &hi[..n], &vr[..n], &vi[..n]);
    #[inline(always)]
    fn fma<const F: bool>(a: f32, b: f32, c: f32) -> f32 {
        if F {
            a.mul_add(b, c)
        } else {
            a * b + c
        }
    }
    if conj {
        // (hr - i hi)(vr + i vi) = hr vr + hi vi + i (hr vi - hi vr)
        for c in 0..n {
            acc_r[c] = fma::<FMA>(hr[c], vr[c], fma::<FMA>(hi[c], vi[c], acc_r[c]));
            acc_i[c] = fma::<FMA>(hr[c], vi[c], fma::<FMA>(-hi[c], vr[c], acc_i[c]));
        }
    } else {
        // (hr + i hi)(vr + i vi) = hr vr - hi vi + i (hr vi + hi vr)
        for c in 0..n {
            acc_r[c] = fma::<FMA>(hr[c], vr[c], fma::<FMA>(-hi[c], vi[c], acc_r[c]));
            acc_i[c] = fma::<FMA>(hr[c], vi[c], fma::<FMA>(hi[c], vr[c], acc_i[c]));
        }
    }
}

/// Plain element-wise `acc += h . v` (or with `conj(h)`), no vector dispatch: the
/// reference the dispatched [`cmac`] is tested against.
pub fn cmac_reference(acc_r: &mut [f32], acc_i: &mut [f32], hr: &[f32], hi: &[f32], vr: &[f32], vi: &[f32], conj: bool) {
    for c in 0..acc_r.len() {
        let h = if conj { Complex32::new(hr[c], -hi[c]) } else { Complex32::new(hr[c], hi[c]) };
        let z = h * Complex32::new(vr[c], vi[c]);
        acc_r[c] += z.re;
        acc_i[c] += z.im;
    }
}

#[cfg(target_arch = "x86_64")]
pub(crate) mod simd {
    use std::sync::OnceLock;

    /// Whether the CPU has AVX2 and FMA (checked once).
    pub fn has_avx2_fma() -> bool {
        static HAS: OnceLock<bool> = OnceLock::new();
        *HAS.get_or_init(|| is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma"))
    }

    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn cmac_avx2(acc_r: &mut [f32], acc_i: &mut [f32], hr: &[f32], hi: &[f32], vr: &[f32], vi: &[f32], conj: bool) {
        super::cmac_body::<true>(acc_r, acc_i, hr, hi, vr, vi, conj)
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
    use crate::model::op::pseudo_random;

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

    #[test]
    fn row_path_matches_the_2d_path_and_the_direct_sum() {
        for (m, n) in [(5, 7), (6, 4), (1, 5), (2, 2), (9, 8), (12, 10)] {
            let psf = pseudo_random(m * n, 21);
            for full in [false, true] {
                let c = if full { Conv2d::full(&psf, m, n) } else { Conv2d::sensor(&psf, m, n) };
                let (mv, nv) = c.video_shape();
                let v = pseudo_random(mv * nv, 22);
                let rows = [0..m.min(2), (m / 2).clamp(2.min(m), m)..m]; // disjoint ranges
                let (mut s2, mut sr) = (c.scratch(), c.row_scratch());
                let mut slow = vec![0.0; m * n];
                c.forward_rows(&v, &rows, &mut s2, |i, row| slow[i * n..(i + 1) * n].copy_from_slice(row));
                let mut fast = vec![0.0; m * n];
                let mut seen = Vec::new();
                c.forward_rows_fast(&v, &rows, &mut sr, |i, row| {
                    seen.push(i);
                    fast[i * n..(i + 1) * n].copy_from_slice(row)
                });
                let want: Vec<usize> = rows.iter().flat_map(|r| r.clone()).collect();
                assert_eq!(seen, want);
                assert!(max_rel(&fast, &slow) < 1e-5, "{m}x{n} full={full}: {}", max_rel(&fast, &slow));
                let direct = conv_direct(&psf, m, n, &v, mv, nv, c.offset());
                let mut direct_rows = vec![0.0; m * n];
                for i in &want {
                    direct_rows[i * n..(i + 1) * n].copy_from_slice(&direct[i * n..(i + 1) * n]);
                }
                assert!(max_rel(&fast, &direct_rows) < 1e-5, "{m}x{n} full={full} vs direct");
            }
        }
    }

    #[test]
    fn row_path_adjoint_matches_the_2d_path() {
        for (m, n) in [(5, 7), (6, 4), (1, 5), (2, 3), (9, 8)] {
            let psf = pseudo_random(m * n, 31);
            for full in [false, true] {
                let c = if full { Conv2d::full(&psf, m, n) } else { Conv2d::sensor(&psf, m, n) };
                let (mv, nv) = c.video_shape();
                let y = pseudo_random(m * n, 32);
                let rows = [0..1, (m / 2).max(1)..m]; // disjoint ranges
                let fill = |i: usize, row: &mut [f32]| row.copy_from_slice(&y[i * n..(i + 1) * n]);
                let mut slow = vec![0.0; mv * nv];
                c.adjoint_rows(&rows, &mut c.scratch(), fill, &mut slow);
                let mut fast = vec![f32::NAN; mv * nv];
                c.adjoint_rows_fast(&rows, &mut c.row_scratch(), fill, &mut fast);
                assert!(max_rel(&fast, &slow) < 1e-5, "{m}x{n} full={full}: {}", max_rel(&fast, &slow));
                // <A v, y> = <v, A^T y> on the chosen rows.
                let v = pseudo_random(mv * nv, 33);
                let mut lhs = 0.0f64;
                c.forward_rows_fast(&v, &rows, &mut c.row_scratch(), |i, row| {
                    lhs += row.iter().zip(&y[i * n..(i + 1) * n]).map(|(a, b)| (a * b) as f64).sum::<f64>()
                });
                let rhs: f64 = v.iter().zip(&fast).map(|(a, b)| (a * b) as f64).sum();
                assert!((lhs - rhs).abs() < 1e-5 * lhs.abs(), "{lhs} vs {rhs}");
            }
        }
    }

    #[test]
    fn vector_complex_products_match_the_plain_loop() {
        for len in [1, 7, 8, 9, 40, 333] {
            let (hr, hi, vr, vi) = (pseudo_random(len, 1), pseudo_random(len, 2), pseudo_random(len, 3), pseudo_random(len, 4));
            for conj in [false, true] {
                let (mut ar, mut ai) = (pseudo_random(len, 5), pseudo_random(len, 6));
                let (mut br, mut bi) = (ar.clone(), ai.clone());
                cmac(&mut ar, &mut ai, &hr, &hi, &vr, &vi, conj);
                cmac_reference(&mut br, &mut bi, &hr, &hi, &vr, &vi, conj);
                assert!(max_rel(&ar, &br) < 1e-6 && max_rel(&ai, &bi) < 1e-6, "len {len} conj {conj}");
                // and it did something: the products are not zero
                assert!(ar.iter().zip(&pseudo_random(len, 5)).any(|(a, b)| a != b));
            }
        }
    }

    #[test]
    fn row_path_fft_is_shorter_for_the_sensor_field_of_view() {
        // Sensor field: 3N/2 (smoothed) instead of the 2D path's 2N - 1.
        let psf = pseudo_random(270 * 320, 1);
        let c = Conv2d::sensor(&psf, 270, 320);
        assert_eq!(c.row_fft_len(), 480);
        assert_eq!(c.fft_shape().1, 640);
        // Full field: the whole linear convolution is needed.
        assert_eq!(row_fft_size(320, 639, 159), fft_size(639, true));
        // Exactness at the shortest length is what the row-path tests above check
        // against the direct sum (odd and even N, both fields of view).
    }
}
