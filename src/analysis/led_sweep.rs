//! The LED sweep experiment: four LEDs flashing square waves in unison, one capture per
//! period (exposure 660 us, effective line time 220 us, dual shutter), each
//! reconstructed and analysed; then one report (`report.md`, `report.json`) with a
//! table and a composed figure (per period: raw, x-t projection, spectrum).
//!
//! Two ways to get the captures: [`run_sweep`] simulates them; the bench
//! (`crate::lab::led_sweep::run_bench_sweep`) programs an LED controller, verifies its
//! readback, records a raw with a camera (on disk first, with the LED settings in the
//! capture metadata) and reconstructs that recorded file through [`analyse_period`]
//! and [`write_report`] here.

use super::report::{analyze_video, write_analysis, write_map_png, AnalysisError, AnalyzeOptions, Region, VideoTiming};
use super::video::{dip_between, fundamental_contrast, time_sum};
use crate::io::cache::LipschitzCache;
use crate::io::output::{Inputs, OutputSet};
use crate::io::sensor_files::SensorFiles;
use crate::io::{self, IoError};
use crate::model::capture::CaptureConfig;
use crate::model::shutter::ShutterMode;
use crate::request::capture::CaptureRequest;
use crate::sim::{self, LedArray, LedLine, LensletParams, NoiseModel};
use crate::solve::problem::{SolveSettings, DEFAULT_ALPHA, DEFAULT_ITERS};
use crate::solve::reconstruct::Hooks;
use ndarray::{Array2, Array3, Array4, Axis};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Instant;

/// Exposure of the sweep, microseconds (3 line times).
pub const EXPOSURE_US: f64 = 660.0;
/// Effective line time of the sweep, microseconds.
pub const LINE_TIME_US: f64 = crate::model::shutter::DEFAULT_LINE_TIME_US;
/// The periods of the sweep, microseconds.
pub const PERIODS_US: [f64; 4] = [2640.0, 1980.0, 1320.0, 660.0];

/// Sensor sizes of the sweep.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum SweepSize {
    /// 64 x 80: seconds per period (tests).
    Small,
    /// 128 x 160: the demo's sensor.
    Demo,
    /// 270 x 320: the paper's sensor after 8x downsampling (slow on few cores).
    Paper8x,
}

impl SweepSize {
    pub fn sensor(self) -> (usize, usize) {
        match self {
            SweepSize::Small => (64, 80),
            SweepSize::Demo => (128, 160),
            SweepSize::Paper8x => (270, 320),
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            SweepSize::Small => "small",
            SweepSize::Demo => "demo",
            SweepSize::Paper8x => "paper-8x",
        }
    }
}

impl std::str::FromStr for SweepSize {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "small" => Ok(SweepSize::Small),
            "demo" => Ok(SweepSize::Demo),
            "paper-8x" => Ok(SweepSize::Paper8x),
            _ => Err(format!("unknown size '{s}': expected small, demo or paper-8x")),
        }
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct SweepOptions {
    pub periods_us: Vec<f64>,
    pub size: SweepSize,
    pub iters: usize,
    /// The TV weight (a number relative to max(A^T b), or the noise rule).
    pub tau: crate::solve::tau::Tau,
    pub alpha: f32,
    /// LED spacing, raw pixels (the paper's target: 6).
    pub spacing_px: f64,
    pub seed: u64,
    /// The bench calibration and background every capture of the sweep uses.
    #[serde(skip)]
    pub sensor: SensorFiles,
}

impl Default for SweepOptions {
    fn default() -> Self {
        SweepOptions {
            periods_us: PERIODS_US.to_vec(),
            size: SweepSize::Demo,
            iters: DEFAULT_ITERS,
            tau: crate::solve::tau::Tau::Noise,
            alpha: DEFAULT_ALPHA,
            spacing_px: 6.0,
            seed: 1,
            sensor: SensorFiles::default(),
        }
    }
}

