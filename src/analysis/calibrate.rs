//! A bench calibration from its shots (`rollcam calibrate`): the per-pixel dark, read
//! noise, fixed pattern and defect map from a stack of dark frames
//! ([`dark_from_stack`]); the PSF from a stack of point-source shots
//! ([`psf_from_stack`]: averaged, dark-subtracted, defects and clipped pixels repaired,
//! noise floor removed, optionally registered, unit sum); the static background from
//! background frames ([`background_from_stack`]); the clipping level
//! ([`detect_saturation`]); all of it together as a [`Calibration`] ([`calibrate`]) and
//! a one-page picture of it ([`report_figure`]).
//!
//! Pure computation on frames in memory (row, col, channel) in counts; reading the
//! shots and writing the folder is the caller's (`crate::io::calibration`). Sums and
//! means are accumulated in f64.

use crate::model::prepare::{estimate_dark, OUTLIER_SIGMAS};
use crate::model::sensor::{
    find_outliers, median_in_place, pixel_noise, repair, robust_sigma, saturation_pile, BackgroundRecord, Calibration, CalibrationRecord, DarkRecord, Defect,
    DefectRecord, PsfRecord,
};
use ndarray::{Array2, Array3, Axis, Zip};

/// How the dark frames are named in errors and notes.
pub const DARK_FRAMES: &str = "dark frames";
/// How the point-source shots are named in errors and notes.
pub const PSF_SHOTS: &str = "PSF shots";
/// How the background frames are named in errors and notes.
pub const BACKGROUND_FRAMES: &str = "background frames";

/// A hot pixel's dark mean lies this many times `max(read noise, fixed pattern rms)`
/// above the channel's median.
pub const HOT_SIGMAS: f64 = 6.0;
/// A stuck pixel's temporal standard deviation is below this share of the read noise.
pub const STUCK_NOISE_FRACTION: f64 = 0.2;
/// A noisy pixel's temporal standard deviation is above this multiple of the read noise.
pub const NOISY_NOISE_FACTOR: f64 = 5.0;
/// Fewest dark frames for stuck and noisy pixels (a temporal standard deviation from
/// fewer frames is too uncertain).
pub const MIN_FRAMES_TEMPORAL_DEFECTS: usize = 4;
/// PSF values below this many noise sigmas of the averaged shot are set to 0.
pub const PSF_NOISE_FLOOR_SIGMAS: f64 = 3.0;
/// Width of the edge band of [`PsfRecord::edge_fraction`], as a share of the sensor's
/// rows (top and bottom) and columns (left and right).
pub const EDGE_BAND_FRACTION: f64 = 0.05;

/// Errors of the calibration, each naming the stack, the frame and what was expected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CalibrateError {
    #[error("no dark frames and no PSF shots: a calibration needs at least one of them")]
    NothingToCalibrate,
    #[error("{what}: no frames")]
    NoFrames { what: String },
    #[error("{what}: frame {index} is {found}, but frame 0 is {expected}; every frame must have the same size and channels")]
    FrameShape { what: String, index: usize, found: String, expected: String },
    #[error("{what}: frame {index} is {found}: expected at least 1 x 1 pixels and 1 (grey) or 3 (RGB) channels")]
    BadFrame { what: String, index: usize, found: String },
    #[error("{what}: frame {index} holds {count} NaN or infinite values (first at row {row}, col {col}, channel {channel}): expected finite counts")]
    NonFinite { what: String, index: usize, count: usize, row: usize, col: usize, channel: usize },
    #[error("{what} are {found}, but the {against} are {expected}: every array of a calibration has the same sensor size and channels")]
    Mismatch { what: String, found: String, against: String, expected: String },
    #[error("{what}: channel {channel} is all zero after subtracting the dark ({dark}) and the noise floor ({floor_counts:.3} counts): expected the image of a point source")]
    ZeroPsf { what: String, channel: usize, dark: String, floor_counts: f64 },
    #[error("saturation level {0}: expected a positive number of counts")]
    SaturationLevel(f64),
    #[error("{what}: channel {channel} is {level} counts at every pixel of every shot (all clipped, or no light): expected the image of a point source; shorten the exposure or dim the source")]
    FlatPsf { what: String, channel: usize, level: f64 },
}

impl CalibrateError {
    /// The frame (index into the stack passed in) an error is about, when it is about one,
    /// so a caller that read the frames from several files can name the file.
    pub fn frame_index(&self) -> Option<usize> {
        match self {
            CalibrateError::FrameShape { index, .. } | CalibrateError::BadFrame { index, .. } | CalibrateError::NonFinite { index, .. } => Some(*index),
            _ => None,
        }
    }

    /// The stack an error is about ([`DARK_FRAMES`], [`PSF_SHOTS`], [`BACKGROUND_FRAMES`]).
    pub fn stack(&self) -> Option<&str> {
        match self {
            CalibrateError::NoFrames { what }
            | CalibrateError::FrameShape { what, .. }
            | CalibrateError::BadFrame { what, .. }
            | CalibrateError::NonFinite { what, .. }
            | CalibrateError::Mismatch { what, .. }
            | CalibrateError::ZeroPsf { what, .. }
            | CalibrateError::FlatPsf { what, .. } => Some(what),
            _ => None,
        }
    }
}

fn describe(dim: (usize, usize, usize)) -> String {
    let (r, c, ch) = dim;
    format!("{r} x {c} with {ch} channel{}", if ch == 1 { "" } else { "s" })
}

/// Checks that a stack is non-empty, that every frame has the size and channels of
/// frame 0 (1 or 3 channels) and holds finite values; returns (rows, cols, channels).
pub fn check_stack(what: &str, frames: &[Array3<f32>]) -> Result<(usize, usize, usize), CalibrateError> {
    let first = frames.first().ok_or_else(|| CalibrateError::NoFrames { what: what.into() })?.dim();
    for (index, f) in frames.iter().enumerate() {
        let d = f.dim();
        if d.0 == 0 || d.1 == 0 || !(d.2 == 1 || d.2 == 3) {
            return Err(CalibrateError::BadFrame { what: what.into(), index, found: describe(d) });
        }
        if d != first {
            return Err(CalibrateError::FrameShape { what: what.into(), index, found: describe(d), expected: describe(first) });
        }
        let mut bad = f.indexed_iter().filter(|(_, v)| !v.is_finite());
        if let Some(((row, col, channel), _)) = bad.next() {
            let count = 1 + bad.count();
            return Err(CalibrateError::NonFinite { what: what.into(), index, count, row, col, channel });
        }
    }
    Ok(first)
}

fn check_same(what: &str, dim: (usize, usize, usize), against: &str, expected: (usize, usize, usize)) -> Result<(), CalibrateError> {
    if dim == expected {
        Ok(())
    } else {
        Err(CalibrateError::Mismatch { what: what.into(), found: describe(dim), against: against.into(), expected: describe(expected) })
    }
}

/// Per-pixel mean of equally shaped frames, accumulated in f64.
fn mean_f64(frames: &[Array3<f32>]) -> Array3<f64> {
    let mut acc = Array3::<f64>::zeros(frames[0].dim());
    for f in frames {
        Zip::from(&mut acc).and(f).for_each(|a, &v| *a += v as f64);
    }
    acc.mapv_inplace(|a| a / frames.len() as f64);
    acc
}

/// Per-pixel temporal standard deviation (divisor `n - 1`; needs `n >= 2`), in f64.
fn temporal_std(frames: &[Array3<f32>], mean: &Array3<f64>) -> Array3<f64> {
    let mut acc = Array3::<f64>::zeros(mean.dim());
    for f in frames {
        Zip::from(&mut acc).and(f).and(mean).for_each(|a, &v, &m| {
            let d = v as f64 - m;
            *a += d * d;
        });
    }
    let dof = (frames.len() - 1) as f64;
    acc.mapv_inplace(|a| (a / dof).sqrt());
    acc
}

