//! Synthetic caustic PSF of a random-lenslet diffuser.
//!
//! Physics (geometric optics, lengths in sensor pixels): the diffuser surface is a
//! mosaic of lenslets, the Voronoi cells of random centres `c_i` drawn uniformly inside
//! a round aperture. Inside cell `i` the surface is a paraboloid of focal length `f_i`;
//! a ray of the on-axis source (parallel to the axis) crossing the diffuser at `p` is
//! deflected by the local slope, `grad = (p - c_i) / f_i`, and lands on the sensor, a
//! distance `d0` behind, at
//!
//! `q = p - d0 * grad = c_i + (1 - d0 / f_i) (p - c_i)`.
//!
//! With `d0` close to `f_i`, each cell shrinks onto a small bright caustic near its
//! centre; the focal lengths vary by a few percent, so the caustics have different
//! small sizes. Rays are traced on a supersampled grid across the aperture, splatted
//! bilinearly onto the pixels they land on, blurred by a small Gaussian (pixel
//! cross-talk, diffraction) and normalised to unit sum. The aperture is centred on the
//! PSF centre pixel `(rows/2, cols/2)` (the convention of [`crate::model::conv`]) and is
//! smaller than the sensor, so the PSF is zero near the borders.

use super::error::{invalid, SimError};
use ndarray::Array2;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rustfft::num_complex::Complex64;
use rustfft::FftPlanner;

/// Parameters of the random-lenslet diffuser.
#[derive(Clone, Debug, PartialEq)]
pub struct LensletParams {
    /// Number of lenslets inside the aperture.
    pub lenslets: usize,
    /// Relative spread of the focal lengths: `f_i = f * (1 + focal_spread * u_i)`,
    /// `u_i` uniform in `[-1, 1]`.
    pub focal_spread: f64,
    /// Relative defocus of the sensor: `d0 = f * (1 + defocus)`.
    pub defocus: f64,
    /// Aperture diameter as a fraction of the smaller sensor side, in `(0, 1]`.
    pub aperture_fraction: f64,
    /// Rays per pixel along each axis (`supersample^2` rays per pixel).
    pub supersample: usize,
    /// Standard deviation of the final Gaussian blur, in pixels (0 for none).
    pub blur_px: f64,
}

/// The most lenslets of a synthetic diffuser (a million tiny lenslets is no longer a
/// diffuser of lenslets, and their table alone would take gigabytes).
pub const MAX_LENSLETS: usize = 100_000;

impl Default for LensletParams {
    fn default() -> Self {
        LensletParams { lenslets: 48, focal_spread: 0.04, defocus: 0.01, aperture_fraction: 0.8, supersample: 4, blur_px: 1.0 }
    }
}

impl LensletParams {
    /// Check the parameters, naming the first one out of range.
    pub fn validate(&self) -> Result<(), SimError> {
        if !(1..=MAX_LENSLETS).contains(&self.lenslets) {
            return Err(invalid("lenslets", self.lenslets, format!("1 to {MAX_LENSLETS} lenslets")));
        }
        // |1 - d0/f_i| <= 1 keeps every ray inside the aperture (see `support_radius_px`).
        if !(self.focal_spread.is_finite() && (0.0..0.25).contains(&self.focal_spread)) {
            return Err(invalid("focal_spread", self.focal_spread, "a relative spread in [0, 0.25)"));
        }
        if !(self.defocus.is_finite() && self.defocus > -0.5 && self.defocus < 0.5) {
            return Err(invalid("defocus", self.defocus, "a relative defocus in (-0.5, 0.5)"));
        }
        if !(self.aperture_fraction.is_finite() && self.aperture_fraction > 0.0 && self.aperture_fraction <= 1.0) {
            return Err(invalid("aperture_fraction", self.aperture_fraction, "a fraction in (0, 1]"));
        }
        if self.supersample == 0 || self.supersample > 64 {
            return Err(invalid("supersample", self.supersample, "1 to 64 rays per pixel along each axis"));
        }
        if !(self.blur_px.is_finite() && self.blur_px >= 0.0) {
            return Err(invalid("blur_px", self.blur_px, "a non-negative standard deviation in pixels"));
        }
        Ok(())
    }

