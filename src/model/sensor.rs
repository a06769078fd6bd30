//! The sensor as a real bench has it: a fixed-pattern dark (one value per pixel),
//! defective pixels (hot, stuck, dead, noisy), a saturation level, and a static
//! background. Plain data and numerics only: a calibration folder is read by
//! `crate::io::calibration`, made by `crate::analysis::calibrate`.
//!
//! What the solver gets from here (through `crate::model::prepare`) is a **mask**:
//! defective pixels, whose value says nothing about the scene, are left out of the data
//! term (`0.5 ||M (A v - b)||^2`) instead of being "repaired" in the data; clipped
//! pixels, which say "at least this much", stay in as lower bounds.

use ndarray::{Array2, Array3, ArrayView2};
use serde::{Deserialize, Serialize};

/// A pixel's code in `defects.tiff` (0 is a good pixel).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[repr(u8)]
pub enum Defect {
    Good = 0,
    /// Far brighter than its neighbours in the dark (dark current or a stuck-high bit).
    Hot = 1,
    /// No temporal noise: the value does not follow the light.
    Stuck = 2,
    /// Temporal noise far above the sensor's read noise (random telegraph noise).
    Noisy = 3,
    /// Far darker than its neighbours under light.
    Dead = 4,
}

impl Defect {
    pub fn code(self) -> u8 {
        self as u8
    }
    pub fn name(self) -> &'static str {
        match self {
            Defect::Good => "good",
            Defect::Hot => "hot",
            Defect::Stuck => "stuck",
            Defect::Noisy => "noisy",
            Defect::Dead => "dead",
        }
    }
}

/// What `calibration.toml` records: what was shot and what was measured. The arrays
/// (`dark.tiff`, `defects.tiff`, `psf.tiff`, `background.tiff`) sit beside it; each
/// record below says its file is there.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationRecord {
    /// Sensor rows and columns every array of the folder has.
    pub rows: usize,
    pub cols: usize,
    /// 1 (grey) or 3 (RGB).
    pub channels: usize,
    /// Raw value at which pixels clip (counts), when known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub saturation_level: Option<f64>,
    /// When the folder was made (UTC, ISO 8601).
    #[serde(default)]
    pub created_utc: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dark: Option<DarkRecord>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub defects: Option<DefectRecord>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub psf: Option<PsfRecord>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub background: Option<BackgroundRecord>,
}

/// The dark stack (`dark.tiff`: the per-pixel mean, counts).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DarkRecord {
    pub frames: usize,
    #[serde(default)]
    pub files: Vec<String>,
    /// Median of the per-pixel dark (counts).
    pub median_level: f64,
    /// Spatial spread of the per-pixel dark (fixed-pattern noise, counts rms, robust).
    pub fixed_pattern_rms: f64,
    /// Median of the per-pixel temporal standard deviations (counts rms).
    pub read_noise: f64,
}

/// The defect map (`defects.tiff`, one [`Defect`] code per pixel).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DefectRecord {
    pub hot: usize,
    pub stuck: usize,
    pub noisy: usize,
    pub dead: usize,
    pub total: usize,
    /// `total` over the sensor's pixels.
    pub fraction: f64,
}

/// The PSF stack (`psf.tiff`: averaged, dark-subtracted, defects repaired, unit sum).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PsfRecord {
    pub frames: usize,
    #[serde(default)]
    pub files: Vec<String>,
    /// Intensity centroid (row, col) on the sensor, before any registration.
    pub centre_row: f64,
    pub centre_col: f64,
    /// Shift (rows, cols) applied to put the centroid at the sensor centre (0, 0 when
    /// the PSF was kept where it fell).
    #[serde(default)]
    pub shift: [i64; 2],
    /// Counts above dark summed over the sensor (mean shot).
    pub energy_counts: f64,
    /// Share of that energy in the outer 5% band of the sensor: a PSF that reaches the
    /// edges loses light off the sensor.
    pub edge_fraction: f64,
    /// Peak signal over the noise of the averaged shot.
    pub peak_snr: f64,
    /// Pixels repaired from their neighbours (defects, clipped).
    pub repaired: usize,
}

/// The background stack (`background.tiff`: the per-pixel mean **as shot**, dark
/// included, so reconstruction subtracts it in place of the dark).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BackgroundRecord {
    pub frames: usize,
    #[serde(default)]
    pub files: Vec<String>,
    /// Mean counts above the dark.
    pub mean_above_dark: f64,
}

