//! `rollcam simulate`: a rolling-shutter capture of a known scene through a diffuser,
//! integrated in continuous time with sensor noise. Writes raw.tiff, psf.tiff,
//! truth.npy (+ truth.tiff), capture.toml. The flags are [`SimParams`] (whose defaults
//! are theirs) plus the files to read; the set-up is `rollcam::sim::setup`'s, the
//! folders `rollcam::lab::sim_output`'s. A bench (`--sensor-defects`,
//! `--background-scene`, `--calibration-shots`) is `rollcam::sim::sensor`'s: a sensor
//! with fixed-pattern dark, hot and stuck pixels and an ADC depth, a static background
//! behind the scene, and calibration shots taken with them.

use anyhow::{bail, Context, Result};
use clap::builder::TypedValueParser;
use clap::{Args, ValueEnum};
use ndarray::Array3;
use rollcam::io;
use rollcam::lab::sim_output;
use rollcam::model::capture::CaptureConfig;
use rollcam::model::shutter::ShutterMode;
use rollcam::sim::setup::{measured_psf, SceneKind};
use rollcam::sim::{BackgroundTexture, KeyFrameParams, KeyFramePlan, KeyTime, SensorDefects, SimError, SimParams, SimSetup, SimulatedSensor};
use std::path::{Path, PathBuf};

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum SceneArg {
    /// A line of LEDs flashing square waves.
    LedArray,
    /// A bright disc crossing the field.
    MovingDisc,
    /// A bright disc crossing a static textured scene; both in the truth (the dense benchmark scene).
    DiscOverTexture,
    /// A dark disc (5% of the texture's mean) crossing a bright static textured scene; both in the truth.
    Occluder,
    /// Frames of an image stack shown one after another.
    Stack,
}