    /// Provenance for the `[simulation]` table of a capture description.
    pub fn describe(&self, seed: u64) -> toml::Table {
        let mut t = toml::Table::new();
        t.insert("kind".into(), "random-lenslets".into());
        t.insert("lenslets".into(), (self.lenslets as i64).into());
        t.insert("focal_spread".into(), self.focal_spread.into());
        t.insert("defocus".into(), self.defocus.into());
        t.insert("aperture_fraction".into(), self.aperture_fraction.into());
        t.insert("supersample".into(), (self.supersample as i64).into());
        t.insert("blur_px".into(), self.blur_px.into());
        t.insert("seed".into(), (seed as i64).into());
        t
    }
}

/// Geometry of the round aperture in continuous pixel coordinates (pixel `(i, j)`
/// covers `[i, i+1) x [j, j+1)`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aperture {
    pub centre_row: f64,
    pub centre_col: f64,
    pub radius_px: f64,
}

impl Aperture {
    /// The aperture of a `rows x cols` PSF for `params`: centred on the centre of pixel
    /// `(rows/2, cols/2)`, diameter `aperture_fraction * min(rows, cols)`.
    pub fn of(rows: usize, cols: usize, params: &LensletParams) -> Aperture {
        Aperture { centre_row: (rows / 2) as f64 + 0.5, centre_col: (cols / 2) as f64 + 0.5, radius_px: 0.5 * params.aperture_fraction * rows.min(cols) as f64 }
    }

    /// Distance (pixels) from the aperture centre to the centre of pixel `(i, j)`.
    pub fn distance_px(&self, i: usize, j: usize) -> f64 {
        let dy = i as f64 + 0.5 - self.centre_row;
        let dx = j as f64 + 0.5 - self.centre_col;
        (dy * dy + dx * dx).sqrt()
    }

    /// Distance from the centre beyond which the PSF is exactly zero: the aperture plus
    /// the reach of the bilinear splat and of the truncated Gaussian blur.
    pub fn support_radius_px(&self, params: &LensletParams) -> f64 {
        // The splat reaches 1 px and the separable blur ceil(3 sigma) px along each
        // axis: a square reach, so the diagonal counts.
        self.radius_px + std::f64::consts::SQRT_2 * (1.0 + (3.0 * params.blur_px).ceil()) + 1e-6
    }
}

/// Nearest-centre lookup on a uniform bucket grid (Voronoi cell of a point).
struct Buckets {
    r0: f64,
    c0: f64,
    size: f64,
    nr: usize,
    nc: usize,
    cells: Vec<Vec<usize>>,
}

impl Buckets {
    fn new(centres: &[(f64, f64)], r0: f64, c0: f64, extent: f64, size: f64) -> Buckets {
        let n = ((extent / size).ceil() as usize).max(1);
        let mut cells = vec![Vec::new(); n * n];
        let mut b = Buckets { r0, c0, size, nr: n, nc: n, cells: Vec::new() };
        for (k, &(r, c)) in centres.iter().enumerate() {
            let (br, bc) = b.bucket(r, c);
            cells[br * n + bc].push(k);
        }
        b.cells = cells;
        b
    }

    fn bucket(&self, r: f64, c: f64) -> (usize, usize) {
        let br = (((r - self.r0) / self.size).floor().max(0.0) as usize).min(self.nr - 1);
        let bc = (((c - self.c0) / self.size).floor().max(0.0) as usize).min(self.nc - 1);
        (br, bc)
    }

