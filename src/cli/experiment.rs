//! `rollcam experiment led-sweep`: the temporal-resolution experiment, simulated, or on
//! the bench with `--camera` and `--led` (an LED controller and a camera; `sim:led-array`
//! and `--led emulator` rehearse it with no hardware).

use crate::cli::common::ctrl_c_flag;
use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use rollcam::analysis::led_sweep::{run_sweep, SweepOptions, SweepSize, PERIODS_US};
use rollcam::request::Hooks;
use rollcam_hw::camera::{Roi, Trigger};
use rollcam_hw::led::TriggerMode;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct ExperimentArgs {
    #[command(subcommand)]
    pub which: Experiment,
}

#[derive(Subcommand, Debug)]
pub enum Experiment {
    /// Four LEDs flashing in unison at each period: simulate (or, with --camera and --led,
    /// program the LED controller and capture), reconstruct, analyse, report.
    LedSweep(LedSweepArgs),
}

#[derive(Args, Debug)]
pub struct LedSweepArgs {
    /// Square-wave periods, microseconds (comma-separated).
    #[arg(long, value_delimiter = ',', default_values_t = PERIODS_US.to_vec())]
    pub periods_us: Vec<f64>,
    /// Output folder: new or empty, or see --force (default: ./rollcam-led-sweep, or
    /// rollcam-led-sweep-2, -3, ... when that one holds files).
    #[arg(long)]
    pub out: Option<PathBuf>,
    #[command(flatten)]
    pub force: crate::cli::common::ForceFlag,
    /// Most solver iterations per period (the default stop rule ends a solve earlier
    /// when its objective settles).
    #[arg(long, default_value_t = rollcam::request::DEFAULT_ITERS)]
    pub iters: usize,
    /// Sensor size: small (64 x 80), demo (128 x 160) or paper-8x (270 x 320).
    #[arg(long, default_value = "demo")]
    pub size: SweepSize,
    /// LED spacing, raw pixels.
    #[arg(long, default_value_t = 6.0)]
    pub spacing_px: f64,
    /// TV weight relative to max(A^T b), or `noise` (the default: from each capture's
    /// noise).
    #[arg(long, default_value_t = rollcam::request::Tau::default(), value_parser = crate::cli::common::parse_tau_rel_fixed)]
    pub tau_rel: rollcam::request::Tau,
    /// Temporal TV weight.
    #[arg(long, default_value_t = rollcam::request::DEFAULT_ALPHA, value_parser = rollcam::request::parse_f32)]
    pub alpha: f32,
    /// Seed of the diffuser and the noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Also write DIR/led-sweep.md and DIR/figures/led-sweep*.png for the documentation.
    #[arg(long)]
    pub docs: Option<PathBuf>,
    /// Bench mode: the camera (aravis:<id>, or sim:led-array, a simulated camera that
    /// renders the LEDs from the LED controller's programmed state). Needs --led.
    #[arg(long, requires = "led")]
    pub camera: Option<String>,
    /// Bench mode: the LED controller's serial port (e.g. /dev/ttyACM0), or `emulator`
    /// (a software controller on a pseudo-terminal). Needs --camera.
    #[arg(long, requires = "camera")]
    pub led: Option<String>,
    /// Bench mode: the diffuser's measured PSF (not with sim:, which brings its own).
    #[arg(long)]
    pub psf: Option<PathBuf>,
    /// Bench mode: capture description of the camera's raw (rows, cols, timing;
    /// exposure and line time are set on the camera from it).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Bench mode: LEDs driven, controller channels 0..N.
    #[arg(long, default_value_t = 4)]
    pub leds: usize,
    /// Bench mode: high fraction of each period.
    #[arg(long, default_value_t = 0.5)]
    pub duty: f64,
    /// Bench mode: first rise after the trigger, microseconds (one value, or one per LED).
    #[arg(long, value_delimiter = ',', default_values_t = vec![0u32])]
    pub phase_us: Vec<u32>,
    /// Bench mode: what starts the LEDs: software (the host, just before the capture),
    /// rising or falling (an edge of the camera's exposure output on the trigger input).
    #[arg(long, default_value = "software", value_parser = parse_led_trigger)]
    pub led_trigger: TriggerMode,
    /// Bench mode: camera output line carrying ExposureActive to the controller (e.g. Line1).
    #[arg(long)]
    pub exposure_output_line: Option<String>,
    /// Bench mode: camera trigger: free-run | software | hardware:<line>[:rising|falling|any].
    #[arg(long)]
    pub camera_trigger: Option<Trigger>,
    /// Bench mode, real cameras: region of interest x,y,width,height (or WxH+X+Y); the
    /// capture description's rows and cols must match it.
    #[arg(long)]
    pub roi: Option<Roi>,
    /// Bench mode, real cameras: raw pixel ROW,COL of an LED, once per LED (default: the
    /// brightest spots of each reconstruction).
    #[arg(long = "led-pixel", value_parser = parse_pixel)]
    pub led_pixels: Vec<(usize, usize)>,
    /// Bench mode: LED controller baud rate.
    #[arg(long, default_value_t = rollcam_hw::led::DEFAULT_BAUD)]
    pub led_baud: u32,
    /// Bench mode: how long to wait for each frame, milliseconds.
    #[arg(long, default_value_t = 10_000)]
    pub frame_timeout_ms: u64,
    #[command(flatten)]
    pub sensor: crate::cli::common::SensorFlags,
}