#[derive(Args, Debug, Clone)]
pub struct SimulateArgs {
    #[arg(long, value_enum, default_value = "led-array")]
    pub scene: SceneArg,
    /// Output folder: new or empty (or see --force).
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub force: crate::cli::common::ForceFlag,
    /// Raw sensor rows (ignored with --psf, whose size rules).
    #[arg(long, default_value_t = SimParams::default().rows)]
    pub rows: usize,
    /// Raw sensor columns (ignored with --psf).
    #[arg(long, default_value_t = SimParams::default().cols)]
    pub cols: usize,
    /// Raw line time, microseconds.
    #[arg(long, default_value_t = SimParams::default().line_time_us)]
    pub line_time_us: f64,
    /// Exposure of each row, microseconds.
    #[arg(long, default_value_t = SimParams::default().exposure_us)]
    pub exposure_us: f64,
    /// Shutter mode: global (a still: one frame), rolling, dual (outside-in) or
    /// dual-center-out.
    #[arg(
        long,
        default_value_t = SimParams::default().shutter,
        value_parser = clap::builder::PossibleValuesParser::new(ShutterMode::ALL.map(ShutterMode::name)).map(|s| s.parse::<ShutterMode>().expect("a listed name"))
    )]
    pub shutter: ShutterMode,
    /// Downsampling the reconstruction will apply (recorded in capture.toml; the truth
    /// is written on that grid).
    #[arg(long, default_value_t = SimParams::default().downsample)]
    pub downsample: usize,
    /// Temporal binning the reconstruction will apply.
    #[arg(long, default_value_t = SimParams::default().binning)]
    pub binning: usize,
    /// A measured PSF image instead of the synthetic diffuser (dark-subtracted,
    /// averaged over colours, box-downsampled by --psf-downsample; its size becomes the
    /// sensor's).
    #[arg(long)]
    pub psf: Option<PathBuf>,
    #[arg(long, default_value_t = 1)]
    pub psf_downsample: usize,
    /// Lenslets of the synthetic diffuser.
    #[arg(long, default_value_t = SimParams::default().lenslets)]
    pub lenslets: usize,
    /// Diameter of the diffuser's round aperture as a fraction of the smaller sensor
    /// side (the PSF's caustics lie inside it; 1 lets them fill the sensor's height, as
    /// in the paper's camera).
    #[arg(long, default_value_t = SimParams::default().aperture_fraction)]
    pub aperture_fraction: f64,
    /// Number of LEDs (led-array).
    #[arg(long, default_value_t = SimParams::default().leds)]
    pub leds: usize,
    /// LED periods, microseconds: one for all or one per LED (comma-separated).
    #[arg(long, value_delimiter = ',', default_values_t = SimParams::default().period_us)]
    pub period_us: Vec<f64>,
    /// LED duty cycle.
    #[arg(long, default_value_t = SimParams::default().duty)]
    pub duty: f64,
    /// LED spacing, raw pixels.
    #[arg(long, default_value_t = SimParams::default().spacing_px)]
    pub spacing_px: f64,
    /// LED spot radius, raw pixels.
    #[arg(long, default_value_t = SimParams::default().led_radius_px)]
    pub led_radius_px: f64,
    /// Brightness of an LED while on, photo-electrons per microsecond (the disc of
    /// moving-disc: a tenth of it per pixel; disc-over-texture: a fortieth for the disc,
    /// the texture's mean that over --disc-contrast).
    #[arg(long, default_value_t = SimParams::default().e_per_us)]
    pub e_per_us: f64,
    /// Disc radius, raw pixels (moving-disc, disc-over-texture).
    #[arg(long, default_value_t = SimParams::default().disc_radius_px)]
    pub disc_radius_px: f64,
    /// Disc speed across the field, raw pixels per millisecond (moving-disc,
    /// disc-over-texture).
    #[arg(long, default_value_t = SimParams::default().disc_px_per_ms)]
    pub disc_px_per_ms: f64,
    /// disc-over-texture: the disc's radiance over the texture's mean radiance.
    #[arg(long, default_value_t = SimParams::default().disc_contrast)]
    pub disc_contrast: f64,
    /// Image stack for --scene stack (multi-page TIFF, .npy, or a folder of images).
    /// Its values are radiance in photo-electrons per microsecond per pixel (averaged
    /// over channels), as they are unless --stack-e-per-us scales them.
    #[arg(long)]
    pub stack: Option<PathBuf>,
    /// --scene stack: the brightness of the stack's largest value, photo-electrons per
    /// microsecond per pixel; the stack is scaled so that its brightest pixel collects
    /// this much (a 0-1 image at 1e2 gives up to 100 e-/us per pixel).
    #[arg(long)]
    pub stack_e_per_us: Option<f64>,
    /// How long each stack frame is shown, microseconds.
    #[arg(long, default_value_t = SimParams::default().stack_interval_us)]
    pub stack_interval_us: f64,
    /// Sensor read noise, photo-electrons.
    #[arg(long, default_value_t = SimParams::default().read_noise_e)]
    pub read_noise_e: f64,
    /// Black offset, ADU.
    #[arg(long, default_value_t = SimParams::default().dark_level_adu)]
    pub dark_level_adu: f64,
    /// No shot or read noise (quantisation and saturation remain).
    #[arg(long)]
    pub no_noise: bool,
    /// Time sub-steps per line time.
    #[arg(long, default_value_t = SimParams::default().substeps)]
    pub substeps: usize,
    /// Seed of the diffuser and the noise.
    #[arg(long, default_value_t = SimParams::default().seed)]
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
    /// A bench sensor instead of an ideal one: a 12-bit ADC, a fixed-pattern dark of 3
    /// ADU rms, 0.05% hot and 0.01% stuck pixels, drawn from --seed. Their truth goes
    /// to sensor_truth.json and sensor_fpn.tiff; capture.toml declares none of it.
    #[arg(long)]
    pub sensor_defects: bool,
    /// ADC depth of the bench sensor: raws clip at 2^bits - 1 counts (1 to 16).
    #[arg(long, requires = "sensor_defects")]
    pub bit_depth: Option<u32>,
    /// Fixed-pattern dark of the bench sensor: per-pixel offset rms, ADU.
    #[arg(long, requires = "sensor_defects")]
    pub dark_fpn_rms_adu: Option<f64>,
    /// Fraction of hot pixels (reading at or near full scale).
    #[arg(long, requires = "sensor_defects")]
    pub hot_fraction: Option<f64>,
    /// Fraction of stuck pixels (a constant whatever the light).
    #[arg(long, requires = "sensor_defects")]
    pub stuck_fraction: Option<f64>,
    /// A static textured background behind the moving scene (smooth blobs and striped
    /// rectangles, from --seed): in raw.tiff, not in the truth.
    #[arg(long)]
    pub background_scene: bool,
    /// Mean radiance of the background, photo-electrons per microsecond per raw pixel.
    #[arg(long, requires = "background_scene", default_value_t = BackgroundTexture::DEFAULT_E_PER_US)]
    pub background_level: f64,
    /// Calibration shots taken with the same sensor and exposure: N dark frames, N
    /// point-source shots of the PSF and, with --background-scene, N background frames,
    /// under calibration-shots/ in the output folder.
    #[arg(long, default_value_t = 0)]
    pub calibration_shots: usize,
    /// Key frames from a second, lensed, global-shutter camera: their start times,
    /// comma-separated, in microseconds on the capture's time axis (0: the earliest raw
    /// row starts, when video frame 0 begins), or first / last (the first / last video
    /// frame's start). Written as keyframe_NNN.tiff with [[keyframes]] in capture.toml.
    #[arg(long, value_delimiter = ',')]
    pub keyframes: Vec<String>,
    /// Exposure of every key frame, microseconds (default: one video frame time).
    #[arg(long, requires = "keyframes")]
    pub keyframe_exposure_us: Option<f64>,
    /// Key-frame counts per video unit (default: the brightest key pixel at 40% of the
    /// 16-bit full scale above the dark level, rounded to 3 digits). Recorded in
    /// [simulation.keyframes], not in [[keyframes]] unless --keyframe-write-gain.
    #[arg(long, requires = "keyframes")]
    pub keyframe_gain: Option<f64>,
    /// Black offset of the key camera, counts.
    #[arg(long, requires = "keyframes", default_value_t = KeyFrameParams::default().dark_level_adu)]
    pub keyframe_dark_level_adu: f64,
    /// Read noise of the key camera, counts rms; with it, shot noise at the raw sensor's
    /// conversion gain. 0 (or --no-noise): noise-free key frames (quantisation remains).
    #[arg(long, requires = "keyframes", default_value_t = KeyFrameParams::default().read_noise_adu)]
    pub keyframe_noise: f64,
    /// Gaussian sigma of the key camera's lens blur, key-frame pixels (0: none; above 0
    /// writes keyframe_psf.tiff, named by each table's psf).
    #[arg(long, requires = "keyframes", default_value_t = 0.0)]
    pub keyframe_blur_px: f64,
    /// Shift of the key camera, ROW,COL key-frame pixels: the video pixel (r, c) lands
    /// on (r + ROW, c + COL) (after --keyframe-scale); written as each table's affine.
    #[arg(long, requires = "keyframes", value_delimiter = ',', allow_hyphen_values = true, value_name = "ROW,COL")]
    pub keyframe_offset_px: Vec<f64>,
    /// Key frames of another size: F times the video grid's rows and columns (over the
    /// same field).
    #[arg(long, requires = "keyframes", default_value_t = 1.0)]
    pub keyframe_scale: f64,
    /// Also write the true gain into each [[keyframes]] table.
    #[arg(long, requires = "keyframes")]
    pub keyframe_write_gain: bool,
}

