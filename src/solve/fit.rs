//! How well a reconstruction explains its data, against the noise: the fit report of
//! every run (summary.json's `fit`, one terminal line, the live page, Python).
//!
//! ## The figures
//! - `chi2_video`: the data misfit per kept pixel over the noise,
//!   `sum_i (A v - b)_i^2 / var_i / N`, over the pixels the data term keeps (the mask's,
//!   clipped pixels left out: they only bound the light from below) of every channel.
//!   A video that explains everything but the noise scores about 1.
//! - `chi2_still`: the same for the best still of the same data (one image repeated in
//!   every frame): the still start's image where the run solved one at a weight no
//!   heavier than the noise rule's, else a one-frame solve of [`STILL_FIT_ITERS`]
//!   iterations at the noise rule's weight (the still form of the prior, as the still
//!   start solves it).
//! - `motion_explained`: `(chi2_still - chi2_video) / (chi2_still - 1)`, clamped to
//!   `[0, 1]`: the share of the still's excess misfit over the noise that the video
//!   explains. Absent when the still leaves no excess to explain (`chi2_still <=`
//!   [`CHI2_FITS`]: a still scene) or the video has one frame.
//!
//! ## The noise
//! `var_i` is what the sensor model predicts where the capture description knows the
//! sensor ([`SensorNoise::SensorModel`]: capture.toml's `[simulation.noise]`, shot noise
//! `gain * b_i`, read noise `(gain * read_noise_e)^2`, quantisation `1/12` ADU^2, and the
//! fixed-pattern dark `[simulation.sensor] dark_fpn_rms_adu`^2 when no per-pixel dark was
//! subtracted; all over `d^2` for a `d x d` downsampled pixel). Elsewhere it is the
//! noise measured from the raw ([`SensorNoise::Measured`],
//! [`crate::model::noise::noise_sigma`], one sigma per channel): on a mostly dark scene
//! that is the dark pixels' noise, so the lit pixels' shot noise raises chi2 above 1.
//!
//! ## The warnings
//! None when the still fits (`chi2_still <= CHI2_FITS`: a still scene) or the video
//! does (`chi2_video <= CHI2_FITS`). Otherwise a **probe** decides whether a better
//! video exists: [`PROBE_ITERS`] iterations of the video problem from the still, at
//! [`PROBE_WEIGHT`] times the lighter of the run's weight and the noise rule's (for a
//! one-frame capture: the same lighter solve of the still). It runs only where it can
//! change the verdict (the video explains under `1 - PROBE_MARGIN` of the still's
//! excess, or stays above [`CHI2_FAR`]).
//! - (a) the data hold motion the video does not show: the probe explains at least
//!   [`PROBE_EXPLAINS`] of the still's excess misfit, and at least [`PROBE_MARGIN`] more
//!   of it than the video does. What to try: a smaller weight, more iterations, key
//!   frames (a coarser time grid first).
//! - (b) nothing fits: the video and the probe stay above [`CHI2_FAR`]
//!   ([`CHI2_FAR_MEASURED`] against a measured noise) (a lighter
//!   weight does not help: the misfit is not the prior's bias) and no motion was found. The
//!   likely causes: the PSF (another diffuser's, flipped, swapped with the raw), the
//!   timing (line time, exposure), the dark level.
//! - (c) the PSF fits better flipped: on every run the still is solved again from zero
//!   with the PSF as given and with it flipped upside down, mirrored left to right and
//!   rotated by 180 degrees ([`PsfFlip`], [`ORIENTATION_ITERS`] iterations each, at the
//!   still's weight). Where the given PSF's still does not fit at the noise (chi2 above
//!   [`ORIENTATION_WARN_ABOVE`]) and a flip's excess chi2 (`chi2 - 1`) is under the
//!   given's over [`ORIENTATION_RATIO`], the flip is named: the PSF file is likely that
//!   flip of the raw's. A still is where this matters most: a deconvolution explains a
//!   dense still nearly as well with a wrong PSF (a natural photograph, 120 x 160
//!   through the measured PSF: chi2 1.03 with its PSF, 2.09 with it flipped upside
//!   down, far below [`CHI2_FAR`]), while the flip back fits at the noise again. The
//!   check costs four still solves of [`ORIENTATION_ITERS`] iterations: a still's
//!   iteration costs a video's over its frames, so on a video it is a small share; on
//!   a still it is about a run's worth again (summary.json's `fit.psf_orientation`
//!   says how long it took).