/// One period's outcome.
#[derive(Clone, Debug, Serialize)]
pub struct SweepRow {
    pub period_us: f64,
    pub expected_frequency_hz: f64,
    pub measured_peak_hz: Option<f64>,
    pub bin_hz: f64,
    pub peak_within_one_bin: bool,
    /// Mean over the LEDs of the reconstruction's fundamental contrast (1: full square wave).
    pub temporal_contrast: f64,
    /// The same measure on the true video (square wave averaged over each frame);
    /// `None` for bench captures, which have no truth.
    pub truth_temporal_contrast: Option<f64>,
    /// `|sinc(f0 T_e)|`: the fundamental contrast left after the exposure's box mean.
    pub expected_temporal_contrast: f64,
    /// Mean over the LEDs of the Michelson contrast (5th/95th percentiles) of the time course.
    pub michelson_contrast: f64,
    /// Exact Michelson contrast of the square wave after the exposure's box mean.
    pub expected_michelson_contrast: f64,
    /// Lowest dip contrast between neighbouring LEDs in the time-summed reconstruction.
    pub spatial_contrast: f64,
    /// Neighbouring LED pairs resolved (dip below 73.5% of the lower peak) of all pairs.
    pub pairs_resolved: usize,
    pub pairs: usize,
    pub psnr_db: Option<f64>,
    pub seconds: f64,
    pub notes: Vec<String>,
    /// Folder of this period's files, relative to the report.
    pub folder: String,
    /// Bench captures: the LED controller's configuration as read back over the link
    /// before the capture (also stored in the capture's `capture.json`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub led_readback: Option<serde_json::Value>,
    /// Bench captures: the recorded capture folder, relative to the report.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub capture: Option<String>,
}

#[derive(Clone, Debug, Serialize)]
pub struct SweepReport {
    pub options: SweepOptions,
    pub sensor: (usize, usize),
    pub exposure_us: f64,
    pub line_time_us: f64,
    pub frame_time_us: f64,
    pub nyquist_hz: f64,
    pub exposure_first_zero_hz: f64,
    pub rows: Vec<SweepRow>,
    pub figure: String,
    pub command: String,
    /// Bench sweeps: the camera, the LED controller and the calibration used.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bench: Option<BenchInfo>,
}

/// What a bench sweep ran on.
#[derive(Clone, Debug, Serialize)]
pub struct BenchInfo {
    /// Camera as given (`aravis:<id>`, `sim:led-array`, ...).
    pub camera: String,
    /// LED controller port (or the emulator's pseudo-terminal).
    pub led_port: String,
    /// LED controller identity (`ID` reply).
    pub led_device: serde_json::Value,
    /// LEDs driven (controller channels 0..leds).
    pub leds: usize,
    pub duty: f64,
    pub phases_us: Vec<u32>,
    /// Trigger the controller was armed with (SW: started by the host; RISE/FALL: the
    /// camera's exposure output).
    pub led_trigger: String,
    pub psf: String,
    pub config: String,
}

pub fn io_err(path: &Path, action: &'static str, source: std::io::Error) -> AnalysisError {
    AnalysisError::Io(IoError::Os { path: path.to_path_buf(), action, source })
}

pub fn other(what: &str, e: impl std::fmt::Display) -> AnalysisError {
    AnalysisError::Input { what: what.into(), problem: e.to_string() }
}

/// LED centres on the raw grid (spot centroids), rounded to pixels.
pub fn led_pixels(leds: &LedArray, cols: usize) -> Vec<(usize, usize)> {
    (0..leds.leds())
        .map(|l| {
            let (r, c) = leds.spot(l).iter().fold((0.0, 0.0), |(r, c), &(i, w)| (r + w as f64 * (i / cols) as f64, c + w as f64 * (i % cols) as f64));
            (r.round() as usize, c.round() as usize)
        })
        .collect()
}

