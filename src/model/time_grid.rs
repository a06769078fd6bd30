//! The global time grid of a sequence of raw captures.
//!
//! Video frame `f` covers `[f T_f, (f+1) T_f)` from the first-row exposure start of the
//! first capture. Capture `c`, whose first row starts exposing at `t_c`, starts at video
//! frame `o_c = round((t_c - t_0) / T_f)` and covers `K` frames (its own shutter model);
//! the rounding residue `(t_c - t_0) - o_c T_f` is kept for the summary. Frames that no
//! capture covers are gap frames: only the temporal regulariser constrains them.

use crate::model::shutter::{ShutterWeights, TimingError, MAX_FRAMES};
use serde::Serialize;
use std::ops::Range;

/// Where the capture start times came from.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(rename_all = "kebab-case", tag = "source")]
pub enum TimeSource {
    /// The cameras' device timestamps (`device_timestamp_ns` of each frame's sidecar).
    DeviceTimestamps,
    /// Frame sequence numbers times a given frame period.
    FramePeriod { period_us: f64 },
}

/// Captures placed on one video time grid.
#[derive(Clone, Debug, Serialize)]
pub struct TimeGrid {
    /// Video frame interval `T_f`, microseconds.
    pub frame_time_us: f64,
    /// Video frames each capture covers (`K`).
    pub capture_frames: usize,
    /// First-row exposure start of every capture relative to the first, microseconds.
    pub start_us: Vec<f64>,
    /// First video frame of every capture (`o_c`).
    pub offsets: Vec<usize>,
    /// `start_us[c] - offsets[c] * T_f`, microseconds (at most half a frame).
    pub residue_us: Vec<f64>,
    /// Video frames of the whole sequence.
    pub frames: usize,
    /// Per video frame: the exposure weight it receives, summed over captures and
    /// sensor rows (rows exposing during the whole frame count 1 each). 0 on gap frames.
    pub coverage: Vec<f64>,
    pub source: TimeSource,
}

impl TimeGrid {
    /// Place captures starting at `start_us` (relative to the first, ascending) on the
    /// grid of `weights` (one capture's shutter model).
    /// Refused when the captures span more than [`MAX_FRAMES`] video frames (a pause
    /// of minutes between two captures, or a frame period typed in the wrong unit),
    /// before anything of that length is allocated.
    pub fn new(start_us: &[f64], weights: &ShutterWeights, source: TimeSource) -> Result<TimeGrid, TimingError> {
        assert!(!start_us.is_empty(), "a sequence needs at least one capture");
        let tf = weights.frame_time_us();
        let t0 = start_us[0];
        let rel: Vec<f64> = start_us.iter().map(|t| t - t0).collect();
        let span = rel.iter().fold(0.0f64, |m, &t| m.max(t / tf)) + weights.frames() as f64;
        if !(span <= MAX_FRAMES as f64) {
            let (c, gap_us) = rel.windows(2).enumerate().map(|(c, w)| (c + 1, w[1] - w[0])).fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
            let what = match source {
                TimeSource::DeviceTimestamps => format!("device timestamps (the longest pause: {gap_us} us before capture {c})"),
                TimeSource::FramePeriod { period_us } => format!("a frame period of {period_us} us"),
            };
            return Err(TimingError::Invalid {
                field: "capture start times",
                value: what,
                expected: format!(
                    "captures within {MAX_FRAMES} video frames of {tf} us (these span {span:.0}); split the capture folder at the pause, or check the unit"
                ),
            });
        }
        let offsets: Vec<usize> = rel.iter().map(|t| (t / tf).round().max(0.0) as usize).collect();
        let residue_us = rel.iter().zip(&offsets).map(|(t, &o)| t - o as f64 * tf).collect();
        Ok(Self::from_offsets(rel, offsets, residue_us, weights, source))
    }

    /// A grid with the given offsets (for tests of what a wrong offset does).
    pub fn with_offsets(offsets: &[usize], weights: &ShutterWeights, source: TimeSource) -> TimeGrid {
        let tf = weights.frame_time_us();
        let rel: Vec<f64> = offsets.iter().map(|&o| o as f64 * tf).collect();
        Self::from_offsets(rel, offsets.to_vec(), vec![0.0; offsets.len()], weights, source)
    }

