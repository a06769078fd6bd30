//! The simulated camera backend (`sim:<scene>`): every frame is a full rolling-shutter
//! capture made by the physical simulator (a scene seen through a synthetic lenslet
//! diffuser, with the camera's applied timing), so a bench session can be rehearsed
//! with no hardware. One renderer ([`SimRenderer`]) whose scene comes from a
//! [`SceneSource`]: a scene of the catalogue ([`SimScene`]), frame `i` seeing it
//! `i / frame_rate_hz` seconds after frame 0, or a live source asked again before
//! every frame (the LED sweep's controller). Also the calibration a real bench would
//! measure beside its frames ([`calibration`], [`write_calibration`]), and the shots a
//! bench takes to measure it ([`SimShot`]: darks with the cap on, a point source,
//! the background), so that `rollcam calibrate` runs on its frames.
//!
//! Opened like every other camera, by [`crate::lab::camera::open_camera`].

use crate::lab::hardware;
use crate::model::capture::CaptureConfig;
use crate::model::shutter::DEFAULT_LINE_TIME_US;
use crate::sim::expose::read_out;
use crate::sim::{self, psf_counts, LedArray, LedLine, LensletParams, MovingDisc, NoiseModel, Scene, TimeShifted};
use anyhow::{anyhow, Context};
use ndarray::{Array3, Array4, ArrayView2};
use rollcam_hw::camera::simulated::{FrameRenderer, RenderError, SimulatedCamera, SimulatedConfig};
use rollcam_hw::camera::{AppliedSettings, Camera, CameraShutter, PixelFormat, SensorGeometry};
use std::path::{Path, PathBuf};

/// The scenes the simulated camera can show, by name (`sim:<scene>`, `--sim-scene`).
#[derive(Clone, Debug, PartialEq)]
pub enum SimScene {
    /// Four LEDs on the middle row, 12 px apart (fewer on narrow sensors), flashing
    /// square waves (duty 0.5) with these periods (one for all, or one per LED).
    LedArray { period_us: Vec<f64> },
    /// A bright disc crossing the field of view.
    MovingDisc,
}

impl std::str::FromStr for SimScene {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "led-array" => Ok(SimScene::LedArray { period_us: vec![2640.0, 1980.0, 1320.0, 1760.0] }),
            "moving-disc" => Ok(SimScene::MovingDisc),
            other => Err(format!("unknown simulated scene '{other}': expected led-array or moving-disc")),
        }
    }
}

impl SimScene {
    /// The scene's name (`led-array`, `moving-disc`).
    pub fn name(&self) -> &'static str {
        match self {
            SimScene::LedArray { .. } => "led-array",
            SimScene::MovingDisc => "moving-disc",
        }
    }

    /// The scene on a `rows x cols` sensor.
    pub fn build(&self, rows: usize, cols: usize) -> Result<Box<dyn Scene>, sim::SimError> {
        Ok(match self {
            SimScene::LedArray { period_us } => {
                let leds = 4;
                let spacing = (12.0f64).min((cols as f64 - 6.0) / leds as f64);
                Box::new(LedArray::new(
                    rows,
                    cols,
                    LedLine { leds, spacing_px: spacing, radius_px: 1.5, period_us: period_us.clone(), duty: 0.5, phase_us: vec![0.0], e_per_us: 2000.0 },
                )?)
            }
            SimScene::MovingDisc => {
                Box::new(MovingDisc::new(rows, cols, (rows.min(cols) as f64 / 20.0).max(2.0), (rows as f64 * 0.4, cols as f64 * 0.2), (0.0003, 0.001), 200.0))
            }
        })
    }
}

/// A scene asked for again before every frame, so that it follows live state (e.g.
/// what an LED controller is driving).
pub type LiveScene = Box<dyn FnMut() -> Result<Box<dyn Scene>, RenderError> + Send>;

/// Where the simulated camera's frames get their scene.
pub enum SceneSource {
    /// A scene of the catalogue; frame `i` sees it `i / frame_rate_hz` seconds after
    /// frame 0, so consecutive frames show it at different moments.
    Catalogue(SimScene),
    /// A live scene named `name` (the camera's id); each frame sees the scene the
    /// source gives, from its own first row on.
    Live { name: String, scene: LiveScene },
}

impl SceneSource {
    /// The camera's id: the scene's name.
    pub fn name(&self) -> &str {
        match self {
            SceneSource::Catalogue(s) => s.name(),
            SceneSource::Live { name, .. } => name,
        }
    }
}

impl std::fmt::Debug for SceneSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SceneSource::Catalogue(s) => f.debug_tuple("Catalogue").field(s).finish(),
            SceneSource::Live { name, .. } => f.debug_struct("Live").field("name", name).finish_non_exhaustive(),
        }
    }
}