fn parse_pixel(s: &str) -> std::result::Result<(usize, usize), String> {
    let (r, c) = s.split_once(',').ok_or_else(|| format!("'{s}': expected ROW,COL"))?;
    let p = |v: &str| v.trim().parse::<usize>().map_err(|_| format!("'{s}': expected ROW,COL in whole pixels"));
    Ok((p(r)?, p(c)?))
}

fn parse_led_trigger(s: &str) -> std::result::Result<TriggerMode, String> {
    match s.to_ascii_lowercase().as_str() {
        "software" | "sw" => Ok(TriggerMode::Software),
        "rising" | "rise" => Ok(TriggerMode::Rising),
        "falling" | "fall" => Ok(TriggerMode::Falling),
        _ => Err(format!("'{s}': expected software, rising or falling")),
    }
}

pub fn run(a: ExperimentArgs) -> Result<()> {
    match a.which {
        Experiment::LedSweep(s) => {
            let out = match &s.out {
                Some(out) => {
                    let inputs = [("the PSF (--psf)", s.psf.as_deref()), ("the capture description (--config)", s.config.as_deref())];
                    crate::cli::common::claim_out(out, &s.force, &["report.md", "report.json", "figure.png", "psf.tiff"], &inputs)?;
                    out.clone()
                }
                None => rollcam::io::out_dir::fresh_folder(std::path::Path::new("rollcam-led-sweep")),
            };
            led_sweep(LedSweepArgs { out: Some(out), ..s })
        }
    }
}