fn median_of(values: impl IntoIterator<Item = f32>) -> f64 {
    let mut v: Vec<f32> = values.into_iter().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        0.0
    } else {
        median_in_place(&mut v) as f64
    }
}

/// `ln Gamma(x)` for `x > 0` (Stirling's series after shifting `x` above 10; about 1e-12).
fn ln_gamma(x: f64) -> f64 {
    let mut shift = 0.0;
    let mut x = x;
    while x < 10.0 {
        shift += x.ln();
        x += 1.0;
    }
    let inv = 1.0 / x;
    let inv2 = inv * inv;
    (x - 0.5) * x.ln() - x + 0.5 * (2.0 * std::f64::consts::PI).ln() + inv * (1.0 / 12.0 - inv2 * (1.0 / 360.0 - inv2 / 1260.0)) - shift
}

/// Regularised lower incomplete gamma function `P(a, x)` by its power series (meant
/// for `x` up to a few times `a`, where the series converges quickly).
fn gamma_p(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    let (mut term, mut sum, mut k) = (1.0f64, 1.0f64, a);
    for _ in 0..1_000_000 {
        k += 1.0;
        term *= x / k;
        sum += term;
        if term < sum * 1e-16 {
            break;
        }
    }
    (-x + a * x.ln() - ln_gamma(a + 1.0) + sum.ln()).exp().min(1.0)
}

/// Probability that a chi-square variable with `dof` degrees of freedom is below `x`.
fn chi2_cdf(dof: usize, x: f64) -> f64 {
    gamma_p(dof as f64 / 2.0, x / 2.0)
}

/// The median of `s / sigma` for the sample standard deviation `s` of `dof + 1`
/// Gaussian samples: `sqrt(median(chi2_dof) / dof)`. The median of per-pixel standard
/// deviations is divided by it so that the read noise is unbiased (0.67 for 2 frames,
/// 0.98 for 16).
fn std_median_factor(dof: usize) -> f64 {
    let k = dof as f64;
    if dof > 200 {
        // Wilson-Hilferty, exact to ~1e-7 here.
        return (1.0 - 2.0 / (9.0 * k)).powf(1.5);
    }
    // Bisection on y = chi2 / k in (0, 2).
    let (mut lo, mut hi) = (0.0f64, 2.0f64);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if chi2_cdf(dof, mid * k) < 0.5 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    (0.5 * (lo + hi)).sqrt()
}

/// Share of good pixels whose sample standard deviation over `frames` frames falls
/// below `fraction` of the true noise by chance (Gaussian noise).
fn chance_below(frames: usize, fraction: f64) -> f64 {
    let dof = frames.saturating_sub(1);
    if dof == 0 {
        return 1.0;
    }
    chi2_cdf(dof, fraction * fraction * dof as f64)
}

/// Which of two defect codes a pixel keeps: hot over stuck over noisy over dead over
/// good (a clipped hot pixel has no temporal noise, but what marks it is its level).
fn stronger(a: u8, b: u8) -> u8 {
    let rank = |c: u8| match c {
        1 => 4, // hot
        2 => 3, // stuck
        3 => 2, // noisy
        4 => 1, // dead
        _ => 0,
    };
    if rank(b) > rank(a) {
        b
    } else {
        a
    }
}

/// What a stack of dark frames says about the sensor.
#[derive(Clone, Debug)]
pub struct DarkCalibration {
    /// Per-pixel mean (counts), (row, col, channel).
    pub mean: Array3<f32>,
    /// Frames, median level, fixed pattern and read noise (`files` left empty).
    pub record: DarkRecord,
    /// [`Defect`] codes (row, col): hot, stuck, noisy; the union over channels.
    pub defects: Array2<u8>,
    /// What the user should know about the measurement (few frames and what it costs).
    pub notes: Vec<String>,
}

/// The dark frames' per-pixel mean, the sensor's read noise and fixed pattern, and its
/// hot, stuck and noisy pixels.
///
/// * read noise: the median over pixels (and channels) of the per-pixel temporal
///   standard deviation, divided by the median of `s / sigma` for that many frames (so
///   it is unbiased for Gaussian noise: with 2 frames the median standard deviation is
///   0.67 sigma). One frame has no temporal noise: then [`pixel_noise`] of the frame,
///   which also holds the fixed pattern (an upper bound);
/// * fixed-pattern rms: [`robust_sigma`] of the mean image (rms over channels), less the
///   read noise left in a mean of `n` frames (`sqrt(s^2 - read^2 / n)`); with one frame
///   the two cannot be told apart and it is the whole spread;
/// * hot: mean above its channel's median by more than
///   `HOT_SIGMAS * max(read noise, fixed pattern rms)`;
/// * stuck: temporal standard deviation below `STUCK_NOISE_FRACTION * read noise`;
///   noisy: above `NOISY_NOISE_FACTOR * read noise`; both need
///   [`MIN_FRAMES_TEMPORAL_DEFECTS`] frames (fewer: not looked for, and a note says so);
///   a note also says how many good pixels are expected to look stuck by chance when
///   the frames are too few for that to be negligible.
///
/// A pixel defective in any channel is defective; a pixel with several findings keeps
/// the strongest (hot, stuck, noisy).
pub fn dark_from_stack(frames: &[Array3<f32>]) -> Result<DarkCalibration, CalibrateError> {
    let (rows, cols, channels) = check_stack(DARK_FRAMES, frames)?;
    let n = frames.len();
    let mean64 = mean_f64(frames);
    let mean = mean64.mapv(|v| v as f32);
    let std = (n >= 2).then(|| temporal_std(frames, &mean64));
    let mut notes = Vec::new();

    let read_noise = match &std {
        Some(s) => median_of(s.iter().map(|&v| v as f32)) / std_median_factor(n - 1),
        None => {
            notes.push(format!(
                "one dark frame: the read noise is the pixel-to-pixel noise of that frame, which includes the fixed pattern (an upper bound), and no stuck or noisy pixels were looked for; shoot at least {MIN_FRAMES_TEMPORAL_DEFECTS} (better 16) dark frames"
            ));
            (0..channels).map(|c| pixel_noise(mean.index_axis(Axis(2), c))).sum::<f64>() / channels as f64
        }
    };
    let spread =
        ((0..channels).map(|c| robust_sigma(&mean.index_axis(Axis(2), c).iter().cloned().collect::<Vec<_>>()).powi(2)).sum::<f64>() / channels as f64).sqrt();
    let fixed_pattern_rms = if n >= 2 { (spread * spread - read_noise * read_noise / n as f64).max(0.0).sqrt() } else { spread };
    let median_level = median_of(mean.iter().cloned());

    let temporal = match &std {
        Some(_) if n < MIN_FRAMES_TEMPORAL_DEFECTS => {
            notes.push(format!("{n} dark frames: stuck and noisy pixels need at least {MIN_FRAMES_TEMPORAL_DEFECTS} and were not looked for"));
            None
        }
        Some(_) if read_noise <= 0.0 => {
            notes.push("the dark frames show no temporal noise at all (identical frames?): stuck and noisy pixels were not looked for".into());
            None
        }
        Some(s) => {
            let per_sensor = (rows * cols * channels) as f64;
            let chance = chance_below(n, STUCK_NOISE_FRACTION) * per_sensor;
            if chance >= 0.5 {
                let enough = (n..=10_000).find(|&k| chance_below(k, STUCK_NOISE_FRACTION) * per_sensor < 0.5).unwrap_or(10_000);
                notes.push(format!(
                    "{n} dark frames: about {chance:.0} good pixels are expected below {STUCK_NOISE_FRACTION} x the read noise by chance and marked stuck; {enough} frames would make that negligible"
                ));
            }
            if read_noise < 0.5 {
                notes.push(format!("read noise {read_noise:.2} counts, under half a count: quantisation alone can make a steady pixel look stuck"));
            }
            Some(s)
        }
        None => None,
    };

    let hot_margin = HOT_SIGMAS * read_noise.max(fixed_pattern_rms);
    let stuck_below = STUCK_NOISE_FRACTION * read_noise;
    let noisy_above = NOISY_NOISE_FACTOR * read_noise;
    let mut defects = Array2::<u8>::zeros((rows, cols));
    for c in 0..channels {
        let plane = mean64.index_axis(Axis(2), c);
        let median = median_of(mean.index_axis(Axis(2), c).iter().cloned());
        for ((i, j), &m) in plane.indexed_iter() {
            let code = if m - median > hot_margin {
                Defect::Hot
            } else if let Some(s) = temporal {
                let sd = s[[i, j, c]];
                if sd < stuck_below {
                    Defect::Stuck
                } else if sd > noisy_above {
                    Defect::Noisy
                } else {
                    Defect::Good
                }
            } else {
                Defect::Good
            };
            defects[[i, j]] = stronger(defects[[i, j]], code.code());
        }
    }
    Ok(DarkCalibration { mean, record: DarkRecord { frames: n, files: Vec::new(), median_level, fixed_pattern_rms, read_noise }, defects, notes })
}