/// What the simulated camera's frames show (`rollcam capture --kind`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SimShot {
    /// The scene, through the diffuser, with the camera's timing.
    #[default]
    Scene,
    /// The cap on: the dark level, read noise and quantisation only.
    Dark,
    /// A point source on the optical axis: the diffuser's PSF, its peak at half the
    /// sensor's range above the dark, with shot and read noise.
    Point,
    /// The scene without what moves: the catalogue's scenes (LEDs, a disc on black)
    /// have nothing still, so it is dark, as a bench's background with the LEDs off
    /// and the room dark is.
    Background,
}

/// What the simulated camera looks like: its scene, its sensor and diffuser, and the
/// timing it powers up with (dual shutter).
#[derive(Debug)]
pub struct SimCameraSpec {
    pub source: SceneSource,
    pub rows: usize,
    pub cols: usize,
    pub line_time_us: f64,
    pub exposure_us: f64,
    pub frame_rate_hz: f64,
    /// Seed of the diffuser and of the noise (frame `i`'s noise: `seed + i`).
    pub seed: u64,
    /// Write each frame's truth video here as `truth_NNNNNN.npy` (frame index = sequence).
    pub truth_dir: Option<PathBuf>,
    /// Temporal downsampling/binning recorded in the capture description (truth grid).
    pub downsample: usize,
    pub binning: usize,
}