    /// Index of the centre nearest to `(r, c)`.
    fn nearest(&self, centres: &[(f64, f64)], r: f64, c: f64) -> usize {
        let (br, bc) = self.bucket(r, c);
        let (mut best, mut best_d2) = (usize::MAX, f64::INFINITY);
        let max_ring = self.nr.max(self.nc);
        for ring in 0..=max_ring {
            // Every centre in ring `ring` or beyond is at least (ring - 1) * size away.
            if best != usize::MAX {
                let lower = (ring as f64 - 1.0).max(0.0) * self.size;
                if lower * lower > best_d2 {
                    break;
                }
            }
            let (lo_r, hi_r) = (br as isize - ring as isize, br as isize + ring as isize);
            let (lo_c, hi_c) = (bc as isize - ring as isize, bc as isize + ring as isize);
            for qr in lo_r..=hi_r {
                for qc in lo_c..=hi_c {
                    let on_ring = qr == lo_r || qr == hi_r || qc == lo_c || qc == hi_c;
                    if !on_ring || qr < 0 || qc < 0 || qr >= self.nr as isize || qc >= self.nc as isize {
                        continue;
                    }
                    for &k in &self.cells[qr as usize * self.nc + qc as usize] {
                        let (dr, dc) = (centres[k].0 - r, centres[k].1 - c);
                        let d2 = dr * dr + dc * dc;
                        if d2 < best_d2 {
                            best_d2 = d2;
                            best = k;
                        }
                    }
                }
            }
        }
        best
    }
}

/// Synthetic random-lenslet PSF of a `rows x cols` sensor: non-negative, unit sum,
/// zero outside [`Aperture::support_radius_px`]; deterministic for a seed.
pub fn lenslet_psf(rows: usize, cols: usize, params: &LensletParams, seed: u64) -> Result<Array2<f32>, SimError> {
    params.validate()?;
    if rows == 0 || cols == 0 {
        return Err(invalid("psf size", format!("{rows} x {cols}"), "at least 1 x 1 pixels"));
    }
    let ap = Aperture::of(rows, cols, params);
    let radius = ap.radius_px;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // Lenslet centres uniform in the aperture disc, each with its image scale
    // s_i = 1 - d0 / f_i.
    let mut centres = Vec::with_capacity(params.lenslets);
    let mut scale = Vec::with_capacity(params.lenslets);
    while centres.len() < params.lenslets {
        let dr = rng.gen_range(-radius..=radius);
        let dc = rng.gen_range(-radius..=radius);
        if dr * dr + dc * dc > radius * radius {
            continue;
        }
        centres.push((ap.centre_row + dr, ap.centre_col + dc));
        let u: f64 = rng.gen_range(-1.0..=1.0);
        let f_rel = 1.0 + params.focal_spread * u;
        scale.push(1.0 - (1.0 + params.defocus) / f_rel);
    }
    let spacing = (std::f64::consts::PI * radius * radius / params.lenslets as f64).sqrt().max(1.0);
    let buckets = Buckets::new(&centres, ap.centre_row - radius, ap.centre_col - radius, 2.0 * radius, spacing);

    // Trace rays on the supersampled grid inside the aperture; splat bilinearly.
    let ss = params.supersample;
    let step = 1.0 / ss as f64;
    let mut acc = vec![0.0f64; rows * cols];
    let r_lo = ((ap.centre_row - radius).floor().max(0.0)) as usize;
    let r_hi = ((ap.centre_row + radius).ceil() as usize).min(rows);
    let c_lo = ((ap.centre_col - radius).floor().max(0.0)) as usize;
    let c_hi = ((ap.centre_col + radius).ceil() as usize).min(cols);
    for i in r_lo..r_hi {
        for a in 0..ss {
            let pr = i as f64 + (a as f64 + 0.5) * step;
            for j in c_lo..c_hi {
                for b in 0..ss {
                    let pc = j as f64 + (b as f64 + 0.5) * step;
                    let (dr, dc) = (pr - ap.centre_row, pc - ap.centre_col);
                    if dr * dr + dc * dc > radius * radius {
                        continue;
                    }
                    let k = buckets.nearest(&centres, pr, pc);
                    let (cr, cc) = centres[k];
                    let qr = cr + scale[k] * (pr - cr);
                    let qc = cc + scale[k] * (pc - cc);
                    splat(&mut acc, rows, cols, qr - 0.5, qc - 0.5);
                }
            }
        }
    }
    let blurred = gaussian_blur(&acc, rows, cols, params.blur_px);
    let total: f64 = blurred.iter().sum();
    if total.is_nan() || total <= 0.0 {
        return Err(invalid("aperture_fraction", params.aperture_fraction, "an aperture that passes light onto the sensor"));
    }
    let psf: Vec<f32> = blurred.iter().map(|&v| (v / total) as f32).collect();
    Ok(Array2::from_shape_vec((rows, cols), psf).expect("rows x cols"))
}

