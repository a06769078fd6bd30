//! Consecutive captures of one scene whose time runs on across them: capture `c`
//! starts its first-row exposure at `c P` (P the frame period) and sees the scene at
//! those times, so an LED keeps flashing with one phase from capture to capture. The
//! ground truth is the scene integrated over every frame of the global video grid
//! (frame `f` covers `[f T_f, (f+1) T_f)`), `round((C-1) P / T_f) + K` frames long.

use super::error::{invalid, SimError};
use super::expose::{simulate, NoiseModel};
use super::scene::Scene;
use crate::model::capture::CaptureConfig;
use crate::model::resample::box_downsample_f64;
use crate::model::shutter::TimingError;
use crate::model::time_grid::{TimeGrid, TimeSource};
use ndarray::{Array2, Array3, Axis};

/// A scene seen `offset_us` later.
pub struct TimeShifted<'a> {
    pub scene: &'a dyn Scene,
    pub offset_us: f64,
}

impl Scene for TimeShifted<'_> {
    fn size(&self) -> (usize, usize) {
        self.scene.size()
    }
    fn integrate(&self, t0_us: f64, t1_us: f64, out: &mut [f32]) {
        self.scene.integrate(t0_us + self.offset_us, t1_us + self.offset_us, out)
    }
    fn describe(&self) -> toml::Table {
        self.scene.describe()
    }
}

/// Consecutive simulated captures and the truth on the global grid.
pub struct SequenceSimulation {
    /// Raw image of every capture, ADU (`rows x cols`).
    pub raws: Vec<Array2<f32>>,
    /// First-row exposure start of every capture, microseconds (`c P`).
    pub start_us: Vec<f64>,
    /// Ground truth on the global grid, `frames x rows/d x cols/d`, ADU per frame.
    pub truth: Array3<f32>,
    pub frame_time_us: f64,
    /// Video frames of one capture.
    pub capture_frames: usize,
    pub saturated_pixels: usize,
    /// `cfg` annotated with the first capture's provenance (dark level, tables).
    pub config: CaptureConfig,
}

/// The continuous-readout frame period of a timing: the span of the row starts plus
/// one line time (the next capture's first rows start as soon as the last row of this
/// one has started).
pub fn readout_period_us(cfg: &CaptureConfig) -> f64 {
    let starts = cfg.timing().raw_row_starts_us();
    starts.iter().cloned().fold(0.0f64, f64::max) + cfg.line_time_us
}

/// The global time grid of `captures` consecutive captures `period_us` apart: the
/// period at least a video frame and an exposure, the captures within
/// [`crate::model::shutter::MAX_FRAMES`] video frames (the check of
/// [`TimeGrid::new`], which `reconstruct-sequence` makes too).
pub fn sequence_grid(cfg: &CaptureConfig, captures: usize, period_us: f64) -> Result<TimeGrid, SimError> {
    if captures == 0 {
        return Err(invalid("captures", 0, "at least 1 capture"));
    }
    let timing = cfg.timing();
    let tf = timing.frame_time_us();
    if !(period_us.is_finite() && period_us >= tf.max(cfg.exposure_us)) {
        return Err(invalid("frame_period_us", period_us, format!("at least one video frame time ({tf} us) and one exposure ({} us)", cfg.exposure_us)));
    }
    let start_us: Vec<f64> = (0..captures).map(|c| c as f64 * period_us).collect();
    TimeGrid::new(&start_us, &timing.weights()?, TimeSource::FramePeriod { period_us })
        .map_err(|TimingError::Invalid { expected, .. }| invalid("frame_period_us", period_us, expected))
}

/// How many consecutive captures, and how far apart their first rows start.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Consecutive {
    pub captures: usize,
    pub period_us: f64,
}