impl SceneArg {
    fn kind(self) -> SceneKind {
        match self {
            SceneArg::LedArray => SceneKind::LedArray,
            SceneArg::MovingDisc => SceneKind::MovingDisc,
            SceneArg::DiscOverTexture => SceneKind::DiscOverTexture,
            SceneArg::Occluder => SceneKind::Occluder,
            SceneArg::Stack => SceneKind::Stack,
        }
    }
}

impl SimulateArgs {
    /// The simulation parameters the flags give.
    fn params(&self) -> SimParams {
        SimParams {
            rows: self.rows,
            cols: self.cols,
            line_time_us: self.line_time_us,
            exposure_us: self.exposure_us,
            shutter: self.shutter,
            downsample: self.downsample,
            binning: self.binning,
            lenslets: self.lenslets,
            aperture_fraction: self.aperture_fraction,
            leds: self.leds,
            period_us: self.period_us.clone(),
            duty: self.duty,
            spacing_px: self.spacing_px,
            led_radius_px: self.led_radius_px,
            e_per_us: self.e_per_us,
            disc_radius_px: self.disc_radius_px,
            disc_px_per_ms: self.disc_px_per_ms,
            disc_contrast: self.disc_contrast,
            stack_interval_us: self.stack_interval_us,
            read_noise_e: self.read_noise_e,
            dark_level_adu: self.dark_level_adu,
            noise: !self.no_noise,
            substeps: self.substeps,
            seed: self.seed,
        }
    }
}