/// Bilinear splat of a unit ray at pixel-centre coordinates `(y, x)`.
fn splat(acc: &mut [f64], rows: usize, cols: usize, y: f64, x: f64) {
    let (y0, x0) = (y.floor(), x.floor());
    let (fy, fx) = (y - y0, x - x0);
    for (dy, wy) in [(0isize, 1.0 - fy), (1, fy)] {
        for (dx, wx) in [(0isize, 1.0 - fx), (1, fx)] {
            let (r, c) = (y0 as isize + dy, x0 as isize + dx);
            if r >= 0 && c >= 0 && (r as usize) < rows && (c as usize) < cols {
                acc[r as usize * cols + c as usize] += wy * wx;
            }
        }
    }
}

/// Separable Gaussian blur (standard deviation `sigma_px`, truncated at `ceil(3 sigma)`,
/// kernel normalised); zero padding.
fn gaussian_blur(img: &[f64], rows: usize, cols: usize, sigma_px: f64) -> Vec<f64> {
    if sigma_px <= 0.0 {
        return img.to_vec();
    }
    let rad = (3.0 * sigma_px).ceil() as isize;
    let mut k: Vec<f64> = (-rad..=rad).map(|x| (-(x * x) as f64 / (2.0 * sigma_px * sigma_px)).exp()).collect();
    let s: f64 = k.iter().sum();
    k.iter_mut().for_each(|v| *v /= s);
    let mut tmp = vec![0.0f64; rows * cols];
    for i in 0..rows {
        for j in 0..cols {
            let mut a = 0.0;
            for (t, w) in k.iter().enumerate() {
                let c = j as isize + t as isize - rad;
                if c >= 0 && (c as usize) < cols {
                    a += w * img[i * cols + c as usize];
                }
            }
            tmp[i * cols + j] = a;
        }
    }
    let mut out = vec![0.0f64; rows * cols];
    for i in 0..rows {
        for j in 0..cols {
            let mut a = 0.0;
            for (t, w) in k.iter().enumerate() {
                let r = i as isize + t as isize - rad;
                if r >= 0 && (r as usize) < rows {
                    a += w * tmp[r as usize * cols + j];
                }
            }
            out[i * cols + j] = a;
        }
    }
    out
}

/// Full linear autocorrelation `R[u, v] = sum_x h[x] h[x + (u, v)]` of an image,
/// normalised by its peak `R[0, 0]` (no mean subtraction). Returns the
/// `(2 rows - 1) x (2 cols - 1)` map with zero shift at `(rows - 1, cols - 1)`.
pub fn normalized_autocorrelation(img: &[f32], rows: usize, cols: usize) -> Array2<f32> {
    assert_eq!(img.len(), rows * cols, "image must be rows x cols");
    let (p, q) = (crate::model::conv::fft_size(2 * rows - 1, false), crate::model::conv::fft_size(2 * cols - 1, false));
    let mut planner = FftPlanner::<f64>::new();
    let (fr, fc) = (planner.plan_fft_forward(q), planner.plan_fft_forward(p));
    let (ir, ic) = (planner.plan_fft_inverse(q), planner.plan_fft_inverse(p));
    let mut a = vec![Complex64::new(0.0, 0.0); p * q];
    for i in 0..rows {
        for j in 0..cols {
            a[i * q + j].re = img[i * cols + j] as f64;
        }
    }
    fft2(&mut a, p, q, &*fr, &*fc);
    a.iter_mut().for_each(|z| *z = Complex64::new(z.norm_sqr(), 0.0));
    fft2(&mut a, p, q, &*ir, &*ic);
    let peak = a[0].re;
    let (h, w) = (2 * rows - 1, 2 * cols - 1);
    let mut out = Array2::<f32>::zeros((h, w));
    for u in 0..h {
        for v in 0..w {
            let su = (u as isize - (rows as isize - 1)).rem_euclid(p as isize) as usize;
            let sv = (v as isize - (cols as isize - 1)).rem_euclid(q as isize) as usize;
            out[(u, v)] = if peak > 0.0 { (a[su * q + sv].re / peak) as f32 } else { 0.0 };
        }
    }
    out
}