fn led_sweep(a: LedSweepArgs) -> Result<()> {
    let out = a.out.clone().expect("the output folder is resolved by run");
    if a.camera.is_some() {
        return bench_sweep(a);
    }
    if a.psf.is_some() || a.config.is_some() {
        anyhow::bail!("--psf and --config belong to the bench mode: give --camera and --led too (without them the sweep simulates)");
    }
    // A calibration or background applies to every simulated capture (its size must be
    // the sweep's sensor).
    let sensor = rollcam::io::sensor_files::SensorFiles::load(a.sensor.calibration.as_deref(), a.sensor.background.as_deref(), None, None)?;
    let opts = sweep_options(&a, sensor);
    let periods: Vec<String> = a.periods_us.iter().map(|p| format!("{p}")).collect();
    let mut command = format!(
        "rollcam experiment led-sweep --periods-us {} --size {} --iters {} --spacing-px {} --tau-rel {} --alpha {} --seed {} --out {}",
        periods.join(","),
        a.size.name(),
        a.iters,
        a.spacing_px,
        a.tau_rel,
        a.alpha,
        a.seed,
        out.display()
    );
    if let Some(d) = &a.docs {
        command.push_str(&format!(" --docs {}", d.display()));
    }
    let stop = ctrl_c_flag();
    let nothing = |_: usize, _: &rollcam::request::TraceRow| {};
    let hooks = Hooks { on_row: &nothing, stop: &stop };
    let (rows, cols) = a.size.sensor();
    println!("LED sweep on a {rows} x {cols} sensor, periods {:?} us, {} iterations each", a.periods_us, a.iters);
    let report = run_sweep(&opts, &out, &command, &hooks, &print_row)?;
    println!("report: {} ({})", out.join("report.md").display(), out.join("report.json").display());
    if let Some(docs) = &a.docs {
        let figs = docs.join("figures");
        std::fs::create_dir_all(&figs).with_context(|| format!("{}: cannot create the folder", figs.display()))?;
        std::fs::copy(out.join(&report.figure), figs.join("led-sweep.png"))
            .with_context(|| format!("{}: cannot write", figs.join("led-sweep.png").display()))?;
        for r in &report.rows {
            let src = out.join(&r.folder).join("analysis").join("timecourse.png");
            let dst = figs.join(format!("led-sweep-timecourse-{:.0}us.png", r.period_us));
            std::fs::copy(&src, &dst).with_context(|| format!("{}: cannot write", dst.display()))?;
        }
        let mut md = rollcam::analysis::led_sweep::report_markdown(&report, "figures/led-sweep.png");
        md.push_str("\n## Time courses\n\n");
        for r in &report.rows {
            md.push_str(&format!("![time courses of the LED regions, period {0:.0} us](figures/led-sweep-timecourse-{0:.0}us.png)\n\n", r.period_us));
        }
        md.push_str(rollcam::lab::led_sweep::BENCH_HOWTO_MD);
        let path = docs.join("led-sweep.md");
        std::fs::write(&path, md).with_context(|| format!("{}: cannot write", path.display()))?;
        println!("documentation: {}", path.display());
    }
    Ok(())
}

fn print_row(r: &rollcam::analysis::led_sweep::SweepRow) {
    println!(
        "period {:.0} us: expected {:.1} Hz, peak {}, temporal contrast {:.2} (theory {:.2}), spatial contrast {:.2}, {}/{} LED pairs resolved, {:.1} s",
        r.period_us,
        r.expected_frequency_hz,
        r.measured_peak_hz.map_or("none".into(), |f| format!("{f:.1} Hz")),
        r.temporal_contrast,
        r.expected_temporal_contrast,
        r.spatial_contrast,
        r.pairs_resolved,
        r.pairs,
        r.seconds
    );
}