use crate::model::capture::CaptureConfig;
use crate::model::data::DataTerm;
use crate::model::noise::noise_sigma;
use crate::model::op::{adjoint_peak, Operator};
use crate::model::prepare::{DarkSource, Prepared};
use crate::model::rolling::RollingShutterModel;
use crate::model::still::Still;
use crate::solve::job::{run, ChannelJob};
use crate::solve::lipschitz::{power_iteration, LIPSCHITZ_MARGIN};
use crate::solve::optimize::{NoObserver, OptimizerSettings, SolverKind, StopRule};
use crate::solve::problem::{Problem, SolveParams};
use crate::solve::prox::prior::{PriorSpec, TvPrior};
use crate::solve::prox::tv_dual::TvProxChoice;
use crate::solve::prox::TotalVariation;
use crate::solve::tau::NOISE_TAU_PER_SIGMA;
use ndarray::{ArrayView4, Axis};
use serde::Serialize;
use std::time::Instant;

/// A misfit per pixel at or below this is "at the noise": no warning.
pub const CHI2_FITS: f64 = 2.0;
/// A video misfit above this, with no motion found, is "nothing fits" (against the
/// sensor model's noise).
pub const CHI2_FAR: f64 = 10.0;
/// The same against a noise measured from the raw: that is the dark pixels' noise, so
/// a lit scene's shot noise and a real bench's small model errors raise a right
/// model's chi2 well above 1. The DiffuserCam tutorial's hand (downsampled 8 times,
/// its PSF's dark level) fits at 21.6 with its own PSF and at 2062 with it flipped.
pub const CHI2_FAR_MEASURED: f64 = 200.0;
/// Iterations of the still solve when the run has no still image to reuse.
pub const STILL_FIT_ITERS: usize = 50;
/// Iterations of the probe video solve (run only when neither the still nor the video
/// fits).
pub const PROBE_ITERS: usize = 40;
/// The probe's weight over the lighter of the run's and the noise rule's.
pub const PROBE_WEIGHT: f32 = 0.25;
/// The share of the still's excess misfit the probe must explain for "motion".
pub const PROBE_EXPLAINS: f64 = 0.5;
/// ... and how much more of it than the video.
pub const PROBE_MARGIN: f64 = 0.25;

/// A flip of the PSF is named only where the given PSF's still leaves a chi2 above this
/// (under it the PSF as given fits at the noise, whatever a flip does).
pub const ORIENTATION_WARN_ABOVE: f64 = 1.1;
/// ... and where the given PSF's excess chi2 (`chi2 - 1`) is above the flip's times
/// this.
pub const ORIENTATION_RATIO: f64 = 1.5;
/// Iterations of each of the orientation check's still solves (the PSF as given and
/// each flip, from zero).
pub const ORIENTATION_ITERS: usize = 100;

/// A flip of the PSF image against the raw's: what a camera's readout, an image
/// viewer's export or a turned mount can do to a PSF shot.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum PsfFlip {
    UpsideDown,
    LeftRight,
    Rotated180,
}

impl PsfFlip {
    /// Every flip the check tries.
    pub const ALL: [PsfFlip; 3] = [PsfFlip::UpsideDown, PsfFlip::LeftRight, PsfFlip::Rotated180];

    /// `psf` (`rows x cols`, row-major) flipped.
    pub fn apply(self, psf: &[f32], rows: usize, cols: usize) -> Vec<f32> {
        assert_eq!(psf.len(), rows * cols, "the PSF must be rows x cols");
        let at = |r: usize, c: usize| match self {
            PsfFlip::UpsideDown => psf[(rows - 1 - r) * cols + c],
            PsfFlip::LeftRight => psf[r * cols + cols - 1 - c],
            PsfFlip::Rotated180 => psf[(rows - 1 - r) * cols + cols - 1 - c],
        };
        (0..rows).flat_map(|r| (0..cols).map(move |c| (r, c))).map(|(r, c)| at(r, c)).collect()
    }

