//! A simulated bench for rehearsals and fixtures: a simulated camera whose every frame
//! is a full rolling-shutter capture made by the physical simulator (a scene seen
//! through a synthetic lenslet diffuser), with the PSF and capture description a real
//! bench would get from calibration, and each frame's ground-truth video.
//!
//! Frame `i` sees the scene `i / frame_rate_hz` seconds after frame 0, so consecutive
//! frames show the scene at different moments.

use crate::lab::hardware;
use crate::lab::simcam::simulated_config;
use crate::model::capture::CaptureConfig;
use crate::model::shutter::DEFAULT_LINE_TIME_US;
use crate::sim::{self, psf_counts, LedArray, LensletParams, MovingDisc, NoiseModel, Scene, TimeShifted};
use ndarray::{Array4, ArrayView2};
use rollcam_hw::camera::simulated::{FrameRenderer, RenderError, SimulatedCamera};
use rollcam_hw::camera::{AppliedSettings, SensorGeometry};
use std::path::PathBuf;

/// Scenes the simulated bench can show.
#[derive(Clone, Debug, PartialEq)]
pub enum BenchScene {
    /// Four LEDs on the middle row, 12 px apart (fewer on narrow sensors), flashing
    /// square waves (duty 0.5) with these periods (one for all, or one per LED).
    LedArray { period_us: Vec<f64> },
    /// A bright disc crossing the field of view.
    MovingDisc,
}

impl std::str::FromStr for BenchScene {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "led-array" => Ok(BenchScene::LedArray { period_us: vec![2640.0, 1980.0, 1320.0, 1760.0] }),
            "moving-disc" => Ok(BenchScene::MovingDisc),
            other => Err(format!("unknown simulated scene '{other}': expected led-array or moving-disc")),
        }
    }
}

/// What the simulated bench looks like.
#[derive(Clone, Debug)]
pub struct BenchSpec {
    pub scene: BenchScene,
    pub rows: usize,
    pub cols: usize,
    pub line_time_us: f64,
    pub exposure_us: f64,
    pub frame_rate_hz: f64,
    pub seed: u64,
    /// Write each frame's truth video here as `truth_NNNNNN.npy` (frame index = sequence).
    pub truth_dir: Option<PathBuf>,
    /// Temporal downsampling/binning recorded in the capture description (truth grid).
    pub downsample: usize,
    pub binning: usize,
}

impl Default for BenchSpec {
    fn default() -> Self {
        BenchSpec {
            scene: BenchScene::LedArray { period_us: vec![2640.0, 1980.0, 1320.0, 1760.0] },
            rows: 128,
            cols: 160,
            line_time_us: DEFAULT_LINE_TIME_US,
            exposure_us: 660.0,
            frame_rate_hz: 20.0,
            seed: 1,
            truth_dir: None,
            downsample: 1,
            binning: 1,
        }
    }
}

/// Dark level of the simulated sensor, ADU.
pub fn dark_level_adu() -> f64 {
    NoiseModel::default().dark_level_adu
}

fn make_scene(spec: &BenchSpec) -> Result<Box<dyn Scene>, sim::SimError> {
    let (rows, cols) = (spec.rows, spec.cols);
    Ok(match &spec.scene {
        BenchScene::LedArray { period_us } => {
            let leds = 4;
            let spacing = (12.0f64).min((cols as f64 - 6.0) / leds as f64);
            Box::new(LedArray::new(rows, cols, leds, spacing, 1.5, period_us.clone(), 0.5, vec![0.0], 2000.0)?)
        }
        BenchScene::MovingDisc => {
            Box::new(MovingDisc::new(rows, cols, (rows.min(cols) as f64 / 20.0).max(2.0), (rows as f64 * 0.4, cols as f64 * 0.2), (0.0003, 0.001), 200.0))
        }
    })
}

/// Renders frames through the simulator and (optionally) writes their truth videos.
pub struct BenchRenderer {
    spec: BenchSpec,
    psf: Vec<f32>,
    scene: Box<dyn Scene>,
    noise: NoiseModel,
}

impl BenchRenderer {
    pub fn new(spec: BenchSpec) -> Result<Self, sim::SimError> {
        let psf = sim::lenslet_psf(spec.rows, spec.cols, &LensletParams { aperture_fraction: 1.0, ..LensletParams::default() }, spec.seed)?;
        let scene = make_scene(&spec)?;
        Ok(BenchRenderer { psf: psf.iter().cloned().collect(), scene, noise: NoiseModel::default(), spec })
    }

    /// The unit-sum PSF at sensor resolution.
    pub fn psf(&self) -> &[f32] {
        &self.psf
    }

    /// The PSF as a calibration image would record it: 16-bit counts over the dark level.
    pub fn psf_image(&self) -> ndarray::Array3<f32> {
        let psf = ArrayView2::from_shape((self.spec.rows, self.spec.cols), &self.psf).expect("PSF has rows x cols samples");
        psf_counts(psf, self.noise.dark_level_adu).mapv(f32::round)
    }

    /// The capture description of frames taken with `settings`.
    pub fn capture_config(&self, settings: &AppliedSettings) -> Result<CaptureConfig, RenderError> {
        let mut cfg = hardware::capture_config(self.spec.rows, self.spec.cols, settings).map_err(|e| format!("simulated camera: {e}"))?;
        cfg.dark_level = Some(self.noise.dark_level_adu);
        cfg.downsample = self.spec.downsample;
        cfg.binning = self.spec.binning;
        cfg.validate()?;
        Ok(cfg)
    }

    /// A simulated camera around this renderer, set to the bench's timing (dual shutter).
    pub fn into_camera(self) -> SimulatedCamera<BenchRenderer> {
        let id = match self.spec.scene {
            BenchScene::LedArray { .. } => "led-array",
            BenchScene::MovingDisc => "moving-disc",
        };
        let config = simulated_config(id, self.spec.line_time_us, self.spec.exposure_us, self.spec.frame_rate_hz);
        SimulatedCamera::new(self, config)
    }
}

impl FrameRenderer for BenchRenderer {
    fn geometry(&self) -> SensorGeometry {
        SensorGeometry { width: self.spec.cols as u32, height: self.spec.rows as u32, max_bit_depth: 16 }
    }

    fn render(&mut self, index: u64, settings: &AppliedSettings) -> Result<Vec<u16>, RenderError> {
        let (w, h) = settings.image_size();
        if (w as usize, h as usize) != (self.spec.cols, self.spec.rows) {
            return Err(
                format!("the simulated camera renders the full {} x {} sensor only (ROI and binning give {w} x {h})", self.spec.cols, self.spec.rows).into()
            );
        }
        let cfg = self.capture_config(settings)?;
        let period_us = 1e6 / settings.frame_rate_hz.unwrap_or(self.spec.frame_rate_hz);
        let shifted = TimeShifted { scene: self.scene.as_ref(), offset_us: index as f64 * period_us };
        let s = sim::simulate(&cfg, &self.psf, &shifted, &self.noise, 4, self.spec.seed.wrapping_add(index))?;
        if let Some(dir) = &self.spec.truth_dir {
            let (k, m, n) = s.truth.dim();
            let video = Array4::from_shape_vec((k, m, n, 1), s.truth.iter().cloned().collect()).expect("truth shape");
            std::fs::create_dir_all(dir)?;
            crate::io::write_npy(dir.join(format!("truth_{index:06}.npy")), video.view())?;
        }
        let max = ((1u32 << settings.pixel_format.bit_depth()) - 1) as f32;
        Ok(s.raw.iter().map(|&v| v.clamp(0.0, max).round() as u16).collect())
    }
}