fn fft2(a: &mut [Complex64], p: usize, q: usize, row_fft: &dyn rustfft::Fft<f64>, col_fft: &dyn rustfft::Fft<f64>) {
    for row in a.chunks_exact_mut(q) {
        row_fft.process(row);
    }
    let mut col = vec![Complex64::new(0.0, 0.0); p];
    for j in 0..q {
        for i in 0..p {
            col[i] = a[i * q + j];
        }
        col_fft.process(&mut col);
        for i in 0..p {
            a[i * q + j] = col[i];
        }
    }
}

/// Peak-to-maximum-sidelobe ratio of the normalised autocorrelation: `1 / max R` over
/// shifts farther than `exclude_radius_px` from zero (the main lobe).
pub fn peak_to_sidelobe(img: &[f32], rows: usize, cols: usize, exclude_radius_px: f64) -> f64 {
    let r = normalized_autocorrelation(img, rows, cols);
    let (cr, cc) = (rows as f64 - 1.0, cols as f64 - 1.0);
    let mut side = 0.0f64;
    for ((u, v), &x) in r.indexed_iter() {
        let (du, dv) = (u as f64 - cr, v as f64 - cc);
        if du * du + dv * dv > exclude_radius_px * exclude_radius_px {
            side = side.max(x as f64);
        }
    }
    1.0 / side.max(1e-300)
}

#[cfg(test)]
mod tests {
    use super::*;

    const ROWS: usize = 64;
    const COLS: usize = 80;

    fn psf(seed: u64) -> Array2<f32> {
        lenslet_psf(ROWS, COLS, &LensletParams::default(), seed).unwrap()
    }

    #[test]
    fn unit_sum_non_negative_finite() {
        let h = psf(1);
        let sum: f64 = h.iter().map(|&v| v as f64).sum();
        assert!((sum - 1.0).abs() < 1e-5, "sum {sum}");
        assert!(h.iter().all(|v| v.is_finite() && *v >= 0.0));
    }

    #[test]
    fn zero_outside_the_aperture_and_near_the_borders() {
        let params = LensletParams::default();
        let h = psf(2);
        let ap = Aperture::of(ROWS, COLS, &params);
        let support = ap.support_radius_px(&params);
        let mut outside = 0usize;
        for ((i, j), &v) in h.indexed_iter() {
            if ap.distance_px(i, j) > support {
                outside += 1;
                assert_eq!(v, 0.0, "pixel ({i},{j}) at {} px from the centre", ap.distance_px(i, j));
            }
        }
        assert!(outside > ROWS * COLS / 4, "the aperture must leave a dark border ({outside} pixels)");
        // The energy lies well inside the aperture proper.
        let inside: f64 = h.indexed_iter().filter(|((i, j), _)| ap.distance_px(*i, *j) <= ap.radius_px).map(|(_, &v)| v as f64).sum();
        assert!(inside > 0.97, "{inside}");
    }