impl SimCameraSpec {
    /// `source` on a 128 x 160 sensor at the paper's timing (220 us line time, 660 us
    /// exposure), 20 frames per second, seed 1, no truth videos written.
    pub fn new(source: SceneSource) -> SimCameraSpec {
        SimCameraSpec {
            source,
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

/// The scene of a [`SimRenderer`], ready to render.
enum Source {
    Fixed(Box<dyn Scene>),
    Live(LiveScene),
}

/// Renders the simulated camera's frames through the physical simulator and
/// (optionally) writes their truth videos.
pub struct SimRenderer {
    rows: usize,
    cols: usize,
    /// Frame rate used when the settings give none.
    frame_rate_hz: f64,
    seed: u64,
    truth_dir: Option<PathBuf>,
    downsample: usize,
    binning: usize,
    psf: Vec<f32>,
    source: Source,
    noise: NoiseModel,
    /// The truth video of the frame rendered last (the simulated key camera's scene).
    last_truth: Option<ndarray::Array3<f32>>,
    /// What the frames show.
    shot: SimShot,
}

impl SimRenderer {
    /// The renderer of `spec`'s sensor (a synthetic lenslet diffuser seeded by
    /// `spec.seed`, the default noise).
    pub fn new(spec: SimCameraSpec) -> Result<SimRenderer, sim::SimError> {
        let (rows, cols) = (spec.rows, spec.cols);
        let psf = sim::lenslet_psf(rows, cols, &LensletParams { aperture_fraction: 1.0, ..LensletParams::default() }, spec.seed)?;
        let source = match spec.source {
            SceneSource::Catalogue(scene) => Source::Fixed(scene.build(rows, cols)?),
            SceneSource::Live { scene, .. } => Source::Live(scene),
        };
        Ok(SimRenderer {
            rows,
            cols,
            frame_rate_hz: spec.frame_rate_hz,
            seed: spec.seed,
            truth_dir: spec.truth_dir,
            downsample: spec.downsample,
            binning: spec.binning,
            psf: psf.iter().cloned().collect(),
            source,
            noise: NoiseModel::default(),
            last_truth: None,
            shot: SimShot::Scene,
        })
    }

    /// Show `shot` from the next frame on.
    pub fn set_shot(&mut self, shot: SimShot) {
        self.shot = shot;
    }

    /// A calibration shot's raw (counts): no light for a dark or background, the PSF
    /// for a point source (its peak at half the range between the dark level and the
    /// saturation level), read out with the sensor's noise.
    fn calibration_shot(&self, seed: u64) -> Vec<f32> {
        let electrons: Vec<f64> = match self.shot {
            SimShot::Point => {
                let peak = self.psf.iter().cloned().fold(0.0f32, f32::max).max(f32::MIN_POSITIVE) as f64;
                let n = &self.noise;
                let peak_e = 0.5 * (n.saturation_level_adu() - n.dark_level_adu) / n.gain_adu_per_e;
                self.psf.iter().map(|&v| v as f64 / peak * peak_e).collect()
            }
            _ => vec![0.0; self.rows * self.cols],
        };
        read_out(&electrons, &self.noise, seed).0
    }

    /// The unit-sum PSF at sensor resolution (what a calibration would measure).
    pub fn psf(&self) -> &[f32] {
        &self.psf
    }

    /// The truth video (frames, rows, cols of the video grid, the raw's video units) of
    /// the frame rendered last; `None` before the first.
    pub fn last_truth(&self) -> Option<&ndarray::Array3<f32>> {
        self.last_truth.as_ref()
    }

    /// The sensor's conversion gain, ADU per photo-electron.
    pub fn conversion_gain_adu_per_e(&self) -> f64 {
        self.noise.gain_adu_per_e
    }

    /// The seed of the diffuser and the noise.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The dark level of the rendered frames, counts.
    pub fn dark_level_adu(&self) -> f64 {
        self.noise.dark_level_adu
    }

    /// The capture description of frames taken with `settings`.
    pub fn capture_config(&self, settings: &AppliedSettings) -> Result<CaptureConfig, RenderError> {
        let mut cfg = hardware::capture_config(self.rows, self.cols, settings, &Default::default()).map_err(|e| format!("simulated camera: {e}"))?;
        cfg.dark_level = Some(self.noise.dark_level_adu);
        // The full well in counts clips before the ADC's full scale does.
        let full_well = self.noise.saturation_level_adu();
        cfg.saturation_level = Some(cfg.saturation_level.map_or(full_well, |adc| adc.min(full_well)));
        cfg.downsample = self.downsample;
        cfg.binning = self.binning;
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
            return Err(format!("the simulated camera renders the full {} x {} sensor only (ROI and binning give {w} x {h})", self.cols, self.rows).into());
        }
        let cfg = self.capture_config(settings)?;
        let seed = self.seed.wrapping_add(index);
        let max = ((1u32 << settings.pixel_format.bit_depth()) - 1) as f32;
        if self.shot != SimShot::Scene {
            return Ok(self.calibration_shot(seed).iter().map(|&v| v.clamp(0.0, max).round() as u16).collect());
        }
        let s = match &mut self.source {
            Source::Fixed(scene) => {
                let period_us = 1e6 / settings.frame_rate_hz.unwrap_or(self.frame_rate_hz);
                let shifted = TimeShifted { scene: scene.as_ref(), offset_us: index as f64 * period_us };
                sim::simulate(&cfg, &self.psf, &shifted, &self.noise, 4, seed)?
            }
            Source::Live(source) => {
                let scene = source()?;
                if scene.size() != (self.rows, self.cols) {
                    return Err(format!("scene source gave a {:?} scene for a {} x {} sensor", scene.size(), self.rows, self.cols).into());
                }
                // The source's scene starts at this frame's first row (t = 0): no offset.
                sim::simulate(&cfg, &self.psf, scene.as_ref(), &self.noise, 4, seed)?
            }
        };
        if let Some(dir) = &self.truth_dir {
            let (k, m, n) = s.truth.dim();
            let video = Array4::from_shape_vec((k, m, n, 1), s.truth.iter().cloned().collect()).expect("truth shape");
            std::fs::create_dir_all(dir)?;
            crate::io::write_npy(dir.join(format!("truth_{index:06}.npy")), video.view())?;
        }
        self.last_truth = Some(s.truth);
        Ok(s.raw.iter().map(|&v| v.clamp(0.0, max).round() as u16).collect())
    }
}

/// The simulated camera.
pub type SimCamera = SimulatedCamera<SimRenderer>;

/// The simulated camera `spec` describes: a 16-bit sensor with the three shutter
/// modes of real cameras, powered up in dual shutter with the spec's timing, its id
/// the scene's name.
pub fn open(spec: SimCameraSpec) -> Result<SimCamera, sim::SimError> {
    let config = SimulatedConfig {
        id: spec.source.name().to_string(),
        shutter_modes: CameraShutter::ALL.to_vec(),
        exposure_us: spec.exposure_us,
        line_time_us: spec.line_time_us,
        frame_rate_hz: spec.frame_rate_hz,
        shutter: CameraShutter::Dual,
        pixel_format: PixelFormat::Mono16,
        ..SimulatedConfig::default()
    };
    Ok(SimulatedCamera::new(SimRenderer::new(spec)?, config))
}

/// The capture description of the frames a simulated camera takes with its current
/// settings (its dark level, and its full well as the saturation level).
pub fn capture_config(cam: &mut SimCamera) -> anyhow::Result<CaptureConfig> {
    let applied = cam.applied_settings()?;
    cam.renderer().capture_config(&applied).map_err(|e| anyhow!("simulated camera: {e}"))
}

/// What a calibration of a simulated camera gives: the diffuser's PSF as recorded
/// (counts, dark level included, `rows x cols x 1`) and the capture description of
/// the frames it takes with its current settings.
pub fn calibration(cam: &mut SimCamera) -> anyhow::Result<(Array3<f32>, CaptureConfig)> {
    let cfg = capture_config(cam)?;
    let r = cam.renderer();
    let psf = ArrayView2::from_shape((r.rows, r.cols), r.psf()).context("PSF has rows x cols samples")?;
    Ok((psf_counts(psf, r.dark_level_adu()), cfg))
}

/// Write the calibration a real bench would have beside a simulated camera's frames:
/// the diffuser's PSF as recorded (`psf.tiff`) and the capture description of its
/// frames (`capture.toml`), so that every frame can be reconstructed.
pub fn write_calibration(dir: &Path, psf: &Array3<f32>, cfg: &CaptureConfig) -> anyhow::Result<()> {
    crate::io::write_tiff_u16(dir.join("psf.tiff"), psf.view())?;
    crate::io::write_text_atomic(&dir.join("capture.toml"), &cfg.to_toml())?;
    Ok(())
}
