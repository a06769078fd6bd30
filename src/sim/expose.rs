//! The capture: a rolling-shutter exposure integrated in continuous time at raw
//! resolution, then read out with sensor noise.
//!
//! Raw row `i` collects, over its window `[s_i, s_i + T_e)`,
//!
//! `e[i, j] = integral_{s_i}^{s_i+T_e} (h * L(t))[i, j] dt`
//!
//! photo-electrons, where `L(t)` is the scene radiance (e-/us per raw pixel) and `h`
//! the raw-resolution PSF (linear convolution, centre `(rows/2, cols/2)`). Time runs
//! from 0 (the earliest row start) to the later of the last exposure end and the end of
//! the last reconstruction frame. It is cut into sub-steps of `T_l / substeps_per_line`
//! and additionally at every row start, row end and frame boundary, so that each
//! sub-step lies inside one frame and every row either exposes during all of it or
//! not at all. The scene's integral over each sub-step is added to the rows exposing
//! during it; since the convolution is linear, consecutive sub-steps with the same set
//! of exposing rows are summed first and convolved once. For scenes that are piecewise
//! constant between those cuts (or exactly integrated, like [`super::LedArray`]) the
//! exposure is exact; otherwise the error is that of the scene's own integrator over
//! sub-steps of `T_l / substeps_per_line`.
//!
//! Readout (per pixel): `raw = clamp(round(gain * (min(Poisson(e), full_well) +
//! N(0, read_noise)) + dark), 0, 2^bits - 1)` in ADU. A bench sensor
//! ([`super::sensor`]) adds a per-pixel offset inside the rounding and replaces stuck
//! pixels by their constant ([`PixelReadout`], [`read_out_pixels`]); light that is not
//! the scene (a static background, [`static_exposure`]) is added to `e` before the
//! readout ([`simulate_with`], [`Extras`]). Without them the readout is exactly the one
//! above.
//!
//! Ground truth: frame `k` is `gain * boxmean_d(integral of L over [k T_f, (k+1) T_f))`
//! on the reconstruction grid (`rows/d x cols/d`), in ADU per frame interval. With the
//! PSF prepared as the reconstruction prepares it (`d x d` box mean, unit sum), the
//! noise-free, dark-subtracted raw, box-mean downsampled by `d`, is then close to
//! `A(truth)` (exact for `d = 1` when `T_e` and the row starts are whole line times).
//!
//! Registration for `d > 1`: a reconstruction pixel stands for the centre of its raw
//! block, `dP + (d-1)/2`; a PSF box-averaged over sensor-aligned blocks puts the
//! model `(d-1)/2` raw pixels off that (4% relative error for smooth scenes at
//! `d = 2` in `tests/model/sim_model_agreement.rs`), while
//! [`crate::model::resample::box_downsample_psf_centred`] removes it (0.3%).

use super::error::{invalid, SimError};
use super::scene::Scene;
use crate::model::capture::CaptureConfig;
use crate::model::conv::Conv2d;
use crate::model::resample::box_downsample_f64;
use crate::model::shutter::MAX_FRAMES;
use ndarray::{Array2, Array3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Poisson, StandardNormal};
use std::ops::Range;

/// The most time sub-steps per line time: 64 resolve every exposure edge the cut
/// points do not already hold; more only costs time and memory.
pub const MAX_SUBSTEPS: usize = 64;

/// Sensor readout: conversion gain, read noise, dark offset, full well, ADC depth.
#[derive(Clone, Debug, PartialEq)]
pub struct NoiseModel {
    /// Conversion gain, ADU per photo-electron.
    pub gain_adu_per_e: f64,
    /// Read noise, standard deviation in photo-electrons.
    pub read_noise_e: f64,
    /// Black offset added to every pixel, ADU.
    pub dark_level_adu: f64,
    /// Full-well capacity, photo-electrons (charge beyond it is lost).
    pub full_well_e: f64,
    /// ADC depth: values are clamped to `[0, 2^bits - 1]`.
    pub bits: u32,
    /// Photon shot noise (Poisson) on the collected photo-electrons.
    pub poisson: bool,
    /// Gaussian read noise.
    pub gaussian: bool,
}

impl Default for NoiseModel {
    /// A scientific CMOS sensor: 0.5 ADU/e-, 2 e- read noise, 100 ADU dark offset,
    /// 30000 e- full well, 16 bits, shot and read noise on.
    fn default() -> Self {
        NoiseModel { gain_adu_per_e: 0.5, read_noise_e: 2.0, dark_level_adu: 100.0, full_well_e: 30000.0, bits: 16, poisson: true, gaussian: true }
    }
}

impl NoiseModel {
    /// The default sensor with shot and read noise off: the raw image is the exact
    /// expected signal, quantised and clamped.
    pub fn noise_free() -> Self {
        NoiseModel { poisson: false, gaussian: false, ..NoiseModel::default() }
    }

