//! The bench a real capture comes from, simulated, so that the calibration procedure
//! can be rehearsed without hardware: a sensor with a fixed-pattern dark and defective
//! pixels ([`SensorDefects`], realised as a [`DefectMap`]), a static background behind
//! the moving scene ([`BackgroundTexture`]), and the calibration shots a bench takes
//! with that same sensor and exposure ([`SimulatedSensor::calibration_shots`]: dark frames,
//! point-source shots of the PSF, background frames).
//!
//! Readout of pixel `(i, j)` on the bench sensor, in ADU:
//!
//! `raw = clamp(round(gain (min(Poisson(e), full_well) + N(0, read_noise)) + dark +
//! fpn(i, j) + hot(i, j)), 0, 2^bits - 1)`
//!
//! with `fpn` the pixel's fixed-pattern dark offset (Gaussian, `dark_fpn_rms_adu` rms),
//! `hot` a hot pixel's extra dark signal (a fraction in [`HOT_LEVEL_FRACTION`] of the
//! range from the dark level to full scale, so it reads at or near full scale; 0
//! elsewhere), and a stuck pixel reading its constant whatever the light. This is
//! [`super::expose::read_out_pixels`]: the ideal readout's noise, drawn with the same
//! random numbers, plus per-pixel offsets and constants. A bench without defects reads
//! out exactly as [`super::expose::read_out`].
//!
//! The background is a static image: every row integrates it over its whole exposure,
//! so its sensor image is `T_e crop(h * B)` ([`super::expose::static_exposure`]). It is
//! added to the capture's light but **not** to the truth, which stays the moving scene
//! alone; the background frames let a calibration remove it.
//!
//! Everything is deterministic from seeds: the defect map from [`SensorDefects::seed`],
//! the background from [`BackgroundTexture::seed`], each calibration frame from the
//! set-up's seed and its own index (one stream per kind of frame).

use super::error::{invalid, SimError};
use super::expose::{read_out_pixels, simulate_with, static_exposure, Extras, NoiseModel, PixelReadout, Simulation};
use super::scene::{derive_seed, texture};
use super::setup::SimSetup;
use crate::model::capture::CaptureConfig;
use ndarray::{Array2, ArrayView2};
use rand::seq::index::sample;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

/// Peak of a point-source calibration shot above the dark level, as a fraction of the
/// sensor's usable range (the smaller of the ADC range above the dark level and the
/// full well in ADU).
pub const PSF_SHOT_PEAK_FRACTION: f64 = 0.7;

/// A hot pixel's extra dark signal, as a fraction (drawn uniformly in this range) of
/// the range from the dark level to full scale.
pub const HOT_LEVEL_FRACTION: (f64, f64) = (0.9, 1.0);

/// Independent random streams derived from one seed.
const STREAM_DEFECTS: u64 = 1;
const STREAM_BACKGROUND: u64 = super::scene::TEXTURE_STREAM;
const STREAM_DARK: u64 = 3;
const STREAM_PSF: u64 = 4;
const STREAM_BACKGROUND_FRAME: u64 = 5;

/// The defects of a bench sensor, as plain data (recorded as provenance in the
/// `[simulation.sensor]` table; a real capture.toml would not know them).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorDefects {
    /// ADC depth: values clip at `2^bit_depth - 1` counts (1 to 16: raws are 16-bit
    /// TIFFs).
    pub bit_depth: u32,
    /// Fixed-pattern dark: each pixel's dark offset around the dark level, Gaussian,
    /// this rms in ADU.
    pub dark_fpn_rms_adu: f64,
    /// Fraction of pixels with a large extra dark current (they read at or near full
    /// scale).
    pub hot_fraction: f64,
    /// Fraction of pixels stuck at a constant value whatever the light.
    pub stuck_fraction: f64,
    /// Seed of the defect map (the sensor's identity: the same seed, the same sensor).
    pub seed: u64,
}

impl Default for SensorDefects {
    /// A realistic bench sensor: 12-bit ADC, 3 ADU rms fixed-pattern dark, 0.05% hot
    /// and 0.01% stuck pixels, seed 1.
    fn default() -> Self {
        SensorDefects { bit_depth: 12, dark_fpn_rms_adu: 3.0, hot_fraction: 0.0005, stuck_fraction: 0.0001, seed: 1 }
    }
}

impl SensorDefects {
    /// A sensor with no defect and this ADC depth.
    pub fn none(bit_depth: u32) -> Self {
        SensorDefects { bit_depth, dark_fpn_rms_adu: 0.0, hot_fraction: 0.0, stuck_fraction: 0.0, seed: 0 }
    }

    /// Full scale, `2^bit_depth - 1` ADU.
    pub fn full_scale_adu(&self) -> f64 {
        ((1u64 << self.bit_depth.min(63)) - 1) as f64
    }

