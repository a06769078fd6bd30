//! Turning a raw capture and a PSF image into solver inputs: dark (one level, or per
//! pixel from a calibration, or a background frame), defective pixels left out of the
//! data term and clipped ones kept as lower bounds, d x d box-mean downsampling (raw and PSF alike), PSF
//! normalisation to unit sum, and the checks that catch bad input before anything is
//! solved. Data keep their physical scale (counts
//! above dark); nothing is normalised to its own maximum.

use crate::model::capture::CaptureConfig;
pub use crate::model::resample::box_downsample;
use crate::model::sensor::{find_outliers, median_in_place, pixel_noise, repair, saturation_pile, Calibration, Defect};
use ndarray::{Array2, ArrayView3, Axis, Zip};
use serde::Serialize;

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PrepareError {
    #[error("{what}: size {got_rows} x {got_cols} does not match {expected}")]
    Size { what: String, got_rows: usize, got_cols: usize, expected: String },
    #[error("{what}: {got} channels, expected {expected}")]
    Channels { what: String, got: usize, expected: String },
    #[error("{what}: contains {count} NaN or infinite values (first at row {row}, col {col})")]
    NonFinite { what: String, count: usize, row: usize, col: usize },
    #[error("{what}: a value of {value:e} at row {row}, col {col}: expected counts of at most {MAX_DATA_VALUE:e} in magnitude (beyond, the solver's f32 products overflow and the video is garbage)")]
    OutOfRange { what: String, value: f32, row: usize, col: usize },
    #[error("{what}: channel {channel} is all zero after subtracting the dark level {dark}: expected a point-source image")]
    ZeroPsf { what: String, channel: usize, dark: f64 },
    #[error("{what}: no pixel is above the dark level ({dark}; the raw's largest value is {max} counts{defective}): no light to reconstruct from; check the dark level, the background, or the exposure")]
    NoLight { what: String, dark: String, max: f32, defective: String },
    #[error("{what}: channel {channel} is {value} counts at every pixel (all clipped, or no light): expected a point-source image")]
    FlatPsf { what: String, channel: usize, value: f32 },
    #[error("{what}: no pixel measures the light ({saturated} at or above the saturation level {level}, the rest defective): nothing to reconstruct from; shorten the exposure or dim the scene")]
    AllMasked { what: String, saturated: usize, level: f64 },
}

/// The one rule for a PSF of another size than the raw (`rows x cols`): a PSF exactly k
/// times the raw's size on both axes (k an integer, e.g. measured at full resolution for
/// a raw binned by k) is box-averaged by k (k x k blocks from the top-left corner, as a
/// camera bins); the factor returned (1: same size). Any other size is refused with the
/// ratios found and what would be taken.
pub fn psf_scale(psf_name: &str, (pr, pc, _): (usize, usize, usize), raw_name: &str, (rows, cols): (usize, usize)) -> Result<usize, PrepareError> {
    if (pr, pc) == (rows, cols) {
        return Ok(1);
    }
    let k = pr / rows.max(1);
    if k >= 2 && (pr, pc) == (k * rows, k * cols) {
        return Ok(k);
    }
    let expected = if rows > 0 && cols > 0 && rows % pr.max(1) == 0 && (rows / pr.max(1)) * pc == cols {
        format!(
            "the raw image {raw_name} ({rows} x {cols}), which is {} times the PSF's size: give a raw of the PSF's size (or a PSF of the raw's)",
            rows / pr.max(1)
        )
    } else {
        format!(
            "the raw image {raw_name} ({rows} x {cols}) or an integer multiple of it on both axes (box-averaged down); it is {:.4} x {:.4} times the raw's",
            pr as f64 / rows.max(1) as f64,
            pc as f64 / cols.max(1) as f64
        )
    };
    Err(PrepareError::Size { what: psf_name.into(), got_rows: pr, got_cols: pc, expected })
}

/// Box mean of `k x k` blocks of every channel of `img` (rows and columns beyond a
/// multiple of k dropped).
fn box_downsample_channels(img: ArrayView3<f32>, k: usize) -> ndarray::Array3<f32> {
    let (r, c, ch) = img.dim();
    let mut out = ndarray::Array3::<f32>::zeros((r / k, c / k, ch));
    for channel in 0..ch {
        let plane: Vec<f32> = img.index_axis(Axis(2), channel).iter().copied().collect();
        let (small, _, _) = box_downsample(&plane, r, c, k);
        out.index_axis_mut(Axis(2), channel).iter_mut().zip(small).for_each(|(o, v)| *o = v);
    }
    out
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

/// The largest magnitude a raw or PSF value may have: far above any sensor's counts,
/// and low enough that its square (the data term's) stays inside f32's range (3.4e38).
pub const MAX_DATA_VALUE: f32 = 1e18;

/// Refuses NaN/Inf and values beyond [`MAX_DATA_VALUE`], naming the first.
fn check_finite(what: &str, img: ArrayView3<f32>) -> Result<(), PrepareError> {
    let mut count = 0;
    let mut first = None;
    let mut huge = None;
    for ((r, c, _), v) in img.indexed_iter() {
        if !v.is_finite() {
            count += 1;
            first.get_or_insert((r, c));
        } else if v.abs() > MAX_DATA_VALUE && huge.is_none() {
            huge = Some((*v, r, c));
        }
    }
    match (first, huge) {
        (Some((row, col)), _) => Err(PrepareError::NonFinite { what: what.into(), count, row, col }),
        (None, Some((value, row, col))) => Err(PrepareError::OutOfRange { what: what.into(), value, row, col }),
        (None, None) => Ok(()),
    }
}

/// One colour plane ready for the solver.
#[derive(Clone, Debug, Default)]
pub struct Plane {
    pub rows: usize,
    pub cols: usize,
    pub data: Vec<f32>,
}

/// What the bench knows about the sensor beyond `capture.toml`, for one capture.
#[derive(Clone, Copy, Debug)]
pub struct SensorInput<'a> {
    /// A bench calibration (per-pixel dark, defect map, saturation level, background).
    pub calibration: Option<&'a Calibration>,
    /// A background frame **as shot** (dark included): subtracted in place of the dark.
    /// Wins over the calibration's background.
    pub background: Option<ArrayView3<'a, f32>>,
    /// The raw file's full scale (255 for 8-bit, 65535 for 16-bit samples), when its
    /// format has one: the saturation level when nothing else names it.
    pub file_full_scale: Option<f64>,
    /// The PSF file's own full scale (255 for 8-bit, 65535 for 16-bit samples), when
    /// its format has one: a PSF recorded at another bit depth than the raw is judged
    /// by it, not by the raw's saturation level.
    pub psf_full_scale: Option<f64>,
    /// The raw file's own black level (a DNG's BlackLevel), when it has one: the dark
    /// level when the capture description gives none and no frame is subtracted.
    pub file_dark_level: Option<f64>,
    /// The PSF file's own black level (a DNG's BlackLevel), likewise for the PSF.
    pub psf_file_dark_level: Option<f64>,
    /// The PSF's black offset as given (counts): wins over every other dark level for
    /// the PSF (a PSF shot with another offset than the raw).
    pub psf_dark_level: Option<f64>,
    /// The PSF is already dark-subtracted (a calibration's `psf.tiff`).
    pub psf_clean: bool,
    /// Look for isolated hot and dead pixels in the raw ([`find_outliers`]).
    pub find_outliers: bool,
    /// Key frames from a second, global-shutter camera, as read.
    pub keyframes: &'a [KeyFrameImage],
}