/// What [`psf_from_stack`] knows besides the shots.
#[derive(Clone, Copy, Debug, Default)]
pub struct PsfOptions<'a> {
    /// The per-pixel dark (counts; the dark frames' mean), subtracted when given.
    pub dark: Option<&'a Array3<f32>>,
    /// Without `dark`: a known dark level (counts) for every pixel; `None` estimates it
    /// per channel from the averaged shot's darkest pixels ([`estimate_dark`]).
    pub dark_level: Option<f64>,
    /// A defect map (row, col) whose pixels are repaired.
    pub defects: Option<&'a Array2<u8>>,
    /// Pixels at or above this level in any shot are clipped and repaired.
    pub saturation_level: Option<f64>,
    /// Shift the PSF by whole pixels so its centroid lands on the sensor centre
    /// `(rows / 2, cols / 2)` (zero fill).
    pub register: bool,
}

/// The PSF measured from point-source shots.
#[derive(Clone, Debug)]
pub struct PsfCalibration {
    /// Unit sum per channel, (row, col, channel).
    pub psf: Array3<f32>,
    /// Frames, centroid, shift, energy, edge fraction, SNR, repaired pixels (`files`
    /// left empty).
    pub record: PsfRecord,
    /// Isolated outliers found in the averaged shot against their neighbours
    /// ([`find_outliers`]): [`Defect::Dead`] or [`Defect::Hot`] codes, 0 elsewhere
    /// (pixels already in the given map are not repeated here).
    pub outliers: Array2<u8>,
    /// Pixels at or above the saturation level in some shot.
    pub clipped_pixels: usize,
    /// The dark level subtracted per channel when there was no per-pixel dark (counts).
    pub dark_level_counts: Option<Vec<f64>>,
    /// Noise of the averaged, dark-subtracted shot (counts rms; the largest over
    /// channels): the unit of the outlier threshold, the noise floor and the SNR.
    pub noise_counts: f64,
    pub notes: Vec<String>,
}

/// Intensity centroid (row, col) of the sum over channels, in f64; `None` for an
/// image without positive energy.
pub(crate) fn centroid(img: &Array3<f32>) -> Option<(f64, f64)> {
    let (mut s, mut sr, mut sc) = (0.0f64, 0.0f64, 0.0f64);
    for ((i, j, _), &v) in img.indexed_iter() {
        let v = v as f64;
        s += v;
        sr += v * i as f64;
        sc += v * j as f64;
    }
    (s > 0.0).then(|| (sr / s, sc / s))
}

/// Share of an image's energy in the outer band of [`EDGE_BAND_FRACTION`] of its rows
/// (top and bottom) and columns (left and right).
fn edge_fraction(img: &Array3<f32>) -> f64 {
    let (rows, cols, _) = img.dim();
    let br = ((rows as f64 * EDGE_BAND_FRACTION).ceil() as usize).max(1);
    let bc = ((cols as f64 * EDGE_BAND_FRACTION).ceil() as usize).max(1);
    let (mut total, mut edge) = (0.0f64, 0.0f64);
    for ((i, j, _), &v) in img.indexed_iter() {
        let v = v as f64;
        total += v;
        if i < br || i + br >= rows || j < bc || j + bc >= cols {
            edge += v;
        }
    }
    if total > 0.0 {
        edge / total
    } else {
        0.0
    }
}

/// `img` shifted by whole pixels (`shift` = (rows, cols), down and right positive),
/// zero fill.
fn shifted(img: &Array3<f32>, shift: [i64; 2]) -> Array3<f32> {
    let (rows, cols, ch) = img.dim();
    let mut out = Array3::<f32>::zeros((rows, cols, ch));
    for ((i, j, c), &v) in img.indexed_iter() {
        let (a, b) = (i as i64 + shift[0], j as i64 + shift[1]);
        if a >= 0 && b >= 0 && (a as usize) < rows && (b as usize) < cols {
            out[[a as usize, b as usize, c]] = v;
        }
    }
    out
}