    /// Each field in its range; an error names the field and what was expected.
    pub fn validate(&self) -> Result<(), SimError> {
        if !(1..=16).contains(&self.bit_depth) {
            return Err(invalid("bit_depth", self.bit_depth, "an ADC depth of 1 to 16 bits (raws are written as 16-bit TIFFs)"));
        }
        if !(self.dark_fpn_rms_adu.is_finite() && self.dark_fpn_rms_adu >= 0.0) {
            return Err(invalid("dark_fpn_rms_adu", self.dark_fpn_rms_adu, "a finite, non-negative rms in ADU"));
        }
        for (field, f) in [("hot_fraction", self.hot_fraction), ("stuck_fraction", self.stuck_fraction)] {
            if !(f.is_finite() && (0.0..=1.0).contains(&f)) {
                return Err(invalid(field, f, "a fraction of the sensor's pixels, 0 to 1"));
            }
        }
        if self.hot_fraction + self.stuck_fraction > 1.0 {
            return Err(invalid("hot_fraction + stuck_fraction", self.hot_fraction + self.stuck_fraction, "at most 1 (a pixel is hot or stuck, not both)"));
        }
        Ok(())
    }

    /// `base` read out by this sensor's ADC: `bits = bit_depth`, the rest unchanged.
    pub fn noise_model(&self, base: &NoiseModel) -> NoiseModel {
        NoiseModel { bits: self.bit_depth, ..base.clone() }
    }

    /// The defect map of a `rows x cols` sensor whose dark level is `dark_level_adu`,
    /// deterministic from [`SensorDefects::seed`]: every pixel's fixed-pattern offset,
    /// then `round(hot_fraction rows cols)` hot and `round(stuck_fraction rows cols)`
    /// stuck pixels at distinct positions, each hot pixel's extra dark signal and each
    /// stuck pixel's constant (uniform over the ADC's range, whole counts).
    pub fn realise(&self, rows: usize, cols: usize, dark_level_adu: f64) -> Result<DefectMap, SimError> {
        self.validate()?;
        let full = self.full_scale_adu();
        if rows == 0 || cols == 0 {
            return Err(invalid("rows x cols", format!("{rows} x {cols}"), "a sensor of at least 1 x 1 pixels"));
        }
        if !(dark_level_adu.is_finite() && dark_level_adu >= 0.0 && dark_level_adu < full) {
            return Err(invalid("dark_level_adu", dark_level_adu, format!("a dark level from 0 to below the full scale 2^bit_depth - 1 = {full} ADU")));
        }
        let pixels = rows * cols;
        let mut rng = ChaCha8Rng::seed_from_u64(derive_seed(self.seed, STREAM_DEFECTS, 0));
        let fpn: Vec<f32> = (0..pixels)
            .map(|_| {
                let z: f64 = StandardNormal.sample(&mut rng);
                (self.dark_fpn_rms_adu * z) as f32
            })
            .collect();
        let n_hot = ((self.hot_fraction * pixels as f64).round() as usize).min(pixels);
        let n_stuck = ((self.stuck_fraction * pixels as f64).round() as usize).min(pixels - n_hot);
        let chosen = sample(&mut rng, pixels, n_hot + n_stuck).into_vec();
        let (mut hot_idx, mut stuck_idx) = (chosen[..n_hot].to_vec(), chosen[n_hot..].to_vec());
        hot_idx.sort_unstable();
        stuck_idx.sort_unstable();
        let (lo, hi) = HOT_LEVEL_FRACTION;
        let hot: Vec<HotPixel> =
            hot_idx.iter().map(|&i| HotPixel { row: i / cols, col: i % cols, extra_adu: rng.gen_range(lo..hi) * (full - dark_level_adu) }).collect();
        let stuck: Vec<StuckPixel> =
            stuck_idx.iter().map(|&i| StuckPixel { row: i / cols, col: i % cols, value_adu: rng.gen_range(0..=full as u64) as f64 }).collect();

        let mut offset_adu: Vec<f64> = fpn.iter().map(|&v| v as f64).collect();
        for h in &hot {
            offset_adu[h.row * cols + h.col] += h.extra_adu;
        }
        let stuck_adu = stuck.iter().map(|s| (s.row * cols + s.col, s.value_adu)).collect();
        Ok(DefectMap {
            defects: self.clone(),
            rows,
            cols,
            dark_level_adu,
            dark_fpn_adu: Array2::from_shape_vec((rows, cols), fpn).expect("rows x cols"),
            hot,
            stuck,
            offset_adu,
            stuck_adu,
        })
    }

    /// Provenance for the `[simulation.sensor]` table.
    pub fn describe(&self) -> toml::Table {
        let mut t = toml::Table::new();
        t.insert("bit_depth".into(), (self.bit_depth as i64).into());
        t.insert("dark_fpn_rms_adu".into(), self.dark_fpn_rms_adu.into());
        t.insert("hot_fraction".into(), self.hot_fraction.into());
        t.insert("stuck_fraction".into(), self.stuck_fraction.into());
        t.insert("seed".into(), (self.seed as i64).into());
        t
    }
}

/// A hot pixel: its position and extra dark signal.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HotPixel {
    pub row: usize,
    pub col: usize,
    /// Extra dark signal added to the pixel's reading (before the clamp), ADU.
    pub extra_adu: f64,
}