/// Bench mode: LED controller + camera (or their stand-ins).
fn bench_sweep(a: LedSweepArgs) -> Result<()> {
    let out = a.out.clone().expect("the output folder is resolved by run");
    use rollcam::analysis::led_sweep::{EXPOSURE_US, LINE_TIME_US};
    use rollcam::lab::camera::{open_camera, CameraOptions, CameraTarget};
    use rollcam::lab::hardware::{camera_settings, camera_shutter};
    use rollcam::lab::led_sweep::{controller_scene, run_bench_sweep, target_pixels, BenchOptions, SweepBench};
    use rollcam::lab::simcam::{SceneSource, SimCameraSpec};
    use rollcam::model::capture::CaptureConfig;
    use rollcam::sim::Scene;
    use rollcam_hw::camera::{CameraSettings, PixelFormat};
    use std::sync::{Arc, Mutex};

    let camera_name = a.camera.clone().expect("bench mode has --camera");
    let led_name = a.led.clone().expect("clap requires --led with --camera");
    let target = CameraTarget::parse(&camera_name)?;
    let simulated = matches!(target, CameraTarget::Simulated { .. });
    if let CameraTarget::Simulated { id } = &target {
        if id != "led-array" {
            anyhow::bail!("camera {}: the LED sweep's simulated camera is sim:led-array", target.spec());
        }
        if a.psf.is_some() || a.config.is_some() || a.roi.is_some() || !a.led_pixels.is_empty() {
            anyhow::bail!(
                "--psf, --config, --roi and --led-pixel are for real cameras: sim:led-array brings its own diffuser and timing (--size sets the sensor)"
            );
        }
    } else if (a.psf.is_none() && a.sensor.calibration.is_none()) || a.config.is_none() {
        anyhow::bail!(
            "camera {camera_name}: --psf (the diffuser's measured PSF, or --calibration with one) and --config (the raw's capture description) are required with a real camera"
        );
    }

    // The LED controller first: if it does not answer, nothing is written.
    let (_emulator, port, led) = open_led(&led_name, a.led_baud)?;
    let led = Arc::new(Mutex::new(led));

    let mut opts =
        sweep_options(&a, rollcam::io::sensor_files::SensorFiles::load(a.sensor.calibration.as_deref(), a.sensor.background.as_deref(), None, None)?);
    let bopts = BenchOptions {
        leds: a.leds,
        duty: a.duty,
        phases_us: a.phase_us.clone(),
        led_trigger: a.led_trigger,
        frame_timeout: std::time::Duration::from_millis(a.frame_timeout_ms),
    };
    let periods: Vec<String> = a.periods_us.iter().map(|p| format!("{p}")).collect();
    let phases: Vec<String> = a.phase_us.iter().map(|p| format!("{p}")).collect();
    let mut command = format!(
        "rollcam experiment led-sweep --camera {camera_name} --led {led_name} --periods-us {} --leds {} --duty {} --phase-us {} --led-trigger {} --iters {} --tau-rel {} --alpha {} --out {}",
        periods.join(","),
        a.leds,
        a.duty,
        phases.join(","),
        a.led_trigger.token().to_ascii_lowercase(),
        a.iters,
        a.tau_rel,
        a.alpha,
        out.display()
    );
    let stop = ctrl_c_flag();
    let nothing = |_: usize, _: &rollcam::request::TraceRow| {};
    let hooks = Hooks { on_row: &nothing, stop: &stop };

    let report = if simulated {
        command.push_str(&format!(" --size {} --spacing-px {} --seed {}", a.size.name(), a.spacing_px, a.seed));
        let (rows, cols) = a.size.sensor();
        let source_led = led.clone();
        let spacing = a.spacing_px;
        let scene = Box::new(move || controller_scene(&source_led, rows, cols, spacing).map(|s| Box::new(s) as Box<dyn Scene>).map_err(|e| e.into()));
        let source = SceneSource::Live { name: "led-array".into(), scene };
        let sim = SimCameraSpec { rows, cols, line_time_us: LINE_TIME_US, exposure_us: EXPOSURE_US, seed: a.seed, ..SimCameraSpec::new(source) };
        let mut cam = open_camera(&target, CameraOptions { simulated: Some(sim), ..CameraOptions::default() })?;
        // The PSF as recorded and the capture description of the camera's power-up timing.
        let (psf_adu, cfg) = cam.calibration().expect("a simulated camera")?;
        let settings =
            camera_settings(&cfg, CameraSettings { pixel_format: Some(PixelFormat::Mono16), trigger: a.camera_trigger.clone(), ..CameraSettings::default() });
        let mut bench = SweepBench {
            camera: cam.camera(),
            camera_name: camera_name.clone(),
            settings,
            led: led.clone(),
            psf: psf_adu.clone(),
            psf_name: "the simulated camera's diffuser (psf.tiff)".into(),
            psf_clean: false,
            cfg,
            config_name: "the simulated camera's timing".into(),
            centres: Some(target_pixels(rows, cols, a.leds, a.spacing_px)?),
        };
        println!("LED sweep on {camera_name} ({rows} x {cols}) with the LED controller on {port}, periods {:?} us", a.periods_us);
        let report = run_bench_sweep(&opts, &mut bench, &bopts, &out, &command, &hooks, &print_row)?;
        rollcam::io::write_tiff_u16(out.join("psf.tiff"), psf_adu.view())?;
        report
    } else {
        let config_path = a.config.clone().expect("checked above");
        command.push_str(&real_camera_flags(&a, &config_path));
        let cfg = CaptureConfig::load(&config_path)?;
        let sensor = a.sensor.load(Some(&config_path), &cfg)?;
        let (psf, psf_name, psf_clean) = crate::cli::common::psf_or_calibration(a.psf.as_deref(), &sensor)?;
        opts.sensor = sensor;
        if camera_shutter(cfg.shutter).is_none() {
            anyhow::bail!("{}: shutter = \"{:?}\" cannot be set on a camera: expected global, rolling or dual", config_path.display(), cfg.shutter);
        }
        let settings = camera_settings(
            &cfg,
            CameraSettings { trigger: a.camera_trigger.clone(), exposure_output_line: a.exposure_output_line.clone(), roi: a.roi, ..CameraSettings::default() },
        );
        let mut cam = open_camera(&target, CameraOptions::default())?;
        let mut bench = SweepBench {
            camera: cam.camera(),
            camera_name: camera_name.clone(),
            settings,
            led: led.clone(),
            psf,
            psf_name,
            psf_clean,
            cfg,
            config_name: config_path.display().to_string(),
            centres: (!a.led_pixels.is_empty()).then(|| a.led_pixels.clone()),
        };
        println!("LED sweep on camera {camera_name} with the LED controller on {port}, periods {:?} us", a.periods_us);
        run_bench_sweep(&opts, &mut bench, &bopts, &out, &command, &hooks, &print_row)?
    };
    println!("report: {} ({}); {} periods", out.join("report.md").display(), out.join("report.json").display(), report.rows.len());
    Ok(())
}