/// One period's capture, ready for reconstruction.
pub struct Acquired {
    /// Raw image, counts, `rows x cols x 1`.
    pub raw: Array3<f32>,
    pub raw_name: String,
    /// PSF in counts (dark level included), `rows x cols x 1`.
    pub psf: Array3<f32>,
    pub psf_name: String,
    /// The PSF is a calibration's (already dark-subtracted).
    pub psf_clean: bool,
    pub cfg: CaptureConfig,
    /// Where `cfg` came from (written to `capture.toml` in the period folder).
    pub config_name: String,
    pub truth: Option<Array4<f32>>,
    /// LED pixels on the sensor grid when known (the simulated target), else found in the video.
    pub centres: Option<Vec<(usize, usize)>>,
    pub leds: usize,
    pub duty: f64,
    pub led_readback: Option<serde_json::Value>,
    pub capture: Option<String>,
}

/// Run one period: simulate, reconstruct, analyse, into `dir`.
pub fn run_period(opts: &SweepOptions, period_us: f64, dir: &Path, hooks: &Hooks) -> Result<SweepRow, AnalysisError> {
    let t0 = Instant::now();
    let (rows, cols) = opts.size.sensor();
    let cfg = CaptureConfig::new(rows, cols, LINE_TIME_US, EXPOSURE_US, ShutterMode::Dual);
    let psf = sim::lenslet_psf(rows, cols, &LensletParams::default(), opts.seed).map_err(|e| other("synthetic PSF", e))?;
    let leds = LedArray::new(
        rows,
        cols,
        LedLine { leds: 4, spacing_px: opts.spacing_px, radius_px: 1.5, period_us: vec![period_us], duty: 0.5, phase_us: vec![0.0], e_per_us: 1000.0 },
    )
    .map_err(|e| other("LED target", e))?;
    let noise = NoiseModel::default();
    let psf_flat: Vec<f32> = psf.iter().cloned().collect();
    let s = sim::simulate(&cfg, &psf_flat, &leds, &noise, 4, opts.seed).map_err(|e| other("simulation", e))?;
    let cfg = s.capture_config(&cfg);
    let raw = s.raw.view().insert_axis(Axis(2)).to_owned();
    let peak = psf.iter().cloned().fold(0.0f32, f32::max);
    let dark = noise.dark_level_adu as f32;
    let psf_adu: Array3<f32> = psf.mapv(|v| v * 50_000.0 / peak + dark).insert_axis(Axis(2));
    let acquired = Acquired {
        raw,
        raw_name: "simulated raw".into(),
        psf: psf_adu,
        psf_name: "synthetic PSF".into(),
        psf_clean: false,
        cfg,
        config_name: "simulated capture".into(),
        truth: Some(s.truth.view().insert_axis(Axis(3)).to_owned()),
        centres: Some(led_pixels(&leds, cols)),
        leds: 4,
        duty: 0.5,
        led_readback: None,
        capture: None,
    };
    analyse_period(opts, period_us, acquired, dir, hooks, t0)
}