/// A bench calibration in memory: the record and the arrays it names, each
/// (row, col, channel) except the defect map (row, col).
#[derive(Clone, Debug, Default)]
pub struct Calibration {
    pub record: CalibrationRecord,
    pub dark: Option<Array3<f32>>,
    pub defects: Option<Array2<u8>>,
    pub psf: Option<Array3<f32>>,
    pub background: Option<Array3<f32>>,
}

/// Robust standard deviation: 1.4826 x the median absolute deviation from the median.
pub fn robust_sigma(values: &[f32]) -> f64 {
    let mut v: Vec<f32> = values.iter().cloned().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return 0.0;
    }
    let med = median_in_place(&mut v);
    let mut dev: Vec<f32> = v.iter().map(|x| (x - med).abs()).collect();
    1.4826 * median_in_place(&mut dev) as f64
}

/// Median of a non-empty slice (reorders it).
pub fn median_in_place(v: &mut [f32]) -> f32 {
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
    *m
}

/// The pixel noise of one image, estimated from differences of horizontally adjacent
/// pixels (a robust sigma of `(x[i,j+1] - x[i,j]) / sqrt 2`): smooth structure cancels,
/// so it is close to the read noise in dark regions, which dominate a lensless raw.
pub fn pixel_noise(img: ArrayView2<f32>) -> f64 {
    let (m, n) = img.dim();
    if n < 2 {
        return 0.0;
    }
    let mut d = Vec::with_capacity(m * (n - 1));
    for i in 0..m {
        for j in 0..n - 1 {
            d.push(img[[i, j + 1]] - img[[i, j]]);
        }
    }
    // The median of the differences is ~0 on smooth images; the MAD is what counts.
    robust_sigma(&d) / std::f64::consts::SQRT_2
}