impl Default for SensorInput<'_> {
    fn default() -> Self {
        SensorInput {
            calibration: None,
            background: None,
            file_full_scale: None,
            psf_full_scale: None,
            file_dark_level: None,
            psf_file_dark_level: None,
            psf_dark_level: None,
            psf_clean: false,
            find_outliers: true,
            keyframes: &[],
        }
    }
}

pub use crate::model::mask::DataMask;

/// Where the dark subtracted from the raw came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum DarkSource {
    /// A background frame as shot (its dark included).
    Background,
    /// The calibration's per-pixel dark (`dark.tiff`).
    Calibration,
    /// `dark_level` of the capture description: one number for the whole sensor.
    CaptureToml,
    /// The raw file's own black level (a DNG's BlackLevel).
    FileBlackLevel,
    /// Estimated from the raw's darkest pixels.
    #[default]
    Estimated,
}

/// Where the saturation level came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum SaturationSource {
    /// `saturation_level` of the capture description.
    CaptureToml,
    /// The calibration record's `saturation_level`.
    Calibration,
    /// A pile of pixels at the raw's largest value ([`saturation_pile`]).
    PileAtMaximum,
    /// The raw file's sample format (255, 65535).
    FileFullScale,
}

/// What sensor handling did to one capture (`summary.json`'s `sensor`).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SensorReport {
    pub dark_source: DarkSource,
    /// The clipping level used (counts), and where it came from; absent when unknown.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub saturation_level: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub saturation_source: Option<SaturationSource>,
    /// Raw pixels at or above the saturation level (any channel) that are not defects,
    /// and their share.
    pub saturated_pixels: usize,
    pub saturated_fraction: f64,
    /// Defective pixels of the calibration's map.
    pub calibration_defects: usize,
    /// Isolated hot and dead pixels found in the raw against their neighbourhood.
    pub outliers_hot: usize,
    pub outliers_dead: usize,
    /// The noise the outlier threshold was set from (counts rms).
    pub noise_counts: f64,
    /// Pixels of the solved sensor grid (after downsampling) left out of the data term
    /// (defects), and their share.
    pub masked_pixels: usize,
    pub masked_fraction: f64,
    /// Pixels of the solved grid whose value is a lower bound (clipped): the data term
    /// is one-sided there (the model may exceed them, not fall short).
    pub lower_bound_pixels: usize,
    /// PSF pixels replaced from their neighbours (calibration defects, clipped).
    pub psf_repaired: usize,
    /// The factor k the PSF was box-averaged by to the raw's size (see [`psf_scale`];
    /// 1: it had the raw's size).
    pub psf_downsampled: usize,
    /// What a user must know (printed and recorded).
    pub warnings: Vec<String>,
}

/// More saturated raw pixels than this share is a warning.
pub const SATURATION_WARNING_FRACTION: f64 = 1e-3;
/// Outliers lie this many noise sigmas (plus a level term) beyond their neighbours.
pub const OUTLIER_SIGMAS: f64 = 6.0;

/// Prepared inputs: per channel, the measurement (dark-subtracted, downsampled) and the
/// PSF (dark-subtracted, clamped at 0, downsampled, unit sum), and what the data term
/// does with each pixel of the solved grid ([`DataMask`], shared by the channels).
#[derive(Clone, Debug, Default)]
pub struct Prepared {
    pub raw: Vec<Plane>,
    pub psf: Vec<Plane>,
    pub raw_dark: f64,
    pub psf_dark: f64,
    /// Whether the dark levels were estimated (no `dark_level` given).
    pub dark_estimated: bool,
    /// The data term's mask (defects left out) and lower bounds (clipped pixels).
    pub data_mask: DataMask,
    pub sensor: SensorReport,
    /// Key frames, one plane per raw channel each ([`crate::model::keyframe`]).
    pub keyframes: Vec<PreparedKeyFrame>,
}