/// Reconstruct and analyse one acquired capture into `dir`.
pub fn analyse_period(opts: &SweepOptions, period_us: f64, acq: Acquired, dir: &Path, hooks: &Hooks, t0: Instant) -> Result<SweepRow, AnalysisError> {
    let cfg = acq.cfg;
    std::fs::create_dir_all(dir).map_err(|e| io_err(dir, "create folder", e))?;
    let text = cfg.to_toml();
    io::write_text_atomic(&dir.join("capture.toml"), &text)?;
    let raw_img = acq.raw.index_axis(Axis(2), 0).mapv(|v| v as f64);
    write_map_png(&dir.join("raw.png"), &raw_img, 256)?;

    let settings = SolveSettings { tau: opts.tau, alpha: opts.alpha, iters: opts.iters, ..SolveSettings::default() };
    let settings = settings.validate().map_err(|e| other("solve settings", e))?;
    let request = CaptureRequest::new(acq.raw.view(), &acq.raw_name, acq.psf.view(), &acq.psf_name, &cfg, &opts.sensor, &settings)
        .with_clean_psf(acq.psf_clean)
        .with_truth(acq.truth.as_ref().map(|t| (t.view(), "truth")));
    let prepared = request.prepare().map_err(|e| other("prepare", e))?;
    let outcome = prepared.reconstruct(&LipschitzCache::default_location(), hooks).map_err(|e| other("reconstruction", e))?;
    let rec = &outcome.reconstruction;
    let simulated = acq.truth.is_some();
    let inputs = Inputs {
        config: Some(format!("{} (as {})", acq.config_name, dir.join("capture.toml").display())),
        truth: simulated.then(|| "simulated".into()),
        ..request.inputs()
    };
    outcome.write(&dir.join("rec"), &cfg, &inputs, OutputSet::Full)?;

    // Analyse as a user would, with the waveform period given.
    let timing = VideoTiming::from_config(&cfg, Some(rec.frame_time_us), &acq.config_name)?;
    let (vr, vc) = (rec.video.dim().1, rec.video.dim().2);
    let d = cfg.downsample.max(1);
    // Known LED pixels move to the video grid; unknown ones are the brightest spots.
    let known: Option<Vec<(usize, usize)>> = acq.centres.as_ref().map(|c| c.iter().map(|&(r, c)| ((r / d).min(vr - 1), (c / d).min(vc - 1))).collect());
    let aopts = AnalyzeOptions {
        regions: known.iter().flatten().map(|&(r, c)| Region::around(r, c, 1, vr, vc)).collect(),
        waveform_period_us: Some(period_us),
        duty: acq.duty,
        max_spots: acq.leds,
        ..AnalyzeOptions::default()
    };
    let v = rec.video.view();
    let analysis = match analyze_video(v, &timing, &aopts) {
        Ok(a) => a,
        Err(e) if known.is_none() => return Err(other("LED regions", format!("{e} (in the LED sweep: give each LED's raw pixel with --led-pixel ROW,COL)"))),
        Err(e) => return Err(e),
    };
    let analysis = write_analysis(&dir.join("analysis"), v, analysis)?;
    let verdict = analysis.verdict.clone().expect("a waveform was given");
    let mut centres = match known {
        Some(c) => c,
        None => analysis.spots.iter().take(acq.leds).map(|s| (s.row, s.col)).collect(),
    };
    centres.sort_by_key(|&(r, c)| (c, r));

    // Truth contrast at the same regions; spatial dips between neighbouring LEDs.
    let truth_contrast = acq.truth.as_ref().map(|t| {
        let tv = t.view();
        aopts.regions.iter().map(|r| fundamental_contrast(&r.time_course(tv), rec.frame_time_us, 1e6 / period_us, acq.duty)).sum::<f64>()
            / aopts.regions.len().max(1) as f64
    });
    let summed: Array2<f64> = time_sum(v);
    let dips: Vec<_> = centres.windows(2).map(|w| dip_between(&summed, w[0], w[1])).collect();
    let spatial = if dips.is_empty() { 0.0 } else { dips.iter().map(|d| d.contrast).fold(f64::INFINITY, f64::min) };
    let resolved = dips.iter().filter(|d| d.resolved).count();
    let mut notes = verdict.notes.clone();
    if centres.len() < acq.leds {
        notes.push(format!("only {} of {} LEDs found as bright spots in the reconstruction", centres.len(), acq.leds));
    }
    if resolved < dips.len() {
        notes.push(format!("only {resolved} of {} neighbouring LED pairs resolved spatially", dips.len()));
    }
    Ok(SweepRow {
        period_us,
        expected_frequency_hz: verdict.expected_frequency_hz,
        measured_peak_hz: verdict.measured_peak_hz,
        bin_hz: verdict.bin_hz,
        peak_within_one_bin: verdict.peak_within_one_bin,
        temporal_contrast: verdict.fundamental_contrast,
        truth_temporal_contrast: truth_contrast,
        expected_temporal_contrast: verdict.expected_fundamental_contrast,
        michelson_contrast: verdict.temporal_contrast,
        expected_michelson_contrast: verdict.expected_contrast_after_exposure,
        spatial_contrast: spatial,
        pairs_resolved: resolved,
        pairs: dips.len(),
        psnr_db: rec.channels[0].stats.error.map(|e| e.psnr_db),
        seconds: t0.elapsed().as_secs_f64(),
        notes,
        folder: dir.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default(),
        led_readback: acq.led_readback,
        capture: acq.capture,
    })
}

