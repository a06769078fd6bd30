//! `rollcam simulate`: a rolling-shutter capture of a known scene through a diffuser,
//! integrated in continuous time with sensor noise. Writes raw.tiff, psf.tiff,
//! truth.npy (+ truth.tiff), capture.toml.

use anyhow::{bail, Context, Result};
use clap::{Args, FromArgMatches, ValueEnum};
use ndarray::{Array2, Array3, Axis};
use rollcam::model::capture::CaptureConfig;
use rollcam::io;
use rollcam::model::prepare::{box_downsample, estimate_dark};
use rollcam::model::shutter::ShutterMode;
use rollcam::sim::{self, LedArray, LensletParams, MovingDisc, NoiseModel, Scene, Simulation};
use std::path::{Path, PathBuf};

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum SceneKind {
    /// A line of LEDs flashing square waves.
    LedArray,
    /// A bright disc crossing the field.
    MovingDisc,
    /// Frames of an image stack shown one after another.
    Stack,
}

#[derive(Args, Debug, Clone)]
pub struct SimulateArgs {
    #[arg(long, value_enum, default_value = "led-array")]
    pub scene: SceneKind,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Raw sensor rows (ignored with --psf, whose size rules).
    #[arg(long, default_value_t = 128)]
    pub rows: usize,
    /// Raw sensor columns (ignored with --psf).
    #[arg(long, default_value_t = 160)]
    pub cols: usize,
    /// Raw line time, microseconds.
    #[arg(long, default_value_t = 220.0)]
    pub line_time_us: f64,
    /// Exposure of each row, microseconds.
    #[arg(long, default_value_t = 660.0)]
    pub exposure_us: f64,
    #[arg(long, default_value = "dual")]
    pub shutter: ShutterMode,
    /// Downsampling the reconstruction will apply (recorded in capture.toml; the truth
    /// is written on that grid).
    #[arg(long, default_value_t = 1)]
    pub downsample: usize,
    /// Temporal binning the reconstruction will apply.
    #[arg(long, default_value_t = 1)]
    pub binning: usize,
    /// A measured PSF image instead of the synthetic diffuser (dark-subtracted,
    /// averaged over colours, box-downsampled by --psf-downsample; its size becomes the
    /// sensor's).
    #[arg(long)]
    pub psf: Option<PathBuf>,
    #[arg(long, default_value_t = 1)]
    pub psf_downsample: usize,
    /// Lenslets of the synthetic diffuser.
    #[arg(long, default_value_t = 48)]
    pub lenslets: usize,
    /// Diameter of the diffuser's round aperture as a fraction of the smaller sensor
    /// side (the PSF's caustics lie inside it; 1 lets them fill the sensor's height, as
    /// in the paper's camera).
    #[arg(long, default_value_t = 1.0)]
    pub aperture_fraction: f64,
    /// Number of LEDs (led-array).
    #[arg(long, default_value_t = 4)]
    pub leds: usize,
    /// LED periods, microseconds: one for all or one per LED (comma-separated).
    #[arg(long, value_delimiter = ',', default_values_t = vec![2640.0, 1980.0, 1320.0, 1760.0])]
    pub period_us: Vec<f64>,
    /// LED duty cycle.
    #[arg(long, default_value_t = 0.5)]
    pub duty: f64,
    /// LED spacing, raw pixels.
    #[arg(long, default_value_t = 12.0)]
    pub spacing_px: f64,
    /// LED spot radius, raw pixels.
    #[arg(long, default_value_t = 1.5)]
    pub led_radius_px: f64,
    /// Brightness of an LED (or the disc) while on, photo-electrons per microsecond.
    #[arg(long, default_value_t = 2000.0)]
    pub e_per_us: f64,
    /// Disc radius, raw pixels (moving-disc).
    #[arg(long, default_value_t = 6.0)]
    pub disc_radius_px: f64,
    /// Disc speed across the field, raw pixels per millisecond (moving-disc).
    #[arg(long, default_value_t = 4.0)]
    pub disc_px_per_ms: f64,
    /// Image stack for --scene stack (multi-page TIFF, .npy, or a folder of images).
    #[arg(long)]
    pub stack: Option<PathBuf>,
    /// How long each stack frame is shown, microseconds.
    #[arg(long, default_value_t = 1000.0)]
    pub stack_interval_us: f64,
    /// Sensor read noise, photo-electrons.
    #[arg(long, default_value_t = 2.0)]
    pub read_noise_e: f64,
    /// Black offset, ADU.
    #[arg(long, default_value_t = 100.0)]
    pub dark_level_adu: f64,
    /// No shot or read noise (quantisation and saturation remain).
    #[arg(long)]
    pub no_noise: bool,
    /// Time sub-steps per line time.
    #[arg(long, default_value_t = 4)]
    pub substeps: usize,
    /// Seed of the diffuser and the noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Consecutive captures of the same scene, its time running on across them (more
    /// than 1: the folder is a capture folder as `capture` records it, frame_NNNNNN.tiff
    /// and .json with device timestamps, plus psf.tiff, capture.toml and the truth on
    /// the global video grid).
    #[arg(long, default_value_t = 1)]
    pub captures: usize,
    /// Start-to-start time of consecutive captures, microseconds (default: continuous
    /// readout, the span of the row starts plus one line time).
    #[arg(long)]
    pub frame_period_us: Option<f64>,
}