    /// Largest ADU value, `2^bits - 1`.
    pub fn max_adu(&self) -> f64 {
        ((1u64 << self.bits) - 1) as f64
    }

    /// The raw value at and above which a pixel is clipped, ADU: the full well in counts
    /// (`gain * full_well + dark`), less four read-noise deviations (the read noise is
    /// added after the charge is clipped, so a full pixel reads about the full well,
    /// above or below it), at most the ADC maximum. What capture.toml's
    /// `saturation_level` says of a simulated raw.
    pub fn saturation_level_adu(&self) -> f64 {
        let margin_e = if self.gaussian { 4.0 * self.read_noise_e } else { 0.0 };
        (self.gain_adu_per_e * (self.full_well_e - margin_e) + self.dark_level_adu).floor().min(self.max_adu())
    }

    pub fn validate(&self) -> Result<(), SimError> {
        if !(self.gain_adu_per_e.is_finite() && self.gain_adu_per_e > 0.0) {
            return Err(invalid("gain_adu_per_e", self.gain_adu_per_e, "a positive gain in ADU per photo-electron"));
        }
        if !(self.read_noise_e.is_finite() && self.read_noise_e >= 0.0) {
            return Err(invalid("read_noise_e", self.read_noise_e, "a non-negative noise in photo-electrons"));
        }
        if !(self.dark_level_adu.is_finite() && self.dark_level_adu >= 0.0) {
            return Err(invalid("dark_level_adu", self.dark_level_adu, "a non-negative offset in ADU"));
        }
        let full_scale = 2f64.powi(self.bits.min(32) as i32) - 1.0;
        if self.dark_level_adu >= full_scale {
            return Err(invalid(
                "dark_level_adu",
                self.dark_level_adu,
                format!("an offset below the ADC's full scale (2^{} - 1 = {full_scale} ADU): at or above it every pixel reads full scale", self.bits),
            ));
        }
        if !(self.full_well_e.is_finite() && self.full_well_e > 0.0) {
            return Err(invalid("full_well_e", self.full_well_e, "a positive capacity in photo-electrons"));
        }
        if !(1..=32).contains(&self.bits) {
            return Err(invalid("bits", self.bits, "an ADC depth of 1 to 32 bits"));
        }
        Ok(())
    }

    fn describe(&self) -> toml::Table {
        let mut t = toml::Table::new();
        t.insert("gain_adu_per_e".into(), self.gain_adu_per_e.into());
        t.insert("read_noise_e".into(), self.read_noise_e.into());
        t.insert("dark_level_adu".into(), self.dark_level_adu.into());
        t.insert("full_well_e".into(), self.full_well_e.into());
        t.insert("bits".into(), (self.bits as i64).into());
        t.insert("poisson".into(), self.poisson.into());
        t.insert("gaussian".into(), self.gaussian.into());
        t
    }
}

/// One simulated capture.
#[derive(Clone, Debug)]
pub struct Simulation {
    /// Raw image, ADU (dark level included, quantised, clamped), `rows x cols`.
    pub raw: Array2<f32>,
    /// Expected photo-electrons per raw pixel (noise-free, before the full well),
    /// `rows x cols`.
    pub electrons: Array2<f32>,
    /// Ground-truth video on the reconstruction grid, `frames x rows/d x cols/d`, in
    /// ADU per frame interval (`gain * boxmean_d` of the scene's integral over each
    /// frame).
    pub truth: Array3<f32>,
    /// Frame interval `T_f = d * b * T_l`, microseconds.
    pub frame_time_us: f64,
    /// Simulated time span, microseconds (from 0 to the later of the last exposure end
    /// and the end of the last frame).
    pub duration_us: f64,
    /// Pixels that reached the full well or the ADC maximum.
    pub saturated_pixels: usize,
    /// Time sub-steps integrated (calls to [`Scene::integrate`]).
    pub substeps: usize,
    /// Convolutions with the PSF performed.
    pub convolutions: usize,
    /// Dark level of the raw image, ADU.
    pub dark_level_adu: f64,
    /// Conversion gain, ADU per photo-electron.
    pub gain_adu_per_e: f64,
    /// The raw value at and above which a pixel is clipped, ADU
    /// ([`NoiseModel::saturation_level_adu`]).
    pub saturation_level_adu: f64,
    /// Provenance for the `[simulation]` table (noise, seed, sub-steps).
    pub simulation_table: toml::Table,
    /// Provenance for the `[scene]` table ([`Scene::describe`]).
    pub scene_table: toml::Table,
}

impl Simulation {
    /// Noise-free, dark-subtracted raw signal in ADU (`gain * electrons`, unquantised,
    /// unclamped): what `raw - dark` would be without noise, rounding or saturation.
    pub fn expected_adu(&self) -> Array2<f32> {
        self.electrons.mapv(|e| (e as f64 * self.gain_adu_per_e) as f32)
    }