    fn from_offsets(start_us: Vec<f64>, offsets: Vec<usize>, residue_us: Vec<f64>, weights: &ShutterWeights, source: TimeSource) -> TimeGrid {
        let k = weights.frames();
        let frames = offsets.iter().map(|o| o + k).max().unwrap_or(0);
        let column: Vec<f64> = (0..k).map(|f| (0..weights.rows()).map(|r| weights.get(r, f) as f64).sum()).collect();
        let mut coverage = vec![0.0f64; frames];
        for &o in &offsets {
            for (f, w) in column.iter().enumerate() {
                coverage[o + f] += w;
            }
        }
        TimeGrid { frame_time_us: weights.frame_time_us(), capture_frames: k, start_us, offsets, residue_us, frames, coverage, source }
    }

    pub fn captures(&self) -> usize {
        self.offsets.len()
    }

    /// Video frames of capture `c`.
    pub fn frames_of(&self, c: usize) -> Range<usize> {
        self.offsets[c]..self.offsets[c] + self.capture_frames
    }

    /// Frames no capture covers.
    pub fn gap_frames(&self) -> Vec<usize> {
        self.coverage.iter().enumerate().filter(|(_, &w)| w == 0.0).map(|(f, _)| f).collect()
    }

    /// Frames covered by more than one capture.
    pub fn shared_frames(&self) -> Vec<usize> {
        let mut count = vec![0usize; self.frames];
        for c in 0..self.captures() {
            for f in self.frames_of(c) {
                count[f] += 1;
            }
        }
        count.iter().enumerate().filter(|(_, &n)| n > 1).map(|(f, _)| f).collect()
    }

    /// Largest rounding residue, microseconds (absolute value).
    pub fn max_residue_us(&self) -> f64 {
        self.residue_us.iter().fold(0.0f64, |m, r| m.max(r.abs()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::shutter::{ShutterMode, Timing};

    #[test]
    fn offsets_residues_gaps_and_overlaps() {
        // Rolling, 4 rows, T_l = 10, T_e = 20: K = 5 frames of 10 us.
        let w = Timing::new(4, 10.0, 20.0, ShutterMode::Rolling).weights().unwrap();
        // Starts 0, 72 (-> 7, residue 2), 118 (-> 12, residue -2).
        let g = TimeGrid::new(&[1000.0, 1072.0, 1118.0], &w, TimeSource::DeviceTimestamps).unwrap();
        assert_eq!(g.offsets, vec![0, 7, 12]);
        assert_eq!(g.frames, 17);
        assert!((g.residue_us[1] - 2.0).abs() < 1e-9 && (g.residue_us[2] + 2.0).abs() < 1e-9);
        assert_eq!(g.gap_frames(), vec![5, 6]);
        assert!(g.shared_frames().is_empty());
        // Column sums of the band: 1, 2, 2, 2, 1.
        assert_eq!(&g.coverage[..5], &[1.0, 2.0, 2.0, 2.0, 1.0]);
        // Overlap: starts 0 and 40 us -> frames 4 is shared.
        let g = TimeGrid::new(&[0.0, 40.0], &w, TimeSource::FramePeriod { period_us: 40.0 }).unwrap();
        assert_eq!(g.shared_frames(), vec![4]);
        assert_eq!(g.coverage[4], 2.0);
        assert!(g.gap_frames().is_empty());
    }

    #[test]
    fn a_pause_of_minutes_is_refused_before_the_grid_is_allocated() {
        // A 1000 s pause on 10 us frames asked for 55 GB (an abort).
        let w = Timing::new(4, 10.0, 20.0, ShutterMode::Rolling).weights().unwrap();
        let e = TimeGrid::new(&[0.0, 100.0, 1e9 + 100.0], &w, TimeSource::DeviceTimestamps).unwrap_err().to_string();
        assert!(e.contains("pause") && e.contains("before capture 2") && e.contains("1000000 video frames"), "{e}");
        let e = TimeGrid::new(&[0.0, 1e12], &w, TimeSource::FramePeriod { period_us: 1e12 }).unwrap_err().to_string();
        assert!(e.contains("frame period of 1000000000000 us"), "{e}");
        assert!(TimeGrid::new(&[0.0, 1e308], &w, TimeSource::FramePeriod { period_us: 1e308 }).is_err());
    }
}