/// Folder name of a period.
/// The longest LED period a sweep takes, microseconds (10 s): a capture lasts
/// milliseconds, so a longer period shows no flashing, and its folder name
/// (`period-<P>us`) stays short.
pub const MAX_PERIOD_US: f64 = 1e7;

/// A sweep's periods (`--periods-us`): at least one, each positive and at most
/// [`MAX_PERIOD_US`]; one check for the simulated and the bench sweep.
pub fn check_periods(periods_us: &[f64]) -> Result<(), AnalysisError> {
    if periods_us.is_empty() {
        return Err(other("--periods-us", "no period: expected at least one period in microseconds"));
    }
    if let Some(p) = periods_us.iter().find(|p| !(p.is_finite() && **p > 0.0 && **p <= MAX_PERIOD_US)) {
        return Err(other("--periods-us", format!("{p}: expected periods from above 0 to {MAX_PERIOD_US:e} us (10 s; a capture lasts milliseconds)")));
    }
    Ok(())
}

pub fn period_folder(period_us: f64) -> String {
    format!("period-{period_us:.0}us")
}

/// Compose the figure: one row per period with its raw image, x-t projection (max)
/// and spectrum, each scaled to `height` pixels.
pub fn compose_figure(dirs: &[PathBuf], path: &Path) -> Result<(), AnalysisError> {
    const HEIGHT: u32 = 300;
    const GAP: u32 = 8;
    let mut rows: Vec<Vec<image::RgbImage>> = Vec::new();
    for d in dirs {
        let mut tiles = Vec::new();
        for f in [d.join("raw.png"), d.join("analysis").join("xt_max.png"), d.join("analysis").join("spectrum.png")] {
            let img = image::open(&f).map_err(|e| other(&f.display().to_string(), e))?.to_rgb8();
            let w = ((img.width() as f64 * HEIGHT as f64 / img.height() as f64).round() as u32).max(1);
            tiles.push(image::imageops::resize(&img, w, HEIGHT, image::imageops::FilterType::Triangle));
        }
        rows.push(tiles);
    }
    let width = rows.iter().map(|r| r.iter().map(|t| t.width() + GAP).sum::<u32>()).max().unwrap_or(1);
    let height = rows.len() as u32 * (HEIGHT + GAP);
    let mut canvas = image::RgbImage::from_pixel(width.max(1), height.max(1), image::Rgb([255, 255, 255]));
    for (i, r) in rows.iter().enumerate() {
        let mut x = 0u32;
        for t in r {
            image::imageops::overlay(&mut canvas, t, x as i64, (i as u32 * (HEIGHT + GAP)) as i64);
            x += t.width() + GAP;
        }
    }
    canvas.save(path).map_err(|e| other(&path.display().to_string(), e))?;
    Ok(())
}