/// Isolated outliers of one image: pixels above **every** one of their 8 neighbours
/// by more than `k * noise` plus the brightest neighbour's level above `floor` (the
/// dark), i.e. more than twice as bright (hot), or below every one by more than
/// `k * noise` plus half the darkest neighbour's level (dead). A caustic line one pixel wide has
/// neighbours along it and is never taken; a cluster of defects is missed. Returns the
/// flagged pixels as [`Defect::Hot`] or [`Defect::Dead`] codes (0 elsewhere).
pub fn find_outliers(img: ArrayView2<f32>, noise: f64, floor: f64, k: f64) -> Array2<u8> {
    let (m, n) = img.dim();
    let mut out = Array2::<u8>::zeros((m, n));
    if m < 3 || n < 3 {
        return out;
    }
    let margin = k * noise.max(1e-6);
    for i in 0..m {
        for j in 0..n {
            let x = img[[i, j]] as f64;
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for di in -1i64..=1 {
                for dj in -1i64..=1 {
                    if di == 0 && dj == 0 {
                        continue;
                    }
                    let (a, b) = (i as i64 + di, j as i64 + dj);
                    if a < 0 || b < 0 || a >= m as i64 || b >= n as i64 {
                        continue;
                    }
                    let v = img[[a as usize, b as usize]] as f64;
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
            }
            if x > hi + margin + (hi - floor).max(0.0) {
                out[[i, j]] = Defect::Hot.code();
            } else if x < lo - margin - 0.5 * (lo - floor).max(0.0) {
                out[[i, j]] = Defect::Dead.code();
            }
        }
    }
    out
}

/// Replace every flagged pixel (`bad[i, j]` true) by the median of its good pixels in
/// the 3 x 3 (else 5 x 5) neighbourhood; returns how many were replaced (a pixel with
/// no good neighbour within 2 is set to 0 and still counted).
pub fn repair(img: &mut Array2<f32>, bad: &Array2<bool>) -> usize {
    let (m, n) = img.dim();
    let src = img.clone();
    let mut count = 0;
    let mut nb = Vec::with_capacity(24);
    for i in 0..m {
        for j in 0..n {
            if !bad[[i, j]] {
                continue;
            }
            count += 1;
            let mut value = 0.0;
            for r in 1..=2i64 {
                nb.clear();
                for di in -r..=r {
                    for dj in -r..=r {
                        let (a, b) = (i as i64 + di, j as i64 + dj);
                        if a < 0 || b < 0 || a >= m as i64 || b >= n as i64 || bad[[a as usize, b as usize]] {
                            continue;
                        }
                        nb.push(src[[a as usize, b as usize]]);
                    }
                }
                if !nb.is_empty() {
                    value = median_in_place(&mut nb);
                    break;
                }
            }
            img[[i, j]] = value;
        }
    }
    count
}

/// The clipping level a raw shows by itself: a pile of pixels at the largest value
/// (at least `max(4, 1e-4 n)` of them, and at least twice as many as in the step just
/// below, and above the median: a flat image is no pile), which a natural image's
/// bright tail does not have. `None` when there is no such pile.
pub fn saturation_pile(values: &[f32]) -> Option<f64> {
    let max = values.iter().cloned().filter(|v| v.is_finite()).fold(f32::NEG_INFINITY, f32::max);
    if !(max > 0.0) {
        return None;
    }
    let at_max = values.iter().filter(|&&v| v == max).count();
    // The step below: one count for integer data, else 0.1% of the value.
    let integer = values.iter().take(4096).all(|v| !v.is_finite() || v.fract() == 0.0);
    let step = if integer { 1.0 } else { max * 1e-3 };
    let below = values.iter().filter(|&&v| v < max && v >= max - step).count();
    let need = ((values.len() as f64 * 1e-4).ceil() as usize).max(4);
    if at_max < need || at_max < 2 * below {
        return None;
    }
    let mut v: Vec<f32> = values.iter().cloned().filter(|v| v.is_finite()).collect();
    (median_in_place(&mut v) < max).then_some(max as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noisy_image(m: usize, n: usize, seed: u64, level: f32, sigma: f32) -> Array2<f32> {
        let u = crate::model::op::pseudo_random(m * n * 2, seed);
        // Box-Muller from pairs.
        Array2::from_shape_fn((m, n), |(i, j)| {
            let k = 2 * (i * n + j);
            let (a, b) = (u[k].max(1e-7) as f64, u[k + 1] as f64);
            level + sigma * ((-2.0 * a.ln()).sqrt() * (2.0 * std::f64::consts::PI * b).cos()) as f32
        })
    }

    #[test]
    fn robust_sigma_and_pixel_noise_find_the_noise() {
        let img = noisy_image(64, 80, 3, 100.0, 2.0);
        let s = pixel_noise(img.view());
        assert!((s - 2.0).abs() < 0.15, "{s}");
        let r = robust_sigma(img.as_slice().unwrap());
        assert!((r - 2.0).abs() < 0.15, "{r}");
    }

    #[test]
    fn outliers_are_single_spikes_not_thin_lines() {
        let mut img = noisy_image(40, 40, 5, 100.0, 2.0);
        // A bright line one pixel wide (a caustic) and a bright blob.
        for j in 5..35 {
            img[[20, j]] += 2000.0;
        }
        for i in 8..12 {
            for j in 8..12 {
                img[[i, j]] += 500.0;
            }
        }
        img[[30, 30]] = 4095.0; // hot
        img[[10, 10]] = 100.0; // dead inside the blob
        img[[5, 30]] = 130.0; // a hot pixel 15 sigma above a dark neighbourhood
        let f = find_outliers(img.view(), 2.0, 100.0, 6.0);
        assert_eq!(f[[30, 30]], Defect::Hot.code());
        assert_eq!(f[[5, 30]], Defect::Hot.code());
        assert_eq!(f[[10, 10]], Defect::Dead.code());
        let flagged: usize = f.iter().filter(|&&c| c != 0).count();
        assert_eq!(flagged, 3, "the line and the blob are not defects");
    }

    #[test]
    fn repair_takes_the_median_of_good_neighbours() {
        let mut img = Array2::from_shape_fn((5, 5), |(i, j)| (i * 5 + j) as f32);
        let mut bad = Array2::from_elem((5, 5), false);
        bad[[2, 2]] = true;
        img[[2, 2]] = 1e6;
        assert_eq!(repair(&mut img, &bad), 1);
        // Neighbours 6,7,8,11,13,16,17,18: the upper median is 13.
        assert_eq!(img[[2, 2]], 13.0);
    }

    #[test]
    fn a_clipped_raw_shows_its_pile_and_a_natural_one_does_not() {
        let img = noisy_image(60, 60, 9, 1000.0, 300.0).mapv(|v| v.round().max(0.0));
        assert_eq!(saturation_pile(img.as_slice().unwrap()), None);
        let clipped = img.mapv(|v| v.min(1200.0));
        assert_eq!(saturation_pile(clipped.as_slice().unwrap()), Some(1200.0));
        let float = noisy_image(60, 60, 9, 1000.0, 300.0);
        assert_eq!(saturation_pile(float.as_slice().unwrap()), None);
        assert_eq!(saturation_pile(float.mapv(|v| v.min(1200.5)).as_slice().unwrap()), Some(1200.5));
        assert_eq!(saturation_pile(&[7.0; 100]), None, "a flat image is no pile");
    }
}