    /// In words.
    pub fn words(self) -> &'static str {
        match self {
            PsfFlip::UpsideDown => "flipped upside down",
            PsfFlip::LeftRight => "mirrored left to right",
            PsfFlip::Rotated180 => "rotated by 180 degrees",
        }
    }
}

/// The still's misfit with one flip of the PSF.
#[derive(Clone, Copy, Debug, Serialize, PartialEq)]
pub struct FlipFit {
    pub flip: PsfFlip,
    pub chi2: f64,
}

/// summary.json's `fit.psf_orientation`: the still solved with each flip of the PSF.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct OrientationCheck {
    /// The still's chi2 with the PSF as given, solved from zero as the flips are
    /// (so it can differ from the report's `chi2_still`, the run's own still).
    pub chi2_given: f64,
    /// Iterations of each flip's still solve.
    pub iterations: usize,
    pub flips: Vec<FlipFit>,
    /// The flip named by the warning, if any: the lowest chi2 among the flips whose
    /// excess (`chi2 - 1`) is under the given PSF's over [`ORIENTATION_RATIO`], where
    /// the given's chi2 is above [`ORIENTATION_WARN_ABOVE`].
    pub better: Option<PsfFlip>,
    pub seconds: f64,
}

/// The still of every channel solved with `flip` of its PSF at the still prior of
/// `tau_ref`, and its misfit; `None` when a solve went non-finite.
fn flipped_still_misfit(channels: &[ChannelFit], flip: Option<PsfFlip>, noise: &SensorNoise, tau_ref: f32, alpha: f32) -> Option<Misfit> {
    let mut m = Misfit::default();
    for c in channels {
        let (rows, cols) = c.model.conv().sensor_shape();
        let flipped = flip.map(|f| c.model.with_psf(&f.apply(c.model.conv().psf(), rows, cols)));
        let model = flipped.as_ref().unwrap_or(c.model);
        let prior = video_prior(model, c.data.observations(), tau_ref, alpha);
        let image = crate::solve::start::still_fit(model, &c.data, &prior, ORIENTATION_ITERS)?;
        m = m.add(still_misfit(model, &c.data, &image, noise, c.ch));
    }
    Some(m)
}

/// The misfit of the still `image` (one frame, shown through the whole exposure) under
/// `model` against `data`.
fn still_misfit(model: &RollingShutterModel, data: &DataTerm, image: &[f32], noise: &SensorNoise, ch: usize) -> Misfit {
    let op = Still::new(model);
    let mut ax = vec![0.0f32; op.output_len()];
    op.forward(image, &mut ax);
    Misfit::of(&ax, data.observations(), model.mask(), data.lower_bounds(), noise, ch)
}

/// The orientation check (the module's (c)) against the still's `chi2_given`.
fn orientation_check(channels: &[ChannelFit], noise: &SensorNoise, tau_ref: f32, alpha: f32) -> Option<OrientationCheck> {
    let clock = Instant::now();
    let chi2_given = flipped_still_misfit(channels, None, noise, tau_ref, alpha)?.chi2();
    let flips: Vec<FlipFit> = PsfFlip::ALL
        .iter()
        .filter_map(|&flip| flipped_still_misfit(channels, Some(flip), noise, tau_ref, alpha).map(|m| FlipFit { flip, chi2: m.chi2() }))
        .filter(|f| f.chi2.is_finite())
        .collect();
    let excess = |chi2: f64| (chi2 - 1.0).max(0.0);
    let better = flips
        .iter()
        .filter(|f| chi2_given > ORIENTATION_WARN_ABOVE && excess(f.chi2) * ORIENTATION_RATIO < excess(chi2_given))
        .min_by(|a, b| a.chi2.total_cmp(&b.chi2))
        .map(|f| f.flip);
    Some(OrientationCheck { chi2_given, iterations: ORIENTATION_ITERS, flips, better, seconds: clock.elapsed().as_secs_f64() })
}