/// Markdown of the report.
pub fn report_markdown(r: &SweepReport, figure: &str) -> String {
    let mut s = String::new();
    match &r.bench {
        None => {
            s.push_str("# LED sweep: temporal and spatial resolution in simulation\n\n");
            s.push_str(&format!(
                "Four LEDs {:.0} px apart flash square waves (duty 0.5) in unison; one simulated capture per period on a {} x {} dual-shutter sensor, \
                 exposure T_e = {:.0} us, line time T_l = {:.0} us (frame time T_f = {:.0} us, {:.0} fps), {} FISTA iterations per reconstruction.\n\n",
                r.options.spacing_px,
                r.sensor.0,
                r.sensor.1,
                r.exposure_us,
                r.line_time_us,
                r.frame_time_us,
                1e6 / r.frame_time_us,
                r.options.iters
            ));
        }
        Some(b) => {
            s.push_str("# LED sweep: temporal and spatial resolution on the bench\n\n");
            s.push_str(&format!(
                "{} LEDs on controller channels 0-{} ({}, {}) flash square waves (duty {}, phases {:?} us) in unison, armed with trigger {}; \
                 one capture per period from camera {} on a {} x {} sensor, exposure T_e = {:.0} us, line time T_l = {:.0} us \
                 (frame time T_f = {:.0} us, {:.0} fps), PSF {}, timing {}, {} FISTA iterations per reconstruction. \
                 Before each capture the controller's configuration was read back over the link and checked against what was programmed; \
                 each raw was recorded to disk (with that readback in its capture.json) before it was reconstructed.\n\n",
                b.leds,
                b.leds.saturating_sub(1),
                b.led_port,
                b.led_device.get("firmware").and_then(|f| f.as_str()).unwrap_or("?"),
                b.duty,
                b.phases_us,
                b.led_trigger,
                b.camera,
                r.sensor.0,
                r.sensor.1,
                r.exposure_us,
                r.line_time_us,
                r.frame_time_us,
                1e6 / r.frame_time_us,
                b.psf,
                b.config,
                r.options.iters
            ));
        }
    }
    s.push_str(&format!(
        "Theory: sampling at 1/T_f gives a Nyquist frequency of {:.0} Hz; the exposure's box mean rect(t/T_e) has its first zero at 1/T_e = {:.0} Hz, \
         so a square wave of period T_e = {:.0} us integrates to a constant in every row (contrast 0) while periods of at least 2 T_e keep full contrast. \
         The raw rows carry |sinc(f0 T_e)| of the fundamental; the reconstruction, whose model includes the exposure window, can restore more of it \
         (up to |sinc(f0 T_f)|, what averaging over a frame leaves), except where the sinc vanishes: at P = T_e the information is gone, whatever the solver.\n\n",
        r.nyquist_hz, r.exposure_first_zero_hz, r.exposure_us
    ));
    s.push_str("Regenerate with:\n\n```\n");
    s.push_str(&r.command);
    s.push_str("\n```\n\n");
    s.push_str("| period (us) | expected frequency (Hz) | measured peak (Hz) | bin (Hz) | temporal contrast | truth | theory \\|sinc(f0 T_e)\\| | Michelson (q5/q95) | Michelson theory after T_e | spatial contrast (min dip) | LED pairs resolved | PSNR (dB) | seconds |\n");
    s.push_str("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for row in &r.rows {
        s.push_str(&format!(
            "| {:.0} | {:.1} | {} | {:.0} | {:.2} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {}/{} | {} | {:.1} |\n",
            row.period_us,
            row.expected_frequency_hz,
            row.measured_peak_hz.map_or("-".into(), |f| format!("{f:.1}")),
            row.bin_hz,
            row.temporal_contrast,
            row.truth_temporal_contrast.map_or("-".into(), |t| format!("{t:.2}")),
            row.expected_temporal_contrast,
            row.michelson_contrast,
            row.expected_michelson_contrast,
            row.spatial_contrast,
            row.pairs_resolved,
            row.pairs,
            row.psnr_db.map_or("-".into(), |p| format!("{p:.1}")),
            row.seconds
        ));
    }
    s.push_str(&format!("\n![raw, x-t projection (max over rows), temporal power spectrum; one row per period, top to bottom as in the table]({figure})\n\n"));
    s.push_str("Rows of the figure, top to bottom, follow the table. Left: the raw image; middle: x-t projection (max over rows; time runs down, x across); right: temporal power spectrum of the LED regions and of the x-t projection, with the exposure's |sinc|^2, 1/T_e, Nyquist and the square wave's odd harmonics marked.\n\n");
    s.push_str("## Measurement against theory\n\n");
    for row in &r.rows {
        s.push_str(&format!("- **{:.0} us**: {}\n", row.period_us, row.notes.join("; ")));
    }
    s.push_str("\n## Definitions\n\n");
    s.push_str(
        "- *Temporal contrast*: fundamental contrast of an LED region's time course (3 x 3 pixels around the LED), averaged over the four LEDs: \
         a least-squares fit of c + s t + a cos(2 pi f0 t) + b sin(2 pi f0 t) (the slope absorbs the slow wipe of the early frames), \
         modulation sqrt(a^2 + b^2) / c divided by the 4/pi of an ideal 0/1 square wave. 1 for a full square wave, 0 for none. \
         *Truth* is the same measure on the simulated true video (the square wave averaged over each frame of T_f, hence about |sinc(f0 T_f)|; it can exceed 1 when the period is a whole number of frames, as at 1320 us = 6 T_f, where the 5th harmonic aliases onto the fundamental); \
         *theory* is |sinc(f0 T_e)|, what the exposure's box mean leaves of the fundamental.\n\
         - *Michelson*: (q95 - q5) / (q95 + q5) of the time course (sensitive to the early frames' wipe, where the reconstruction is dark); \
         its theory is the square wave convolved with rect(t/T_e), (max - min) / (max + min), computed exactly at the kinks of the piecewise-linear box mean.\n\
         - *Measured peak*: frequency of the largest power (above 1.5 native bins) of the summed power spectra of the LED regions (detrended, Hann window, zero-padded 8x); \
         *bin* is the native resolution 1/(K T_f).\n\
         - *Spatial contrast*: along the line joining neighbouring LEDs in the time-summed reconstruction, (lower peak - dip) / (lower peak + dip) above the median background; \
         a pair counts as resolved when the dip falls below 73.5% of the lower peak (Rayleigh).\n\
         - *Truth* and *PSNR* exist only in simulation; bench captures show \"-\".\n",
    );
    s
}

