//! Simulations set up from plain parameters: the capture timing, the synthetic or
//! measured PSF, the scenes (a line of flashing LEDs, a moving disc, a disc over a
//! static texture, an image stack) and the noise model behind `rollcam simulate`,
//! `rollcam demo` and the simulated cameras, and the PSF as a calibration image would
//! record it. No files: the callers read measured PSFs and image stacks and write the
//! results.

use super::error::SimError;
use super::expose::{simulate, NoiseModel, Simulation};
use super::psf::{lenslet_psf, LensletParams};
use super::scene::{derive_seed, DiscOverTexture, ImageStack, LedArray, LedLine, MovingDisc, Scene, TEXTURE_STREAM};
use super::sequence::{readout_period_us, simulate_sequence, Consecutive, SequenceSimulation};
use crate::model::capture::CaptureConfig;
use crate::model::prepare::{box_downsample, estimate_dark};
use crate::model::shutter::{ShutterMode, TimingError, DEFAULT_LINE_TIME_US};
use ndarray::{Array2, Array3, ArrayView2, ArrayView3, ArrayView4, Axis};

/// The occluder's radiance over its texture's mean ([`SimParams::occluder`]).
pub const OCCLUDER_DISC_FRACTION: f64 = 0.05;

/// Peak of a PSF as recorded by [`psf_counts`], counts above the dark level.
pub const PSF_PEAK_COUNTS: f32 = 50_000.0;

/// The parameters of a simulated capture: the flags of `rollcam simulate`, whose
/// defaults are [`SimParams::default`]. Sizes and radii are in raw pixels, times in
/// microseconds.
///
/// Deserialised from a table of its fields (the Python module's keyword arguments):
/// missing fields take the defaults, unknown ones are refused by name.
#[derive(Clone, Debug, PartialEq, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimParams {
    /// Raw sensor rows (a measured PSF's size rules instead).
    pub rows: usize,
    /// Raw sensor columns.
    pub cols: usize,
    /// Raw line time.
    pub line_time_us: f64,
    /// Exposure of each row.
    pub exposure_us: f64,
    pub shutter: ShutterMode,
    /// Downsampling the reconstruction will apply (recorded in capture.toml; the truth
    /// is written on that grid).
    pub downsample: usize,
    /// Temporal binning the reconstruction will apply.
    pub binning: usize,
    /// Lenslets of the synthetic diffuser.
    pub lenslets: usize,
    /// Diameter of the diffuser's round aperture as a fraction of the smaller sensor side.
    pub aperture_fraction: f64,
    /// Number of LEDs of the LED line.
    pub leds: usize,
    /// LED periods: one for all or one per LED.
    pub period_us: Vec<f64>,
    /// LED duty cycle.
    pub duty: f64,
    /// LED spacing.
    pub spacing_px: f64,
    /// LED spot radius.
    pub led_radius_px: f64,
    /// Brightness of an LED (or the disc, divided by 10) while on, photo-electrons per
    /// microsecond.
    pub e_per_us: f64,
    /// Radius of the moving disc.
    pub disc_radius_px: f64,
    /// Speed of the moving disc, raw pixels per millisecond.
    pub disc_px_per_ms: f64,
    /// disc-over-texture: the disc's radiance over the texture's mean radiance.
    pub disc_contrast: f64,
    /// How long each frame of an image stack is shown.
    pub stack_interval_us: f64,
    /// Sensor read noise, photo-electrons.
    pub read_noise_e: f64,
    /// Black offset, ADU.
    pub dark_level_adu: f64,
    /// Shot and read noise (quantisation and saturation remain without them).
    pub noise: bool,
    /// Time sub-steps per line time.
    pub substeps: usize,
    /// Seed of the diffuser and the noise.
    pub seed: u64,
}