/// The noise each pixel of the data is compared with.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "source", rename_all = "kebab-case")]
pub enum SensorNoise {
    /// Predicted by the capture description's sensor model.
    SensorModel {
        gain_adu_per_e: f64,
        /// Read noise in ADU (0 when the model has none).
        read_noise_adu: f64,
        /// Photon shot noise on.
        shot: bool,
        /// Fixed-pattern dark left in the data (ADU rms; 0 when a per-pixel dark was
        /// subtracted or the sensor has none).
        fixed_pattern_adu: f64,
        /// Raw pixels averaged into one data pixel (`d^2`).
        pixels_averaged: usize,
    },
    /// Measured from the raw, one standard deviation per channel (data units).
    Measured { sigma: Vec<f32> },
}

impl SensorNoise {
    /// The sensor model of capture.toml's `[simulation.noise]` table (and
    /// `[simulation.sensor] dark_fpn_rms_adu` unless `per_pixel_dark`), if it has one.
    pub fn from_description(cfg: &CaptureConfig, per_pixel_dark: bool) -> Option<SensorNoise> {
        let sim = cfg.simulation.as_ref()?;
        let noise = sim.get("noise")?.as_table()?;
        let float = |t: &toml::Table, k: &str| t.get(k).and_then(|v| v.as_float().or_else(|| v.as_integer().map(|i| i as f64)));
        let flag = |k: &str| noise.get(k).and_then(|v| v.as_bool()).unwrap_or(true);
        let gain = float(noise, "gain_adu_per_e").filter(|g| g.is_finite() && *g > 0.0)?;
        let read_e = float(noise, "read_noise_e").filter(|r| r.is_finite() && *r >= 0.0)?;
        let fpn = if per_pixel_dark { None } else { sim.get("sensor").and_then(|s| s.as_table()).and_then(|s| float(s, "dark_fpn_rms_adu")) };
        Some(SensorNoise::SensorModel {
            gain_adu_per_e: gain,
            read_noise_adu: if flag("gaussian") { gain * read_e } else { 0.0 },
            shot: flag("poisson"),
            fixed_pattern_adu: fpn.filter(|f| f.is_finite() && *f >= 0.0).unwrap_or(0.0),
            pixels_averaged: cfg.downsample.max(1).pow(2),
        })
    }

    /// The noise of a prepared capture: the description's sensor model, else the noise
    /// measured from each channel of the raw (`None`: neither is known).
    pub fn of(cfg: &CaptureConfig, prepared: &Prepared) -> Option<SensorNoise> {
        let per_pixel = matches!(prepared.sensor.dark_source, DarkSource::Calibration | DarkSource::Background);
        SensorNoise::from_description(cfg, per_pixel).or_else(|| {
            let sigma: Option<Vec<f32>> = prepared.raw.iter().map(|p| noise_sigma(&p.data, p.rows, p.cols, &prepared.data_mask)).collect();
            sigma.filter(|s| s.iter().all(|v| v.is_finite() && *v > 0.0)).map(|sigma| SensorNoise::Measured { sigma })
        })
    }

    /// The noise variance of a data pixel of channel `ch` whose value is `b` (data
    /// units above the dark).
    pub fn variance(&self, ch: usize, b: f32) -> f64 {
        match self {
            SensorNoise::SensorModel { gain_adu_per_e, read_noise_adu, shot, fixed_pattern_adu, pixels_averaged } => {
                let shot = if *shot { gain_adu_per_e * f64::from(b).max(0.0) } else { 0.0 };
                (shot + read_noise_adu.powi(2) + fixed_pattern_adu.powi(2) + 1.0 / 12.0) / *pixels_averaged as f64
            }
            SensorNoise::Measured { sigma } => f64::from(sigma[ch.min(sigma.len() - 1)]).powi(2),
        }
    }

    /// Which source, as the report names it.
    pub fn source(&self) -> &'static str {
        match self {
            SensorNoise::SensorModel { .. } => "sensor-model",
            SensorNoise::Measured { .. } => "measured",
        }
    }
}