/// The PSF at raw resolution (unit sum) and the sensor size.
fn raw_psf(a: &SimulateArgs) -> Result<(Array2<f32>, usize, usize)> {
    match &a.psf {
        None => {
            let p = LensletParams { lenslets: a.lenslets, aperture_fraction: a.aperture_fraction, ..LensletParams::default() };
            let psf = sim::lenslet_psf(a.rows, a.cols, &p, a.seed)?;
            Ok((psf, a.rows, a.cols))
        }
        Some(path) => {
            let img = io::read_image(path)?;
            let (r, c, ch) = img.dim();
            let mean: Vec<f32> = img.mean_axis(Axis(2)).unwrap().iter().cloned().collect();
            let dark = estimate_dark(&mean);
            let sub: Vec<f32> = mean.iter().map(|v| ((*v as f64 - dark) as f32).max(0.0)).collect();
            let d = a.psf_downsample.max(1);
            let (data, m, n) = box_downsample(&sub, r, c, d);
            let s: f64 = data.iter().map(|&v| v as f64).sum();
            if !(s > 0.0) {
                bail!("{}: no light above the dark level {dark:.1}: expected a point-source image", path.display());
            }
            tracing::info!(file = %path.display(), rows = m, cols = n, channels = ch, dark, "measured PSF");
            let data: Vec<f32> = data.iter().map(|v| (*v as f64 / s) as f32).collect();
            Ok((Array2::from_shape_vec((m, n), data).unwrap(), m, n))
        }
    }
}

/// The LED line the arguments describe.
pub fn led_scene(a: &SimulateArgs, rows: usize, cols: usize) -> Result<LedArray> {
    Ok(LedArray::new(rows, cols, a.leds, a.spacing_px, a.led_radius_px, a.period_us.clone(), a.duty, vec![0.0], a.e_per_us)?)
}

fn scene(a: &SimulateArgs, rows: usize, cols: usize) -> Result<Box<dyn Scene>> {
    Ok(match a.scene {
        SceneKind::LedArray => Box::new(led_scene(a, rows, cols)?),
        SceneKind::MovingDisc => {
            let v = a.disc_px_per_ms / 1000.0;
            Box::new(MovingDisc::new(rows, cols, a.disc_radius_px, (rows as f64 * 0.4, cols as f64 * 0.2), (v * 0.3, v), a.e_per_us / 10.0))
        }
        SceneKind::Stack => {
            let path = a.stack.as_ref().context("--scene stack needs --stack FILE")?;
            let v = io::read_stack(path)?;
            let (k, r, c, _) = v.dim();
            if (r, c) != (rows, cols) {
                bail!("{}: frames are {r} x {c}, expected the sensor size {rows} x {cols}", path.display());
            }
            let grey: Array3<f32> = v.mean_axis(Axis(3)).unwrap();
            tracing::info!(frames = k, "image stack scene");
            Box::new(sim::ImageStack::new(grey, a.stack_interval_us, false)?)
        }
    })
}