impl Default for SimParams {
    /// The paper's setting on a 128 x 160 sensor: 220 us line time, 660 us exposure,
    /// dual shutter, four LEDs flashing at 2640, 1980, 1320 and 1760 us.
    fn default() -> Self {
        SimParams {
            rows: 128,
            cols: 160,
            line_time_us: DEFAULT_LINE_TIME_US,
            exposure_us: 660.0,
            shutter: ShutterMode::Dual,
            downsample: 1,
            binning: 1,
            lenslets: 48,
            aperture_fraction: 1.0,
            leds: 4,
            period_us: vec![2640.0, 1980.0, 1320.0, 1760.0],
            duty: 0.5,
            spacing_px: 12.0,
            led_radius_px: 1.5,
            e_per_us: 2000.0,
            disc_radius_px: 6.0,
            disc_px_per_ms: 4.0,
            disc_contrast: 4.0,
            stack_interval_us: 1000.0,
            read_noise_e: 2.0,
            dark_level_adu: 100.0,
            noise: true,
            substeps: 4,
            seed: 1,
        }
    }
}

/// The scenes a simulation can show: the `--scene` values of `rollcam simulate`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneKind {
    /// A line of LEDs flashing square waves.
    LedArray,
    /// A bright disc crossing the field.
    MovingDisc,
    /// A bright disc crossing a static textured scene; both in the truth.
    DiscOverTexture,
    /// A dark disc crossing a bright static textured scene; both in the truth.
    Occluder,
    /// Frames of an image stack shown one after another.
    Stack,
}

impl SceneKind {
    pub const ALL: [SceneKind; 5] = [SceneKind::LedArray, SceneKind::MovingDisc, SceneKind::DiscOverTexture, SceneKind::Occluder, SceneKind::Stack];

    pub fn name(self) -> &'static str {
        match self {
            SceneKind::LedArray => "led-array",
            SceneKind::MovingDisc => "moving-disc",
            SceneKind::DiscOverTexture => "disc-over-texture",
            SceneKind::Occluder => "occluder",
            SceneKind::Stack => "stack",
        }
    }
}

impl std::str::FromStr for SceneKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        SceneKind::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| format!("unknown scene '{s}': expected one of {}", SceneKind::ALL.map(|k| k.name()).join(", ")))
    }
}

impl SimParams {
    /// Refuse a sensor no simulation can have: rows and cols from 1 to
    /// [`crate::model::shutter::MAX_SENSOR_SIDE`].
    pub fn check_sensor(&self) -> Result<(), SimError> {
        let side = crate::model::shutter::MAX_SENSOR_SIDE;
        for (field, v) in [("rows", self.rows), ("cols", self.cols)] {
            if v == 0 || v > side {
                return Err(super::error::invalid(field, v, format!("1 to {side} pixels")));
            }
        }
        Ok(())
    }

    /// The scene `kind` on a `rows x cols` sensor; `stack` (frames, rows, cols,
    /// channels, finite) is the image stack of [`SceneKind::Stack`] and must be given
    /// for it alone.
    pub fn scene(&self, kind: SceneKind, rows: usize, cols: usize, stack: Option<ArrayView4<f32>>) -> Result<Box<dyn Scene>, SimError> {
        Ok(match (kind, stack) {
            (SceneKind::LedArray, None) => Box::new(self.led_array(rows, cols)?),
            (SceneKind::MovingDisc, None) => Box::new(self.moving_disc(rows, cols)?),
            (SceneKind::DiscOverTexture, None) => Box::new(self.disc_over_texture(rows, cols)?),
            (SceneKind::Occluder, None) => Box::new(self.occluder(rows, cols)?),
            (SceneKind::Stack, Some(v)) => {
                let (_, r, c, _) = v.dim();
                if (r, c) != (rows, cols) {
                    return Err(SimError::SceneSize { rows, cols, got_rows: r, got_cols: c });
                }
                Box::new(self.image_stack(v)?)
            }
            (SceneKind::Stack, None) => return Err(super::error::invalid("stack", "none", "an image stack for the stack scene")),
            (k, Some(_)) => return Err(super::error::invalid("stack", "an image stack", format!("none for the {} scene", k.name()))),
        })
    }

    /// The synthetic lenslet diffuser's PSF at raw resolution (`rows x cols`, unit sum).
    pub fn synthetic_psf(&self) -> Result<Array2<f32>, SimError> {
        let p = LensletParams { lenslets: self.lenslets, aperture_fraction: self.aperture_fraction, ..LensletParams::default() };
        lenslet_psf(self.rows, self.cols, &p, self.seed)
    }

    /// The validated capture timing of a `rows x cols` sensor.
    pub fn capture_config(&self, rows: usize, cols: usize) -> Result<CaptureConfig, TimingError> {
        let mut cfg = CaptureConfig::new(rows, cols, self.line_time_us, self.exposure_us, self.shutter);
        cfg.downsample = self.downsample;
        cfg.binning = self.binning;
        cfg.validate()?;
        Ok(cfg)
    }

