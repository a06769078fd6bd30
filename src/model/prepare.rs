//! Turning a raw capture and a PSF image into solver inputs: dark level, d x d box-mean
//! downsampling (raw and PSF alike), PSF normalisation to unit sum, and the checks that
//! catch bad input before anything is solved. Data keep their physical scale (counts
//! above dark); nothing is normalised to its own maximum.

pub use crate::model::resample::box_downsample;
use ndarray::{Array2, Array3, ArrayView3, Axis};

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PrepareError {
    #[error("{what}: size {got_rows} x {got_cols} does not match {expected}")]
    Size { what: String, got_rows: usize, got_cols: usize, expected: String },
    #[error("{what}: {got} channels, expected {expected}")]
    Channels { what: String, got: usize, expected: String },
    #[error("{what}: contains {count} NaN or infinite values (first at row {row}, col {col})")]
    NonFinite { what: String, count: usize, row: usize, col: usize },
    #[error("{what}: channel {channel} is all zero after subtracting the dark level {dark}: expected a point-source image")]
    ZeroPsf { what: String, channel: usize, dark: f64 },
}

/// Dark level estimated from the darkest pixels: the mode of the histogram of the
/// darkest 20% of pixels (the dark-current-plus-read-noise peak, assuming at least
/// that share of the sensor sees no light, as outside a diffuser's aperture).
pub fn estimate_dark(values: &[f32]) -> f64 {
    let mut v: Vec<f32> = values.iter().cloned().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return 0.0;
    }
    let cut = ((v.len() as f64 * 0.2).ceil() as usize).clamp(1, v.len());
    v.select_nth_unstable_by(cut - 1, |a, b| a.total_cmp(b));
    let low = &mut v[..cut];
    let (lo, hi) = low.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    if hi <= lo {
        return lo as f64;
    }
    // Integer counts: one bin per count; otherwise (or for a huge range) 64 bins.
    let span = (hi - lo) as f64;
    let integer = low.iter().all(|x| x.fract() == 0.0) && span < 4096.0;
    let (bins, width) = if integer { (span as usize + 1, 1.0) } else { (64, span / 64.0) };
    let mut hist = vec![0usize; bins];
    for &x in low.iter() {
        let b = (((x - lo) as f64) / width) as usize;
        hist[b.min(bins - 1)] += 1;
    }
    // Most populated bin; the darkest one on ties.
    let best = (0..bins).max_by_key(|&i| (hist[i], usize::MAX - i)).unwrap();
    if integer {
        lo as f64 + best as f64
    } else {
        lo as f64 + (best as f64 + 0.5) * width
    }
}

fn check_finite(what: &str, img: ArrayView3<f32>) -> Result<(), PrepareError> {
    let mut count = 0;
    let mut first = None;
    for ((r, c, _), v) in img.indexed_iter() {
        if !v.is_finite() {
            count += 1;
            first.get_or_insert((r, c));
        }
    }
    match first {
        None => Ok(()),
        Some((row, col)) => Err(PrepareError::NonFinite { what: what.into(), count, row, col }),
    }
}

/// One colour plane ready for the solver.
#[derive(Clone, Debug)]
pub struct Plane {
    pub rows: usize,
    pub cols: usize,
    pub data: Vec<f32>,
}

/// Prepared inputs: per channel, the measurement (dark-subtracted, downsampled) and the
/// PSF (dark-subtracted, clamped at 0, downsampled, unit sum).
#[derive(Clone, Debug)]
pub struct Prepared {
    pub raw: Vec<Plane>,
    pub psf: Vec<Plane>,
    pub raw_dark: f64,
    pub psf_dark: f64,
    /// Whether the dark levels were estimated (no `dark_level` given).
    pub dark_estimated: bool,
}