    /// `cfg` annotated with this simulation: dark level, saturation level (the full
    /// well in counts) and the provenance tables.
    pub fn capture_config(&self, cfg: &CaptureConfig) -> CaptureConfig {
        let mut c = cfg.clone();
        c.dark_level = Some(self.dark_level_adu);
        c.saturation_level = Some(self.saturation_level_adu);
        c.simulation = Some(self.simulation_table.clone());
        c.scene = Some(self.scene_table.clone());
        c
    }
}

/// Per-pixel departures of a real sensor from [`NoiseModel`]'s uniform readout,
/// borrowed from a realised defect map ([`super::sensor::DefectMap`]).
#[derive(Clone, Copy, Debug)]
pub struct PixelReadout<'a> {
    /// Added to each pixel's value before rounding and clamping, ADU (`rows * cols`,
    /// row-major): a fixed-pattern dark offset, a hot pixel's extra dark signal.
    pub offset_adu: &'a [f64],
    /// Pixels that read a constant whatever the light, as (row-major index, ADU), the
    /// indices strictly ascending.
    pub stuck_adu: &'a [(usize, f64)],
}

/// What a bench capture adds to [`simulate`]'s ideal one. The default adds nothing.
#[derive(Clone, Copy, Debug, Default)]
pub struct Extras<'a> {
    /// Expected photo-electrons added to every pixel's exposure before the readout
    /// (`rows * cols`, row-major): light that is not the scene, such as a static
    /// background through the diffuser ([`static_exposure`]). Not part of the truth.
    pub static_electrons: Option<&'a [f64]>,
    /// Per-pixel readout departures (fixed-pattern dark, hot and stuck pixels).
    pub pixels: Option<PixelReadout<'a>>,
}

impl Extras<'_> {
    /// Sizes against a `pixels`-pixel sensor, stuck indices in range and ascending.
    fn validate(&self, pixels: usize) -> Result<(), SimError> {
        if let Some(e) = self.static_electrons {
            if e.len() != pixels {
                return Err(invalid("static_electrons", format!("{} values", e.len()), format!("one per sensor pixel ({pixels})")));
            }
            if let Some(i) = e.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
                return Err(invalid("static_electrons", e[i], format!("finite, non-negative photo-electrons (pixel {i})")));
            }
        }
        if let Some(p) = self.pixels {
            p.validate(pixels)?;
        }
        Ok(())
    }
}

impl PixelReadout<'_> {
    /// Sizes against a `pixels`-pixel sensor, finite values, stuck indices in range
    /// and strictly ascending.
    pub fn validate(&self, pixels: usize) -> Result<(), SimError> {
        if self.offset_adu.len() != pixels {
            return Err(invalid("offset_adu", format!("{} values", self.offset_adu.len()), format!("one per sensor pixel ({pixels})")));
        }
        if let Some(i) = self.offset_adu.iter().position(|v| !v.is_finite()) {
            return Err(invalid("offset_adu", self.offset_adu[i], format!("a finite offset in ADU (pixel {i})")));
        }
        let mut next = 0usize;
        for &(i, v) in self.stuck_adu {
            if i < next || i >= pixels || !v.is_finite() {
                return Err(invalid("stuck_adu", format!("({i}, {v})"), format!("strictly ascending pixel indices below {pixels} with finite values")));
            }
            next = i + 1;
        }
        Ok(())
    }
}

/// The PSF's size and values against the capture's sensor.
fn check_psf(cfg: &CaptureConfig, psf_raw: &[f32]) -> Result<(), SimError> {
    let (m, n) = (cfg.rows, cfg.cols);
    if psf_raw.len() != m * n {
        return Err(SimError::PsfSize { rows: m, cols: n, got: psf_raw.len() });
    }
    if let Some((i, &v)) = psf_raw.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(SimError::PsfNotFinite { row: i / n, col: i % n, value: v });
    }
    Ok(())
}

/// Expected photo-electrons (`rows * cols`, row-major) of a static scene of radiance
/// `radiance_e_per_us` (e-/us per raw pixel, `cfg.rows x cfg.cols`) seen through the
/// raw-resolution PSF `psf_raw`: every row integrates it over its whole exposure,
/// whatever the shutter, so the sensor image is `T_e crop(h * s)`, one convolution
/// (the one [`simulate`] uses).
pub fn static_exposure(cfg: &CaptureConfig, psf_raw: &[f32], radiance_e_per_us: &[f32]) -> Result<Vec<f64>, SimError> {
    cfg.validate()?;
    check_psf(cfg, psf_raw)?;
    let (m, n) = (cfg.rows, cfg.cols);
    if radiance_e_per_us.len() != m * n {
        return Err(invalid("radiance_e_per_us", format!("{} values", radiance_e_per_us.len()), format!("one per sensor pixel ({m} x {n})")));
    }
    if let Some(i) = radiance_e_per_us.iter().position(|v| !v.is_finite()) {
        return Err(SimError::SceneNotFinite { row: i / n, col: i % n });
    }
    let conv = Conv2d::sensor(psf_raw, m, n);
    let mut scratch = conv.scratch();
    let mut electrons = vec![0.0f64; m * n];
    let te = cfg.exposure_us;
    let all_rows = 0..m;
    conv.forward_rows(radiance_e_per_us, std::slice::from_ref(&all_rows), &mut scratch, |i, row| {
        for (e, &v) in electrons[i * n..(i + 1) * n].iter_mut().zip(row) {
            *e = te * v as f64;
        }
    });
    Ok(electrons)
}