/// Prepare a raw image and a PSF image (both (row, col, channel)) for the capture `cfg`
/// describes, with what `sensor` knows about the sensor:
/// 1. the saturation level (capture.toml, else the calibration, else a pile at the
///    raw's maximum, else the file's full scale) marks clipped pixels;
/// 2. the dark is subtracted: a background frame as shot, else the calibration's
///    per-pixel dark, else `dark_level`, else an estimate;
/// 3. defects (the calibration's map, and isolated outliers found in the raw, a lone
///    clipped pixel among them) are left out: a d x d block is the mean of its good
///    pixels, masked out of the data term when fewer than half are good, and a lower
///    bound when one of its good pixels clipped. The raw values are not altered
///    anywhere else;
/// 4. the PSF's defects and clipped pixels are repaired from their neighbours (a PSF
///    cannot be masked), then it is downsampled and normalised.
pub fn prepare(
    raw: ArrayView3<f32>,
    raw_name: &str,
    psf: ArrayView3<f32>,
    psf_name: &str,
    cfg: &CaptureConfig,
    sensor: &SensorInput,
) -> Result<Prepared, PrepareError> {
    let (rows, cols) = (cfg.rows, cfg.cols);
    let (rr, rc, _) = raw.dim();
    if (rr, rc) != (rows, cols) {
        return Err(PrepareError::Size { what: raw_name.into(), got_rows: rr, got_cols: rc, expected: format!("the capture's rows x cols ({rows} x {cols})") });
    }
    let psf_factor = psf_scale(psf_name, psf.dim(), raw_name, (rr, rc))?;
    let psf_fitted = (psf_factor > 1).then(|| box_downsample_channels(psf, psf_factor));
    let psf = match &psf_fitted {
        Some(fitted) => fitted.view(),
        None => psf.reborrow(),
    };
    let frames = SensorFrames::checked(raw, raw_name, psf, psf_name, (rows, cols), sensor)?;
    let mut report = SensorReport { psf_downsampled: psf_factor, ..SensorReport::default() };
    let raw_std = raw.as_standard_layout();
    let raw_flat = raw_std.as_slice().unwrap();

    // 1. Clipped pixels.
    let saturated = clipped_pixels(raw, raw_flat, cfg, sensor, &mut report);
    // 2. The dark.
    let dark = subtract_dark(raw, raw_flat, cfg, sensor.file_dark_level, &frames);
    report.dark_source = dark.source;
    let mut planes = dark.planes;
    // 3. Defects: the calibration's map and isolated outliers.
    let bad = defective_pixels(&planes, &frames, (rows, cols), sensor.find_outliers, &mut report);
    if !planes.iter().any(|p| p.iter().zip(&bad).any(|(&v, &b)| v > 0.0 && !b)) {
        return Err(no_light(raw, raw_name, &bad, cols, dark.source, dark.level));
    }
    // Clipped light: clipped pixels that are not defects.
    report.saturated_pixels = saturated.iter().zip(&bad).filter(|&(&s, &b)| s && !b).count();
    report.saturated_fraction = report.saturated_pixels as f64 / (rows * cols) as f64;

    // 4. The data on the solved grid, its mask (defects) and its lower bounds (clipped).
    let mut out = Prepared { raw_dark: dark.level, dark_estimated: dark.source == DarkSource::Estimated, ..Prepared::default() };
    let (raw_planes, data_mask) = solved_grid(&mut planes, &bad, &saturated, cfg, raw_name, &mut report)?;
    out.raw = raw_planes;
    out.data_mask = data_mask;

    // 5. The PSF: dark, repaired defects and clipped pixels, downsampled, unit sum.
    let (psf_dark, psf_sat) = psf_levels(psf, cfg, sensor);
    out.psf_dark = psf_dark;
    for ch in 0..psf.dim().2 {
        out.psf.push(prepared_psf(psf, psf_name, ch, (psf_dark, psf_sat), frames.defects, cfg, &mut report)?);
    }
    if let Some(w) = dark_above_psf(raw_name, psf_name, (dark.level, dark.source), psf_dark, sensor) {
        report.warnings.push(w);
    }
    if report.saturated_fraction > SATURATION_WARNING_FRACTION {
        report.warnings.push(format!(
            "{raw_name}: {} pixels ({:.2}%) at or above the saturation level {} ({}): kept as lower bounds (the data term is one-sided there); shorten the exposure or dim the scene",
            report.saturated_pixels,
            100.0 * report.saturated_fraction,
            report.saturation_level.unwrap_or(f64::NAN),
            report.saturation_source.map(|s| s.describe()).unwrap_or("unknown"),
        ));
    }
    out.sensor = report;
    let video = match cfg.fov {
        crate::model::capture::Fov::Sensor => cfg.grid(),
        crate::model::capture::Fov::Full => (2 * cfg.grid().0 - 1, 2 * cfg.grid().1 - 1),
    };
    out.keyframes = sensor.keyframes.iter().map(|k| prepare_keyframe(k, out.raw.len(), video)).collect::<Result<_, _>>()?;
    Ok(out)
}

/// The frames beside the raw that [`prepare`] reads, checked against it: a background
/// frame as shot (given, else the calibration's), the calibration's per-pixel dark and
/// its defect map.
struct SensorFrames<'a> {
    background: Option<ArrayView3<'a, f32>>,
    dark_map: Option<&'a ndarray::Array3<f32>>,
    defects: Option<&'a Array2<u8>>,
}

impl<'a> SensorFrames<'a> {
    /// The channels of the raw and the PSF, every value finite, and the sensor's frames
    /// of the raw's size and channels.
    fn checked(
        raw: ArrayView3<f32>,
        raw_name: &str,
        psf: ArrayView3<f32>,
        psf_name: &str,
        (rows, cols): (usize, usize),
        sensor: &SensorInput<'a>,
    ) -> Result<Self, PrepareError> {
        let rch = raw.dim().2;
        if !(rch == 1 || rch == 3) {
            return Err(PrepareError::Channels { what: raw_name.into(), got: rch, expected: "1 (grey) or 3 (RGB)".into() });
        }
        if psf.dim().2 != rch {
            return Err(PrepareError::Channels { what: psf_name.into(), got: psf.dim().2, expected: format!("{rch}, as in the raw image {raw_name}") });
        }
        check_finite(raw_name, raw)?;
        check_finite(psf_name, psf)?;
        let cal = sensor.calibration;
        let check = |what: &str, img: ArrayView3<f32>| -> Result<(), PrepareError> {
            let (r, c, ch) = img.dim();
            if (r, c) != (rows, cols) {
                return Err(PrepareError::Size {
                    what: what.into(),
                    got_rows: r,
                    got_cols: c,
                    expected: format!("the raw image {raw_name} ({rows} x {cols})"),
                });
            }
            if ch != rch {
                return Err(PrepareError::Channels { what: what.into(), got: ch, expected: format!("{rch}, as in the raw image {raw_name}") });
            }
            check_finite(what, img)
        };
        let background = sensor.background.or_else(|| cal.and_then(|c| c.background.as_ref()).map(|b| b.view()));
        if let Some(b) = background {
            check("the background frame", b)?;
        }
        let dark_map = cal.and_then(|c| c.dark.as_ref());
        if let Some(dm) = dark_map {
            check("the calibration's dark.tiff", dm.view())?;
        }
        let defects = cal.and_then(|c| c.defects.as_ref());
        if let Some(m) = defects {
            if m.dim() != (rows, cols) {
                return Err(PrepareError::Size {
                    what: "the calibration's defects.tiff".into(),
                    got_rows: m.dim().0,
                    got_cols: m.dim().1,
                    expected: format!("the raw image {raw_name} ({rows} x {cols})"),
                });
            }
        }
        Ok(SensorFrames { background, dark_map, defects })
    }
}

/// Step 1 of [`prepare`]: the raw's clipped pixels (row-major), at the saturation level
/// of capture.toml, else the calibration's, else a pile at the raw's maximum, else the
/// file's full scale; the level and its source go in `report`.
fn clipped_pixels(raw: ArrayView3<f32>, raw_flat: &[f32], cfg: &CaptureConfig, sensor: &SensorInput, report: &mut SensorReport) -> Vec<bool> {
    let cal = sensor.calibration;
    let cols = cfg.cols;
    let declared = cfg
        .saturation_level
        .map(|v| (v, SaturationSource::CaptureToml))
        .or_else(|| cal.and_then(|c| c.record.saturation_level).map(|v| (v, SaturationSource::Calibration)));
    let level = declared
        .or_else(|| saturation_pile(raw_flat).map(|v| (v, SaturationSource::PileAtMaximum)))
        .or_else(|| sensor.file_full_scale.map(|v| (v, SaturationSource::FileFullScale)));
    let mut saturated = vec![false; cfg.rows * cols];
    if let Some((lv, source)) = level {
        report.saturation_level = Some(lv);
        report.saturation_source = Some(source);
        for ((r, c, _), &v) in raw.indexed_iter() {
            if v as f64 >= lv {
                saturated[r * cols + c] = true;
            }
        }
    }
    saturated
}