impl SimulateArgs {
    /// The bench sensor the flags ask for (`--sensor-defects` and its overrides).
    fn sensor_defects(&self) -> Option<SensorDefects> {
        self.sensor_defects.then(|| {
            let d = SensorDefects { seed: self.seed, ..SensorDefects::default() };
            SensorDefects {
                bit_depth: self.bit_depth.unwrap_or(d.bit_depth),
                dark_fpn_rms_adu: self.dark_fpn_rms_adu.unwrap_or(d.dark_fpn_rms_adu),
                hot_fraction: self.hot_fraction.unwrap_or(d.hot_fraction),
                stuck_fraction: self.stuck_fraction.unwrap_or(d.stuck_fraction),
                ..d
            }
        })
    }

    /// The static background the flags ask for.
    fn background(&self) -> Option<BackgroundTexture> {
        self.background_scene.then_some(BackgroundTexture { e_per_us: self.background_level, seed: self.seed })
    }

    /// The key frames the flags ask for (`None`: no --keyframes).
    fn keyframe_params(&self) -> Result<Option<KeyFrameParams>> {
        if self.keyframes.is_empty() {
            return Ok(None);
        }
        let times = self.keyframes.iter().map(|t| KeyTime::parse(t)).collect::<Result<Vec<_>, _>>().map_err(named)?;
        let offset_px = match self.keyframe_offset_px[..] {
            [] => (0.0, 0.0),
            [r, c] => (r, c),
            _ => bail!("--keyframe-offset-px = {:?}: expected ROW,COL (two numbers of key-frame pixels)", self.keyframe_offset_px),
        };
        Ok(Some(KeyFrameParams {
            times,
            exposure_us: self.keyframe_exposure_us,
            gain: self.keyframe_gain,
            dark_level_adu: self.keyframe_dark_level_adu,
            read_noise_adu: self.keyframe_noise,
            noise: !self.no_noise,
            blur_px: self.keyframe_blur_px,
            offset_px,
            scale: self.keyframe_scale,
            write_gain: self.keyframe_write_gain,
        }))
    }

    /// Whether the capture is taken on a bench rather than an ideal sensor.
    fn bench(&self) -> bool {
        self.sensor_defects || self.background_scene || self.calibration_shots > 0
    }
}

/// The flag that sets a simulator field (`substeps_per_line` is `--substeps`), `None` for
/// a field no flag sets. Checked against the flags themselves, so a renamed flag cannot
/// be named wrongly.
fn flag_of(field: &str) -> Option<String> {
    let long = match field {
        "substeps_per_line" => "substeps",
        "radius_px" => "led-radius-px",
        "background e_per_us" => "background-level",
        "frame_interval_us" => "stack-interval-us",
        "bits" => "bit-depth",
        f => f,
    }
    .replace('_', "-");
    let cmd = <SimulateArgs as clap::Args>::augment_args(clap::Command::new("simulate"));
    let known = cmd.get_arguments().any(|a| a.get_long() == Some(long.as_str()));
    known.then(|| format!("--{long}"))
}

/// A simulator error in the command line's words: a field some flag sets is named by
/// that flag (`--substeps = 0: expected ...`).
fn named(e: SimError) -> anyhow::Error {
    if let SimError::Invalid { field, value, expected } = &e {
        let flags: Option<Vec<String>> = field.split(" + ").map(flag_of).collect();
        if let Some(flags) = flags {
            return anyhow::anyhow!("{} = {value}: expected {expected}", flags.join(" + "));
        }
    }
    e.into()
}

/// The flags' sensor and background; a bad value names its flag.
fn bench(a: &SimulateArgs, setup: &SimSetup) -> Result<SimulatedSensor> {
    let defects = a.sensor_defects();
    let background = a.background();
    if let Some(d) = &defects {
        d.validate().map_err(named)?;
    }
    if let Some(b) = &background {
        b.validate().map_err(named)?;
    }
    SimulatedSensor::new(setup, defects.as_ref(), background.as_ref()).map_err(named)
}

/// What a simulation needs from the flags and files: the validated capture timing,
/// the raw PSF (synthetic, or measured from --psf, whose size becomes the sensor's),
/// the scene and the noise model.
/// The most consecutive captures one `simulate` writes.
const MAX_CAPTURES: usize = 10_000;