/// The sweep's options from the flags, with the sensor's calibration and background.
fn sweep_options(a: &LedSweepArgs, sensor: rollcam::io::sensor_files::SensorFiles) -> SweepOptions {
    SweepOptions {
        periods_us: a.periods_us.clone(),
        size: a.size,
        iters: a.iters,
        tau: a.tau_rel,
        alpha: a.alpha,
        spacing_px: a.spacing_px,
        seed: a.seed,
        sensor,
    }
}

/// The LED controller `name` (a serial port, or `emulator`: a software controller on a
/// pseudo-terminal, kept alive by the first value), its port and the open controller.
fn open_led(name: &str, baud: u32) -> Result<(Option<rollcam_hw::led::LinkedEmulator>, String, rollcam_hw::led::LedController)> {
    use rollcam_hw::led::{Identity, LedController, LinkedEmulator};
    let (emulator, port) = if name == "emulator" {
        let link = std::env::temp_dir().join(format!("rollcam-led-sweep-emulator-{}", std::process::id()));
        let e = LinkedEmulator::create(&link, Identity::default())?;
        println!("LED controller: emulator on {} -> {}", link.display(), e.target().display());
        (Some(e), link.display().to_string())
    } else {
        (None, name.to_string())
    };
    let led = LedController::open(&port, baud)?;
    Ok((emulator, port, led))
}

/// The real-camera flags of the report's command line.
fn real_camera_flags(a: &LedSweepArgs, config_path: &std::path::Path) -> String {
    let mut flags = String::new();
    if let Some(p) = &a.psf {
        flags.push_str(&format!(" --psf {}", p.display()));
    }
    if let Some(c) = &a.sensor.calibration {
        flags.push_str(&format!(" --calibration {}", c.display()));
    }
    flags.push_str(&format!(" --config {}", config_path.display()));
    if let Some(r) = a.roi {
        flags.push_str(&format!(" --roi {},{},{},{}", r.x, r.y, r.width, r.height));
    }
    for (r, c) in &a.led_pixels {
        flags.push_str(&format!(" --led-pixel {r},{c}"));
    }
    if let Some(line) = &a.exposure_output_line {
        flags.push_str(&format!(" --exposure-output-line {line}"));
    }
    if let Some(t) = &a.camera_trigger {
        flags.push_str(&format!(" --camera-trigger {t}"));
    }
    flags
}