/// Run the whole sweep into `out`. `on_period` reports progress.
pub fn run_sweep(opts: &SweepOptions, out: &Path, command: &str, hooks: &Hooks, on_period: &dyn Fn(&SweepRow)) -> Result<SweepReport, AnalysisError> {
    check_periods(&opts.periods_us)?;
    std::fs::create_dir_all(out).map_err(|e| io_err(out, "create folder", e))?;
    let mut rows = Vec::new();
    let mut dirs = Vec::new();
    for &p in &opts.periods_us {
        let dir = out.join(period_folder(p));
        let row = run_period(opts, p, &dir, hooks)?;
        on_period(&row);
        rows.push(row);
        dirs.push(dir);
    }
    let figure = "figure.png".to_string();
    compose_figure(&dirs, &out.join(&figure))?;
    let report = SweepReport {
        options: opts.clone(),
        sensor: opts.size.sensor(),
        exposure_us: EXPOSURE_US,
        line_time_us: LINE_TIME_US,
        frame_time_us: LINE_TIME_US,
        nyquist_hz: super::theory::nyquist_hz(LINE_TIME_US),
        exposure_first_zero_hz: super::theory::exposure_first_zero_hz(EXPOSURE_US),
        rows,
        figure: figure.clone(),
        command: command.to_string(),
        bench: None,
    };
    write_report(out, &report)?;
    Ok(report)
}

/// `report.md` and `report.json` into `out`.
/// Write `report.md` and `report.json` into `out`.
pub fn write_report(out: &Path, report: &SweepReport) -> Result<(), AnalysisError> {
    let md = report_markdown(report, &report.figure);
    let json = serde_json::to_string_pretty(report).expect("report serialises");
    for (name, text) in [("report.md", md), ("report.json", json)] {
        let path = out.join(name);
        io::write_text_atomic(&path, &text)?;
    }
    Ok(())
}

/// Hooks that do nothing (no progress, never stop).
pub fn quiet_hooks(stop: &AtomicBool) -> Hooks<'_> {
    fn nothing(_: usize, _: &crate::solve::trace::TraceRow) {}
    Hooks { on_row: &nothing, stop }
}