/// The PSF from a stack of point-source shots:
/// 1. the per-pixel mean (f64), less the dark (per pixel when given, else a level:
///    given, or estimated per channel from the mean's darkest pixels);
/// 2. pixels of the defect map and pixels that clip (at or above the saturation level
///    in any shot) are repaired from their neighbours ([`repair`]);
/// 3. isolated outliers of the repaired mean ([`find_outliers`], noise = the largest
///    [`pixel_noise`] over channels, floor 0, `OUTLIER_SIGMAS`) are repaired too and
///    returned (dead pixels only show under light);
/// 4. values below `PSF_NOISE_FLOOR_SIGMAS` noise sigmas become 0 (so the flat noise
///    of the dark region does not add energy over the whole sensor), negatives too;
/// 5. the centroid, energy, edge fraction and peak SNR are measured (on the sensor as
///    shot); with `register` the image is shifted by whole pixels so the centroid lands
///    on the sensor centre (`(rows / 2, cols / 2)`, the convolution's centre pixel);
/// 6. each channel is normalised to unit sum.
///
/// Known limit: a PSF sharper than a pixel (a focused spot, not a diffuser's caustics)
/// would be taken for a hot pixel in step 3.
pub fn psf_from_stack(frames: &[Array3<f32>], opts: &PsfOptions) -> Result<PsfCalibration, CalibrateError> {
    let dim = check_stack(PSF_SHOTS, frames)?;
    let (rows, cols, channels) = dim;
    if let Some(d) = opts.dark {
        check_same(PSF_SHOTS, dim, DARK_FRAMES, d.dim())?;
    }
    if let Some(m) = opts.defects {
        let (r, c) = m.dim();
        if (r, c) != (rows, cols) {
            return Err(CalibrateError::Mismatch {
                what: "the defect map".into(),
                found: format!("{r} x {c}"),
                against: PSF_SHOTS.into(),
                expected: format!("{rows} x {cols}"),
            });
        }
    }
    let mut notes = Vec::new();
    let mean = mean_f64(frames);

    // A flat mean (every shot clipped at full scale, or no light) holds no point source.
    for c in 0..channels {
        let (lo, hi) = mean.index_axis(Axis(2), c).iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)));
        if !(hi > lo) {
            return Err(CalibrateError::FlatPsf { what: PSF_SHOTS.into(), channel: c, level: lo });
        }
    }

    // 1. The dark.
    let (mut planes, dark_level_counts, dark_name): (Vec<Array2<f32>>, Option<Vec<f64>>, String) = match opts.dark {
        Some(d) => {
            let planes = (0..channels)
                .map(|c| Zip::from(&mean.index_axis(Axis(2), c)).and(&d.index_axis(Axis(2), c)).map_collect(|&m, &k| (m - k as f64) as f32))
                .collect();
            (planes, None, "the per-pixel dark of the dark frames".into())
        }
        None => {
            let levels: Vec<f64> = (0..channels)
                .map(|c| opts.dark_level.unwrap_or_else(|| estimate_dark(&mean.index_axis(Axis(2), c).iter().map(|&v| v as f32).collect::<Vec<_>>())))
                .collect();
            let planes = (0..channels).map(|c| mean.index_axis(Axis(2), c).mapv(|m| (m - levels[c]) as f32)).collect();
            let how = if opts.dark_level.is_some() { "given" } else { "estimated from the shots' darkest pixels" };
            let list = levels.iter().map(|l| format!("{l:.2}")).collect::<Vec<_>>().join(", ");
            notes.push(format!("no dark frames: subtracted a dark level of {list} counts ({how})"));
            (planes, Some(levels), format!("level {list}, {how}"))
        }
    };

    // 2. Known defects and clipped pixels.
    let mut bad = Array2::from_elem((rows, cols), false);
    if let Some(m) = opts.defects {
        Zip::from(&mut bad).and(m).for_each(|b, &code| *b |= code != Defect::Good.code());
    }
    let mut clipped_pixels = 0;
    if let Some(level) = opts.saturation_level {
        let mut clipped = Array2::from_elem((rows, cols), false);
        for f in frames {
            for ((i, j, _), &v) in f.indexed_iter() {
                if v as f64 >= level {
                    clipped[[i, j]] = true;
                }
            }
        }
        clipped_pixels = clipped.iter().filter(|&&c| c).count();
        // Clipped pixels the map already marks (hot pixels at full scale) say nothing
        // about the exposure; the others are the PSF's own light clipping.
        let light_clipped = Zip::from(&clipped).and(&bad).fold(0usize, |n, &c, &b| n + usize::from(c && !b));
        if light_clipped > 0 {
            notes.push(format!(
                "{light_clipped} pixels outside the defect map clip (at or above {level} counts in some shot) and were repaired from their neighbours: the PSF there is a guess; shorten the exposure or dim the source"
            ));
        }
        Zip::from(&mut bad).and(&clipped).for_each(|b, &c| *b |= c);
    }
    for p in planes.iter_mut() {
        repair(p, &bad);
    }

    // 3. Isolated outliers.
    let noise_counts = planes.iter().map(|p| pixel_noise(p.view())).fold(0.0f64, f64::max);
    let mut outliers = Array2::<u8>::zeros((rows, cols));
    for p in &planes {
        let found = find_outliers(p.view(), noise_counts, 0.0, OUTLIER_SIGMAS);
        Zip::from(&mut outliers).and(&found).and(&bad).for_each(|o, &f, &b| {
            if !b && f != 0 {
                *o = stronger(*o, f);
            }
        });
    }
    let outlier_mask = outliers.mapv(|c| c != 0);
    for p in planes.iter_mut() {
        repair(p, &outlier_mask);
    }
    let repaired = Zip::from(&bad).and(&outlier_mask).fold(0usize, |n, &a, &b| n + usize::from(a || b));

    // 4. The noise floor.
    let floor_counts = PSF_NOISE_FLOOR_SIGMAS * noise_counts;
    let mut img = Array3::<f32>::zeros(dim);
    for (c, p) in planes.iter().enumerate() {
        let mut sum = 0.0f64;
        for ((i, j), &v) in p.indexed_iter() {
            let v = if (v as f64) < floor_counts { 0.0 } else { v.max(0.0) };
            img[[i, j, c]] = v;
            sum += v as f64;
        }
        if !(sum > 0.0) {
            return Err(CalibrateError::ZeroPsf { what: PSF_SHOTS.into(), channel: c, dark: dark_name, floor_counts });
        }
    }

    // 5. Measurements, registration.
    let energy_counts = img.iter().map(|&v| v as f64).sum::<f64>();
    let edge = edge_fraction(&img);
    let (centre_row, centre_col) = centroid(&img).expect("positive energy was checked per channel");
    let peak_counts = img.iter().cloned().fold(0.0f32, f32::max) as f64;
    let peak_snr = if noise_counts > 0.0 { peak_counts / noise_counts } else { f64::INFINITY };
    let shift = if opts.register { [((rows / 2) as f64 - centre_row).round() as i64, ((cols / 2) as f64 - centre_col).round() as i64] } else { [0, 0] };
    if shift != [0, 0] {
        img = shifted(&img, shift);
        let kept = img.iter().map(|&v| v as f64).sum::<f64>();
        let lost = 1.0 - kept / energy_counts;
        if lost > 1e-3 {
            notes.push(format!("registration by {shift:?} px moved {:.1}% of the PSF's energy off the sensor", 100.0 * lost));
        }
    }
    if edge > 0.05 {
        notes.push(format!("{:.1}% of the PSF's energy lies in the sensor's outer 5% band: some of it probably falls off the sensor", 100.0 * edge));
    }

    // 6. Unit sum per channel.
    for mut plane in img.axis_iter_mut(Axis(2)) {
        let sum = plane.iter().map(|&v| v as f64).sum::<f64>();
        if sum > 0.0 {
            plane.mapv_inplace(|v| (v as f64 / sum) as f32);
        }
    }
    let record = PsfRecord { frames: frames.len(), files: Vec::new(), centre_row, centre_col, shift, energy_counts, edge_fraction: edge, peak_snr, repaired };
    Ok(PsfCalibration { psf: img, record, outliers, clipped_pixels, dark_level_counts, noise_counts, notes })
}

/// The static background as shot.
#[derive(Clone, Debug)]
pub struct BackgroundCalibration {
    /// Per-pixel mean **as shot** (dark included; counts), (row, col, channel).
    pub mean: Array3<f32>,
    /// Frames and mean level above the dark (`files` left empty).
    pub record: BackgroundRecord,
}

/// The background frames' per-pixel mean as shot (dark included: a reconstruction
/// subtracts it in place of the dark), and its mean level above the dark: the
/// per-pixel `dark` when given, else `dark_level`, else a level estimated from the
/// background's own darkest pixels ([`estimate_dark`]; low when the background lights
/// the whole sensor).
pub fn background_from_stack(frames: &[Array3<f32>], dark: Option<&Array3<f32>>, dark_level: Option<f64>) -> Result<BackgroundCalibration, CalibrateError> {
    let dim = check_stack(BACKGROUND_FRAMES, frames)?;
    if let Some(d) = dark {
        check_same(BACKGROUND_FRAMES, dim, DARK_FRAMES, d.dim())?;
    }
    let mean64 = mean_f64(frames);
    let pixels = mean64.len() as f64;
    let mean_above_dark = match dark {
        Some(d) => Zip::from(&mean64).and(d).fold(0.0f64, |s, &m, &k| s + (m - k as f64)) / pixels,
        None => {
            let mean = mean64.sum() / pixels;
            let level = dark_level.unwrap_or_else(|| estimate_dark(&mean64.iter().map(|&v| v as f32).collect::<Vec<_>>()));
            mean - level
        }
    };
    Ok(BackgroundCalibration { mean: mean64.mapv(|v| v as f32), record: BackgroundRecord { frames: frames.len(), files: Vec::new(), mean_above_dark } })
}