/// The most regular sub-steps one capture's integration takes: as many as the longest
/// rolling capture ([`MAX_FRAMES`] frames of one line time) at [`MAX_SUBSTEPS`].
pub const MAX_INTEGRATION_STEPS: f64 = MAX_FRAMES as f64 * MAX_SUBSTEPS as f64;

/// Refuses an integration over `t_end_us` of more than [`MAX_INTEGRATION_STEPS`]
/// sub-steps of `line_time_us / substeps` (a global exposure of 1e12 us would take
/// 1.8e10 of them: hours and a list of 145 GB), naming the exposure when it is what
/// makes the capture long (`exposure_rules`: its value), else the sub-steps.
fn check_steps(t_end_us: f64, line_time_us: f64, substeps: usize, exposure_rules: Option<f64>) -> Result<(), SimError> {
    let lines = t_end_us / line_time_us;
    let steps = lines * substeps as f64;
    if steps <= MAX_INTEGRATION_STEPS {
        return Ok(());
    }
    let expected = format!(
        "an integration of at most {MAX_INTEGRATION_STEPS:.0} sub-steps (this capture lasts {lines:.3e} line times of {line_time_us} us, x {substeps} sub-steps = {steps:.3e}): shorten the exposure, lengthen the line time or take fewer sub-steps"
    );
    Err(match exposure_rules {
        Some(exposure_us) => invalid("exposure_us", exposure_us, expected),
        None => invalid("substeps_per_line", substeps, expected),
    })
}

/// Simulate one capture described by `cfg` of `scene` through the raw-resolution PSF
/// `psf_raw` (`cfg.rows x cfg.cols`, row-major, unit sum: light the PSF loses outside
/// the sensor is lost), with `substeps_per_line` time sub-steps per line time and the
/// readout `noise` (seeded by `seed`).
pub fn simulate(
    cfg: &CaptureConfig,
    psf_raw: &[f32],
    scene: &dyn Scene,
    noise: &NoiseModel,
    substeps_per_line: usize,
    seed: u64,
) -> Result<Simulation, SimError> {
    simulate_with(cfg, psf_raw, scene, noise, substeps_per_line, seed, Extras::default())
}