/// Step 2 of [`prepare`]: each channel of the raw less its dark.
struct DarkSubtracted {
    planes: Vec<Array2<f32>>,
    source: DarkSource,
    /// The scalar reported: the dark level, or the mean of a per-pixel dark.
    level: f64,
}

/// The dark subtracted: a background frame as shot, else the calibration's per-pixel
/// dark, else `dark_level`, else the raw file's black level, else an estimate from the
/// raw's darkest pixels.
fn subtract_dark(raw: ArrayView3<f32>, raw_flat: &[f32], cfg: &CaptureConfig, file_dark: Option<f64>, frames: &SensorFrames) -> DarkSubtracted {
    let (source, level) = if frames.background.is_some() {
        (DarkSource::Background, f64::NAN)
    } else if frames.dark_map.is_some() {
        (DarkSource::Calibration, f64::NAN)
    } else if let Some(l) = cfg.dark_level {
        (DarkSource::CaptureToml, l)
    } else if let Some(l) = file_dark {
        (DarkSource::FileBlackLevel, l)
    } else {
        (DarkSource::Estimated, estimate_dark(raw_flat))
    };
    let per_pixel = frames.background.or(frames.dark_map.map(|d| d.view()));
    let planes: Vec<Array2<f32>> = (0..raw.dim().2)
        .map(|ch| {
            let r = raw.index_axis(Axis(2), ch);
            match per_pixel {
                Some(dm) => Zip::from(&r).and(&dm.index_axis(Axis(2), ch)).map_collect(|&v, &dk| (v as f64 - dk as f64) as f32),
                None => r.mapv(|v| (v as f64 - level) as f32),
            }
        })
        .collect();
    let level = match per_pixel {
        Some(dm) => dm.iter().map(|&v| v as f64).sum::<f64>() / dm.len().max(1) as f64,
        None => level,
    };
    DarkSubtracted { planes, source, level }
}

/// Step 3 of [`prepare`]: the defective pixels (row-major): the calibration's map and,
/// when `find`, isolated outliers of the dark-subtracted planes; counted in `report`.
fn defective_pixels(planes: &[Array2<f32>], frames: &SensorFrames, (rows, cols): (usize, usize), find: bool, report: &mut SensorReport) -> Vec<bool> {
    let mut bad = vec![false; rows * cols];
    if let Some(m) = frames.defects {
        for ((r, c), &code) in m.indexed_iter() {
            if code != Defect::Good.code() {
                bad[r * cols + c] = true;
            }
        }
        report.calibration_defects = bad.iter().filter(|&&b| b).count();
    }
    if !find {
        return bad;
    }
    // The pixel noise, floored at 1% of the median level: a noise-free image (a
    // simulation) has smooth minima and maxima that are not defects.
    let mut noise = 0.0f64;
    for p in planes {
        let mut level: Vec<f32> = p.iter().map(|v| v.abs()).collect();
        noise = noise.max(pixel_noise(p.view()).max(0.01 * median_in_place(&mut level) as f64));
    }
    report.noise_counts = noise;
    for p in planes {
        let found = find_outliers(p.view(), noise, 0.0, OUTLIER_SIGMAS);
        for ((r, c), &code) in found.indexed_iter() {
            let i = r * cols + c;
            // A lone clipped pixel far above its neighbours is a hot pixel, not light.
            if code != 0 && !bad[i] {
                bad[i] = true;
                if code == Defect::Hot.code() {
                    report.outliers_hot += 1;
                } else {
                    report.outliers_dead += 1;
                }
            }
        }
    }
    bad
}

/// The refusal of a raw with no light: no good pixel above the dark (an 8-bit export
/// under dark_level = 100, a constant raw, the raw given as its own background), refused
/// like an all-clipped raw. The largest value named is a measuring pixel's; brighter
/// defective pixels (a hot pixel at full scale) are said apart, not given as the raw's
/// light.
fn no_light(raw: ArrayView3<f32>, raw_name: &str, bad: &[bool], cols: usize, source: DarkSource, raw_dark: f64) -> PrepareError {
    let dark = match source {
        DarkSource::Background => format!("the background frame, pixel by pixel: {raw_dark} counts on average"),
        DarkSource::Calibration => format!("the calibration's dark frame, pixel by pixel: {raw_dark} counts on average"),
        DarkSource::CaptureToml => format!("dark_level = {raw_dark} of the capture description"),
        DarkSource::FileBlackLevel => format!("the raw file's black level, {raw_dark} counts"),
        DarkSource::Estimated => format!("{raw_dark} counts, estimated from the darkest pixels"),
    };
    let (mut max, mut max_bad, mut n_bad) = (f32::NEG_INFINITY, f32::NEG_INFINITY, 0usize);
    for ((r, c, _), &v) in raw.indexed_iter() {
        if bad[r * cols + c] {
            max_bad = max_bad.max(v);
            n_bad += 1;
        } else {
            max = max.max(v);
        }
    }
    let defective = if max_bad > max {
        format!(" outside the {} defective pixel value(s) (hot, stuck or outliers, the brightest at {max_bad} counts), which measure no light", n_bad)
    } else {
        String::new()
    };
    PrepareError::NoLight { what: raw_name.into(), dark, max, defective }
}

/// Step 4 of [`prepare`]: the data on the solved grid (d x d blocks) and the data
/// term's mask and lower bounds, when any pixel is defective or clipped; a raw whose
/// every block is masked or a lower bound is refused.
fn solved_grid(
    planes: &mut [Array2<f32>],
    bad: &[bool],
    saturated: &[bool],
    cfg: &CaptureConfig,
    raw_name: &str,
    report: &mut SensorReport,
) -> Result<(Vec<Plane>, DataMask), PrepareError> {
    let (rows, cols, d) = (cfg.rows, cfg.cols, cfg.downsample);
    let any_bad = bad.iter().any(|&b| b) || report.saturated_pixels > 0;
    let mut out = Vec::with_capacity(planes.len());
    let (mut mask, mut lower) = (None, None);
    for p in planes.iter_mut() {
        let flat = p.as_slice().unwrap();
        if any_bad {
            let (data, m, n, mk, lb) = masked_box_downsample(flat, bad, saturated, rows, cols, d);
            out.push(Plane { rows: m, cols: n, data });
            mask = Some(mk);
            lower = Some(lb);
        } else {
            let (data, m, n) = box_downsample(flat, rows, cols, d);
            out.push(Plane { rows: m, cols: n, data });
        }
    }
    if let (Some(mk), Some(lb)) = (&mask, &lower) {
        report.masked_pixels = mk.iter().filter(|&&v| v == 0.0).count();
        report.masked_fraction = report.masked_pixels as f64 / mk.len().max(1) as f64;
        report.lower_bound_pixels = lb.iter().filter(|&&l| l).count();
        if report.masked_pixels + report.lower_bound_pixels == mk.len() {
            return Err(PrepareError::AllMasked {
                what: raw_name.into(),
                saturated: report.saturated_pixels,
                level: report.saturation_level.unwrap_or(f64::NAN),
            });
        }
    }
    Ok((out, DataMask { mask: mask.filter(|m| m.contains(&0.0)), lower_bounds: lower.filter(|l| l.iter().any(|&v| v)) }))
}