/// A stuck pixel: its position and the constant it reads.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StuckPixel {
    pub row: usize,
    pub col: usize,
    /// The pixel's reading whatever the light, ADU (a whole count within the ADC's
    /// range).
    pub value_adu: f64,
}

/// [`SensorDefects`] realised on one sensor ([`SensorDefects::realise`]): what a
/// detector of defects is scored against.
#[derive(Clone, Debug, PartialEq)]
pub struct DefectMap {
    /// What was asked.
    pub defects: SensorDefects,
    pub rows: usize,
    pub cols: usize,
    /// The sensor's dark level, ADU.
    pub dark_level_adu: f64,
    /// Fixed-pattern dark offset of every pixel around the dark level, ADU (`rows x
    /// cols`): a good pixel's mean dark reading is `dark_level_adu + dark_fpn_adu[(i,
    /// j)]` (to the rounding's bias).
    pub dark_fpn_adu: Array2<f32>,
    /// Hot pixels, in row-major order.
    pub hot: Vec<HotPixel>,
    /// Stuck pixels, in row-major order (never hot).
    pub stuck: Vec<StuckPixel>,
    /// `dark_fpn_adu` plus the hot pixels' extra signal, row-major.
    offset_adu: Vec<f64>,
    /// Stuck pixels as (row-major index, ADU), ascending.
    stuck_adu: Vec<(usize, f64)>,
}

impl DefectMap {
    /// Positions (row, col) of the hot pixels, row-major order.
    pub fn hot_positions(&self) -> Vec<(usize, usize)> {
        self.hot.iter().map(|h| (h.row, h.col)).collect()
    }

    /// Positions (row, col) of the stuck pixels, row-major order.
    pub fn stuck_positions(&self) -> Vec<(usize, usize)> {
        self.stuck.iter().map(|s| (s.row, s.col)).collect()
    }

    /// Full scale, `2^bit_depth - 1` ADU.
    pub fn full_scale_adu(&self) -> f64 {
        self.defects.full_scale_adu()
    }

    /// The map as [`super::expose::read_out_pixels`] applies it.
    pub fn pixel_readout(&self) -> PixelReadout<'_> {
        PixelReadout { offset_adu: &self.offset_adu, stuck_adu: &self.stuck_adu }
    }

    /// Spatial rms of the realised fixed-pattern offsets, ADU (f64 accumulation).
    pub fn dark_fpn_rms_adu(&self) -> f64 {
        let n = self.dark_fpn_adu.len().max(1) as f64;
        (self.dark_fpn_adu.iter().map(|&v| (v as f64).powi(2)).sum::<f64>() / n).sqrt()
    }

    /// What `sensor_truth.json` records (the fixed-pattern map itself is an image,
    /// written beside it).
    pub fn truth(&self) -> SensorTruth {
        SensorTruth {
            rows: self.rows,
            cols: self.cols,
            dark_level_adu: self.dark_level_adu,
            full_scale_adu: self.full_scale_adu(),
            defects: self.defects.clone(),
            dark_fpn_rms_realised_adu: self.dark_fpn_rms_adu(),
            dark_fpn_file: None,
            hot: self.hot.clone(),
            stuck: self.stuck.clone(),
        }
    }
}

/// The defects a simulated sensor really has, for scoring detectors
/// (`sensor_truth.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SensorTruth {
    pub rows: usize,
    pub cols: usize,
    pub dark_level_adu: f64,
    /// `2^bit_depth - 1`, ADU.
    pub full_scale_adu: f64,
    /// What was asked.
    pub defects: SensorDefects,
    /// Spatial rms of the realised fixed-pattern offsets, ADU.
    pub dark_fpn_rms_realised_adu: f64,
    /// File of the fixed-pattern offsets (float32, ADU around the dark level), when
    /// written.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dark_fpn_file: Option<String>,
    pub hot: Vec<HotPixel>,
    pub stuck: Vec<StuckPixel>,
}

/// A static, textured scene behind the moving one: smooth random blobs and a few
/// rectangles with a striped texture on a floor, deterministic from `seed`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BackgroundTexture {
    /// Mean radiance over the field, photo-electrons per microsecond per raw pixel
    /// (what the scene's units are: a flat field of this radiance gives `T_e` times it
    /// in photo-electrons per pixel through a unit-sum PSF, away from the edges).
    pub e_per_us: f64,
    /// Seed of the texture.
    pub seed: u64,
}

impl BackgroundTexture {
    /// Default mean radiance: 0.5 e-/us per pixel, about 330 e- (165 ADU at the default
    /// gain) over the default 660 us exposure, the order of the default LEDs' light on
    /// the sensor.
    pub const DEFAULT_E_PER_US: f64 = 0.5;
    /// Name of the texture in provenance.
    pub const KIND: &'static str = super::scene::TEXTURE_KIND;

    pub fn validate(&self) -> Result<(), SimError> {
        if !(self.e_per_us.is_finite() && self.e_per_us >= 0.0) {
            return Err(invalid("background e_per_us", self.e_per_us, "a finite, non-negative mean radiance in photo-electrons per microsecond per pixel"));
        }
        Ok(())
    }