/// The misfit of one prediction: `sum (a - b)^2 / var` over the kept pixels, and their
/// count.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Misfit {
    pub weighted_sq: f64,
    pub pixels: usize,
}

impl Misfit {
    /// Of the prediction `ax` of channel `ch`'s data `b` (`mask`: pixels kept where
    /// positive; `lower`: clipped pixels, left out).
    pub fn of(ax: &[f32], b: &[f32], mask: Option<&[f32]>, lower: Option<&[bool]>, noise: &SensorNoise, ch: usize) -> Misfit {
        let mut m = Misfit::default();
        for (i, (&a, &q)) in ax.iter().zip(b).enumerate() {
            if mask.is_some_and(|m| m[i] <= 0.0) || lower.is_some_and(|l| l[i]) || !q.is_finite() {
                continue;
            }
            let var = noise.variance(ch, q);
            if var > 0.0 {
                m.weighted_sq += (f64::from(a) - f64::from(q)).powi(2) / var;
                m.pixels += 1;
            }
        }
        m
    }

    fn add(self, o: Misfit) -> Misfit {
        Misfit { weighted_sq: self.weighted_sq + o.weighted_sq, pixels: self.pixels + o.pixels }
    }

    /// Per pixel (`NaN` with none).
    pub fn chi2(self) -> f64 {
        if self.pixels > 0 {
            self.weighted_sq / self.pixels as f64
        } else {
            f64::NAN
        }
    }
}

/// One channel of a capture as the fit sees it.
pub struct ChannelFit<'a> {
    pub ch: usize,
    pub model: &'a RollingShutterModel,
    /// The data (observations, clipped pixels).
    pub data: DataTerm<'a>,
    /// The video of this channel, (frames, rows, cols) on the model's grid.
    pub video: &'a [f32],
    /// A still image already solved at a weight no heavier than the noise rule's.
    pub still: Option<&'a [f32]>,
    /// The video's Lipschitz constant (with margin), when known.
    pub lipschitz: Option<f64>,
}

/// The weights the fit solves with.
#[derive(Clone, Copy, Debug)]
pub struct FitWeights {
    /// The run's TV weight and temporal weight.
    pub tau: f32,
    pub alpha: f32,
}

/// The lighter video solved to see whether the data hold motion.
#[derive(Clone, Copy, Debug, Serialize, PartialEq)]
pub struct Probe {
    pub tau: f32,
    /// `tau` over the first channel's `max(A^T b)`: the `--tau-rel` it stands for.
    pub tau_rel: f32,
    pub iterations: usize,
    pub chi2: f64,
    /// The share of the still's excess misfit it explains.
    pub motion_explained: f64,
}

/// summary.json's `fit`.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct FitReport {
    pub chi2_video: f64,
    pub chi2_still: f64,
    /// `(chi2_still - chi2_video) / (chi2_still - 1)` in `[0, 1]`; `None` when the still
    /// leaves no excess to explain, or the video has one frame.
    pub motion_explained: Option<f64>,
    pub warnings: Vec<String>,
    /// Where the noise came from: `sensor-model` or `measured`.
    pub noise: &'static str,
    /// The noise's rms over the kept pixels (data units).
    pub noise_sigma: f64,
    /// Kept pixels (all channels).
    pub pixels: usize,
    pub frames: usize,
    /// Where the still came from: `start` (the still start's) or `fit` (solved here).
    pub still_from: &'static str,
    /// The probe, when one ran.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub probe: Option<Probe>,
    /// The PSF's orientation check, when it ran.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub psf_orientation: Option<OrientationCheck>,
    pub seconds: f64,
    /// The terminal's line, as printed there (the live page shows it as written).
    pub line: String,
}

impl FitReport {
    /// The terminal line.
    pub fn line(&self) -> String {
        self.line.clone()
    }

    /// The terminal line of these figures.
    fn compose_line(&self) -> String {
        let head = format!("fit: chi2 {:.3} (video) vs {:.3} (still) per pixel over the noise ({})", self.chi2_video, self.chi2_still, self.noise);
        match self.motion_explained {
            Some(m) => format!("{head}, the video explains {:.0}% of the still's excess misfit", 100.0 * m),
            None if self.frames <= 1 => format!("{head}, one frame"),
            None => format!("{head}, the still is within {CHI2_FITS}x the noise: the misfit alone shows no motion"),
        }
    }
}