/// A clipping level found in the shots.
#[derive(Clone, Debug, PartialEq)]
pub struct SaturationFound {
    /// Counts.
    pub level: f64,
    /// The stack and the frame (index in it) where the pile was found first.
    pub stack: String,
    pub frame: usize,
}

/// The clipping level the shots show ([`saturation_pile`] of each frame): the lowest
/// pile found, or `None` when no frame has one.
pub fn detect_saturation(stacks: &[(&str, &[Array3<f32>])]) -> Option<SaturationFound> {
    let mut best: Option<SaturationFound> = None;
    for (name, frames) in stacks {
        for (i, f) in frames.iter().enumerate() {
            let values: Vec<f32> = f.iter().cloned().collect();
            if let Some(level) = saturation_pile(&values) {
                if best.as_ref().map_or(true, |b| level < b.level) {
                    best = Some(SaturationFound { level, stack: (*name).into(), frame: i });
                }
            }
        }
    }
    best
}

/// Where the calibration's saturation level came from.
#[derive(Clone, Debug, PartialEq)]
pub enum SaturationOrigin {
    /// Given by the caller (`--saturation-level`).
    Given,
    /// A pile at the largest value of a shot.
    Detected(SaturationFound),
}

/// The shots of one calibration, each stack possibly empty (dark frames or PSF shots
/// needed).
#[derive(Clone, Copy, Debug, Default)]
pub struct CalibrationInput<'a> {
    pub dark: &'a [Array3<f32>],
    pub psf: &'a [Array3<f32>],
    pub background: &'a [Array3<f32>],
    /// The clipping level (counts), when known; else it is looked for in the PSF and
    /// background shots.
    pub saturation_level: Option<f64>,
    /// Register the PSF's centroid on the sensor centre.
    pub register: bool,
}

/// A calibration and what the user should hear about it.
#[derive(Clone, Debug)]
pub struct CalibrationOutcome {
    /// The record (its `files` and `created_utc` left for the caller) and the arrays.
    pub calibration: Calibration,
    pub saturation_origin: Option<SaturationOrigin>,
    /// Clipped PSF pixels, isolated outliers found in the PSF (hot, dead).
    pub psf_clipped_pixels: usize,
    pub psf_outliers_hot: usize,
    pub psf_outliers_dead: usize,
    pub notes: Vec<String>,
}

/// Counts of a defect map by kind.
pub fn defect_record(map: &Array2<u8>) -> DefectRecord {
    let count = |d: Defect| map.iter().filter(|&&c| c == d.code()).count();
    let total = map.iter().filter(|&&c| c != Defect::Good.code()).count();
    DefectRecord {
        hot: count(Defect::Hot),
        stuck: count(Defect::Stuck),
        noisy: count(Defect::Noisy),
        dead: count(Defect::Dead),
        total,
        fraction: total as f64 / map.len().max(1) as f64,
    }
}

/// Everything of a calibration from its shots: the dark (with the defect map), then the
/// saturation level (given, else a pile in the PSF or background shots), the PSF (the
/// dark's defects and the clipped pixels repaired; its isolated outliers added to the
/// map where the map has none), the background (above the dark, else above the PSF
/// shots' dark level). Every stack must have the same size and channels.
pub fn calibrate(input: &CalibrationInput) -> Result<CalibrationOutcome, CalibrateError> {
    if input.dark.is_empty() && input.psf.is_empty() {
        return Err(CalibrateError::NothingToCalibrate);
    }
    if let Some(s) = input.saturation_level {
        if !(s.is_finite() && s > 0.0) {
            return Err(CalibrateError::SaturationLevel(s));
        }
    }
    // Sizes first, so a mismatch is reported before any work.
    let mut dims: Vec<(&str, (usize, usize, usize))> = Vec::new();
    for (name, frames) in [(DARK_FRAMES, input.dark), (PSF_SHOTS, input.psf), (BACKGROUND_FRAMES, input.background)] {
        if !frames.is_empty() {
            let d = check_stack(name, frames)?;
            if let Some((first, fd)) = dims.first() {
                check_same(name, d, first, *fd)?;
            }
            dims.push((name, d));
        }
    }
    let (rows, cols, channels) = dims[0].1;
    let mut notes = Vec::new();

    let dark = (!input.dark.is_empty()).then(|| dark_from_stack(input.dark)).transpose()?;
    if let Some(d) = &dark {
        notes.extend(d.notes.iter().cloned());
    }
    let (saturation_level, saturation_origin) = match input.saturation_level {
        Some(s) => (Some(s), Some(SaturationOrigin::Given)),
        None => match detect_saturation(&[(PSF_SHOTS, input.psf), (BACKGROUND_FRAMES, input.background)]) {
            Some(found) => (Some(found.level), Some(SaturationOrigin::Detected(found))),
            None => (None, None),
        },
    };
    let psf = (!input.psf.is_empty())
        .then(|| {
            psf_from_stack(
                input.psf,
                &PsfOptions {
                    dark: dark.as_ref().map(|d| &d.mean),
                    dark_level: None,
                    defects: dark.as_ref().map(|d| &d.defects),
                    saturation_level,
                    register: input.register,
                },
            )
        })
        .transpose()?;
    if let Some(p) = &psf {
        notes.extend(p.notes.iter().cloned());
    }
    let psf_dark_level = psf.as_ref().and_then(|p| p.dark_level_counts.as_ref()).map(|l| l.iter().sum::<f64>() / l.len() as f64);
    let background =
        (!input.background.is_empty()).then(|| background_from_stack(input.background, dark.as_ref().map(|d| &d.mean), psf_dark_level)).transpose()?;

    let defects = match (&dark, &psf) {
        (Some(d), Some(p)) => {
            let mut m = d.defects.clone();
            Zip::from(&mut m).and(&p.outliers).for_each(|a, &b| {
                if *a == Defect::Good.code() {
                    *a = b;
                }
            });
            Some(m)
        }
        (Some(d), None) => Some(d.defects.clone()),
        (None, Some(p)) => Some(p.outliers.clone()),
        (None, None) => None,
    };
    let (psf_outliers_hot, psf_outliers_dead) = psf.as_ref().map_or((0, 0), |p| {
        (p.outliers.iter().filter(|&&c| c == Defect::Hot.code()).count(), p.outliers.iter().filter(|&&c| c == Defect::Dead.code()).count())
    });
    let record = CalibrationRecord {
        rows,
        cols,
        channels,
        saturation_level,
        created_utc: String::new(),
        dark: dark.as_ref().map(|d| d.record.clone()),
        defects: defects.as_ref().map(defect_record),
        psf: psf.as_ref().map(|p| p.record.clone()),
        background: background.as_ref().map(|b| b.record.clone()),
    };
    Ok(CalibrationOutcome {
        calibration: Calibration {
            record,
            dark: dark.map(|d| d.mean),
            defects,
            psf: psf.as_ref().map(|p| p.psf.clone()),
            background: background.map(|b| b.mean),
        },
        saturation_origin,
        psf_clipped_pixels: psf.as_ref().map_or(0, |p| p.clipped_pixels),
        psf_outliers_hot,
        psf_outliers_dead,
        notes,
    })
}

/// Height of every panel of [`report_figure`], in pixels.
pub const FIGURE_PANEL_HEIGHT: usize = 256;
/// Width of the per-row dark profile panel.
const PROFILE_WIDTH: usize = 120;
const GAP: usize = 8;

/// Colour of a defect code in the figure: hot red, stuck blue, noisy yellow, dead green,
/// good black.
pub fn defect_colour(code: u8) -> [f32; 3] {
    match code {
        1 => [230.0, 40.0, 40.0],
        2 => [60.0, 120.0, 255.0],
        3 => [240.0, 200.0, 30.0],
        4 => [40.0, 200.0, 70.0],
        _ => [0.0, 0.0, 0.0],
    }
}