type SimSetup = (CaptureConfig, Array2<f32>, Box<dyn sim::Scene>, NoiseModel);

/// What a simulation needs from the flags: the validated capture timing, the raw PSF,
/// the scene and the noise model.
fn setup(a: &SimulateArgs) -> Result<SimSetup> {
    let (psf, rows, cols) = raw_psf(a)?;
    let mut cfg = CaptureConfig::new(rows, cols, a.line_time_us, a.exposure_us, a.shutter);
    cfg.downsample = a.downsample;
    cfg.binning = a.binning;
    cfg.validate().context("invalid capture timing")?;
    let scene = scene(a, rows, cols)?;
    let noise = NoiseModel {
        dark_level_adu: a.dark_level_adu,
        read_noise_e: a.read_noise_e,
        poisson: !a.no_noise,
        gaussian: !a.no_noise,
        ..NoiseModel::default()
    };
    Ok((cfg, psf, scene, noise))
}

/// Simulate and write the folder; returns the capture description and the simulation.
pub fn simulate_to(a: &SimulateArgs, out: &Path) -> Result<(CaptureConfig, Simulation)> {
    let (cfg, psf, scene, noise) = setup(a)?;
    let psf_flat: Vec<f32> = psf.iter().cloned().collect();
    let simulation = sim::simulate(&cfg, &psf_flat, scene.as_ref(), &noise, a.substeps, a.seed)?;
    if simulation.saturated_pixels > 0 {
        tracing::warn!(pixels = simulation.saturated_pixels, "saturated pixels in the simulated raw image");
    }
    let cfg = simulation.capture_config(&cfg);
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create the folder", out.display()))?;
    io::write_tiff_u16(out.join("raw.tiff"), simulation.raw.view().insert_axis(Axis(2)))?;
    // The PSF as a camera would record it: scaled to most of the 16-bit range, on
    // the same dark offset as the raw image.
    let peak = psf.iter().cloned().fold(0.0f32, f32::max);
    let scale = 50_000.0 / peak;
    let psf_adu = psf.mapv(|v| v * scale + a.dark_level_adu as f32);
    io::write_tiff_u16(out.join("psf.tiff"), psf_adu.view().insert_axis(Axis(2)))?;
    let truth = simulation.truth.view().insert_axis(Axis(3));
    io::write_npy(out.join("truth.npy"), truth)?;
    io::write_tiff_stack_f32(out.join("truth.tiff"), truth)?;
    let text = cfg.to_toml();
    io::write_text_atomic(&out.join("capture.toml"), &text)?;
    Ok((cfg, simulation))
}

pub fn run(a: SimulateArgs) -> Result<()> {
    let t0 = std::time::Instant::now();
    if a.captures > 1 || a.frame_period_us.is_some() {
        return simulate_sequence_to(&a, &a.out);
    }
    let (cfg, s) = simulate_to(&a, &a.out)?;
    let (k, m, n) = s.truth.dim();
    println!(
        "simulated {} x {} raw ({} shutter, line {} us, exposure {} us): truth {k} frames of {m} x {n} at {:.1} us, {} saturated pixels, {:.2} s",
        cfg.rows,
        cfg.cols,
        cfg.shutter,
        cfg.line_time_us,
        cfg.exposure_us,
        s.frame_time_us,
        s.saturated_pixels,
        t0.elapsed().as_secs_f64()
    );
    println!("wrote raw.tiff, psf.tiff, truth.npy, truth.tiff, capture.toml to {}", a.out.display());
    Ok(())
}

impl SimulateArgs {
    /// The defaults of every flag, writing to `out`.
    pub fn defaults(out: &Path) -> SimulateArgs {
        let cmd = SimulateArgs::augment_args(clap::Command::new("simulate"));
        let m = cmd.get_matches_from([std::ffi::OsStr::new("simulate"), "--out".as_ref(), out.as_os_str()]);
        SimulateArgs::from_arg_matches(&m).expect("defaults parse")
    }
}