    /// The line of LEDs, centred on a `rows x cols` sensor.
    pub fn led_array(&self, rows: usize, cols: usize) -> Result<LedArray, SimError> {
        LedArray::new(
            rows,
            cols,
            LedLine {
                leds: self.leds,
                spacing_px: self.spacing_px,
                radius_px: self.led_radius_px,
                period_us: self.period_us.clone(),
                duty: self.duty,
                phase_us: vec![0.0],
                e_per_us: self.e_per_us,
            },
        )
    }

    /// A disc crossing a `rows x cols` field, from 40% down and 20% across, mostly
    /// left to right, a tenth as bright as an LED.
    pub fn moving_disc(&self, rows: usize, cols: usize) -> Result<MovingDisc, SimError> {
        use super::error::invalid;
        if !(self.disc_radius_px.is_finite() && self.disc_radius_px > 0.0) {
            return Err(invalid("disc_radius_px", self.disc_radius_px, "a positive radius in pixels"));
        }
        if !self.disc_px_per_ms.is_finite() {
            return Err(invalid("disc_px_per_ms", self.disc_px_per_ms, "a finite speed in pixels per millisecond"));
        }
        if !(self.e_per_us.is_finite() && self.e_per_us >= 0.0) {
            return Err(invalid("e_per_us", self.e_per_us, "a finite, non-negative brightness in photo-electrons per microsecond"));
        }
        let v = self.disc_px_per_ms / 1000.0;
        Ok(MovingDisc::new(rows, cols, self.disc_radius_px, (rows as f64 * 0.4, cols as f64 * 0.2), (v * 0.3, v), self.e_per_us / 10.0))
    }

    /// Radiance of the disc of [`SimParams::disc_over_texture`], e-/us per pixel: a
    /// fortieth of an LED's (50 at the defaults), a quarter of [`SimParams::moving_disc`]'s,
    /// so that the texture under it stays well inside the sensor's range.
    pub fn texture_disc_e_per_us(&self) -> f64 {
        self.e_per_us / 40.0
    }

    /// Mean radiance of the texture of [`SimParams::disc_over_texture`], e-/us per
    /// pixel: its disc's over [`SimParams::disc_contrast`] ([`SimParams::texture_disc_e_per_us`]; 12.5 at the
    /// defaults, about 8300 e- per pixel over the default 660 us exposure through a
    /// unit-sum PSF, under a third of the default 30000 e- full well).
    pub fn texture_mean_e_per_us(&self) -> f64 {
        self.texture_disc_e_per_us() / self.disc_contrast
    }

    /// The dense benchmark scene on a `rows x cols` field: the disc of
    /// [`SimParams::moving_disc`] (same radius, start and velocity), of radiance
    /// [`SimParams::texture_disc_e_per_us`], crossing and occluding a static texture
    /// (smooth blobs and striped rectangles, [`super::scene::texture`], the bench background's, drawn from
    /// `seed`) of mean radiance [`SimParams::texture_mean_e_per_us`]: the disc is
    /// [`SimParams::disc_contrast`] times as bright as the texture on average. Both are in the truth.
    pub fn disc_over_texture(&self, rows: usize, cols: usize) -> Result<DiscOverTexture, SimError> {
        let disc = self.moving_disc(rows, cols)?;
        if !(self.disc_contrast.is_finite() && self.disc_contrast > 0.0) {
            return Err(super::error::invalid("disc_contrast", self.disc_contrast, "a positive ratio of the disc's radiance to the texture's mean"));
        }
        let texture = super::scene::texture(rows, cols, self.texture_mean_e_per_us(), derive_seed(self.seed, TEXTURE_STREAM, 0));
        let scene = DiscOverTexture::new(texture, disc.radius_px, disc.start_px, disc.velocity_px_per_us, self.texture_disc_e_per_us())?;
        Ok(scene.with_texture_provenance(super::scene::TEXTURE_KIND, Some(self.seed)))
    }