    /// The radiance, e-/us per raw pixel (`rows x cols`), positive where `e_per_us` is,
    /// its mean `e_per_us`.
    pub fn radiance(&self, rows: usize, cols: usize) -> Array2<f32> {
        texture(rows, cols, self.e_per_us, derive_seed(self.seed, STREAM_BACKGROUND, 0))
    }

    /// Provenance for the `[simulation.background]` table.
    pub fn describe(&self) -> toml::Table {
        let mut t = toml::Table::new();
        t.insert("kind".into(), Self::KIND.into());
        t.insert("e_per_us".into(), self.e_per_us.into());
        t.insert("seed".into(), (self.seed as i64).into());
        t.insert("in_truth".into(), false.into());
        t.insert(
            "note".into(),
            "static light behind the moving scene, in raw.tiff but not in truth.npy (the truth is the moving scene only); the background frames let calibration remove it".into(),
        );
        t
    }
}

/// A background realised for one set-up: its radiance and its light on the sensor.
#[derive(Clone, Debug)]
pub struct BackgroundImage {
    pub params: BackgroundTexture,
    /// Radiance, e-/us per raw pixel (`rows x cols`).
    pub radiance_e_per_us: Array2<f32>,
    /// Expected photo-electrons per pixel over one exposure through the PSF,
    /// `T_e crop(h * B)` (row-major).
    pub electrons: Vec<f64>,
}

/// The most calibration shots of each kind one simulation takes.
pub const MAX_CALIBRATION_SHOTS: usize = 1000;

/// Frames a bench takes, with the capture's sensor and exposure, to calibrate it.
#[derive(Clone, Debug, Default)]
pub struct CalibrationShots {
    /// No light: dark level, fixed pattern, read noise, hot and stuck pixels, clipped
    /// (ADU, `rows x cols` each).
    pub dark: Vec<Array2<f32>>,
    /// A point source: the PSF scaled to a peak of [`PSF_SHOT_PEAK_FRACTION`] of the
    /// usable range, with shot and read noise, over the dark.
    pub psf: Vec<Array2<f32>>,
    /// The background alone through the shutter, with noise, over the dark (empty
    /// without a background).
    pub background: Vec<Array2<f32>>,
    /// Expected photo-electrons at the PSF shots' peak.
    pub psf_peak_e: f64,
}

impl CalibrationShots {
    /// Provenance for the `[simulation.calibration_shots]` table.
    pub fn describe(&self) -> toml::Table {
        let mut t = toml::Table::new();
        t.insert("dark_frames".into(), (self.dark.len() as i64).into());
        t.insert("psf_frames".into(), (self.psf.len() as i64).into());
        t.insert("background_frames".into(), (self.background.len() as i64).into());
        t.insert("psf_peak_e".into(), self.psf_peak_e.into());
        t.insert("psf_peak_fraction".into(), PSF_SHOT_PEAK_FRACTION.into());
        t
    }
}

/// The sensor of a simulated set-up ([`SimSetup`]): ideal or with defects, with an
/// optional static background behind the scene.
#[derive(Clone, Debug)]
pub struct SimulatedSensor {
    pub rows: usize,
    pub cols: usize,
    /// The readout: the set-up's noise, with the defects' ADC depth when there are
    /// defects.
    pub noise: NoiseModel,
    /// The realised defects (none: the set-up's ideal sensor).
    pub defects: Option<DefectMap>,
    pub background: Option<BackgroundImage>,
}

impl SimulatedSensor {
    /// `setup`'s sensor with `defects` (realised at its dark level) and
    /// `background` (seen through its PSF over its exposure).
    pub fn new(setup: &SimSetup, defects: Option<&SensorDefects>, background: Option<&BackgroundTexture>) -> Result<SimulatedSensor, SimError> {
        let (rows, cols) = (setup.cfg.rows, setup.cfg.cols);
        setup.noise.validate()?;
        let (noise, defects) = match defects {
            None => (setup.noise.clone(), None),
            Some(d) => (d.noise_model(&setup.noise), Some(d.realise(rows, cols, setup.noise.dark_level_adu)?)),
        };
        let background = match background {
            None => None,
            Some(b) => {
                b.validate()?;
                let radiance = b.radiance(rows, cols);
                let psf: Vec<f32> = setup.psf.iter().cloned().collect();
                let flat: Vec<f32> = radiance.iter().cloned().collect();
                let electrons = static_exposure(&setup.cfg, &psf, &flat)?;
                Some(BackgroundImage { params: b.clone(), radiance_e_per_us: radiance, electrons })
            }
        };
        Ok(SimulatedSensor { rows, cols, noise, defects, background })
    }

