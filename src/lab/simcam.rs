//! The simulated camera's renderers: every frame is a full rolling-shutter capture
//! made by the physical simulator (scene + diffuser PSF + the camera's applied
//! timing), so a bench session can be rehearsed with no hardware. Also the simulated
//! camera's device description ([`simulated_config`]) and `rollcam capture`'s
//! simulated cameras ([`capture_camera`], [`write_calibration`]).

use crate::lab::hardware;
use crate::model::capture::CaptureConfig;
use crate::sim::{self, psf_counts, LensletParams, MovingDisc, NoiseModel, Scene, SimParams, TimeShifted};
use anyhow::{anyhow, bail, Context};
use ndarray::ArrayView2;
use rollcam_hw::camera::simulated::{FrameRenderer, RenderError, SimulatedCamera, SimulatedConfig};
use rollcam_hw::camera::{AppliedSettings, Camera, PixelFormat, SensorGeometry, ShutterMode};
use std::path::Path;

/// The simulated camera `sim:<id>`: a 16-bit sensor with the three shutter modes of
/// real cameras, powered up in dual shutter with this timing.
pub fn simulated_config(id: impl Into<String>, line_time_us: f64, exposure_us: f64, frame_rate_hz: f64) -> SimulatedConfig {
    SimulatedConfig {
        id: id.into(),
        shutter_modes: ShutterMode::ALL.to_vec(),
        exposure_us,
        line_time_us,
        frame_rate_hz,
        shutter: ShutterMode::Dual,
        pixel_format: PixelFormat::Mono16,
        ..SimulatedConfig::default()
    }
}

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
    let mut cfg = hardware::capture_config(rows, cols, settings).map_err(|e| format!("simulated camera: {e}"))?;
    cfg.dark_level = Some(dark_level_adu);
    cfg.validate()?;
    Ok(cfg)
}

impl FrameRenderer for SimRenderer {
    fn geometry(&self) -> SensorGeometry {
        SensorGeometry { width: self.cols as u32, height: self.rows as u32, max_bit_depth: 16 }
    }

    fn render(&mut self, index: u64, settings: &AppliedSettings) -> Result<Vec<u16>, RenderError> {
        let (w, h) = settings.image_size();
        if (w as usize, h as usize) != (self.cols, self.rows) {
            return Err(format!("simulated camera renders the full {} x {} sensor only (ROI and binning give {w} x {h})", self.cols, self.rows).into());
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

/// Sensor of `rollcam capture`'s simulated cameras, rows x cols.
pub const CAPTURE_SENSOR: (usize, usize) = (128, 160);

/// `rollcam capture`'s simulated camera `sim:<id>`: a [`CAPTURE_SENSOR`] dual-shutter
/// sensor looking at the LED line of `rollcam simulate`'s defaults (`led-array`, also
/// `0` and `sim0`) or a moving disc (`moving-disc`), at the paper's timing.
pub fn capture_camera(id: &str) -> anyhow::Result<SimulatedCamera<SimRenderer>> {
    let (rows, cols) = CAPTURE_SENSOR;
    let defaults = SimParams::default();
    let scene: Box<dyn Scene> = match id {
        "led-array" | "0" | "sim0" => Box::new(defaults.led_array(rows, cols)?),
        "moving-disc" => Box::new(MovingDisc::new(rows, cols, 6.0, (50.0, 30.0), (0.0012, 0.004), 200.0)),
        other => bail!("camera sim:{other}: unknown simulated scene: expected sim:led-array or sim:moving-disc"),
    };
    let renderer = SimRenderer::new(rows, cols, scene, defaults.seed)?;
    let config = simulated_config(id, defaults.line_time_us, defaults.exposure_us, 20.0);
    Ok(SimulatedCamera::new(renderer, config))
}

/// What a calibration of a simulated camera gives: the diffuser's PSF as recorded
/// (counts, dark level included, `rows x cols x 1`) and the capture description of
/// the frames it takes with its current settings.
pub fn calibration(cam: &mut SimulatedCamera<SimRenderer>) -> anyhow::Result<(ndarray::Array3<f32>, CaptureConfig)> {
    let applied = cam.applied_settings()?;
    let r = cam.renderer();
    let cfg = r.capture_config(&applied).map_err(|e| anyhow!("{e}"))?;
    let psf = ArrayView2::from_shape((r.rows, r.cols), r.psf()).context("PSF has rows x cols samples")?;
    Ok((psf_counts(psf, cfg.dark_level.unwrap_or(0.0)), cfg))
}

/// Write the calibration a real bench would have beside a simulated camera's frames:
/// the diffuser's PSF as recorded (`psf.tiff`) and the timing the camera applied
/// (`capture.toml`), so that every frame can be reconstructed.
pub fn write_calibration(dir: &Path, cam: &mut SimulatedCamera<SimRenderer>) -> anyhow::Result<()> {
    let (psf, cfg) = calibration(cam)?;
    crate::io::write_tiff_u16(dir.join("psf.tiff"), psf.view())?;
    crate::io::write_text_atomic(&dir.join("capture.toml"), &cfg.to_toml())?;
    Ok(())
}