    /// Mean radiance of the texture of [`SimParams::occluder`], e-/us per pixel: an
    /// LED's over 160 (12.5 at the defaults, the texture of
    /// [`SimParams::disc_over_texture`] at its default contrast: about 8300 e- per pixel
    /// over the default exposure, well inside the full well).
    pub fn occluder_texture_e_per_us(&self) -> f64 {
        self.e_per_us / 160.0
    }

    /// The occlusion scene on a `rows x cols` field: the disc of
    /// [`SimParams::moving_disc`] (same radius, start and velocity), dark
    /// ([`OCCLUDER_DISC_FRACTION`] of the texture's mean radiance), crossing and hiding the
    /// texture of [`SimParams::disc_over_texture`] (drawn from `seed`) of mean radiance
    /// [`SimParams::occluder_texture_e_per_us`]. `disc_contrast` is not used. Both are in
    /// the truth; provenance names it [`super::scene::OCCLUDER_KIND`].
    pub fn occluder(&self, rows: usize, cols: usize) -> Result<DiscOverTexture, SimError> {
        let disc = self.moving_disc(rows, cols)?;
        let mean = self.occluder_texture_e_per_us();
        let texture = super::scene::texture(rows, cols, mean, derive_seed(self.seed, TEXTURE_STREAM, 0));
        let scene = DiscOverTexture::new(texture, disc.radius_px, disc.start_px, disc.velocity_px_per_us, OCCLUDER_DISC_FRACTION * mean)?;
        Ok(scene.with_texture_provenance(super::scene::TEXTURE_KIND, Some(self.seed)).with_kind(super::scene::OCCLUDER_KIND))
    }

    /// The frames of an image stack (`frames x rows x cols x channels`, averaged over
    /// the channels) shown one after another, each for `stack_interval_us`.
    pub fn image_stack(&self, stack: ArrayView4<f32>) -> Result<ImageStack, SimError> {
        let grey: Array3<f32> = stack.mean_axis(Axis(3)).expect("a stack has at least one channel");
        tracing::info!(frames = grey.dim().0, "image stack scene");
        ImageStack::new(grey, self.stack_interval_us, false)
    }

    /// The sensor noise: the default sensor with this read noise and dark level, shot
    /// and read noise switched by `noise`.
    pub fn noise_model(&self) -> NoiseModel {
        NoiseModel { dark_level_adu: self.dark_level_adu, read_noise_e: self.read_noise_e, poisson: self.noise, gaussian: self.noise, ..NoiseModel::default() }
    }
}

/// A measured PSF image (`rows x cols x channels`, raw counts) made ready for the
/// simulator: averaged over the channels, dark level (estimated) subtracted,
/// box-downsampled by `downsample`, normalised to unit sum. `origin` (the file) starts
/// the error message of an image with no light.
pub fn measured_psf(image: ArrayView3<f32>, downsample: usize, origin: &str) -> Result<Array2<f32>, SimError> {
    let (r, c, ch) = image.dim();
    if downsample == 0 || downsample > r.min(c) {
        return Err(super::error::invalid("psf_downsample", downsample, format!("a factor from 1 to the PSF's smaller side ({})", r.min(c))));
    }
    if let Some((i, v)) = image.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(super::error::invalid("psf", format!("{origin}: {v} at row {}, col {}", i / (c * ch), i / ch % c), "finite pixel values"));
    }
    let mean: Vec<f32> = image.mean_axis(Axis(2)).expect("an image has at least one channel").iter().cloned().collect();
    let dark = estimate_dark(&mean);
    let sub: Vec<f32> = mean.iter().map(|v| ((*v as f64 - dark) as f32).max(0.0)).collect();
    let (data, m, n) = box_downsample(&sub, r, c, downsample);
    let s: f64 = data.iter().map(|&v| v as f64).sum();
    if !(s > 0.0) {
        return Err(SimError::PsfNoLight { origin: origin.to_string(), dark });
    }
    tracing::info!(file = origin, rows = m, cols = n, channels = ch, dark, "measured PSF");
    let data: Vec<f32> = data.iter().map(|v| (*v as f64 / s) as f32).collect();
    Ok(Array2::from_shape_vec((m, n), data).expect("m x n samples"))
}