/// Simulate `run.captures` consecutive captures `run.period_us` apart (noise seeded by
/// `seed + c` for capture `c`).
pub fn simulate_sequence(
    cfg: &CaptureConfig,
    psf_raw: &[f32],
    scene: &dyn Scene,
    noise: &NoiseModel,
    substeps_per_line: usize,
    seed: u64,
    run: Consecutive,
) -> Result<SequenceSimulation, SimError> {
    let Consecutive { captures, period_us } = run;
    let tf = sequence_grid(cfg, captures, period_us)?.frame_time_us;
    let mut raws = Vec::with_capacity(captures);
    let mut start_us = Vec::with_capacity(captures);
    let mut saturated_pixels = 0;
    let mut config = None;
    let mut k = 0;
    for c in 0..captures {
        let t = c as f64 * period_us;
        let shifted = TimeShifted { scene, offset_us: t };
        let s = simulate(cfg, psf_raw, &shifted, noise, substeps_per_line, seed.wrapping_add(c as u64))?;
        saturated_pixels += s.saturated_pixels;
        k = s.truth.dim().0;
        if config.is_none() {
            config = Some(s.capture_config(cfg));
        }
        raws.push(s.raw);
        start_us.push(t);
    }
    let frames = ((captures - 1) as f64 * period_us / tf).round() as usize + k;
    let (m, n) = (cfg.rows, cfg.cols);
    let (tr, tc) = cfg.grid();
    let mut truth = Array3::<f32>::zeros((frames, tr, tc));
    let mut buf = vec![0.0f32; m * n];
    let gain = noise.gain_adu_per_e;
    for (f, mut plane) in truth.axis_iter_mut(Axis(0)).enumerate() {
        scene.integrate(f as f64 * tf, (f + 1) as f64 * tf, &mut buf);
        let acc: Vec<f64> = buf.iter().map(|&v| v as f64).collect();
        let (small, _, _) = box_downsample_f64(&acc, m, n, cfg.downsample);
        for (t, v) in plane.iter_mut().zip(small) {
            *t = (v as f64 * gain) as f32;
        }
    }
    Ok(SequenceSimulation { raws, start_us, truth, frame_time_us: tf, capture_frames: k, saturated_pixels, config: config.expect("one capture") })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::shutter::ShutterMode;
    use crate::sim::{LedArray, LedLine};

    #[test]
    fn each_capture_sees_the_global_truth_at_its_offset() {
        // Period a whole number of frames: capture c's own truth is the global truth
        // from frame c P / T_f on, so the scene's time runs on across captures.
        let cfg = CaptureConfig::new(12, 10, 100.0, 300.0, ShutterMode::Dual);
        let psf = vec![1.0 / 120.0; 120];
        let scene = LedArray::new(
            12,
            10,
            LedLine { leds: 1, spacing_px: 0.0, radius_px: 1.5, period_us: vec![700.0], duty: 0.5, phase_us: vec![0.0], e_per_us: 100.0 },
        )
        .unwrap();
        let s = simulate_sequence(&cfg, &psf, &scene, &NoiseModel::noise_free(), 4, 1, Consecutive { captures: 3, period_us: 900.0 }).unwrap();
        assert_eq!(s.capture_frames, 8);
        assert_eq!(s.truth.dim().0, 18 + 8);
        for c in 0..3 {
            let shifted = TimeShifted { scene: &scene, offset_us: c as f64 * 900.0 };
            let own = simulate(&cfg, &psf, &shifted, &NoiseModel::noise_free(), 4, 1).unwrap().truth;
            for k in 0..8 {
                for (a, b) in own.index_axis(Axis(0), k).iter().zip(s.truth.index_axis(Axis(0), 9 * c + k).iter()) {
                    assert!((a - b).abs() <= 1e-3 * b.abs().max(1.0), "capture {c} frame {k}: {a} vs {b}");
                }
            }
        }
        // Period shorter than the exposure is refused, naming the field.
        let e =
            simulate_sequence(&cfg, &psf, &scene, &NoiseModel::noise_free(), 4, 1, Consecutive { captures: 2, period_us: 200.0 }).err().unwrap().to_string();
        assert!(e.contains("frame_period_us"), "{e}");
    }
}