/// Rows (or columns) of the sensor that panel row `r` of `out` rows covers.
fn block(r: usize, out: usize, n: usize) -> (usize, usize) {
    let a = r * n / out;
    let b = ((r + 1) * n / out).max(a + 1).min(n);
    (a, b)
}

/// Panel `(h, w)` of a sensor image: each panel pixel the mean of the block it covers,
/// mapped to 0..255 by `lo..hi` and `gamma`, per channel (grey becomes RGB).
fn image_panel(img: &Array3<f32>, h: usize, w: usize, lo: f64, hi: f64, gamma: f64) -> Array3<f32> {
    let (rows, cols, ch) = img.dim();
    let mut out = Array3::<f32>::zeros((h, w, 3));
    for r in 0..h {
        let (r0, r1) = block(r, h, rows);
        for c in 0..w {
            let (c0, c1) = block(c, w, cols);
            for k in 0..3 {
                let src = k.min(ch - 1);
                let mut s = 0.0f64;
                for i in r0..r1 {
                    for j in c0..c1 {
                        s += img[[i, j, src]] as f64;
                    }
                }
                let v = s / ((r1 - r0) * (c1 - c0)) as f64;
                let t = if hi > lo { ((v - lo) / (hi - lo)).clamp(0.0, 1.0) } else { f64::from(u8::from(v > lo)) };
                out[[r, c, k]] = (255.0 * t.powf(gamma)).round() as f32;
            }
        }
    }
    out
}

/// The defect panel: each panel pixel the strongest code of its block (a single defect
/// stays visible however far the map is reduced), drawn 3 x 3 panel pixels large.
fn defect_panel(map: &Array2<u8>, h: usize, w: usize) -> Array3<f32> {
    let (rows, cols) = map.dim();
    let mut reduced = Array2::<u8>::zeros((h, w));
    for r in 0..h {
        let (r0, r1) = block(r, h, rows);
        for c in 0..w {
            let (c0, c1) = block(c, w, cols);
            for i in r0..r1 {
                for j in c0..c1 {
                    reduced[[r, c]] = stronger(reduced[[r, c]], map[[i, j]]);
                }
            }
        }
    }
    let mut out = Array3::<f32>::zeros((h, w, 3));
    for r in 0..h {
        for c in 0..w {
            let mut code = 0u8;
            for i in r.saturating_sub(1)..(r + 2).min(h) {
                for j in c.saturating_sub(1)..(c + 2).min(w) {
                    code = stronger(code, reduced[[i, j]]);
                }
            }
            for (k, v) in defect_colour(code).into_iter().enumerate() {
                out[[r, c, k]] = v;
            }
        }
    }
    out
}

/// The per-row mean of the dark (defective pixels left out) as a vertical profile: panel
/// row `r` shows the mean over the sensor rows it covers, left = lowest, right =
/// highest; the rows line up with the image panels.
fn profile_panel(dark: &Array3<f32>, defects: Option<&Array2<u8>>, h: usize) -> Array3<f32> {
    let (rows, cols, ch) = dark.dim();
    let row_means: Vec<f64> = (0..rows)
        .map(|i| {
            let (mut s, mut n) = (0.0f64, 0usize);
            for j in 0..cols {
                if defects.is_some_and(|m| m[[i, j]] != Defect::Good.code()) {
                    continue;
                }
                for c in 0..ch {
                    s += dark[[i, j, c]] as f64;
                    n += 1;
                }
            }
            if n > 0 {
                s / n as f64
            } else {
                f64::NAN
            }
        })
        .collect();
    let values: Vec<f64> = (0..h)
        .map(|r| {
            let (a, b) = block(r, h, rows);
            let good: Vec<f64> = row_means[a..b].iter().cloned().filter(|v| v.is_finite()).collect();
            if good.is_empty() {
                f64::NAN
            } else {
                good.iter().sum::<f64>() / good.len() as f64
            }
        })
        .collect();
    let (lo, hi) = values.iter().filter(|v| v.is_finite()).fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
    let mut out = Array3::<f32>::from_elem((h, PROFILE_WIDTH, 3), 255.0);
    // A light frame.
    for r in 0..h {
        for c in [0, PROFILE_WIDTH - 1] {
            for k in 0..3 {
                out[[r, c, k]] = 200.0;
            }
        }
    }
    let margin = 6.0;
    let x_of = |v: f64| -> Option<usize> {
        if !v.is_finite() {
            return None;
        }
        let t = if hi > lo { (v - lo) / (hi - lo) } else { 0.5 };
        Some((margin + t * (PROFILE_WIDTH as f64 - 1.0 - 2.0 * margin)).round() as usize)
    };
    let mut prev: Option<usize> = None;
    for (r, &v) in values.iter().enumerate() {
        let Some(x) = x_of(v) else {
            prev = None;
            continue;
        };
        let (a, b) = match prev {
            Some(p) => (p.min(x), p.max(x)),
            None => (x, x),
        };
        for c in a..=b {
            for k in 0..3 {
                out[[r, c, k]] = 0.0;
            }
        }
        prev = Some(x);
    }
    out
}

/// Percentile (0-100) of the finite values.
fn percentile(values: impl Iterator<Item = f32>, pct: f64) -> f64 {
    let mut v: Vec<f32> = values.filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return 0.0;
    }
    let idx = ((pct / 100.0) * (v.len() - 1) as f64).round() as usize;
    *v.select_nth_unstable_by(idx, f32::total_cmp).1 as f64
}