/// Step 5 of [`prepare`], channel `ch` of the PSF: refused when flat; less its dark,
/// clamped at 0; defects and clipped pixels repaired from their neighbours (a PSF
/// cannot be masked); downsampled in blocks centred on its centre pixel; unit sum.
fn prepared_psf(
    psf: ArrayView3<f32>,
    psf_name: &str,
    ch: usize,
    (psf_dark, psf_sat): (f64, Option<f64>),
    defects: Option<&Array2<u8>>,
    cfg: &CaptureConfig,
    report: &mut SensorReport,
) -> Result<Plane, PrepareError> {
    let (rows, cols, d) = (cfg.rows, cfg.cols, cfg.downsample);
    let plane = psf.index_axis(Axis(2), ch);
    let first = plane[[0, 0]];
    if plane.iter().all(|&v| v == first) {
        return Err(PrepareError::FlatPsf { what: psf_name.into(), channel: ch, value: first });
    }
    let mut p: Array2<f32> = plane.mapv(|v| ((v as f64 - psf_dark) as f32).max(0.0));
    let mut fix = Array2::from_elem((rows, cols), false);
    if let Some(m) = defects {
        Zip::from(&mut fix).and(m).for_each(|f, &code| *f = code != Defect::Good.code());
    }
    if let Some(lv) = psf_sat {
        Zip::from(&mut fix).and(&plane).for_each(|f, &v| *f |= v as f64 >= lv);
    }
    if fix.iter().any(|&f| f) {
        report.psf_repaired += repair(&mut p, &fix);
    }
    // Blocks centred on the PSF's centre pixel, so the model registers with the
    // box-mean video (see `resample::box_downsample_psf_centred`).
    let (mut data, m, n) = crate::model::resample::box_downsample_psf_centred(p.as_slice().unwrap(), rows, cols, d);
    let sum: f64 = data.iter().map(|&v| v as f64).sum();
    if !(sum > 0.0) {
        return Err(PrepareError::ZeroPsf { what: psf_name.into(), channel: ch, dark: psf_dark });
    }
    let inv = (1.0 / sum) as f32;
    data.iter_mut().for_each(|v| *v *= inv);
    Ok(Plane { rows: m, cols: n, data })
}

/// A warning when the raw's dark, estimated from its darkest pixels, sits far above the
/// PSF's (same sample format): a diffuser spreads a bright scene over every pixel, so
/// the darkest pixels are not the dark and the video loses that much light.
fn dark_above_psf(raw_name: &str, psf_name: &str, (raw_dark, source): (f64, DarkSource), psf_dark: f64, sensor: &SensorInput) -> Option<String> {
    let same_format = sensor.file_full_scale == sensor.psf_full_scale;
    let far = raw_dark > 2.0 * psf_dark + 20.0;
    (source == DarkSource::Estimated && !sensor.psf_clean && same_format && far).then(|| {
        format!(
            "{raw_name}: its darkest pixels sit at {raw_dark:.0} counts, {psf_name}'s at {psf_dark:.0}: the raw may have light on every pixel (a diffuser spreads a bright scene over the whole sensor), so its estimated dark level takes that light away; if both come from one camera, give dark_level = {psf_dark:.0} in the capture description (or --dark-level, or a calibration's dark frame)"
        )
    })
}

/// The PSF's dark level and saturation level. A calibration's PSF is already
/// dark-subtracted. A PSF shot with the raw's camera at the raw's bit depth shares the
/// capture's `dark_level` and saturation level (capture.toml, else the calibration's);
/// one recorded at another bit depth (values above that saturation level, or a file
/// whose full scale is below it: a 16-bit PSF beside an 8-bit camera, or the reverse)
/// is judged by its own file: its full scale (else a pile at its maximum) and its own
/// black level (a DNG's), else a dark estimated from its own darkest pixels. Without a
/// `dark_level`, a PSF file's black level comes before the estimate.
fn psf_levels(psf: ArrayView3<f32>, cfg: &CaptureConfig, sensor: &SensorInput) -> (f64, Option<f64>) {
    let capture_sat = cfg.saturation_level.or_else(|| sensor.calibration.and_then(|c| c.record.saturation_level));
    if sensor.psf_clean {
        return (0.0, capture_sat);
    }
    let flat = psf.as_standard_layout();
    let flat = flat.as_slice().unwrap();
    let psf_max = flat.iter().fold(f32::NEG_INFINITY, |m, &v| m.max(v)) as f64;
    let own_scale = capture_sat.is_some_and(|level| psf_max > level || sensor.psf_full_scale.is_some_and(|f| f < level));
    // A dark level given for the PSF wins; else its file's, or the capture's.
    let (given, own_dark) = (sensor.psf_dark_level, sensor.psf_file_dark_level);
    if own_scale {
        (given.or(own_dark).unwrap_or_else(|| estimate_dark(flat)), sensor.psf_full_scale.or_else(|| saturation_pile(flat)))
    } else {
        (given.or(cfg.dark_level).or(own_dark).unwrap_or_else(|| estimate_dark(flat)), capture_sat)
    }
}

impl DarkSource {
    pub fn describe(self) -> &'static str {
        match self {
            DarkSource::Background => "the background frame",
            DarkSource::Calibration => "the calibration's per-pixel dark",
            DarkSource::CaptureToml => "dark_level in the capture description",
            DarkSource::FileBlackLevel => "the raw file's black level (DNG BlackLevel)",
            DarkSource::Estimated => "an estimate from the darkest pixels",
        }
    }
}

impl SaturationSource {
    pub fn describe(self) -> &'static str {
        match self {
            SaturationSource::CaptureToml => "saturation_level in the capture description",
            SaturationSource::Calibration => "the calibration's saturation_level",
            SaturationSource::PileAtMaximum => "a pile of pixels at the raw's maximum",
            SaturationSource::FileFullScale => "the file's full scale",
        }
    }
}