fn setup(a: &SimulateArgs) -> Result<SimSetup> {
    let p = a.params();
    p.check_sensor().map_err(named)?;
    if a.captures == 0 || a.captures > MAX_CAPTURES {
        bail!("--captures = {}: expected 1 to {MAX_CAPTURES} captures", a.captures);
    }
    // The truth video of every capture (and its TIFF copy) is held at once; the
    // synthetic PSF's grid is checked before it is drawn, a measured one's once read.
    let checked_config = |rows: usize, cols: usize| -> Result<rollcam::model::capture::CaptureConfig> {
        let cfg = p.capture_config(rows, cols).context("invalid capture timing")?;
        rollcam::io::budget::check_simulation(&cfg, a.captures, 2)?;
        Ok(cfg)
    };
    let psf = match &a.psf {
        None => {
            checked_config(p.rows, p.cols)?;
            p.synthetic_psf().map_err(named)?
        }
        Some(path) => measured_psf(io::read_image(path)?.view(), a.psf_downsample, &path.display().to_string()).map_err(named)?,
    };
    let (rows, cols) = psf.dim();
    let cfg = checked_config(rows, cols)?;
    let kind = a.scene.kind();
    let stack = match (kind, &a.stack) {
        (SceneKind::Stack, None) => bail!("--scene stack needs --stack FILE"),
        (SceneKind::Stack, Some(path)) => {
            let mut v = io::read_stack(path)?;
            io::truth::check_finite(path, &v)?;
            if let Some(e_per_us) = a.stack_e_per_us {
                if !(e_per_us.is_finite() && e_per_us > 0.0) {
                    bail!("--stack-e-per-us = {e_per_us}: expected a positive brightness in photo-electrons per microsecond");
                }
                let brightest = v.mean_axis(ndarray::Axis(3)).expect("a stack has a channel").fold(0.0f32, |m, &x| m.max(x)) as f64;
                if !(brightest > 0.0) {
                    bail!("{}: no value above 0 to scale to --stack-e-per-us {e_per_us}", path.display());
                }
                v.mapv_inplace(|x| (x as f64 * e_per_us / brightest) as f32);
            }
            Some((v, path))
        }
        (_, None) if a.stack_e_per_us.is_some() => bail!("--stack-e-per-us scales the image stack of --scene stack: expected --scene stack --stack FILE"),
        _ => None,
    };
    let scene = p.scene(kind, rows, cols, stack.as_ref().map(|(v, _)| v.view())).map_err(|e| match (&e, &stack) {
        (SimError::SceneSize { .. }, Some((_, path))) => anyhow::anyhow!("{}: {e}", path.display()),
        _ => named(e),
    })?;
    Ok(SimSetup::new(&p, cfg, psf, scene))
}

pub fn run(a: SimulateArgs) -> Result<()> {
    let t0 = std::time::Instant::now();
    let setup = setup(&a)?;
    if a.bench() && (a.captures > 1 || a.frame_period_us.is_some()) {
        bail!("--sensor-defects, --background-scene and --calibration-shots simulate one capture: expected --captures 1 and no --frame-period-us");
    }
    let keys = keyframe_plan(&a, &setup)?;
    let mut writes: Vec<String> = sim_output::SIMULATION_FILES.iter().map(|s| s.to_string()).collect();
    if let Some(k) = &keys {
        writes.extend(sim_output::keyframe_files(k.starts_us.len(), k.psf.is_some()));
    }
    crate::cli::common::claim_out(
        &a.out,
        &a.force,
        &writes.iter().map(String::as_str).collect::<Vec<_>>(),
        &[("the PSF (--psf)", a.psf.as_deref()), ("the scene stack (--stack)", a.stack.as_deref())],
    )?;
    if a.bench() {
        return run_bench(&a, &setup, keys.as_ref(), t0);
    }
    if a.captures > 1 || a.frame_period_us.is_some() {
        let grid = setup.sequence_grid(a.captures, a.frame_period_us).map_err(named)?;
        rollcam::io::budget::check_sequence_truth(&setup.cfg, grid.frames)?;
        let (period_us, s) = setup.simulate_sequence(a.captures, a.frame_period_us).map_err(named)?;
        sim_output::write_sequence(&a.out, &setup, period_us, &s)?;
        let (k, m, n) = s.truth.dim();
        let (rows, cols) = setup.psf.dim();
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
            a.out.display(),
            a.out.display(),
            a.out.display()
        );
        return Ok(());
    }
    let (cfg, s) = setup.simulate().map_err(named)?;
    let cfg = with_keyframes(&a.out, keys.as_ref(), &setup, cfg, &s.truth)?;
    sim_output::write_capture(&a.out, &setup, &cfg, &s)?;
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