/// Prepare a raw image and a PSF image (both (row, col, channel)) for a capture whose
/// raw size is `rows x cols`, downsampled by `d`.
#[allow(clippy::too_many_arguments)]
pub fn prepare(
    raw: ArrayView3<f32>,
    raw_name: &str,
    psf: ArrayView3<f32>,
    psf_name: &str,
    rows: usize,
    cols: usize,
    d: usize,
    dark_level: Option<f64>,
) -> Result<Prepared, PrepareError> {
    let (rr, rc, rch) = raw.dim();
    let (pr, pc, pch) = psf.dim();
    if (rr, rc) != (rows, cols) {
        return Err(PrepareError::Size { what: raw_name.into(), got_rows: rr, got_cols: rc, expected: format!("the capture's rows x cols ({rows} x {cols})") });
    }
    if (pr, pc) != (rr, rc) {
        return Err(PrepareError::Size { what: psf_name.into(), got_rows: pr, got_cols: pc, expected: format!("the raw image {raw_name} ({rr} x {rc})") });
    }
    if !(rch == 1 || rch == 3) {
        return Err(PrepareError::Channels { what: raw_name.into(), got: rch, expected: "1 (grey) or 3 (RGB)".into() });
    }
    if pch != rch {
        return Err(PrepareError::Channels { what: psf_name.into(), got: pch, expected: format!("{rch}, as in the raw image {raw_name}") });
    }
    check_finite(raw_name, raw)?;
    check_finite(psf_name, psf)?;
    let dark_estimated = dark_level.is_none();
    let raw_dark = dark_level.unwrap_or_else(|| estimate_dark(raw.as_standard_layout().as_slice().unwrap()));
    let psf_dark = dark_level.unwrap_or_else(|| estimate_dark(psf.as_standard_layout().as_slice().unwrap()));
    let plane = |img: &ArrayView3<f32>, ch: usize| -> Vec<f32> { img.index_axis(Axis(2), ch).iter().cloned().collect() };
    let mut out = Prepared { raw: Vec::new(), psf: Vec::new(), raw_dark, psf_dark, dark_estimated };
    for ch in 0..rch {
        let r: Vec<f32> = plane(&raw, ch).iter().map(|v| (*v as f64 - raw_dark) as f32).collect();
        let (data, m, n) = box_downsample(&r, rows, cols, d);
        out.raw.push(Plane { rows: m, cols: n, data });
        let p: Vec<f32> = plane(&psf, ch).iter().map(|v| ((*v as f64 - psf_dark) as f32).max(0.0)).collect();
        // Blocks centred on the PSF's centre pixel, so the model registers with the
        // box-mean video (see `resample::box_downsample_psf_centred`).
        let (mut data, m, n) = crate::model::resample::box_downsample_psf_centred(&p, rows, cols, d);
        let sum: f64 = data.iter().map(|&v| v as f64).sum();
        if !(sum > 0.0) {
            return Err(PrepareError::ZeroPsf { what: psf_name.into(), channel: ch, dark: psf_dark });
        }
        let inv = (1.0 / sum) as f32;
        data.iter_mut().for_each(|v| *v *= inv);
        out.psf.push(Plane { rows: m, cols: n, data });
    }
    Ok(out)
}

/// An (rows, cols, 1) image from a row-major plane.
pub fn grey_image(data: &[f32], rows: usize, cols: usize) -> Array3<f32> {
    Array2::from_shape_vec((rows, cols), data.to_vec()).unwrap().insert_axis(Axis(2))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_mean_and_crop() {
        let img: Vec<f32> = (0..20).map(|v| v as f32).collect(); // 4 x 5
        let (o, r, c) = box_downsample(&img, 4, 5, 2);
        assert_eq!((r, c), (2, 2));
        assert_eq!(o, vec![(0. + 1. + 5. + 6.) / 4., (2. + 3. + 7. + 8.) / 4., (10. + 11. + 15. + 16.) / 4., (12. + 13. + 17. + 18.) / 4.]);
    }

    #[test]
    fn dark_estimate_finds_the_noise_peak() {
        // 70% dark pixels around 100 ADU (+-2), 30% bright.
        let mut v = Vec::new();
        for i in 0..7000 {
            v.push(100.0 + ((i * 7919) % 5) as f32 - 2.0);
        }
        for i in 0..3000 {
            v.push(500.0 + (i % 300) as f32);
        }
        let d = estimate_dark(&v);
        assert!((d - 100.0).abs() <= 2.0, "{d}");
    }

    #[test]
    fn psf_is_unit_sum_and_errors_name_the_file() {
        let raw = Array3::<f32>::from_elem((4, 4, 1), 10.0);
        let mut psf = Array3::<f32>::from_elem((4, 4, 1), 5.0);
        psf[[1, 2, 0]] = 25.0;
        let p = prepare(raw.view(), "raw.tiff", psf.view(), "psf.tiff", 4, 4, 1, Some(5.0)).unwrap();
        let s: f32 = p.psf[0].data.iter().sum();
        assert!((s - 1.0).abs() < 1e-6);
        assert_eq!(p.raw[0].data[0], 5.0);

        let zero = Array3::<f32>::from_elem((4, 4, 1), 5.0);
        let e = prepare(raw.view(), "raw.tiff", zero.view(), "psf.tiff", 4, 4, 1, Some(5.0)).unwrap_err();
        assert!(e.to_string().contains("psf.tiff") && e.to_string().contains("all zero"));

        let mut nan = psf.clone();
        nan[[2, 3, 0]] = f32::NAN;
        let e = prepare(raw.view(), "raw.tiff", nan.view(), "psf.tiff", 4, 4, 1, Some(5.0)).unwrap_err();
        assert_eq!(e, PrepareError::NonFinite { what: "psf.tiff".into(), count: 1, row: 2, col: 3 });

        let small = Array3::<f32>::from_elem((3, 4, 1), 5.0);
        let e = prepare(raw.view(), "raw.tiff", small.view(), "psf.tiff", 4, 4, 1, None).unwrap_err();
        assert!(e.to_string().contains("psf.tiff") && e.to_string().contains("3 x 4"));

        let rgb = Array3::<f32>::from_elem((4, 4, 3), 5.0);
        let e = prepare(raw.view(), "raw.tiff", rgb.view(), "psf.tiff", 4, 4, 1, None).unwrap_err();
        assert!(matches!(e, PrepareError::Channels { .. }));

        let e = prepare(raw.view(), "raw.tiff", psf.view(), "psf.tiff", 5, 4, 1, None).unwrap_err();
        assert!(e.to_string().contains("raw.tiff") && e.to_string().contains("5 x 4"));
    }
}