/// A PSF as a camera would record it: scaled to a peak of [`PSF_PEAK_COUNTS`] over
/// `dark_level_adu`, the dark offset of the raw images (`rows x cols x 1`, counts).
pub fn psf_counts(psf: ArrayView2<f32>, dark_level_adu: f64) -> Array3<f32> {
    let peak = psf.iter().cloned().fold(0.0f32, f32::max);
    psf.mapv(|v| v * (PSF_PEAK_COUNTS / peak) + dark_level_adu as f32).insert_axis(Axis(2))
}

/// Everything a simulation needs: the validated capture timing, the raw PSF (unit
/// sum, the sensor's size), the scene and the noise.
pub struct SimSetup {
    pub cfg: CaptureConfig,
    pub psf: Array2<f32>,
    pub scene: Box<dyn Scene>,
    pub noise: NoiseModel,
    /// Time sub-steps per line time.
    pub substeps: usize,
    pub seed: u64,
}

impl SimSetup {
    /// The set-up of `params`' noise, sub-steps and seed around a validated capture
    /// timing `cfg` (see [`SimParams::capture_config`]), a raw PSF of the sensor's size
    /// and a scene.
    pub fn new(params: &SimParams, cfg: CaptureConfig, psf: Array2<f32>, scene: Box<dyn Scene>) -> Self {
        SimSetup { cfg, psf, scene, noise: params.noise_model(), substeps: params.substeps, seed: params.seed }
    }

    /// `params`' LED line seen through its synthetic diffuser (the scene of `rollcam
    /// demo` and of `rollcam simulate`'s defaults).
    pub fn led_array(params: &SimParams) -> Result<Self, SimError> {
        let psf = params.synthetic_psf()?;
        let (rows, cols) = psf.dim();
        let cfg = params.capture_config(rows, cols)?;
        let scene = Box::new(params.led_array(rows, cols)?);
        Ok(SimSetup::new(params, cfg, psf, scene))
    }

    /// One capture. Returns the capture description annotated with the simulation's
    /// provenance (dark level, `[simulation]` and `[scene]` tables) and the simulation.
    pub fn simulate(&self) -> Result<(CaptureConfig, Simulation), SimError> {
        let psf: Vec<f32> = self.psf.iter().cloned().collect();
        let simulation = simulate(&self.cfg, &psf, self.scene.as_ref(), &self.noise, self.substeps, self.seed)?;
        if simulation.saturated_pixels > 0 {
            tracing::warn!(pixels = simulation.saturated_pixels, "saturated pixels in the simulated raw image");
        }
        Ok((simulation.capture_config(&self.cfg), simulation))
    }

    /// `captures` consecutive captures of the scene, `frame_period_us` apart (default:
    /// continuous readout, [`readout_period_us`]). Returns the period used and the
    /// simulation.
    /// The global time grid of `captures` consecutive captures `frame_period_us` apart
    /// (default: continuous readout), checked as `reconstruct-sequence` checks it:
    /// a period shorter than a frame or an exposure, or captures spanning more than
    /// [`crate::model::shutter::MAX_FRAMES`] video frames, is refused before anything
    /// is simulated.
    pub fn sequence_grid(&self, captures: usize, frame_period_us: Option<f64>) -> Result<crate::model::time_grid::TimeGrid, SimError> {
        let period_us = frame_period_us.unwrap_or_else(|| readout_period_us(&self.cfg));
        super::sequence::sequence_grid(&self.cfg, captures, period_us)
    }