/// `--captures C`: consecutive captures written as a capture folder (the recorder's
/// format: capture.json, frame_NNNNNN.tiff + .json with device timestamps `c P`), with
/// psf.tiff, capture.toml and truth.npy/truth.tiff on the global video grid.
pub fn simulate_sequence_to(a: &SimulateArgs, out: &Path) -> Result<()> {
    use rollcam_hw::camera::{self as hwcam, AppliedSettings, Binning, CameraInfo, Frame, FrameMeta, FrameStatus, PixelFormat, Roi, Trigger};
    use rollcam_hw::record::{CaptureSession, Recorder};
    let t0 = std::time::Instant::now();
    let (cfg, psf, scene, noise) = setup(a)?;
    let (rows, cols) = psf.dim();
    let psf_flat: Vec<f32> = psf.iter().cloned().collect();
    let period_us = a.frame_period_us.unwrap_or_else(|| sim::readout_period_us(&cfg));
    let s = sim::simulate_sequence(&cfg, &psf_flat, scene.as_ref(), &noise, a.substeps, a.seed, a.captures, period_us)?;
    if s.saturated_pixels > 0 {
        tracing::warn!(pixels = s.saturated_pixels, "saturated pixels in the simulated raw images");
    }
    let camera = CameraInfo {
        backend: "sim".into(),
        id: "simulate".into(),
        vendor: None,
        model: Some("rollcam simulator".into()),
        serial: None,
        address: None,
        protocol: None,
    };
    let settings = AppliedSettings {
        exposure_us: a.exposure_us,
        line_time_us: Some(a.line_time_us),
        frame_rate_hz: Some(1e6 / period_us),
        shutter: match a.shutter {
            ShutterMode::Global => Some(hwcam::ShutterMode::Global),
            ShutterMode::Rolling => Some(hwcam::ShutterMode::Rolling),
            ShutterMode::Dual => Some(hwcam::ShutterMode::Dual),
            _ => None,
        },
        roi: Roi { x: 0, y: 0, width: cols as u32, height: rows as u32 },
        binning: Binning::default(),
        pixel_format: PixelFormat::Mono16,
        trigger: Trigger::FreeRun,
        exposure_output_line: None,
    };
    let mut session = CaptureSession::new(camera.clone());
    session.applied = Some(settings.clone());
    session.frames_requested = Some(a.captures as u64);
    let mut rec = Recorder::create(out, session)?;
    for (c, raw) in s.raws.iter().enumerate() {
        let pixels: Vec<u16> = raw.iter().map(|&v| v.clamp(0.0, 65535.0) as u16).collect();
        let meta = FrameMeta {
            camera: camera.spec(),
            frame_id: c as u64,
            sequence: c as u64,
            device_timestamp_ns: (s.start_us[c] * 1e3).round() as u64,
            host_timestamp_ns: hwcam::host_now_ns(),
            status: FrameStatus::Complete,
            width: cols as u32,
            height: rows as u32,
            bit_depth: 16,
            valid_pixels: pixels.len() as u64,
            settings: settings.clone(),
        };
        rec.write_frame(&Frame { meta, pixels })?;
    }
    rec.finish(None)?;
    let peak = psf.iter().cloned().fold(0.0f32, f32::max);
    let psf_adu = psf.mapv(|v| v * (50_000.0 / peak) + a.dark_level_adu as f32);
    io::write_tiff_u16(out.join("psf.tiff"), psf_adu.view().insert_axis(Axis(2)))?;
    let truth = s.truth.view().insert_axis(Axis(3));
    io::write_npy(out.join("truth.npy"), truth)?;
    io::write_tiff_stack_f32(out.join("truth.tiff"), truth)?;
    let text = s.config.to_toml();
    io::write_text_atomic(&out.join("capture.toml"), &text)?;
    let (k, m, n) = s.truth.dim();
    println!(
        "simulated {} consecutive {} x {} captures {period_us} us apart ({} frames of {:.1} us each): truth {k} frames of {m} x {n}, {:.2} s",
        a.captures,
        rows,
        cols,
        s.capture_frames,
        s.frame_time_us,
        t0.elapsed().as_secs_f64()
    );
    println!(
        "wrote frame_*.tiff/.json, capture.json, psf.tiff, capture.toml, truth.npy, truth.tiff to {}: reconstruct with rollcam reconstruct-sequence {} --truth {}/truth.npy --out rec/",
        out.display(),
        out.display(),
        out.display()
    );
    Ok(())
}