/// Box means over the good pixels (`bad` false) of each `d x d` block, the mask of the
/// blocks the data term keeps (1) or leaves out (0: fewer than half good pixels), and
/// the blocks whose value is a lower bound (a good pixel of the block clipped: the
/// block's light was at least its mean). Returns `(values, rows/d, cols/d, mask,
/// lower)`; a left-out block's value is 0.
pub fn masked_box_downsample(
    img: &[f32],
    bad: &[bool],
    saturated: &[bool],
    rows: usize,
    cols: usize,
    d: usize,
) -> (Vec<f32>, usize, usize, Vec<f32>, Vec<bool>) {
    assert!(d >= 1 && img.len() == rows * cols && bad.len() == rows * cols && saturated.len() == rows * cols);
    let (r, c) = (rows / d, cols / d);
    let mut values = vec![0.0f32; r * c];
    let mut mask = vec![0.0f32; r * c];
    let mut lower = vec![false; r * c];
    for br in 0..r {
        for bc in 0..c {
            let (mut sum, mut good, mut clipped) = (0.0f64, 0usize, false);
            for i in br * d..(br + 1) * d {
                for j in bc * d..(bc + 1) * d {
                    let k = i * cols + j;
                    if !bad[k] {
                        sum += img[k] as f64;
                        good += 1;
                        clipped |= saturated[k];
                    }
                }
            }
            if 2 * good >= d * d && good > 0 {
                values[br * c + bc] = (sum / good as f64) as f32;
                mask[br * c + bc] = 1.0;
                lower[br * c + bc] = clipped;
            }
        }
    }
    (values, r, c, mask, lower)
}

/// A key frame as read: its table, its image (rows, cols, channels) and the lens blur's.
#[derive(Clone, Debug)]
pub struct KeyFrameImage {
    /// The file's name for messages.
    pub name: String,
    pub spec: crate::model::keyframe::KeyFrameRef,
    pub image: ndarray::Array3<f32>,
    /// The file's sample full scale (255 for 8-bit samples), when its format has one:
    /// pixels at it are clipped and left out.
    pub full_scale: Option<f64>,
    pub psf: Option<ndarray::Array3<f32>>,
}

/// A key frame ready for the data term: one plane per raw channel, dark subtracted, on
/// its own pixels (box-averaged to the video grid when it is an integer multiple of it
/// and no map is given).
#[derive(Clone, Debug)]
pub struct PreparedKeyFrame {
    pub name: String,
    pub spec: crate::model::keyframe::KeyFrameRef,
    pub rows: usize,
    pub cols: usize,
    /// One plane per raw channel (counts above the dark).
    pub planes: Vec<Vec<f32>>,
    /// Pixels the data term keeps (not clipped, finite).
    pub usable: Vec<bool>,
    pub dark: f64,
    pub dark_estimated: bool,
    /// The map from the video grid to these pixels (after any box-averaging).
    pub affine: Option<[[f64; 3]; 2]>,
    pub blur: Option<crate::model::keyframe::Kernel>,
    /// The noise of each plane measured on the frame itself (counts).
    pub sigma: Vec<Option<f32>>,
}

