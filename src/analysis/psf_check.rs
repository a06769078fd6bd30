//! The check of point-source shots as they are taken (`rollcam capture --kind psf`):
//! is the source bright enough without clipping, near the sensor's centre, and spread
//! as a diffuser's caustic is. Measured on the shots as recorded, before any
//! calibration.

use crate::analysis::calibrate::centroid;
use crate::model::prepare::estimate_dark;
use ndarray::{Array3, Axis};
use serde::Serialize;

/// What the PSF shots look like.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PsfShotCheck {
    pub frames: usize,
    /// The largest value of the mean shot, counts.
    pub peak: f64,
    /// The level at which pixels clip, counts, when known.
    pub saturation_level: Option<f64>,
    /// `peak / saturation_level`.
    pub peak_fraction: Option<f64>,
    /// Share of the recorded samples (every frame) at or above the saturation level.
    pub clipped_fraction: f64,
    /// The dark level estimated from the darkest pixels of the mean shot, counts.
    pub dark_level: f64,
    /// Centroid (row, col) of the light above the dark, pixels.
    pub centroid_px: (f64, f64),
    /// The centroid minus the sensor centre (rows/2, cols/2), pixels.
    pub offset_px: (f64, f64),
    /// Rms radius of the light above the dark about its centroid, pixels.
    pub spread_px: f64,
    /// What to change, in words (empty: the shots look usable).
    pub advice: Vec<String>,
}

/// The peak below this share of the saturation level is dim (noisy PSF).
pub const DIM_PEAK_FRACTION: f64 = 0.3;

/// Check point-source shots (equal shapes, at least one); `None` when no light rises
/// above the dark.
pub fn check_psf_shots(frames: &[Array3<f32>], saturation_level: Option<f64>) -> Option<PsfShotCheck> {
    let first = frames.first()?;
    let (rows, cols, ch) = first.dim();
    let mut mean = Array3::<f64>::zeros((rows, cols, ch));
    for f in frames {
        mean.zip_mut_with(f, |m, &v| *m += f64::from(v));
    }
    mean /= frames.len() as f64;
    let peak = mean.iter().copied().fold(0.0f64, f64::max);
    let samples: usize = frames.iter().map(|f| f.len()).sum();
    let clipped = saturation_level.map_or(0, |level| frames.iter().flat_map(|f| f.iter()).filter(|&&v| f64::from(v) >= level).count());
    let clipped_fraction = clipped as f64 / samples.max(1) as f64;
    let flat: Vec<f32> = mean.iter().map(|&v| v as f32).collect();
    let dark_level = estimate_dark(&flat);
    let light = mean.map(|&v| (v - dark_level).max(0.0) as f32).sum_axis(Axis(2)).insert_axis(Axis(2));
    let centroid_px = centroid(&light)?;
    let (mut w, mut r2) = (0.0f64, 0.0f64);
    for ((i, j, _), &v) in light.indexed_iter() {
        let v = f64::from(v);
        w += v;
        r2 += v * ((i as f64 - centroid_px.0).powi(2) + (j as f64 - centroid_px.1).powi(2));
    }
    let spread_px = (r2 / w).sqrt();
    let offset_px = (centroid_px.0 - (rows / 2) as f64, centroid_px.1 - (cols / 2) as f64);
    let peak_fraction = saturation_level.map(|level| peak / level);
    let mut advice = Vec::new();
    if clipped > 0 {
        advice.push("pixels clip: shorten the exposure or dim the source".to_string());
    } else if peak_fraction.is_some_and(|f| f < DIM_PEAK_FRACTION) {
        advice.push(format!(
            "the peak is under {:.0}% of the saturation level: lengthen the exposure, brighten the source or take more frames",
            100.0 * DIM_PEAK_FRACTION
        ));
    }
    if offset_px.0.abs() > rows as f64 / 8.0 || offset_px.1.abs() > cols as f64 / 8.0 {
        advice.push("the light is far off centre: move the source onto the axis (or calibrate --register)".to_string());
    }
    if spread_px < 0.05 * rows.min(cols) as f64 {
        advice.push("the light is concentrated in a few pixels: is the diffuser in place?".to_string());
    }
    Some(PsfShotCheck { frames: frames.len(), peak, saturation_level, peak_fraction, clipped_fraction, dark_level, centroid_px, offset_px, spread_px, advice })
}

impl PsfShotCheck {
    /// One line for a terminal.
    pub fn summary(&self) -> String {
        let level = match (self.saturation_level, self.peak_fraction) {
            (Some(l), Some(f)) => format!(" of {l} counts ({:.0}%)", 100.0 * f),
            _ => String::new(),
        };
        format!(
            "psf shot ({} frames): peak {:.0}{level}, {:.3}% clipped, dark {:.1}, centroid x {:.1}, y {:.1} (column, row, as --roi's x,y) = {:+.1}, {:+.1} px from the centre, spread {:.1} px rms",
            self.frames,
            self.peak,
            100.0 * self.clipped_fraction,
            self.dark_level,
            self.centroid_px.1,
            self.centroid_px.0,
            self.offset_px.1,
            self.offset_px.0,
            self.spread_px
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ring of light of radius `r` about `(cr, cc)` on a dark of 100 counts.
    fn ring(rows: usize, cols: usize, cr: f64, cc: f64, r: f64, level: f32) -> Array3<f32> {
        Array3::from_shape_fn((rows, cols, 1), |(i, j, _)| {
            let d = ((i as f64 - cr).powi(2) + (j as f64 - cc).powi(2)).sqrt();
            100.0 + if (d - r).abs() < 0.7 { level } else { 0.0 }
        })
    }

    #[test]
    fn a_centred_caustic_passes_and_faults_are_named() {
        let good = ring(64, 80, 32.0, 40.0, 12.0, 2000.0);
        let c = check_psf_shots(&[good.clone(), good], Some(4095.0)).unwrap();
        assert_eq!(c.dark_level, 100.0);
        assert!((c.centroid_px.0 - 32.0).abs() < 0.2 && (c.centroid_px.1 - 40.0).abs() < 0.2, "{c:?}");
        assert!((c.spread_px - 12.0).abs() < 0.5, "{c:?}");
        assert_eq!((c.peak, c.clipped_fraction), (2100.0, 0.0));
        assert!(c.advice.is_empty(), "{:?}", c.advice);
        assert!(c.summary().contains("peak 2100 of 4095 counts (51%)"), "{}", c.summary());

        let clipping = ring(64, 80, 32.0, 40.0, 12.0, 4000.0);
        let c = check_psf_shots(&[clipping], Some(4095.0)).unwrap();
        assert!(c.clipped_fraction > 0.0 && c.advice[0].contains("clip"), "{c:?}");
        let off = ring(64, 80, 10.0, 12.0, 4.0, 2000.0);
        let c = check_psf_shots(&[off], Some(4095.0)).unwrap();
        assert!(c.advice.iter().any(|a| a.contains("off centre")), "{:?}", c.advice);
        let point = ring(64, 80, 32.0, 40.0, 0.0, 2000.0);
        let c = check_psf_shots(&[point], None).unwrap();
        assert!(c.advice.iter().any(|a| a.contains("diffuser")), "{:?}", c.advice);
        assert!(check_psf_shots(&[Array3::from_elem((8, 8, 1), 7.0)], None).is_none());
    }
}