/// `(still - video) / (still - 1)` clamped to `[0, 1]`, `None` when the still fits.
fn explained(still: f64, video: f64) -> Option<f64> {
    (still.is_finite() && video.is_finite() && still > CHI2_FITS).then(|| ((still - video) / (still - 1.0)).clamp(0.0, 1.0))
}

/// The fit report of `channels` against `noise` (the run's weights in `w`).
pub fn fit_report(channels: &[ChannelFit], noise: &SensorNoise, w: FitWeights) -> FitReport {
    let clock = Instant::now();
    let mut video = Misfit::default();
    let mut var_sum = 0.0;
    let mut frames = 1;
    for c in channels {
        let mut ax = vec![0.0f32; c.model.output_len()];
        c.model.forward(c.video, &mut ax);
        video = video.add(Misfit::of(&ax, c.data.observations(), c.model.mask(), c.data.lower_bounds(), noise, c.ch));
        var_sum += kept_variance(c, noise);
        frames = c.model.frames();
    }
    let noise_sigma = (var_sum / video.pixels.max(1) as f64).sqrt();
    let tau_noise = NOISE_TAU_PER_SIGMA * noise_sigma as f32 / (frames as f32).sqrt();
    let tau_ref = if tau_noise > 0.0 && tau_noise.is_finite() { w.tau.min(tau_noise) } else { w.tau };
    let reuse = w.tau <= tau_ref * 1.001;
    let mut still = Misfit::default();
    let mut still_from = "start";
    let mut stills: Vec<Vec<f32>> = Vec::new();
    for c in channels {
        let image = if frames <= 1 {
            c.video.to_vec()
        } else {
            match c.still.filter(|s| reuse && s.len() * frames == c.video.len()) {
                Some(s) => s.to_vec(),
                None => {
                    still_from = "fit";
                    let prior = video_prior(c.model, c.data.observations(), tau_ref, w.alpha);
                    crate::solve::start::still_fit(c.model, &c.data, &prior, STILL_FIT_ITERS).unwrap_or_else(|| vec![0.0; c.video.len() / frames])
                }
            }
        };
        still = still.add(still_misfit(c.model, &c.data, &image, noise, c.ch));
        stills.push(image);
    }
    let (chi2_video, chi2_still) = (video.chi2(), if frames <= 1 { video.chi2() } else { still.chi2() });
    let motion_explained = if frames > 1 { explained(chi2_still, chi2_video) } else { None };
    let mut warnings = Vec::new();
    let mut probe = None;
    let neither_fits = chi2_video > CHI2_FITS && chi2_still > CHI2_FITS;
    let far = match noise {
        SensorNoise::SensorModel { .. } => CHI2_FAR,
        SensorNoise::Measured { .. } => CHI2_FAR_MEASURED,
    };
    let video_share = motion_explained.unwrap_or(0.0);
    // The probe can only change the verdict where the video explains less than the
    // motion rule asks beyond it, or fits far from the noise.
    if neither_fits && (video_share + PROBE_MARGIN < 1.0 || chi2_video > far) {
        let tau = PROBE_WEIGHT * tau_ref;
        let mut m = Misfit::default();
        for (c, s) in channels.iter().zip(&stills) {
            let x = probe_video(c, s, tau, w.alpha, frames);
            let mut ax = vec![0.0f32; c.model.output_len()];
            c.model.forward(&x, &mut ax);
            m = m.add(Misfit::of(&ax, c.data.observations(), c.model.mask(), c.data.lower_bounds(), noise, c.ch));
        }
        let chi2 = m.chi2();
        let scale = channels.first().map_or(0.0, |c| adjoint_peak(c.model, c.data.observations()) as f64);
        let tau_rel = if scale > 0.0 { (f64::from(tau) / scale) as f32 } else { 0.0 };
        probe = Some(Probe { tau, tau_rel, iterations: PROBE_ITERS, chi2, motion_explained: explained(chi2_still, chi2).unwrap_or(0.0) });
    }
    let motion = frames > 1 && probe.is_some_and(|p| p.motion_explained >= PROBE_EXPLAINS && p.motion_explained >= video_share + PROBE_MARGIN);
    match probe {
        Some(p) if motion => warnings.push(format!(
            "the data hold motion the video does not show: the still leaves chi2 {chi2_still:.3} per pixel, the video {chi2_video:.3} ({:.0}% of the still's excess explained), while a lighter video ({} iterations from the still at --tau-rel {:.1e}) reaches {:.3} ({:.0}%). Try a smaller weight (--tau-rel {:.1e} or less), more iterations (--iters, --obj-tol 0), or key frames (solve a coarser time grid first: --binning)",
            100.0 * video_share,
            p.iterations,
            p.tau_rel,
            p.chi2,
            100.0 * p.motion_explained,
            p.tau_rel
        )),
        Some(p) if chi2_video > far && p.chi2 > far => warnings.push(format!(
            "nothing fits the data: chi2 {chi2_video:.3} (video), {chi2_still:.3} (still) and {:.3} (a lighter solve) per pixel, far above the noise ({} sigma {noise_sigma:.3}): the model does not describe this capture. Likely causes: the PSF (another diffuser's, flipped or rotated, or swapped with the raw: check --psf and --raw), the timing (line time and exposure in capture.toml), the dark level (dark_level, or the calibration's dark)",
            p.chi2,
            noise.source()
        )),
        _ => {}
    }
    let psf_orientation = orientation_check(channels, noise, tau_ref, w.alpha);
    if let Some((o, flip)) = psf_orientation.as_ref().and_then(|o| o.better.map(|f| (o, f))) {
        let chi2_flip = o.flips.iter().find(|f| f.flip == flip).map_or(f64::NAN, |f| f.chi2);
        warnings.push(format!(
            "the PSF fits the data better {w}: a still solved with the PSF as given leaves chi2 {:.3} per pixel, with the PSF {w} {chi2_flip:.3} ({} iterations each). The PSF file is likely {w} against the raw (a camera's readout, an image export or the mount): check its orientation (--psf) and flip it to match the raw",
            o.chi2_given,
            o.iterations,
            w = flip.words()
        ));
    }
    let mut report = FitReport {
        chi2_video,
        chi2_still,
        motion_explained,
        warnings,
        noise: noise.source(),
        noise_sigma,
        pixels: video.pixels,
        frames,
        still_from: if frames <= 1 { "video" } else { still_from },
        probe,
        psf_orientation,
        seconds: clock.elapsed().as_secs_f64(),
        line: String::new(),
    };
    report.line = report.compose_line();
    report
}