/// Prepare `k` for a raw of `channels` channels whose video grid is `video` (rows,
/// cols): the dark (given, else the darkest pixels' mode, as for the raw), clipped pixels
/// left out, colours matched (one plane per raw channel: the same plane for a mono key
/// frame, the channels' mean for a colour key frame of a mono raw), an integer multiple
/// of the video grid box-averaged down, its noise measured.
pub fn prepare_keyframe(k: &KeyFrameImage, channels: usize, video: (usize, usize)) -> Result<PreparedKeyFrame, PrepareError> {
    let (rows, cols, kc) = k.image.dim();
    if let Some((i, v)) = k.image.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        let _ = v;
        let count = k.image.iter().filter(|v| !v.is_finite()).count();
        return Err(PrepareError::NonFinite { what: k.name.clone(), count, row: i / (cols * kc), col: (i / kc) % cols });
    }
    if kc != channels && kc != 1 && channels != 1 {
        return Err(PrepareError::Channels { what: k.name.clone(), got: kc, expected: format!("1 or {channels} (the raw's)") });
    }
    let all: Vec<f32> = k.image.iter().copied().collect();
    let (dark, dark_estimated) = match k.spec.dark_level {
        Some(d) => (d, false),
        None => (estimate_dark(&all), true),
    };
    let clip = k.full_scale.map(|f| f as f32);
    let mut usable = vec![true; rows * cols];
    let plane_of = |c: usize| -> Vec<f32> { (0..rows * cols).map(|p| k.image[[p / cols, p % cols, c]] - dark as f32).collect() };
    for (p, u) in usable.iter_mut().enumerate() {
        if let Some(f) = clip {
            if (0..kc).any(|c| k.image[[p / cols, p % cols, c]] >= f) {
                *u = false;
            }
        }
    }
    let mut planes: Vec<Vec<f32>> = if kc == channels {
        (0..kc).map(plane_of).collect()
    } else if kc == 1 {
        vec![plane_of(0); channels]
    } else {
        let sum = (0..kc).map(plane_of).fold(vec![0.0f32; rows * cols], |mut a, p| {
            a.iter_mut().zip(p).for_each(|(x, y)| *x += y / kc as f32);
            a
        });
        vec![sum]
    };
    let (mut r, mut c) = (rows, cols);
    let f = rows / video.0.max(1);
    if k.spec.affine.is_none() && f >= 2 && (rows, cols) == (f * video.0, f * video.1) {
        for p in planes.iter_mut() {
            let (small, _, _) = crate::model::resample::box_downsample(p, rows, cols, f);
            *p = small;
        }
        let u: Vec<f32> = usable.iter().map(|&b| b as u8 as f32).collect();
        let (u, _, _) = crate::model::resample::box_downsample(&u, rows, cols, f);
        usable = u.into_iter().map(|v| v >= 1.0).collect();
        (r, c) = video;
    }
    let mask = DataMask { mask: Some(usable.iter().map(|&b| b as u8 as f32).collect()), lower_bounds: None };
    let sigma = planes.iter().map(|p| crate::model::noise::noise_sigma(p, r, c, &mask)).collect();
    let blur = match &k.psf {
        None => None,
        Some(img) => {
            let (pr, pc, pch) = img.dim();
            let mean: Vec<f32> = (0..pr * pc).map(|p| (0..pch).map(|ch| img[[p / pc, p % pc, ch]]).sum::<f32>() / pch as f32).collect();
            Some(crate::model::keyframe::Kernel::from_image(&mean, pr, pc).ok_or_else(|| PrepareError::ZeroPsf {
                what: format!("{} (keyframes psf)", k.name),
                channel: 0,
                dark: 0.0,
            })?)
        }
    };
    Ok(PreparedKeyFrame {
        name: k.name.clone(),
        spec: k.spec.clone(),
        rows: r,
        cols: c,
        planes,
        usable,
        dark,
        dark_estimated,
        affine: k.spec.affine,
        blur,
        sigma,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;

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

    fn cfg(m: usize, n: usize, dark: Option<f64>) -> CaptureConfig {
        CaptureConfig { dark_level: dark, ..CaptureConfig::new(m, n, 10.0, 30.0, crate::model::shutter::ShutterMode::Rolling) }
    }

    fn prep(raw: &Array3<f32>, psf: &Array3<f32>, c: &CaptureConfig) -> Result<Prepared, PrepareError> {
        prepare(raw.view(), "raw.tiff", psf.view(), "psf.tiff", c, &SensorInput::default())
    }

    #[test]
    fn a_psf_k_times_the_raw_is_box_averaged_and_other_sizes_are_refused_with_the_ratio() {
        let raw = Array3::<f32>::from_elem((4, 6, 1), 10.0);
        let small = Array3::from_shape_fn((4, 6, 1), |(r, c, _)| if (r, c) == (1, 2) { 45.0 } else { 5.0 + (r + c) as f32 });
        // Each pixel of `small` as a 3 x 3 block whose mean is that pixel.
        let big = Array3::from_shape_fn((12, 18, 1), |(r, c, _)| small[[r / 3, c / 3, 0]] + [-1.0, 0.0, 1.0][(r + c) % 3]);
        let want = prep(&raw, &small, &cfg(4, 6, Some(5.0))).unwrap();
        let got = prep(&raw, &big, &cfg(4, 6, Some(5.0))).unwrap();
        assert_eq!(got.sensor.psf_downsampled, 3);
        assert_eq!(want.sensor.psf_downsampled, 1);
        for (a, b) in got.psf[0].data.iter().zip(&want.psf[0].data) {
            assert!((a - b).abs() < 1e-6, "{a} vs {b}");
        }
        let odd = Array3::<f32>::from_elem((10, 15, 1), 5.0);
        let e = prep(&raw, &odd, &cfg(4, 6, None)).unwrap_err().to_string();
        assert!(e.contains("psf.tiff") && e.contains("2.5000 x 2.5000 times"), "{e}");
        let half = Array3::<f32>::from_elem((2, 3, 1), 5.0);
        let e = prep(&raw, &half, &cfg(4, 6, None)).unwrap_err().to_string();
        assert!(e.contains("2 times the PSF's size"), "{e}");
    }

    #[test]
    fn a_raw_lit_everywhere_is_warned_when_its_dark_sits_far_above_the_psfs() {
        // The PSF's darkest pixels at 40; the raw's at 500 (light on every pixel).
        let psf = Array3::from_shape_fn((16, 16, 1), |(r, c, _)| if (r, c) == (8, 8) { 900.0 } else { 40.0 + ((r * 3 + c) % 3) as f32 });
        let lit = Array3::from_shape_fn((16, 16, 1), |(r, c, _)| 500.0 + ((r * 7 + c * 5) % 40) as f32);
        let p = prep(&lit, &psf, &cfg(16, 16, None)).unwrap();
        let w = p.sensor.warnings.iter().find(|w| w.contains("dark_level = 40")).expect("a warning naming the PSF's dark");
        assert!(w.contains("raw.tiff") && w.contains("psf.tiff") && w.contains("500"), "{w}");
        // A raw with dark pixels at the PSF's level, or a given dark level: no warning.
        let dark = Array3::from_shape_fn((16, 16, 1), |(r, c, _)| if r < 8 { 41.0 } else { 500.0 + c as f32 });
        assert!(!prep(&dark, &psf, &cfg(16, 16, None)).unwrap().sensor.warnings.iter().any(|w| w.contains("darkest pixels sit")));
        assert!(!prep(&lit, &psf, &cfg(16, 16, Some(40.0))).unwrap().sensor.warnings.iter().any(|w| w.contains("darkest pixels sit")));
    }

    #[test]
    fn psf_is_unit_sum_and_errors_name_the_file() {
        let raw = Array3::<f32>::from_elem((4, 4, 1), 10.0);
        let mut psf = Array3::<f32>::from_elem((4, 4, 1), 5.0);
        psf[[1, 2, 0]] = 25.0;
        let p = prep(&raw, &psf, &cfg(4, 4, Some(5.0))).unwrap();
        let s: f32 = p.psf[0].data.iter().sum();
        assert!((s - 1.0).abs() < 1e-6);
        assert_eq!(p.raw[0].data[0], 5.0);
        assert!(p.data_mask.mask.is_none(), "a clean raw uses every pixel");

        let mut zero = Array3::<f32>::from_elem((4, 4, 1), 5.0);
        zero[[0, 0, 0]] = 3.0;
        let e = prep(&raw, &zero, &cfg(4, 4, Some(5.0))).unwrap_err();
        assert!(e.to_string().contains("psf.tiff") && e.to_string().contains("all zero"));
        // A flat PSF (all clipped, or no light) is refused as calibrate refuses it.
        let flat = Array3::<f32>::from_elem((4, 4, 1), 65535.0);
        let e = prep(&raw, &flat, &cfg(4, 4, Some(5.0))).unwrap_err().to_string();
        assert!(e.contains("psf.tiff") && e.contains("65535 counts at every pixel"), "{e}");

        let mut nan = psf.clone();
        nan[[2, 3, 0]] = f32::NAN;
        let e = prep(&raw, &nan, &cfg(4, 4, Some(5.0))).unwrap_err();
        assert_eq!(e, PrepareError::NonFinite { what: "psf.tiff".into(), count: 1, row: 2, col: 3 });

        let small = Array3::<f32>::from_elem((3, 4, 1), 5.0);
        let e = prep(&raw, &small, &cfg(4, 4, None)).unwrap_err();
        assert!(e.to_string().contains("psf.tiff") && e.to_string().contains("3 x 4"));

        let rgb = Array3::<f32>::from_elem((4, 4, 3), 5.0);
        let e = prep(&raw, &rgb, &cfg(4, 4, None)).unwrap_err();
        assert!(matches!(e, PrepareError::Channels { .. }));

        let e = prep(&raw, &psf, &cfg(5, 4, None)).unwrap_err();
        assert!(e.to_string().contains("raw.tiff") && e.to_string().contains("5 x 4"));
    }

    /// A smooth 16 x 16 raw (a ramp over a dark of 100) and a PSF.
    fn smooth(m: usize, n: usize) -> (Array3<f32>, Array3<f32>) {
        let raw = Array3::from_shape_fn((m, n, 1), |(i, j, _)| 100.0 + 10.0 * i as f32 + 5.0 * j as f32);
        let psf = Array3::from_shape_fn((m, n, 1), |(i, j, _)| if (i, j) == (m / 2, n / 2) { 1000.0 } else { 100.0 + ((i + j) % 3) as f32 });
        (raw, psf)
    }

    #[test]
    fn clipped_pixels_are_lower_bounds_at_the_declared_level_or_the_pile() {
        let (mut raw, psf) = smooth(16, 16);
        // Declared: every raw value >= 250 is clipped.
        let c = CaptureConfig { saturation_level: Some(250.0), ..cfg(16, 16, Some(100.0)) };
        let p = prep(&raw, &psf, &c).unwrap();
        let clipped = raw.iter().filter(|&&v| v >= 250.0).count();
        assert_eq!(p.sensor.saturated_pixels, clipped);
        assert_eq!(p.sensor.saturation_source, Some(SaturationSource::CaptureToml));
        assert!(p.data_mask.mask.is_none(), "clipped pixels stay in the data term");
        let lower = p.data_mask.lower_bounds.as_ref().unwrap();
        assert_eq!(p.sensor.lower_bound_pixels, clipped);
        for (k, &v) in raw.iter().enumerate() {
            assert_eq!(lower[k], v >= 250.0, "pixel {k}");
            assert_eq!(p.raw[0].data[k], v - 100.0);
        }
        assert!(p.sensor.warnings.iter().any(|w| w.contains("raw.tiff") && w.contains("lower bounds")), "{:?}", p.sensor.warnings);
        // Downsampled by 2: a block with a clipped pixel is a lower bound.
        let p2 = prep(&raw, &psf, &CaptureConfig { downsample: 2, ..c.clone() }).unwrap();
        let l2 = p2.data_mask.lower_bounds.as_ref().unwrap();
        for (b, &l) in l2.iter().enumerate() {
            let (br, bc) = (b / 8, b % 8);
            let any = (0..2).any(|i| (0..2).any(|j| raw[[2 * br + i, 2 * bc + j, 0]] >= 250.0));
            assert_eq!(l, any, "block {b}");
        }
        // Undeclared: a pile at the maximum is found.
        raw.mapv_inplace(|v| v.min(240.0));
        let p = prep(&raw, &psf, &cfg(16, 16, Some(100.0))).unwrap();
        assert_eq!(p.sensor.saturation_source, Some(SaturationSource::PileAtMaximum));
        assert_eq!(p.sensor.saturation_level, Some(240.0));
        assert_eq!(p.sensor.saturated_pixels, raw.iter().filter(|&&v| v >= 240.0).count());
        // Everything clipped: refused, not an all-zero video.
        let flat = Array3::<f32>::from_elem((16, 16, 1), 4095.0);
        let e = prep(&flat, &psf, &CaptureConfig { saturation_level: Some(4095.0), ..cfg(16, 16, Some(100.0)) }).unwrap_err().to_string();
        assert!(e.contains("raw.tiff") && e.contains("no pixel measures the light"), "{e}");
        // A lone clipped pixel far above its neighbours is a hot pixel: left out.
        let (mut raw, _) = smooth(16, 16);
        raw[[9, 9, 0]] = 65535.0;
        let p = prep(&raw, &psf, &CaptureConfig { saturation_level: Some(65535.0), ..cfg(16, 16, Some(100.0)) }).unwrap();
        assert_eq!((p.sensor.outliers_hot, p.sensor.saturated_pixels), (1, 0));
        assert_eq!(p.data_mask.mask.as_ref().unwrap()[9 * 16 + 9], 0.0);
        assert!(p.data_mask.lower_bounds.is_none());
    }

    #[test]
    fn a_hot_pixel_is_masked_and_blocks_average_their_good_pixels() {
        let (mut raw, psf) = smooth(16, 16);
        raw[[5, 7, 0]] = 60000.0;
        let p = prep(&raw, &psf, &cfg(16, 16, Some(100.0))).unwrap();
        assert_eq!((p.sensor.outliers_hot, p.sensor.outliers_dead, p.sensor.saturated_pixels), (1, 0, 0));
        let mask = p.data_mask.mask.as_ref().unwrap();
        assert_eq!(mask.iter().filter(|&&v| v == 0.0).count(), 1);
        assert_eq!(mask[5 * 16 + 7], 0.0);
        // Downsampled by 2: the block keeps the mean of its three good pixels.
        let c2 = CaptureConfig { downsample: 2, ..cfg(16, 16, Some(100.0)) };
        let p = prep(&raw, &psf, &c2).unwrap();
        assert!(p.data_mask.mask.is_none(), "every block keeps at least half its pixels");
        let good = [raw[[4, 6, 0]], raw[[4, 7, 0]], raw[[5, 6, 0]]].iter().map(|v| v - 100.0).sum::<f32>() / 3.0;
        assert!((p.raw[0].data[2 * 8 + 3] - good).abs() < 1e-4);
    }

    #[test]
    fn a_calibration_subtracts_its_dark_per_pixel_and_masks_its_defects() {
        let (raw, psf) = smooth(8, 8);
        let dark = Array3::from_shape_fn((8, 8, 1), |(i, j, _)| 90.0 + (i + 2 * j) as f32);
        let mut defects = Array2::<u8>::zeros((8, 8));
        defects[[3, 3]] = Defect::Stuck.code();
        let cal = Calibration { dark: Some(dark.clone()), defects: Some(defects), ..Calibration::default() };
        let sensor = SensorInput { calibration: Some(&cal), ..SensorInput::default() };
        let p = prepare(raw.view(), "raw.tiff", psf.view(), "psf.tiff", &cfg(8, 8, Some(100.0)), &sensor).unwrap();
        assert_eq!(p.sensor.dark_source, DarkSource::Calibration);
        assert_eq!(p.sensor.calibration_defects, 1);
        assert_eq!(p.raw[0].data[9], raw[[1, 1, 0]] - dark[[1, 1, 0]]);
        assert_eq!(p.data_mask.mask.as_ref().unwrap()[3 * 8 + 3], 0.0);
        // The PSF's pixel at the stuck position is repaired, not kept.
        assert_eq!(p.sensor.psf_repaired, 1);
        // A background frame as shot wins over the dark.
        let bg = Array3::from_elem((8, 8, 1), 120.0f32);
        let sensor = SensorInput { calibration: Some(&cal), background: Some(bg.view()), ..SensorInput::default() };
        let p = prepare(raw.view(), "raw.tiff", psf.view(), "psf.tiff", &cfg(8, 8, Some(100.0)), &sensor).unwrap();
        assert_eq!(p.sensor.dark_source, DarkSource::Background);
        assert_eq!(p.raw[0].data[9], raw[[1, 1, 0]] - 120.0);
        // A dark of another size is named.
        let small = Calibration { dark: Some(Array3::zeros((4, 8, 1))), ..Calibration::default() };
        let sensor = SensorInput { calibration: Some(&small), ..SensorInput::default() };
        let e = prepare(raw.view(), "raw.tiff", psf.view(), "psf.tiff", &cfg(8, 8, None), &sensor).unwrap_err().to_string();
        assert!(e.contains("dark.tiff") && e.contains("4 x 8"), "{e}");
    }
}