    pub fn simulate_sequence(&self, captures: usize, frame_period_us: Option<f64>) -> Result<(f64, SequenceSimulation), SimError> {
        let psf: Vec<f32> = self.psf.iter().cloned().collect();
        let period_us = frame_period_us.unwrap_or_else(|| readout_period_us(&self.cfg));
        let s = simulate_sequence(&self.cfg, &psf, self.scene.as_ref(), &self.noise, self.substeps, self.seed, Consecutive { captures, period_us })?;
        if s.saturated_pixels > 0 {
            tracing::warn!(pixels = s.saturated_pixels, "saturated pixels in the simulated raw images");
        }
        Ok((period_us, s))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn measured_psf_is_dark_subtracted_downsampled_and_unit_sum() {
        let mut img = Array3::from_elem((8, 8, 2), 100.0f32);
        img[[2, 3, 0]] = 300.0;
        img[[2, 3, 1]] = 500.0;
        let psf = measured_psf(img.view(), 2, "psf.tiff").unwrap();
        assert_eq!(psf.dim(), (4, 4));
        assert!((psf.sum() - 1.0).abs() < 1e-6);
        assert!((psf[[1, 1]] - 1.0).abs() < 1e-6);
        let flat = Array3::from_elem((4, 4, 1), 100.0f32);
        let e = measured_psf(flat.view(), 1, "dark.tiff").unwrap_err().to_string();
        assert!(e.starts_with("dark.tiff: no light above the dark level 100.0"), "{e}");
    }

    #[test]
    fn recorded_psf_peaks_at_the_full_scale_over_the_dark_level() {
        let psf = Array2::from_shape_vec((1, 3), vec![0.25f32, 0.5, 0.25]).unwrap();
        let counts = psf_counts(psf.view(), 100.0);
        assert_eq!(counts.dim(), (1, 3, 1));
        assert_eq!(counts[[0, 1, 0]], PSF_PEAK_COUNTS + 100.0);
        assert_eq!(counts[[0, 0, 0]], PSF_PEAK_COUNTS / 2.0 + 100.0);
    }

    #[test]
    fn defaults_describe_a_valid_capture() {
        let p = SimParams::default();
        let cfg = p.capture_config(p.rows, p.cols).unwrap();
        assert_eq!((cfg.line_time_us, cfg.exposure_us, cfg.shutter), (DEFAULT_LINE_TIME_US, 660.0, ShutterMode::Dual));
        assert_eq!(p.led_array(p.rows, p.cols).unwrap().leds(), 4);
        let dense = p.disc_over_texture(p.rows, p.cols).unwrap();
        let disc = p.moving_disc(p.rows, p.cols).unwrap();
        assert_eq!((dense.disc.radius_px, dense.disc.start_px, dense.disc.velocity_px_per_us), (disc.radius_px, disc.start_px, disc.velocity_px_per_us));
        assert!((dense.texture_mean_e_per_us() - p.texture_mean_e_per_us()).abs() < 1e-3 * p.texture_mean_e_per_us());
        assert_eq!(dense.disc.disc_e_per_us, p.disc_contrast * p.texture_mean_e_per_us());
        assert!(dense.texture().iter().all(|&v| v > 0.0));
        let noise = SimParams { noise: false, ..p }.noise_model();
        assert!(!noise.poisson && !noise.gaussian);
    }

    #[test]
    fn the_occluder_is_a_dark_disc_over_a_bright_texture() {
        let p = SimParams::default();
        let occ = p.occluder(p.rows, p.cols).unwrap();
        let dense = p.disc_over_texture(p.rows, p.cols).unwrap();
        assert!((occ.texture_mean_e_per_us() / p.occluder_texture_e_per_us() - 1.0).abs() < 1e-3);
        assert!((occ.disc.disc_e_per_us - OCCLUDER_DISC_FRACTION * p.occluder_texture_e_per_us()).abs() < 1e-12);
        assert_eq!((occ.disc.radius_px, occ.disc.start_px), (dense.disc.radius_px, dense.disc.start_px));
        // At the defaults, the dense scene's texture (same seed, same mean), brighter than
        // the disc everywhere.
        assert_eq!(occ.texture(), dense.texture());
        assert!(occ.texture().iter().all(|&v| v as f64 > 2.0 * occ.disc.disc_e_per_us));
        // Integrated: the disc's centre is dark, a point two radii away is not.
        let (m, n) = (p.rows, p.cols);
        let mut out = vec![0.0f32; m * n];
        occ.integrate(0.0, 10.0, &mut out);
        let (r, c) = occ.centre_px(5.0);
        let at = |r: f64, c: f64| out[r as usize * n + c as usize] as f64 / 10.0;
        assert!((at(r, c) - occ.disc.disc_e_per_us).abs() < 1e-3 * p.occluder_texture_e_per_us(), "{}", at(r, c));
        assert!(at(r, c + 2.0 * occ.disc.radius_px) > 5.0 * at(r, c));
        let d = occ.describe();
        assert_eq!(d["kind"].as_str(), Some(super::super::scene::OCCLUDER_KIND));
        assert!(d["note"].as_str().unwrap().starts_with("a dark disc"));
        assert_eq!(dense.describe()["kind"].as_str(), Some("disc-over-texture"));
        assert_eq!("occluder".parse::<SceneKind>().unwrap(), SceneKind::Occluder);
    }
}