/// [`simulate`] on a bench: `extras`' static light is added to the exposure (and to
/// [`Simulation::electrons`], not to the truth) and its per-pixel departures to the
/// readout. With [`Extras::default`] this is [`simulate`], bit for bit.
pub fn simulate_with(
    cfg: &CaptureConfig,
    psf_raw: &[f32],
    scene: &dyn Scene,
    noise: &NoiseModel,
    substeps_per_line: usize,
    seed: u64,
    extras: Extras<'_>,
) -> Result<Simulation, SimError> {
    check_inputs(cfg, psf_raw, scene, noise, substeps_per_line, &extras)?;
    let (m, n) = (cfg.rows, cfg.cols);
    let timing = cfg.timing();
    let frames = timing.weights()?.frames();
    let tf = timing.frame_time_us();
    let tl = cfg.line_time_us;
    let te = cfg.exposure_us;
    let d = cfg.downsample;
    let starts = timing.raw_row_starts_us();
    let exposure_end = starts.iter().map(|s| s + te).fold(0.0f64, f64::max);
    let t_end = exposure_end.max(frames as f64 * tf);

    // Cut points: regular sub-steps, row starts and ends, frame boundaries.
    let dt = tl / substeps_per_line as f64;
    check_steps(t_end, tl, substeps_per_line, (exposure_end >= frames as f64 * tf).then_some(te))?;
    let tol = 1e-9 * tl;
    let mut cuts: Vec<f64> = (0..=((t_end / dt).ceil() as usize)).map(|j| (j as f64 * dt).min(t_end)).collect();
    cuts.extend(starts.iter().copied());
    cuts.extend(starts.iter().map(|s| s + te));
    cuts.extend((0..=frames).map(|k| k as f64 * tf));
    cuts.retain(|&t| t >= 0.0 && t <= t_end + tol);
    cuts.sort_by(|a, b| a.partial_cmp(b).expect("finite times"));
    cuts.dedup_by(|b, a| (*b - *a).abs() <= tol);

    let conv = Conv2d::sensor(psf_raw, m, n);
    let mut scratch = conv.scratch();
    let mut electrons = vec![0.0f64; m * n];
    let mut buf = vec![0.0f32; m * n];
    let mut group = vec![0.0f64; m * n];
    let mut group_in = vec![0.0f32; m * n];
    let mut group_rows: Vec<Range<usize>> = Vec::new();
    let mut frame_acc = vec![0.0f64; m * n];
    let mut frame_of_acc: Option<usize> = None;
    let (tr, tc) = cfg.grid();
    let mut truth = Array3::<f32>::zeros((frames, tr, tc));
    let gain = noise.gain_adu_per_e;
    let mut convolutions = 0usize;
    let mut substeps = 0usize;

    let mut flush_group = |group: &mut [f64], rows: &[Range<usize>], electrons: &mut [f64], count: &mut usize| {
        if rows.is_empty() {
            return;
        }
        for (g, &v) in group_in.iter_mut().zip(group.iter()) {
            *g = v as f32;
        }
        conv.forward_rows(&group_in, rows, &mut scratch, |i, row| {
            for (e, &v) in electrons[i * n..(i + 1) * n].iter_mut().zip(row) {
                *e += v as f64;
            }
        });
        group.fill(0.0);
        *count += 1;
    };
    let flush_frame = |acc: &mut [f64], k: usize, truth: &mut Array3<f32>| {
        let (small, _, _) = box_downsample_f64(acc, m, n, d);
        for (t, v) in truth.index_axis_mut(ndarray::Axis(0), k).iter_mut().zip(small) {
            *t = (v as f64 * gain) as f32;
        }
        acc.fill(0.0);
    };

    for w in cuts.windows(2) {
        let (a, b) = (w[0], w[1]);
        if b - a <= tol {
            continue;
        }
        scene.integrate(a, b, &mut buf);
        substeps += 1;
        // Rows exposing during all of [a, b) (the cuts make it all or nothing).
        let active = exposing_rows(&starts, te, a, b, tol);
        if active != group_rows {
            flush_group(&mut group, &group_rows, &mut electrons, &mut convolutions);
            group_rows = active;
        }
        if !group_rows.is_empty() {
            for (g, &v) in group.iter_mut().zip(&buf) {
                *g += v as f64;
            }
        }
        let k = (0.5 * (a + b) / tf).floor() as usize;
        if frame_of_acc != Some(k) {
            if let Some(prev) = frame_of_acc {
                if prev < frames {
                    flush_frame(&mut frame_acc, prev, &mut truth);
                }
            }
            frame_of_acc = Some(k);
        }
        if k < frames {
            for (f, &v) in frame_acc.iter_mut().zip(&buf) {
                *f += v as f64;
            }
        }
    }
    flush_group(&mut group, &group_rows, &mut electrons, &mut convolutions);
    if let Some(prev) = frame_of_acc {
        if prev < frames {
            flush_frame(&mut frame_acc, prev, &mut truth);
        }
    }
    if let Some(i) = electrons.iter().position(|e| !e.is_finite()) {
        return Err(SimError::SceneNotFinite { row: i / n, col: i % n });
    }

    if let Some(extra) = extras.static_electrons {
        for (e, &x) in electrons.iter_mut().zip(extra) {
            *e += x;
        }
    }
    let (raw, saturated_pixels) = read_out_pixels(&electrons, noise, extras.pixels.as_ref(), seed);
    let simulation_table = simulation_table(seed, substeps_per_line, noise);
    Ok(Simulation {
        raw: Array2::from_shape_vec((m, n), raw).expect("rows x cols"),
        electrons: Array2::from_shape_vec((m, n), electrons.iter().map(|&e| e as f32).collect()).expect("rows x cols"),
        truth,
        frame_time_us: tf,
        duration_us: t_end,
        saturated_pixels,
        substeps,
        convolutions,
        dark_level_adu: noise.dark_level_adu,
        gain_adu_per_e: gain,
        saturation_level_adu: noise.saturation_level_adu(),
        simulation_table,
        scene_table: scene.describe(),
    })
}

/// Refuses a capture description, noise model, PSF, bench extras or scene that do not
/// fit one another, and a sub-step count out of range, before anything is simulated.
fn check_inputs(
    cfg: &CaptureConfig,
    psf_raw: &[f32],
    scene: &dyn Scene,
    noise: &NoiseModel,
    substeps_per_line: usize,
    extras: &Extras<'_>,
) -> Result<(), SimError> {
    cfg.validate()?;
    noise.validate()?;
    let (m, n) = (cfg.rows, cfg.cols);
    check_psf(cfg, psf_raw)?;
    extras.validate(m * n)?;
    let (sr, sc) = scene.size();
    if (sr, sc) != (m, n) {
        return Err(SimError::SceneSize { rows: m, cols: n, got_rows: sr, got_cols: sc });
    }
    if !(1..=MAX_SUBSTEPS).contains(&substeps_per_line) {
        return Err(invalid("substeps_per_line", substeps_per_line, format!("1 to {} sub-steps per line time", MAX_SUBSTEPS)));
    }
    Ok(())
}