/// The key frames the flags ask for, checked against the capture's video (its frames,
/// grid and frame time) before anything is simulated; a bad value names its flag.
fn keyframe_plan(a: &SimulateArgs, setup: &SimSetup) -> Result<Option<KeyFramePlan>> {
    let Some(params) = a.keyframe_params()? else { return Ok(None) };
    if a.captures > 1 || a.frame_period_us.is_some() {
        bail!("--keyframes: key frames are simulated with one capture: expected --captures 1 and no --frame-period-us");
    }
    let timing = setup.cfg.timing();
    let frames = timing.weights().context("invalid capture timing")?.frames();
    let (rows, cols) = setup.cfg.grid();
    Ok(Some(params.plan((frames, rows, cols), timing.frame_time_us()).map_err(named)?))
}

/// Renders `plan`'s key frames from `truth` and writes them into `out`; `cfg` with
/// their `[[keyframes]]` tables and `[simulation.keyframes]` provenance (the true gain).
fn with_keyframes(out: &Path, plan: Option<&KeyFramePlan>, setup: &SimSetup, mut cfg: CaptureConfig, truth: &Array3<f32>) -> Result<CaptureConfig> {
    let Some(plan) = plan else { return Ok(cfg) };
    let keys = plan.render(truth.view(), setup.noise.gain_adu_per_e, setup.seed).map_err(named)?;
    sim_output::write_keyframes(out, &keys)?;
    let starts: Vec<String> = plan.starts_us.iter().map(|s| format!("{s}")).collect();
    let files = sim_output::keyframe_files(keys.refs.len(), keys.psf.is_some());
    println!(
        "key frames: {} of {} x {} starting at {} us, exposure {} us; gain {} counts per video unit ({}), dark {} counts, {} saturated pixels: {}",
        keys.refs.len(),
        plan.key.0,
        plan.key.1,
        starts.join(", "),
        plan.exposure_us,
        keys.gain,
        if keys.refs.iter().any(|r| r.gain.is_some()) { "in [[keyframes]] and [simulation.keyframes]" } else { "in [simulation.keyframes] only" },
        keys.refs[0].dark_level.unwrap_or(0.0),
        keys.saturated_pixels,
        files.join(", ")
    );
    cfg.keyframes = keys.refs;
    cfg.simulation.get_or_insert_with(toml::Table::new).insert("keyframes".into(), keys.table.into());
    Ok(cfg)
}

/// One capture on a bench (sensor defects, background, calibration shots).
fn run_bench(a: &SimulateArgs, setup: &SimSetup, keys: Option<&KeyFramePlan>, t0: std::time::Instant) -> Result<()> {
    let bench = bench(a, setup)?;
    let (cfg, s) = bench.simulate(setup).map_err(named)?;
    let shots = match a.calibration_shots {
        0 => None,
        n => Some(bench.calibration_shots(setup, n).map_err(named)?),
    };
    let cfg = with_keyframes(&a.out, keys, setup, cfg, &s.truth)?;
    sim_output::write_bench_capture(&a.out, setup, &bench, &cfg, &s, shots.as_ref())?;
    let (k, m, n) = s.truth.dim();
    println!(
        "simulated {} x {} raw ({} shutter, line {} us, exposure {} us, {}-bit): truth {k} frames of {m} x {n} at {:.1} us, {} saturated pixels, {:.2} s",
        cfg.rows,
        cfg.cols,
        cfg.shutter,
        cfg.line_time_us,
        cfg.exposure_us,
        bench.noise.bits,
        s.frame_time_us,
        s.saturated_pixels,
        t0.elapsed().as_secs_f64()
    );
    let mut wrote = vec!["raw.tiff", "psf.tiff", "truth.npy", "truth.tiff", "capture.toml"];
    if let Some(d) = &bench.defects {
        println!("sensor: {} hot and {} stuck pixels, fixed-pattern dark {:.2} ADU rms", d.hot.len(), d.stuck.len(), d.dark_fpn_rms_adu());
        wrote.extend([sim_output::SENSOR_TRUTH_FILE, sim_output::SENSOR_FPN_FILE]);
    }
    if let Some(b) = &bench.background {
        println!("background: {} e-/us per pixel on average, in raw.tiff, not in the truth", b.params.e_per_us);
    }
    if let Some(shots) = &shots {
        println!(
            "calibration shots: {} dark, {} PSF (peak {:.0} e-), {} background frames in {}/",
            shots.dark.len(),
            shots.psf.len(),
            shots.psf_peak_e,
            shots.background.len(),
            sim_output::CALIBRATION_SHOTS_DIR
        );
    }
    println!("wrote {} to {}", wrote.join(", "), a.out.display());
    Ok(())
}