/// A one-page picture of a calibration, as RGB levels 0..255 (row, col, 3), panels of
/// [`FIGURE_PANEL_HEIGHT`] rows side by side on white, each present when its array is:
/// the dark mean (0.5-99.5 percentile), the per-row mean of the dark (a vertical
/// profile aligned with the rows), the defect map ([`defect_colour`]), the PSF (0 to
/// its maximum, gamma 0.5), the background as shot (0.5-99.5 percentile).
pub fn report_figure(cal: &Calibration) -> Array3<f32> {
    let (rows, cols) = (cal.record.rows.max(1), cal.record.cols.max(1));
    let h = FIGURE_PANEL_HEIGHT;
    let w = ((cols * h) as f64 / rows as f64).round().max(1.0) as usize;
    let mut panels: Vec<Array3<f32>> = Vec::new();
    if let Some(d) = &cal.dark {
        let (lo, hi) = (percentile(d.iter().cloned(), 0.5), percentile(d.iter().cloned(), 99.5));
        panels.push(image_panel(d, h, w, lo, hi, 1.0));
        panels.push(profile_panel(d, cal.defects.as_ref(), h));
    }
    if let Some(m) = &cal.defects {
        panels.push(defect_panel(m, h, w));
    }
    if let Some(p) = &cal.psf {
        let hi = p.iter().cloned().fold(0.0f32, f32::max) as f64;
        // Block means lower a sparse PSF's peaks: scale to the largest block mean.
        let reduced = image_panel(p, h, w, 0.0, hi, 1.0);
        let top = reduced.iter().cloned().fold(0.0f32, f32::max) as f64 / 255.0 * hi;
        panels.push(image_panel(p, h, w, 0.0, if top > 0.0 { top } else { hi }, 0.5));
    }
    if let Some(b) = &cal.background {
        let (lo, hi) = (percentile(b.iter().cloned(), 0.5), percentile(b.iter().cloned(), 99.5));
        panels.push(image_panel(b, h, w, lo, hi, 1.0));
    }
    let width = panels.iter().map(|p| p.dim().1).sum::<usize>() + GAP * (panels.len() + 1);
    let mut out = Array3::<f32>::from_elem((h + 2 * GAP, width.max(1), 3), 255.0);
    let mut x = GAP;
    for p in &panels {
        let pw = p.dim().1;
        out.slice_mut(ndarray::s![GAP..GAP + h, x..x + pw, ..]).assign(p);
        x += pw + GAP;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::ArrayView2;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    /// `n` dark frames (m x k, one channel): level 100, fixed pattern `fpn` rms, read
    /// noise `read` rms, rounded to counts; hot pixels (+300) at `hot`, stuck pixels
    /// (constant 104) at `stuck`, noisy pixels (8 x read noise) at `noisy`.
    fn darks(
        n: usize,
        (m, k): (usize, usize),
        fpn: f64,
        read: f64,
        hot: &[(usize, usize)],
        stuck: &[(usize, usize)],
        noisy: &[(usize, usize)],
    ) -> Vec<Array3<f32>> {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let g = Normal::new(0.0, 1.0).unwrap();
        let pattern = Array2::from_shape_fn((m, k), |_| 100.0 + fpn * g.sample(&mut rng));
        (0..n)
            .map(|_| {
                let mut f = Array3::from_shape_fn((m, k, 1), |(i, j, _)| {
                    let mut s = read;
                    if noisy.contains(&(i, j)) {
                        s *= 8.0;
                    }
                    let mut v = pattern[[i, j]] + s * g.sample(&mut rng);
                    if hot.contains(&(i, j)) {
                        v += 300.0;
                    }
                    v.round() as f32
                });
                for &(i, j) in stuck {
                    f[[i, j, 0]] = 104.0;
                }
                f
            })
            .collect()
    }

    #[test]
    fn chi_square_helpers_match_known_values() {
        // P(1/2, x) = erf(sqrt x); erf(1) = 0.8427007929.
        assert!((gamma_p(0.5, 1.0) - 0.842_700_792_9).abs() < 1e-8);
        // Median of chi2_1 is 0.454936.
        assert!((std_median_factor(1).powi(2) - 0.454_936).abs() < 1e-5);
        // Median of chi2_15 is 14.3389.
        assert!((std_median_factor(15).powi(2) * 15.0 - 14.338_9).abs() < 1e-3);
        assert!((std_median_factor(300) - std_median_factor(199)).abs() < 2e-3);
        // ln Gamma(0.5) = ln sqrt(pi).
        assert!((ln_gamma(0.5) - 0.5 * std::f64::consts::PI.ln()).abs() < 1e-10);
    }

    #[test]
    fn a_dark_stack_gives_read_noise_fixed_pattern_and_defects() {
        let hot = [(5, 7), (30, 40)];
        let stuck = [(12, 3), (20, 20)];
        let noisy = [(33, 10)];
        let frames = darks(24, (48, 64), 3.0, 4.0, &hot, &stuck, &noisy);
        let d = dark_from_stack(&frames).unwrap();
        let truth_read = (16.0f64 + 1.0 / 12.0).sqrt();
        assert!((d.record.read_noise - truth_read).abs() < 0.05 * truth_read, "{:?}", d.record);
        assert!((d.record.fixed_pattern_rms - 3.0).abs() < 0.45, "{:?}", d.record);
        assert!((d.record.median_level - 100.0).abs() < 0.5, "{:?}", d.record);
        assert_eq!(d.record.frames, 24);
        for p in hot {
            assert_eq!(d.defects[p], Defect::Hot.code(), "{p:?}");
        }
        for p in stuck {
            assert_eq!(d.defects[p], Defect::Stuck.code(), "{p:?}");
        }
        assert_eq!(d.defects[(33, 10)], Defect::Noisy.code());
        assert_eq!(d.defects.iter().filter(|&&c| c != 0).count(), 5, "no false defects");
        assert!(d.notes.is_empty(), "{:?}", d.notes);
        let rec = defect_record(&d.defects);
        assert_eq!((rec.hot, rec.stuck, rec.noisy, rec.dead, rec.total), (2, 2, 1, 0, 5));
    }

    #[test]
    fn few_dark_frames_skip_the_temporal_defects_and_say_so() {
        let frames = darks(3, (32, 40), 0.0, 2.0, &[(4, 4)], &[(10, 10)], &[]);
        let d = dark_from_stack(&frames).unwrap();
        assert_eq!(d.defects[(4, 4)], Defect::Hot.code());
        assert_eq!(d.defects[(10, 10)], Defect::Good.code(), "stuck needs 4 frames");
        assert!(d.notes.iter().any(|n| n.contains("stuck and noisy")), "{:?}", d.notes);
        // Two frames: the median correction keeps the read noise unbiased.
        let two = dark_from_stack(&darks(2, (64, 80), 0.0, 3.0, &[], &[], &[])).unwrap();
        assert!((two.record.read_noise - 3.0).abs() < 0.15, "{:?}", two.record);
        // One frame: pixel noise, and a note.
        let one = dark_from_stack(&frames[..1]).unwrap();
        assert!((one.record.read_noise - 2.0).abs() < 0.3, "{:?}", one.record);
        assert!(one.notes[0].contains("one dark frame"), "{:?}", one.notes);
        // Four frames: allowed, with the expected chance count.
        let four = dark_from_stack(&darks(4, (64, 80), 0.0, 3.0, &[], &[], &[])).unwrap();
        assert!(four.notes.iter().any(|n| n.contains("by chance")), "{:?}", four.notes);
    }

    #[test]
    fn frames_are_checked_by_index() {
        let mut frames = darks(3, (8, 9), 0.0, 1.0, &[], &[], &[]);
        frames.push(Array3::zeros((8, 10, 1)));
        let e = dark_from_stack(&frames).unwrap_err();
        assert_eq!(e.frame_index(), Some(3));
        assert!(e.to_string().contains("frame 3 is 8 x 10") && e.to_string().contains("frame 0 is 8 x 9"), "{e}");
        frames[3] = Array3::zeros((8, 9, 1));
        frames[2][[1, 2, 0]] = f32::NAN;
        let e = dark_from_stack(&frames).unwrap_err().to_string();
        assert!(e.contains("frame 2") && e.contains("row 1, col 2"), "{e}");
        assert!(matches!(dark_from_stack(&[]), Err(CalibrateError::NoFrames { .. })));
        let e = calibrate(&CalibrationInput { background: &frames[..1], ..Default::default() }).unwrap_err();
        assert_eq!(e, CalibrateError::NothingToCalibrate);
    }

    /// A PSF: two Gaussian blobs and a thin line, unit sum.
    fn psf_truth(m: usize, k: usize, at: (f64, f64)) -> Array2<f64> {
        let mut p = Array2::from_shape_fn((m, k), |(i, j)| {
            let (di, dj) = (i as f64 - at.0, j as f64 - at.1);
            (-(di * di + dj * dj) / 18.0).exp() + 0.5 * (-((di - 6.0).powi(2) + (dj + 9.0).powi(2)) / 8.0).exp()
        });
        for j in 5..k - 20 {
            p[[(at.0 as usize + 10).min(m - 1), j]] += 0.3;
        }
        let s = p.sum();
        p / s
    }

    fn shots(truth: &Array2<f64>, n: usize, scale: f64, dark: f64, read: f64, seed: u64) -> Vec<Array3<f32>> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let g = Normal::new(0.0, 1.0).unwrap();
        let (m, k) = truth.dim();
        (0..n)
            .map(|_| {
                Array3::from_shape_fn((m, k, 1), |(i, j, _)| {
                    let s = scale * truth[[i, j]];
                    (dark + s + (read * read + s).sqrt() * g.sample(&mut rng)).round() as f32
                })
            })
            .collect()
    }

    fn correlation(a: &Array2<f64>, b: ArrayView2<f32>) -> f64 {
        let n = a.len() as f64;
        let (ma, mb) = (a.sum() / n, b.iter().map(|&v| v as f64).sum::<f64>() / n);
        let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
        for (&x, &y) in a.iter().zip(b.iter()) {
            let (x, y) = (x - ma, y as f64 - mb);
            sab += x * y;
            saa += x * x;
            sbb += y * y;
        }
        sab / (saa * sbb).sqrt()
    }

    #[test]
    fn a_psf_stack_is_averaged_cleaned_measured_and_registered() {
        let (m, k) = (60, 80);
        let truth = psf_truth(m, k, (22.0, 50.0));
        let mut frames = shots(&truth, 8, 2e5, 100.0, 3.0, 11);
        // A dead pixel on the bright blob, and a hot one in the dark.
        for f in frames.iter_mut() {
            f[[22, 50, 0]] = 100.0;
            f[[50, 10, 0]] = 3000.0;
        }
        let p = psf_from_stack(&frames, &PsfOptions::default()).unwrap();
        assert_eq!(p.outliers[[22, 50]], Defect::Dead.code());
        assert_eq!(p.outliers[[50, 10]], Defect::Hot.code());
        assert_eq!(p.record.repaired, 2);
        assert!((p.psf.sum() - 1.0).abs() < 1e-5);
        let plane = p.psf.index_axis(Axis(2), 0);
        let r = correlation(&truth, plane);
        assert!(r > 0.99, "correlation {r}");
        let (tr, tc) = {
            let s = truth.sum();
            let r: f64 = truth.indexed_iter().map(|((i, _), &v)| i as f64 * v).sum::<f64>() / s;
            let c: f64 = truth.indexed_iter().map(|((_, j), &v)| j as f64 * v).sum::<f64>() / s;
            (r, c)
        };
        assert!((p.record.centre_row - tr).abs() < 0.3 && (p.record.centre_col - tc).abs() < 0.3, "{:?} vs {tr} {tc}", p.record);
        assert!((p.record.energy_counts - 2e5).abs() < 0.03 * 2e5, "{:?}", p.record);
        assert!(p.record.peak_snr > 100.0, "{:?}", p.record);
        assert_eq!(p.record.shift, [0, 0]);
        assert!(p.dark_level_counts.as_ref().unwrap()[0] > 98.0);

        let reg = psf_from_stack(&frames, &PsfOptions { register: true, ..Default::default() }).unwrap();
        assert_eq!(reg.record.shift, [(30.0 - tr).round() as i64, (40.0 - tc).round() as i64]);
        let (cr, cc) = centroid(&reg.psf).unwrap();
        assert!((cr - 30.0).abs() <= 0.55 && (cc - 40.0).abs() <= 0.55, "{cr} {cc}");
    }

    #[test]
    fn clipped_and_mapped_pixels_are_repaired_and_a_dark_psf_is_refused() {
        let (m, k) = (40, 50);
        let truth = psf_truth(m, k, (20.0, 30.0));
        let frames: Vec<Array3<f32>> = shots(&truth, 4, 1e5, 50.0, 2.0, 3).into_iter().map(|f| f.mapv(|v| v.min(800.0))).collect();
        let sat = detect_saturation(&[(PSF_SHOTS, &frames)]).expect("a pile at 800");
        assert_eq!((sat.level, sat.frame), (800.0, 0));
        let dark = Array3::from_elem((m, k, 1), 50.0f32);
        let mut map = Array2::<u8>::zeros((m, k));
        map[[5, 5]] = Defect::Stuck.code();
        let p = psf_from_stack(&frames, &PsfOptions { dark: Some(&dark), defects: Some(&map), saturation_level: Some(800.0), ..Default::default() }).unwrap();
        assert!(p.clipped_pixels > 0);
        assert_eq!(p.record.repaired, p.clipped_pixels + 1);
        assert!(p.notes.iter().any(|n| n.contains("clip")), "{:?}", p.notes);
        assert!(p.dark_level_counts.is_none());

        // Every shot clipped at full scale: a flat PSF was accepted.
        let clipped = vec![Array3::from_elem((m, k, 1), 65535.0f32); 2];
        let e = psf_from_stack(&clipped, &PsfOptions { dark: Some(&dark), ..Default::default() }).unwrap_err();
        assert!(matches!(e, CalibrateError::FlatPsf { channel: 0, .. }) && e.to_string().contains("65535 counts at every pixel"), "{e}");
        let flat = vec![Array3::from_shape_fn((m, k, 1), |(i, _, _)| 40.0 + (i % 3) as f32); 2];
        let e = psf_from_stack(&flat, &PsfOptions { dark: Some(&dark), ..Default::default() }).unwrap_err();
        assert!(matches!(e, CalibrateError::ZeroPsf { channel: 0, .. }), "{e}");
        assert!(e.to_string().contains("all zero"), "{e}");
        let wrong = Array3::from_elem((m, k + 1, 1), 50.0f32);
        let e = psf_from_stack(&frames, &PsfOptions { dark: Some(&wrong), ..Default::default() }).unwrap_err().to_string();
        assert!(e.contains("PSF shots are 40 x 50") && e.contains("dark frames are 40 x 51"), "{e}");
    }

    #[test]
    fn the_whole_calibration_merges_the_maps_and_measures_the_background() {
        let (m, k) = (40, 50);
        let dark_frames = darks(16, (m, k), 2.0, 3.0, &[(3, 3)], &[(30, 30)], &[]);
        let truth = psf_truth(m, k, (20.0, 25.0));
        let mut psf_frames = shots(&truth, 6, 1e5, 100.0, 3.0, 5);
        for f in psf_frames.iter_mut() {
            f[[20, 25, 0]] = 100.0; // dead on the blob
        }
        let bg: Vec<Array3<f32>> = (0..3).map(|_| Array3::from_elem((m, k, 1), 130.0f32)).collect();
        let out =
            calibrate(&CalibrationInput { dark: &dark_frames, psf: &psf_frames, background: &bg, saturation_level: Some(4095.0), register: false }).unwrap();
        let cal = &out.calibration;
        let map = cal.defects.as_ref().unwrap();
        assert_eq!(map[[3, 3]], Defect::Hot.code());
        assert_eq!(map[[30, 30]], Defect::Stuck.code());
        assert_eq!(map[[20, 25]], Defect::Dead.code());
        let rec = cal.record.defects.as_ref().unwrap();
        assert_eq!((rec.hot, rec.stuck, rec.dead), (1, 1, 1), "{rec:?}");
        assert_eq!((cal.record.rows, cal.record.cols, cal.record.channels), (m, k, 1));
        assert_eq!(out.saturation_origin, Some(SaturationOrigin::Given));
        let b = cal.record.background.as_ref().unwrap();
        assert!((b.mean_above_dark - 30.0).abs() < 0.5, "{b:?}");
        let fig = report_figure(cal);
        assert_eq!(fig.dim().0, FIGURE_PANEL_HEIGHT + 2 * GAP);
        assert_eq!(fig.dim().2, 3);
        assert!(fig.iter().all(|&v| (0.0..=255.0).contains(&v)));

        // A background of another size is refused naming both stacks.
        let small = vec![Array3::<f32>::zeros((m, k - 1, 1))];
        let e = calibrate(&CalibrationInput { dark: &dark_frames, background: &small, ..Default::default() }).unwrap_err().to_string();
        assert!(e.contains("background frames are 40 x 49") && e.contains("dark frames are 40 x 50"), "{e}");
        let e = calibrate(&CalibrationInput { dark: &dark_frames, saturation_level: Some(-1.0), ..Default::default() }).unwrap_err();
        assert_eq!(e, CalibrateError::SaturationLevel(-1.0));
    }
}