/// The `[simulation]` table a simulated capture's description records.
fn simulation_table(seed: u64, substeps_per_line: usize, noise: &NoiseModel) -> toml::Table {
    let mut table = toml::Table::new();
    table.insert("simulator".into(), "rollcam continuous-time exposure".into());
    table.insert("seed".into(), (seed as i64).into());
    table.insert("substeps_per_line".into(), (substeps_per_line as i64).into());
    table.insert("noise".into(), noise.describe().into());
    table
}

/// Raw rows whose window `[s_i, s_i + te)` contains `[a, b)`, as sorted ranges.
fn exposing_rows(starts: &[f64], te: f64, a: f64, b: f64, tol: f64) -> Vec<Range<usize>> {
    let mut ranges: Vec<Range<usize>> = Vec::new();
    for (i, &s) in starts.iter().enumerate() {
        if s <= a + tol && s + te >= b - tol {
            match ranges.last_mut() {
                Some(r) if r.end == i => r.end = i + 1,
                _ => ranges.push(i..i + 1),
            }
        }
    }
    ranges
}

/// Readout of the expected photo-electrons: shot noise, full well, read noise, gain,
/// dark offset, rounding and ADC clamp. Returns the raw ADU and the saturated count.
pub fn read_out(electrons: &[f64], noise: &NoiseModel, seed: u64) -> (Vec<f32>, usize) {
    read_out_pixels(electrons, noise, None, seed)
}