    #[test]
    fn caustics_are_sparse() {
        let h = psf(3);
        let mut v: Vec<f32> = h.iter().cloned().collect();
        v.sort_by(|a, b| b.partial_cmp(a).unwrap());
        let top = v.len() / 20;
        let top_energy: f64 = v[..top].iter().map(|&x| x as f64).sum();
        assert!(top_energy > 0.5, "top 5% of pixels hold {top_energy}");
        // A blur-free, in-focus diffuser is sparser still.
        let sharp = LensletParams { blur_px: 0.0, ..LensletParams::default() };
        let hs = lenslet_psf(ROWS, COLS, &sharp, 3).unwrap();
        let mut v: Vec<f32> = hs.iter().cloned().collect();
        v.sort_by(|a, b| b.partial_cmp(a).unwrap());
        let sharp_energy: f64 = v[..top].iter().map(|&x| x as f64).sum();
        assert!(sharp_energy > top_energy, "{sharp_energy} vs {top_energy}");
    }

    #[test]
    fn autocorrelation_has_a_sharp_peak() {
        let h = psf(4);
        let psr = peak_to_sidelobe(h.as_slice().unwrap(), ROWS, COLS, 4.0);
        // 48 blurred caustics in a 51 px aperture: about 3-4 across seeds (no mean
        // subtraction; fewer, sharper or more spread-out caustics give more).
        assert!(psr > 3.0, "peak-to-sidelobe {psr}");
        // A flat, caustic-free aperture (every lenslet defocused into a wide blur) has
        // a broad autocorrelation: its ratio is far lower.
        let flat = LensletParams { lenslets: 1, defocus: -0.45, focal_spread: 0.0, ..LensletParams::default() };
        let hf = lenslet_psf(ROWS, COLS, &flat, 4).unwrap();
        let psr_flat = peak_to_sidelobe(hf.as_slice().unwrap(), ROWS, COLS, 4.0);
        assert!(psr_flat < 1.5 && psr > 2.0 * psr_flat, "caustic {psr} vs flat {psr_flat}");
    }

    #[test]
    fn deterministic_for_a_seed_and_varies_with_it() {
        assert_eq!(psf(7), psf(7));
        assert_ne!(psf(7), psf(8));
    }

    #[test]
    fn one_lenslet_focuses_to_its_centre() {
        // An in-focus single lenslet without spread maps every ray to its centre.
        let p = LensletParams { lenslets: 1, focal_spread: 0.0, defocus: 0.0, blur_px: 0.0, ..LensletParams::default() };
        let h = lenslet_psf(ROWS, COLS, &p, 9).unwrap();
        let max = h.iter().cloned().fold(0.0f32, f32::max);
        let nonzero = h.iter().filter(|&&v| v > 0.0).count();
        assert!(nonzero <= 4 && max > 0.25, "{nonzero} pixels, max {max}");
    }

    #[test]
    fn autocorrelation_of_a_point_is_a_point() {
        let mut img = vec![0.0f32; 5 * 6];
        img[2 * 6 + 3] = 2.0;
        img[4 * 6 + 1] = 1.0;
        let r = normalized_autocorrelation(&img, 5, 6);
        assert_eq!(r.dim(), (9, 11));
        assert!((r[(4, 5)] - 1.0).abs() < 1e-6);
        // Shift (2, -2): product 2 * 1 over the peak 5.
        assert!((r[(6, 3)] - 0.4).abs() < 1e-6, "{}", r[(6, 3)]);
        assert!((r[(2, 7)] - 0.4).abs() < 1e-6);
        assert!(r[(0, 0)].abs() < 1e-6);
    }

    #[test]
    fn bad_parameters_are_named() {
        let p = LensletParams { supersample: 0, ..LensletParams::default() };
        assert!(lenslet_psf(8, 8, &p, 0).unwrap_err().to_string().contains("supersample"));
        let p = LensletParams { aperture_fraction: 1.5, ..LensletParams::default() };
        assert!(lenslet_psf(8, 8, &p, 0).unwrap_err().to_string().contains("aperture_fraction"));
    }
}