/// The sum of the noise variances over `c`'s kept pixels.
fn kept_variance(c: &ChannelFit, noise: &SensorNoise) -> f64 {
    kept_variance_of(c.model, &c.data, noise, c.ch)
}

/// The sum of the noise variances of channel `ch` over the pixels of `data` that
/// `model`'s mask keeps (clipped pixels left out).
fn kept_variance_of(model: &RollingShutterModel, data: &DataTerm, noise: &SensorNoise, ch: usize) -> f64 {
    let (mask, lower) = (model.mask(), data.lower_bounds());
    data.observations()
        .iter()
        .enumerate()
        .filter(|&(i, q)| q.is_finite() && !mask.is_some_and(|m| m[i] <= 0.0) && !lower.is_some_and(|l| l[i]))
        .map(|(_, &q)| noise.variance(ch, q))
        .filter(|v| *v > 0.0)
        .sum()
}

/// The data term's value at which channel `ch`'s misfit is the noise's: half the sum
/// of the noise variances over its kept pixels, where the capture description's sensor
/// model gives them ([`SensorNoise::SensorModel`]). `None` for a noise measured from
/// the raw: that is the dark pixels' noise, below a lit scene's, so a floor from it
/// would end solves early ([`crate::solve::optimize::StopRule::noise_floor`]).
pub fn noise_floor(problem: &Problem, ch: usize) -> Option<f64> {
    let noise = SensorNoise::of(problem.cfg, problem.prepared)?;
    if !matches!(noise, SensorNoise::SensorModel { .. }) {
        return None;
    }
    let raw = problem.prepared.raw.get(ch)?;
    let data = DataTerm::new(&raw.data).with_lower_bounds(problem.prepared.data_mask.lower_bounds.as_deref());
    Some(0.5 * kept_variance_of(problem.channel(ch).model(), &data, &noise, ch))
}