/// [`read_out`] with per-pixel departures: `pixels.offset_adu[i]` is added before the
/// rounding and clamp, and stuck pixels read their constant (clamped to the ADC range;
/// counted as saturated when at its maximum). Every pixel draws the same random numbers
/// as without `pixels`, so the other pixels' noise does not change. With `None` this is
/// [`read_out`], bit for bit.
///
/// Panics when `pixels` does not fit `electrons` ([`PixelReadout::validate`]).
pub fn read_out_pixels(electrons: &[f64], noise: &NoiseModel, pixels: Option<&PixelReadout<'_>>, seed: u64) -> (Vec<f32>, usize) {
    if let Some(p) = pixels {
        if let Err(e) = p.validate(electrons.len()) {
            panic!("read_out_pixels: {e}");
        }
    }
    let mut stuck = pixels.map_or(&[][..], |p| p.stuck_adu).iter().peekable();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let max_adu = noise.max_adu();
    let mut saturated = 0usize;
    let raw = electrons
        .iter()
        .enumerate()
        .map(|(i, &e)| {
            let e = e.max(0.0);
            let mut x = if noise.poisson && e > 0.0 { Poisson::new(e).map(|p| p.sample(&mut rng)).unwrap_or(e) } else { e };
            let mut sat = false;
            if x >= noise.full_well_e {
                x = noise.full_well_e;
                sat = true;
            }
            if noise.gaussian && noise.read_noise_e > 0.0 {
                let z: f64 = StandardNormal.sample(&mut rng);
                x += noise.read_noise_e * z;
            }
            let mut adu = noise.gain_adu_per_e * x + noise.dark_level_adu;
            if let Some(p) = pixels {
                adu += p.offset_adu[i];
            }
            let mut adu = adu.round();
            if let Some(&(_, v)) = stuck.next_if(|&&(k, _)| k == i) {
                adu = v.round().min(max_adu);
                sat = adu >= max_adu;
            }
            if adu >= max_adu {
                adu = max_adu;
                sat = true;
            }
            saturated += sat as usize;
            adu.max(0.0) as f32
        })
        .collect();
    (raw, saturated)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::shutter::ShutterMode;
    use crate::sim::scene::{ImageStack, LedArray, LedLine};

    fn delta_psf(m: usize, n: usize) -> Vec<f32> {
        let mut h = vec![0.0; m * n];
        h[(m / 2) * n + n / 2] = 1.0;
        h
    }

    fn flat(m: usize, n: usize, e_per_us: f32) -> ImageStack {
        ImageStack::still(Array2::from_elem((m, n), e_per_us)).unwrap()
    }

    #[test]
    fn static_scene_every_row_collects_exposure_times_radiance() {
        for mode in ShutterMode::ALL {
            let cfg = CaptureConfig::new(10, 8, 10.0, 35.0, mode);
            let img = Array2::from_shape_fn((10, 8), |(i, j)| 1.0 + (i * 8 + j) as f32 * 0.1);
            let scene = ImageStack::still(img.clone()).unwrap();
            let sim = simulate(&cfg, &delta_psf(10, 8), &scene, &NoiseModel::noise_free(), 3, 1).unwrap();
            for ((i, j), &e) in sim.electrons.indexed_iter() {
                let expect = 35.0 * img[(i, j)];
                assert!((e - expect).abs() < 1e-4 * expect, "{mode} ({i},{j}): {e} vs {expect}");
            }
        }
    }

    #[test]
    fn led_rows_see_the_waveform_over_their_own_window() {
        // Rolling shutter, delta PSF: each row sees the LED's on-time inside its
        // window; T_e = 2.5 T_l and a period that is no multiple of anything.
        let (m, n) = (12, 16);
        let cfg = CaptureConfig::new(m, n, 7.0, 17.5, ShutterMode::Rolling);
        let leds =
            LedArray::new(m, n, LedLine { leds: 1, spacing_px: 0.0, radius_px: 1.0, period_us: vec![13.3], duty: 0.4, phase_us: vec![2.1], e_per_us: 50.0 })
                .unwrap();
        let sim = simulate(&cfg, &delta_psf(m, n), &leds, &NoiseModel::noise_free(), 1, 0).unwrap();
        // The LED sits on row m/2; its spot's row sum in that row follows the wave.
        let row = m / 2;
        let s = 7.0 * row as f64;
        let spot_row: f64 = leds.spot(0).iter().filter(|(i, _)| i / n == row).map(|&(_, w)| w as f64).sum();
        let got: f64 = sim.electrons.row(row).iter().map(|&v| v as f64).sum();
        let expect = 50.0 * spot_row * leds.waveform(0, s, s + 17.5) * 17.5;
        assert!((got - expect).abs() < 1e-4 * expect, "{got} vs {expect}");
    }

    #[test]
    fn truth_is_the_scene_integral_per_frame() {
        let (m, n) = (8, 6);
        let mut cfg = CaptureConfig::new(m, n, 5.0, 10.0, ShutterMode::Dual);
        cfg.downsample = 2;
        let leds =
            LedArray::new(m, n, LedLine { leds: 1, spacing_px: 0.0, radius_px: 1.0, period_us: vec![17.0], duty: 0.5, phase_us: vec![0.0], e_per_us: 10.0 })
                .unwrap();
        let noise = NoiseModel::noise_free();
        let sim = simulate(&cfg, &delta_psf(m, n), &leds, &noise, 2, 0).unwrap();
        let k = cfg.timing().weights().unwrap().frames();
        assert_eq!(sim.truth.dim(), (k, m / 2, n / 2));
        assert_eq!(sim.frame_time_us, 10.0);
        for f in 0..k {
            let total: f64 = sim.truth.index_axis(ndarray::Axis(0), f).iter().map(|&v| v as f64).sum();
            // Box means divide by d^2; gain converts to ADU.
            let expect = 0.5 * 10.0 * leds.waveform(0, f as f64 * 10.0, (f + 1) as f64 * 10.0) * 10.0 / 4.0;
            assert!((total - expect).abs() < 1e-5 * expect.max(1.0), "frame {f}: {total} vs {expect}");
        }
    }

    #[test]
    fn noise_free_readout_is_exact() {
        let (m, n) = (4, 5);
        let cfg = CaptureConfig::new(m, n, 10.0, 20.0, ShutterMode::Global);
        let scene = flat(m, n, 3.3);
        let noise = NoiseModel::noise_free();
        let sim = simulate(&cfg, &delta_psf(m, n), &scene, &noise, 1, 0).unwrap();
        // The delta PSF keeps the flat field: 66 e- -> 0.5 * 66 + 100 = 133 ADU.
        assert!(sim.raw.iter().all(|&v| v == 133.0), "{:?}", sim.raw);
        assert_eq!(sim.saturated_pixels, 0);
    }

    #[test]
    fn flat_field_noise_matches_shot_plus_read_noise() {
        let (m, n) = (64, 64);
        let e_mean = 400.0f64;
        let noise = NoiseModel { gain_adu_per_e: 2.0, read_noise_e: 5.0, ..NoiseModel::default() };
        let electrons = vec![e_mean; m * n];
        let (raw, sat) = read_out(&electrons, &noise, 42);
        assert_eq!(sat, 0);
        let adu: Vec<f64> = raw.iter().map(|&v| (v as f64 - noise.dark_level_adu) / noise.gain_adu_per_e).collect();
        let mean = adu.iter().sum::<f64>() / adu.len() as f64;
        let var = adu.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (adu.len() - 1) as f64;
        // Expected: mean 400 e-, variance 400 + 25 (+ 1/12 / gain^2 quantisation).
        let expect_var = e_mean + 25.0 + 1.0 / 12.0 / 4.0;
        let n_px = (m * n) as f64;
        assert!((mean - e_mean).abs() < 4.0 * (expect_var / n_px).sqrt(), "mean {mean}");
        // Standard error of a sample variance: var * sqrt(2 / n) ~ 2.2%.
        assert!((var / expect_var - 1.0).abs() < 4.0 * (2.0 / n_px).sqrt(), "var {var} vs {expect_var}");
        // Read noise alone.
        let read_only = NoiseModel { poisson: false, ..noise.clone() };
        let (raw, _) = read_out(&electrons, &read_only, 43);
        let adu: Vec<f64> = raw.iter().map(|&v| v as f64 / 2.0).collect();
        let m0 = adu.iter().sum::<f64>() / adu.len() as f64;
        let v0 = adu.iter().map(|v| (v - m0).powi(2)).sum::<f64>() / (adu.len() - 1) as f64;
        assert!((v0 / 25.0 - 1.0).abs() < 0.15, "read variance {v0}");
        // Seeded: the same seed repeats, another differs.
        assert_eq!(read_out(&electrons, &noise, 42).0, read_out(&electrons, &noise, 42).0);
        assert_ne!(read_out(&electrons, &noise, 42).0, read_out(&electrons, &noise, 7).0);
    }

    #[test]
    fn saturation_clamps_and_is_counted() {
        // Full well 30000 e- at 0.5 ADU/e- is 15100 ADU; raise the gain so the ADC
        // clips first for some pixels.
        let electrons = vec![10.0, 29_000.0, 40_000.0, 1e9];
        let noise = NoiseModel { gain_adu_per_e: 4.0, ..NoiseModel::noise_free() };
        let (raw, sat) = read_out(&electrons, &noise, 0);
        assert_eq!(raw, vec![140.0, 65535.0, 65535.0, 65535.0]);
        assert_eq!(sat, 3);
        let noise = NoiseModel::noise_free();
        let (raw, sat) = read_out(&electrons, &noise, 0);
        assert_eq!(raw, vec![105.0, 14600.0, 15100.0, 15100.0]);
        assert_eq!(sat, 2, "full well");
        // Through the simulator: a bright flat field saturates every pixel.
        let (m, n) = (4, 4);
        let cfg = CaptureConfig::new(m, n, 10.0, 20.0, ShutterMode::Rolling);
        let noise = NoiseModel { gain_adu_per_e: 4.0, full_well_e: 1e6, ..NoiseModel::default() };
        let sim = simulate(&cfg, &delta_psf(m, n), &flat(m, n, 1000.0), &noise, 1, 0).unwrap();
        assert_eq!(sim.saturated_pixels, m * n);
        assert!(sim.raw.iter().all(|&v| v == 65535.0));
    }

    #[test]
    fn mismatches_are_named() {
        let cfg = CaptureConfig::new(6, 5, 10.0, 20.0, ShutterMode::Dual);
        let scene = flat(6, 5, 1.0);
        let noise = NoiseModel::default();
        let e = simulate(&cfg, &delta_psf(5, 5), &scene, &noise, 1, 0).unwrap_err().to_string();
        assert!(e.contains("PSF") && e.contains("6 x 5"), "{e}");
        let mut h = delta_psf(6, 5);
        h[7] = f32::NAN;
        let e = simulate(&cfg, &h, &scene, &noise, 1, 0).unwrap_err().to_string();
        assert!(e.contains("row 1, col 2") && e.contains("finite"), "{e}");
        let e = simulate(&cfg, &delta_psf(6, 5), &flat(6, 4, 1.0), &noise, 1, 0).unwrap_err().to_string();
        assert!(e.contains("6 x 4") && e.contains("6 x 5"), "{e}");
        let e = simulate(&cfg, &delta_psf(6, 5), &scene, &noise, 0, 0).unwrap_err().to_string();
        assert!(e.contains("substeps_per_line"), "{e}");
        let bad = CaptureConfig::new(6, 5, 10.0, 5.0, ShutterMode::Dual);
        let e = simulate(&bad, &delta_psf(6, 5), &scene, &noise, 1, 0).unwrap_err().to_string();
        assert!(e.contains("exposure_us"), "{e}");
    }

    #[test]
    fn provenance_is_recorded() {
        let cfg = CaptureConfig::new(6, 5, 10.0, 20.0, ShutterMode::Dual);
        let sim = simulate(&cfg, &delta_psf(6, 5), &flat(6, 5, 1.0), &NoiseModel::default(), 2, 9).unwrap();
        let c = sim.capture_config(&cfg);
        assert_eq!(c.dark_level, Some(100.0));
        assert_eq!(c.scene.as_ref().unwrap()["kind"].as_str(), Some("image-stack"));
        assert_eq!(c.simulation.as_ref().unwrap()["seed"].as_integer(), Some(9));
        let back: CaptureConfig = toml::from_str(&c.to_toml()).unwrap();
        assert_eq!(back, c);
    }
}
