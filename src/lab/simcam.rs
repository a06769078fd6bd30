//! The simulated camera's renderer: every frame is a full rolling-shutter capture made
//! by the physical simulator (scene + diffuser PSF + the camera's applied timing), so
//! a bench session can be rehearsed with no hardware.

use crate::model::capture::CaptureConfig;
use crate::model::shutter::ShutterMode;
use crate::sim::{self, LensletParams, NoiseModel, Scene, TimeShifted};
use rollcam_hw::camera::simulated::{FrameRenderer, RenderError};
use rollcam_hw::camera::{self as hwcam, AppliedSettings, SensorGeometry};

/// Renders frames of a fixed-size sensor through a synthetic lenslet diffuser.
pub struct SimRenderer {
    rows: usize,
    cols: usize,
    psf: Vec<f32>,
    scene: Box<dyn Scene>,
    noise: NoiseModel,
    seed: u64,
}

impl SimRenderer {
    /// A `rows x cols` sensor looking at `scene` (which must have that size).
    pub fn new(rows: usize, cols: usize, scene: Box<dyn Scene>, seed: u64) -> Result<Self, sim::SimError> {
        let psf = sim::lenslet_psf(rows, cols, &LensletParams { aperture_fraction: 1.0, ..LensletParams::default() }, seed)?;
        Ok(SimRenderer { rows, cols, psf: psf.iter().cloned().collect(), scene, noise: NoiseModel::default(), seed })
    }

    /// The unit-sum PSF at sensor resolution (what a calibration would measure).
    pub fn psf(&self) -> &[f32] {
        &self.psf
    }

    /// The capture description of a frame taken with `settings`.
    pub fn capture_config(&self, settings: &AppliedSettings) -> Result<CaptureConfig, RenderError> {
        capture_config(self.rows, self.cols, self.noise.dark_level_adu, settings)
    }
}

/// The capture description of a `rows x cols` frame taken with `settings`.
pub fn capture_config(rows: usize, cols: usize, dark_level_adu: f64, settings: &AppliedSettings) -> Result<CaptureConfig, RenderError> {
    {
        let line_time_us = settings.line_time_us.ok_or("simulated camera: no line time applied")?;
        let shutter = match settings.shutter.unwrap_or(hwcam::ShutterMode::Rolling) {
            hwcam::ShutterMode::Global => ShutterMode::Global,
            hwcam::ShutterMode::Rolling => ShutterMode::Rolling,
            hwcam::ShutterMode::Dual => ShutterMode::Dual,
        };
        let mut cfg = CaptureConfig::new(rows, cols, line_time_us, settings.exposure_us, shutter);
        cfg.dark_level = Some(dark_level_adu);
        cfg.validate()?;
        Ok(cfg)
    }
}

impl FrameRenderer for SimRenderer {
    fn geometry(&self) -> SensorGeometry {
        SensorGeometry { width: self.cols as u32, height: self.rows as u32, max_bit_depth: 16 }
    }

    fn render(&mut self, index: u64, settings: &AppliedSettings) -> Result<Vec<u16>, RenderError> {
        let (w, h) = settings.image_size();
        if (w as usize, h as usize) != (self.cols, self.rows) {
            return Err(format!(
                "simulated camera renders the full {} x {} sensor only (ROI and binning give {w} x {h})",
                self.cols, self.rows
            )
            .into());
        }
        let cfg = self.capture_config(settings)?;
        let period_us = 1e6 / settings.frame_rate_hz.unwrap_or(10.0);
        let shifted = TimeShifted { scene: self.scene.as_ref(), offset_us: index as f64 * period_us };
        let s = sim::simulate(&cfg, &self.psf, &shifted, &self.noise, 4, self.seed.wrapping_add(index))?;
        let max = ((1u32 << settings.pixel_format.bit_depth()) - 1) as f32;
        Ok(s.raw.iter().map(|&v| v.clamp(0.0, max) as u16).collect())
    }
}

/// Where a [`SourcedRenderer`] gets the scene of each frame: asked again before every
/// frame, so the scene follows live state (e.g. what an LED controller is driving).
pub type SceneSource = Box<dyn FnMut() -> Result<Box<dyn Scene>, RenderError> + Send>;

/// Like [`SimRenderer`], but the scene comes from a [`SceneSource`] at render time.
pub struct SourcedRenderer {
    rows: usize,
    cols: usize,
    psf: Vec<f32>,
    source: SceneSource,
    noise: NoiseModel,
    seed: u64,
}

impl SourcedRenderer {
    /// A `rows x cols` sensor (same diffuser as [`SimRenderer::new`] with this seed).
    pub fn new(rows: usize, cols: usize, source: SceneSource, seed: u64) -> Result<Self, sim::SimError> {
        let psf = sim::lenslet_psf(rows, cols, &LensletParams { aperture_fraction: 1.0, ..LensletParams::default() }, seed)?;
        Ok(SourcedRenderer { rows, cols, psf: psf.iter().cloned().collect(), source, noise: NoiseModel::default(), seed })
    }

    /// The unit-sum PSF at sensor resolution.
    pub fn psf(&self) -> &[f32] {
        &self.psf
    }

    /// The dark level of the rendered frames, counts.
    pub fn dark_level_adu(&self) -> f64 {
        self.noise.dark_level_adu
    }
}

impl FrameRenderer for SourcedRenderer {
    fn geometry(&self) -> SensorGeometry {
        SensorGeometry { width: self.cols as u32, height: self.rows as u32, max_bit_depth: 16 }
    }

    fn render(&mut self, index: u64, settings: &AppliedSettings) -> Result<Vec<u16>, RenderError> {
        let (w, h) = settings.image_size();
        if (w as usize, h as usize) != (self.cols, self.rows) {
            return Err(format!("simulated camera renders the full {} x {} sensor only (ROI and binning give {w} x {h})", self.cols, self.rows).into());
        }
        let scene = (self.source)()?;
        if scene.size() != (self.rows, self.cols) {
            return Err(format!("scene source gave a {:?} scene for a {} x {} sensor", scene.size(), self.rows, self.cols).into());
        }
        let cfg = capture_config(self.rows, self.cols, self.noise.dark_level_adu, settings)?;
        // The source's scene starts at this frame's first row (t = 0): no offset.
        let s = sim::simulate(&cfg, &self.psf, scene.as_ref(), &self.noise, 4, self.seed.wrapping_add(index))?;
        let max = ((1u32 << settings.pixel_format.bit_depth()) - 1) as f32;
        Ok(s.raw.iter().map(|&v| v.clamp(0.0, max) as u16).collect())
    }
}