/// The video prior at `tau` (TV with temporal weight `alpha`, non-negative, the map
/// chosen by `auto` on the data's `max(A^T b)`).
fn video_prior(model: &RollingShutterModel, b: &[f32], tau: f32, alpha: f32) -> PriorSpec {
    let scale = adjoint_peak(model, b) as f64;
    PriorSpec::Tv(TvPrior::new(TotalVariation::new(model.video_shape(), tau, alpha), TvProxChoice::Auto, scale))
}

/// [`PROBE_ITERS`] iterations of the video problem at `tau` from `still` in every frame.
fn probe_video(c: &ChannelFit, still: &[f32], tau: f32, alpha: f32, frames: usize) -> Vec<f32> {
    let lipschitz = c.lipschitz.filter(|l| l.is_finite() && *l > 0.0).unwrap_or_else(|| power_iteration(c.model, 30, 1e-4, 1).lambda_max * LIPSCHITZ_MARGIN);
    let prior = video_prior(c.model, c.data.observations(), tau, alpha).build(None);
    let settings = OptimizerSettings::new(SolverKind::FistaRestart, lipschitz, StopRule::iterations(PROBE_ITERS));
    let x0 = still.repeat(frames);
    let r = run(ChannelJob { settings: &settings, operator: c.model, data: &c.data, prior: prior.as_ref(), start: Some(x0.clone()) }, &mut NoObserver);
    if r.x.iter().all(|v| v.is_finite()) {
        r.x
    } else {
        x0
    }
}

/// What a channel's solve left that the fit reuses.
#[derive(Clone, Copy, Debug, Default)]
pub struct SolvedChannel<'a> {
    /// The still start's image, when one was solved.
    pub still: Option<&'a [f32]>,
    /// The video's Lipschitz constant (with margin).
    pub lipschitz: f64,
}

/// The fit report of a reconstructed capture: `video` (frames, rows, cols, channels)
/// against `problem`'s data, with what each channel's solve left (`solved`; its still
/// reused only for a `plain` solve: no scene declaration, no static + dynamic model),
/// the run's weights (`params`) and the capture's noise ([`SensorNoise::of`]). `None`
/// where the video and the data are not one-to-one by channel (a grey declaration of an
/// RGB raw) or the noise is unknown.
pub fn fit_capture(problem: &Problem, video: ArrayView4<f32>, solved: &[SolvedChannel], plain: bool, params: &SolveParams) -> Option<FitReport> {
    let prepared = problem.prepared;
    let noise = SensorNoise::of(problem.cfg, prepared)?;
    let (k, mv, nv, channels) = video.dim();
    if channels != prepared.raw.len() || problem.models().len() != channels {
        return None;
    }
    let lower = prepared.data_mask.lower_bounds.as_deref();
    let videos: Vec<Vec<f32>> = (0..channels).map(|ch| video.index_axis(Axis(3), ch).iter().copied().collect()).collect();
    let fits: Vec<ChannelFit> = (0..channels)
        .map(|ch| {
            let s = solved.get(ch).copied().unwrap_or_default();
            ChannelFit {
                ch,
                model: problem.channel(ch).model(),
                data: DataTerm::new(&prepared.raw[ch].data).with_lower_bounds(lower),
                video: &videos[ch],
                still: s.still.filter(|i| plain && i.len() == mv * nv),
                lipschitz: Some(s.lipschitz),
            }
        })
        .collect();
    if fits.iter().any(|f| f.model.input_len() != k * mv * nv) {
        return None;
    }
    let report = fit_report(&fits, &noise, FitWeights { tau: params.tau, alpha: params.alpha });
    tracing::info!(seconds = report.seconds, "{}", report.line());
    Some(report)
}