    fn pixels(&self) -> Option<PixelReadout<'_>> {
        self.defects.as_ref().map(DefectMap::pixel_readout)
    }

    /// Read out expected photo-electrons (`rows * cols`) with this sensor and noise
    /// seeded by `seed`: the raw ADU and the saturated count (defects included).
    pub fn read_out(&self, electrons: &[f64], seed: u64) -> (Vec<f32>, usize) {
        read_out_pixels(electrons, &self.noise, self.pixels().as_ref(), seed)
    }

    fn frame(&self, electrons: &[f64], seed: u64) -> Array2<f32> {
        Array2::from_shape_vec((self.rows, self.cols), self.read_out(electrons, seed).0).expect("rows x cols")
    }

    /// One capture of `setup`'s scene on this bench (the background added to the light,
    /// not to the truth), with the provenance of the sensor and background in the
    /// `[simulation]` table. Returns the annotated capture description and the
    /// simulation; without defects or background it is [`SimSetup::simulate`], bit for
    /// bit.
    pub fn simulate(&self, setup: &SimSetup) -> Result<(CaptureConfig, Simulation), SimError> {
        if (setup.cfg.rows, setup.cfg.cols) != (self.rows, self.cols) {
            return Err(SimError::SceneSize { rows: self.rows, cols: self.cols, got_rows: setup.cfg.rows, got_cols: setup.cfg.cols });
        }
        let psf: Vec<f32> = setup.psf.iter().cloned().collect();
        let extras = Extras { static_electrons: self.background.as_ref().map(|b| b.electrons.as_slice()), pixels: self.pixels() };
        let mut sim = simulate_with(&setup.cfg, &psf, setup.scene.as_ref(), &self.noise, setup.substeps, setup.seed, extras)?;
        let defective = self.defects.as_ref().map_or(0, |d| d.hot.len() + d.stuck.len());
        if sim.saturated_pixels > defective {
            tracing::warn!(pixels = sim.saturated_pixels, defective, "saturated pixels in the simulated raw image (defective pixels included)");
        }
        if let Some(d) = &self.defects {
            let mut t = d.defects.describe();
            t.insert("hot_pixels".into(), (d.hot.len() as i64).into());
            t.insert("stuck_pixels".into(), (d.stuck.len() as i64).into());
            t.insert("dark_fpn_rms_realised_adu".into(), d.dark_fpn_rms_adu().into());
            sim.simulation_table.insert("sensor".into(), t.into());
        }
        if let Some(b) = &self.background {
            sim.simulation_table.insert("background".into(), b.params.describe().into());
        }
        let mut cfg = sim.capture_config(&setup.cfg);
        if self.defects.is_some() {
            // A bench sensor's description is a real user's: the dark level as today, no
            // saturation level (the reconstruction finds the pile at the clipped value).
            cfg.saturation_level = None;
        }
        Ok((cfg, sim))
    }

    /// `frames` dark frames: no light, each with its own noise (seeds derived from
    /// `seed`).
    pub fn dark_frames(&self, frames: usize, seed: u64) -> Vec<Array2<f32>> {
        let zeros = vec![0.0f64; self.rows * self.cols];
        (0..frames).map(|k| self.frame(&zeros, derive_seed(seed, STREAM_DARK, k as u64))).collect()
    }

    /// Expected photo-electrons at the peak of a point-source shot:
    /// [`PSF_SHOT_PEAK_FRACTION`] of the usable range (the ADC's range above the dark
    /// level or the full well, whichever is smaller), in photo-electrons.
    pub fn psf_peak_e(&self) -> f64 {
        let adc_e = (self.noise.max_adu() - self.noise.dark_level_adu).max(0.0) / self.noise.gain_adu_per_e;
        PSF_SHOT_PEAK_FRACTION * adc_e.min(self.noise.full_well_e)
    }

    /// `frames` point-source shots of `psf` (`rows x cols`, any scale: its peak is set
    /// to [`SimulatedSensor::psf_peak_e`]), each with its own shot and read noise over the dark
    /// (seeds derived from `seed`).
    pub fn psf_shots(&self, psf: ArrayView2<f32>, frames: usize, seed: u64) -> Result<Vec<Array2<f32>>, SimError> {
        if psf.dim() != (self.rows, self.cols) {
            return Err(SimError::PsfSize { rows: self.rows, cols: self.cols, got: psf.len() });
        }
        let peak = psf.iter().map(|&v| v as f64).fold(0.0f64, f64::max);
        if !(peak.is_finite() && peak > 0.0) || psf.iter().any(|v| !v.is_finite()) {
            return Err(invalid("psf", format!("peak {peak}"), "a finite PSF with some light"));
        }
        let scale = self.psf_peak_e() / peak;
        let electrons: Vec<f64> = psf.iter().map(|&v| (v as f64 * scale).max(0.0)).collect();
        Ok((0..frames).map(|k| self.frame(&electrons, derive_seed(seed, STREAM_PSF, k as u64))).collect())
    }

    /// `frames` shots of the background alone through the rolling shutter (a static
    /// scene: every row sees it over its whole exposure), each with its own noise
    /// (seeds derived from `seed`). Empty without a background.
    pub fn background_frames(&self, frames: usize, seed: u64) -> Vec<Array2<f32>> {
        match &self.background {
            None => Vec::new(),
            Some(b) => (0..frames).map(|k| self.frame(&b.electrons, derive_seed(seed, STREAM_BACKGROUND_FRAME, k as u64))).collect(),
        }
    }

    /// `frames` of each calibration shot for `setup` (its PSF, its seed): darks,
    /// point-source shots, and background frames when there is a background.
    pub fn calibration_shots(&self, setup: &SimSetup, frames: usize) -> Result<CalibrationShots, SimError> {
        if !(1..=MAX_CALIBRATION_SHOTS).contains(&frames) {
            return Err(super::error::invalid(
                "calibration_shots",
                frames,
                format!("1 to {MAX_CALIBRATION_SHOTS} shots of each kind (a calibration averages tens)"),
            ));
        }
        Ok(CalibrationShots {
            dark: self.dark_frames(frames, setup.seed),
            psf: self.psf_shots(setup.psf.view(), frames, setup.seed)?,
            background: self.background_frames(frames, setup.seed),
            psf_peak_e: self.psf_peak_e(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::expose::{read_out, simulate};
    use crate::sim::scene::ImageStack;
    use crate::sim::setup::SimParams;

    fn small_setup() -> SimSetup {
        let p = SimParams { rows: 32, cols: 40, spacing_px: 6.0, lenslets: 12, ..SimParams::default() };
        SimSetup::led_array(&p).unwrap()
    }

    fn mean_sd(v: impl Iterator<Item = f64>) -> (f64, f64) {
        let v: Vec<f64> = v.collect();
        let n = v.len() as f64;
        let m = v.iter().sum::<f64>() / n;
        (m, (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt())
    }

    #[test]
    fn clips_at_full_scale_exactly() {
        let noise = NoiseModel::default();
        for bits in [8u32, 10, 12] {
            let d = SensorDefects { bit_depth: bits, ..SensorDefects::default() };
            let map = d.realise(20, 30, noise.dark_level_adu).unwrap();
            let nm = d.noise_model(&noise);
            let full = ((1u32 << bits) - 1) as f32;
            // From dark to far beyond the full scale (but below the full well, so the
            // ADC clips first at 12 bits, and the full well at 8 and 10 bits).
            let electrons: Vec<f64> = (0..600).map(|i| i as f64 * 40.0).collect();
            let (raw, sat) = read_out_pixels(&electrons, &nm, Some(&map.pixel_readout()), 3);
            assert_eq!(raw.iter().cloned().fold(0.0f32, f32::max), full, "{bits} bits");
            assert!(raw.iter().all(|&v| (0.0..=full).contains(&v) && v.fract() == 0.0));
            let at_full = raw.iter().filter(|&&v| v == full).count();
            assert!(at_full > 10 && sat >= at_full, "{bits} bits: {at_full} at full scale, {sat} saturated");
        }
        // Without defects too: the ADC depth alone.
        let nm = SensorDefects::none(12).noise_model(&NoiseModel::noise_free());
        let (raw, sat) = read_out(&[1e4, 8000.0, 7990.0], &nm, 0);
        assert_eq!(raw, vec![4095.0, 4095.0, 4095.0]);
        assert_eq!(sat, 3);
        let (raw, _) = read_out(&[7988.0], &nm, 0);
        assert_eq!(raw, vec![4094.0]);
    }

    #[test]
    fn fixed_pattern_has_the_asked_rms_and_darks_show_it() {
        let d = SensorDefects { dark_fpn_rms_adu: 3.0, hot_fraction: 0.0, stuck_fraction: 0.0, ..SensorDefects::default() };
        let map = d.realise(64, 80, 100.0).unwrap();
        let rms = map.dark_fpn_rms_adu();
        assert!((rms / 3.0 - 1.0).abs() < 0.1, "rms {rms}");
        // The per-pixel mean of 16 darks is dark + fpn, to the read noise over 4.
        let setup = small_setup();
        let bench = SimulatedSensor::new(&setup, Some(&SensorDefects { seed: 5, ..d }), None).unwrap();
        let darks = bench.dark_frames(16, 9);
        let map = bench.defects.as_ref().unwrap();
        let mut resid = Vec::new();
        for ((i, j), &f) in map.dark_fpn_adu.indexed_iter() {
            let mean = darks.iter().map(|k| k[(i, j)] as f64).sum::<f64>() / 16.0;
            resid.push(mean - 100.0 - f as f64);
        }
        let (m, sd) = mean_sd(resid.into_iter());
        // Read noise 2 e- at 0.5 ADU/e- is 1 ADU; quantisation adds 1/12 ADU^2.
        let expect = ((1.0 + 1.0 / 12.0) / 16.0f64).sqrt();
        assert!(m.abs() < 0.05, "mean residual {m}");
        assert!((sd / expect - 1.0).abs() < 0.15, "residual sd {sd} vs {expect}");
        let (_, spatial) = mean_sd(darks[0].iter().map(|&v| v as f64));
        assert!((spatial / (9.0 + 1.0 + 1.0 / 12.0f64).sqrt() - 1.0).abs() < 0.1, "one dark's spatial sd {spatial}");
    }

    #[test]
    fn hot_and_stuck_fractions_are_as_asked_and_behave() {
        let d = SensorDefects { hot_fraction: 0.01, stuck_fraction: 0.004, ..SensorDefects::default() };
        let (rows, cols) = (50, 60);
        let map = d.realise(rows, cols, 100.0).unwrap();
        assert_eq!(map.hot.len(), 30);
        assert_eq!(map.stuck.len(), 12);
        let hot = map.hot_positions();
        let stuck = map.stuck_positions();
        assert!(hot.iter().chain(&stuck).all(|&(i, j)| i < rows && j < cols));
        let mut all: Vec<_> = hot.iter().chain(&stuck).collect();
        all.sort();
        all.dedup();
        assert_eq!(all.len(), 42, "hot and stuck pixels are distinct");
        assert!(hot.windows(2).all(|w| w[0] < w[1]) && stuck.windows(2).all(|w| w[0] < w[1]), "row-major order");

        // Dark, then bright: hot pixels read near full scale, stuck ones their constant.
        let nm = d.noise_model(&NoiseModel::default());
        let dark = vec![0.0; rows * cols];
        let bright = vec![3000.0; rows * cols];
        let full = 4095.0f32;
        for (e, seed) in [(&dark, 1u64), (&dark, 2), (&bright, 3)] {
            let (raw, _) = read_out_pixels(e, &nm, Some(&map.pixel_readout()), seed);
            for h in &map.hot {
                let v = raw[h.row * cols + h.col];
                assert!(v >= (100.0 + 0.88 * (4095.0 - 100.0)) as f32 && v <= full, "hot ({}, {}) reads {v}", h.row, h.col);
            }
            for s in &map.stuck {
                assert_eq!(raw[s.row * cols + s.col] as f64, s.value_adu, "stuck ({}, {})", s.row, s.col);
            }
        }
        // Good pixels in the dark sit near the dark level.
        let (raw, _) = read_out_pixels(&dark, &nm, Some(&map.pixel_readout()), 4);
        let bad: std::collections::HashSet<_> = hot.iter().chain(&stuck).map(|&(i, j)| i * cols + j).collect();
        assert!(raw.iter().enumerate().filter(|(i, _)| !bad.contains(i)).all(|(_, &v)| (v - 100.0).abs() < 30.0));
    }

    #[test]
    fn deterministic_from_the_seed() {
        let d = SensorDefects { hot_fraction: 0.01, stuck_fraction: 0.01, ..SensorDefects::default() };
        assert_eq!(d.realise(30, 20, 100.0).unwrap(), d.realise(30, 20, 100.0).unwrap());
        let other = SensorDefects { seed: 2, ..d.clone() }.realise(30, 20, 100.0).unwrap();
        let first = d.realise(30, 20, 100.0).unwrap();
        assert_ne!(other.dark_fpn_adu, first.dark_fpn_adu);
        assert_ne!(other.hot_positions(), first.hot_positions());
        let b = BackgroundTexture { e_per_us: 1.0, seed: 3 };
        assert_eq!(b.radiance(30, 20), b.radiance(30, 20));
        assert_ne!(b.radiance(30, 20), BackgroundTexture { seed: 4, ..b.clone() }.radiance(30, 20));
        // Calibration frames: the same seed repeats, frames differ from one another.
        let setup = small_setup();
        let bench = SimulatedSensor::new(&setup, Some(&d), Some(&b)).unwrap();
        let a = bench.calibration_shots(&setup, 2).unwrap();
        let again = bench.calibration_shots(&setup, 2).unwrap();
        assert_eq!(a.dark, again.dark);
        assert_eq!(a.psf, again.psf);
        assert_eq!(a.background, again.background);
        assert_ne!(a.dark[0], a.dark[1]);
        assert_ne!(a.psf[0], a.psf[1]);
        assert_ne!(a.background[0], a.background[1]);
    }

    #[test]
    fn no_defects_reads_out_as_today() {
        let noise = NoiseModel::default();
        let electrons: Vec<f64> = (0..2000).map(|i| (i as f64 * 17.3) % 31000.0).collect();
        let map = SensorDefects::none(noise.bits).realise(40, 50, noise.dark_level_adu).unwrap();
        assert!(map.hot.is_empty() && map.stuck.is_empty());
        let nm = SensorDefects::none(noise.bits).noise_model(&noise);
        assert_eq!(nm, noise);
        let with = read_out_pixels(&electrons, &nm, Some(&map.pixel_readout()), 11);
        let today = read_out(&electrons, &noise, 11);
        assert_eq!(with.0.iter().map(|v| v.to_bits()).collect::<Vec<_>>(), today.0.iter().map(|v| v.to_bits()).collect::<Vec<_>>());
        assert_eq!(with.1, today.1);
        // A bench with neither defects nor background simulates as the set-up does.
        let setup = small_setup();
        let bench = SimulatedSensor::new(&setup, None, None).unwrap();
        let (cfg_b, sim_b) = bench.simulate(&setup).unwrap();
        let (cfg_s, sim_s) = setup.simulate().unwrap();
        assert_eq!(sim_b.raw, sim_s.raw);
        assert_eq!(sim_b.truth, sim_s.truth);
        assert_eq!(cfg_b, cfg_s);
    }

    #[test]
    fn background_is_one_static_exposure_and_stays_out_of_the_truth() {
        let setup = small_setup();
        let (m, n) = (setup.cfg.rows, setup.cfg.cols);
        let b = BackgroundTexture { e_per_us: 0.5, seed: 7 };
        let radiance = b.radiance(m, n);
        let mean = radiance.iter().map(|&v| v as f64).sum::<f64>() / (m * n) as f64;
        assert!((mean - 0.5).abs() < 1e-5 && radiance.iter().all(|&v| v > 0.0), "mean {mean}");
        // T_e crop(h * B) is what the continuous-time simulator integrates for a still.
        let bench = SimulatedSensor::new(&setup, None, Some(&b)).unwrap();
        let psf: Vec<f32> = setup.psf.iter().cloned().collect();
        let still = ImageStack::still(radiance.clone()).unwrap();
        let through = simulate(&setup.cfg, &psf, &still, &NoiseModel::noise_free(), 2, 0).unwrap();
        let bg = &bench.background.as_ref().unwrap().electrons;
        for (&a, &e) in bg.iter().zip(through.electrons.iter()) {
            assert!((a - e as f64).abs() <= 1e-4 * (e as f64).max(1.0), "{a} vs {e}");
        }
        // With the background: the same truth, more light by exactly the background.
        let (cfg, with) = bench.simulate(&setup).unwrap();
        let (_, without) = setup.simulate().unwrap();
        assert_eq!(with.truth, without.truth);
        for ((&w, &wo), &x) in with.electrons.iter().zip(without.electrons.iter()).zip(bg) {
            assert!((w as f64 - wo as f64 - x).abs() <= 1e-3 * (w as f64).max(1.0));
        }
        let table = &cfg.simulation.as_ref().unwrap()["background"];
        assert_eq!(table["in_truth"].as_bool(), Some(false));
        // Background frames: dark + gain * background on average.
        let frames = bench.background_frames(4, 1);
        let mean_frame: f64 = frames.iter().flat_map(|f| f.iter()).map(|&v| v as f64).sum::<f64>() / (4 * m * n) as f64;
        let expect = 100.0 + 0.5 * bg.iter().sum::<f64>() / (m * n) as f64;
        assert!((mean_frame - expect).abs() < 0.01 * expect, "{mean_frame} vs {expect}");
    }

    #[test]
    fn psf_shots_peak_in_the_upper_range() {
        let setup = small_setup();
        let d = SensorDefects { hot_fraction: 0.0, stuck_fraction: 0.0, ..SensorDefects::default() };
        let bench = SimulatedSensor::new(&setup, Some(&d), None).unwrap();
        let shots = bench.psf_shots(setup.psf.view(), 3, 1).unwrap();
        assert_eq!(shots.len(), 3);
        for s in &shots {
            let peak = s.iter().cloned().fold(0.0f32, f32::max) as f64;
            assert!((0.6 * 4095.0..0.8 * 4095.0).contains(&peak), "peak {peak}");
        }
        // The ideal 16-bit sensor: the full well is the limit.
        let ideal = SimulatedSensor::new(&setup, None, None).unwrap();
        assert!((ideal.psf_peak_e() - 0.7 * 30000.0).abs() < 1e-9);
        let e = bench.psf_shots(Array2::<f32>::zeros((32, 40)).view(), 1, 0).unwrap_err().to_string();
        assert!(e.contains("psf") && e.contains("light"), "{e}");
    }

    #[test]
    fn bad_fields_are_named() {
        let cases = [
            (SensorDefects { bit_depth: 0, ..SensorDefects::default() }, "bit_depth"),
            (SensorDefects { bit_depth: 17, ..SensorDefects::default() }, "bit_depth"),
            (SensorDefects { dark_fpn_rms_adu: -1.0, ..SensorDefects::default() }, "dark_fpn_rms_adu"),
            (SensorDefects { hot_fraction: 1.5, ..SensorDefects::default() }, "hot_fraction"),
            (SensorDefects { stuck_fraction: f64::NAN, ..SensorDefects::default() }, "stuck_fraction"),
            (SensorDefects { hot_fraction: 0.6, stuck_fraction: 0.6, ..SensorDefects::default() }, "hot_fraction + stuck_fraction"),
        ];
        for (d, field) in cases {
            let e = d.validate().unwrap_err().to_string();
            assert!(e.starts_with(field) && e.contains("expected"), "{e}");
        }
        let e = SensorDefects { bit_depth: 6, ..SensorDefects::default() }.realise(4, 4, 100.0).unwrap_err().to_string();
        assert!(e.contains("dark_level_adu") && e.contains("63"), "{e}");
        let e = BackgroundTexture { e_per_us: -1.0, seed: 0 }.validate().unwrap_err().to_string();
        assert!(e.contains("e_per_us"), "{e}");
        // Provenance round-trips through serde.
        let d = SensorDefects::default();
        let back: SensorDefects = serde_json::from_str(&serde_json::to_string(&d).unwrap()).unwrap();
        assert_eq!(back, d);
    }
}
