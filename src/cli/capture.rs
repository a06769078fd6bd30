//! `rollcam capture`: configure a camera and record frames to a capture folder.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use rollcam::lab::camera::{open_camera, CameraOptions, CameraTarget, OpenCamera};
use rollcam::lab::hardware::capture_config;
use rollcam::lab::keycam::{KeyCameraRequest, KeyClock, KeyedCamera};
use rollcam::lab::record::{free_bytes_for, read_led_json, record_configured, RecordingEstimate, RecordingRequest};
use rollcam::lab::simcam::SimShot;
use rollcam::model::capture::{CaptureConfig, CaptureOverrides};
use rollcam_hw::camera::{AppliedSettings, Binning, Camera, CameraSettings, CameraShutter, PixelFormat, Roi, Trigger};
use rollcam_hw::record::{CaptureReader, TriggerLink};

#[derive(clap::Args, Debug, Clone)]
pub struct CaptureArgs {
    /// Camera as backend:id, e.g. aravis:Fake_1, aravis:<device id or IP>, replay:<capture folder>, sim:led-array.
    #[arg(long)]
    pub camera: String,
    /// Number of frames to record (at least 1).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    pub frames: u64,
    /// What the frames are: scene (default), or calibration shots `rollcam calibrate`
    /// reads (the folder as --dark, --psf-shots or --background): dark (cap on), psf
    /// (a point source on axis: a check of the shots is printed and written to
    /// psf-check.json) or background (the static scene alone).
    #[arg(long, value_enum, default_value_t = ShotKind::Scene)]
    pub kind: ShotKind,
    /// Output capture folder: new or empty (or see --force); checked before the camera
    /// is opened.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub force: crate::cli::common::ForceFlag,
    #[command(flatten)]
    pub keys: crate::cli::common::KeyCameraFlags,
    #[arg(long)]
    pub exposure_us: Option<f64>,
    /// Rolling-shutter row-to-row time.
    #[arg(long)]
    pub line_time_us: Option<f64>,
    #[arg(long)]
    pub frame_rate_hz: Option<f64>,
    /// global | rolling | dual
    #[arg(long)]
    pub shutter: Option<CameraShutter>,
    /// x,y,width,height in sensor pixels (or WxH+X+Y).
    #[arg(long)]
    pub roi: Option<Roi>,
    /// Binning factor applied in both directions.
    #[arg(long)]
    pub binning: Option<u32>,
    /// Mono8 | Mono10 | Mono12 | Mono14 | Mono16
    #[arg(long)]
    pub pixel_format: Option<PixelFormat>,
    /// free-run | software | hardware:<line>[:rising|falling|any]
    #[arg(long)]
    pub trigger: Option<Trigger>,
    /// Output line that carries the exposure-active signal to the LED pulser (e.g. Line1).
    #[arg(long)]
    pub exposure_output_line: Option<String>,
    /// LED pulse start relative to the first row's exposure start, in µs (recorded in capture.json).
    #[arg(long)]
    pub led_phase_us: Option<f64>,
    /// JSON file with the LED controller's settings, stored verbatim in capture.json.
    #[arg(long)]
    pub led_json: Option<PathBuf>,
    /// How long to wait for each frame before giving up.
    #[arg(long, default_value_t = 5000)]
    pub timeout_ms: u64,
    /// Start a recording estimated beyond an hour (refused without it).
    #[arg(long)]
    pub yes: bool,
}

/// What a capture's frames are (`--kind`).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShotKind {
    Scene,
    Dark,
    Psf,
    Background,
}

impl ShotKind {
    /// What the simulated camera shows for this kind of shot.
    fn sim_shot(self) -> SimShot {
        match self {
            ShotKind::Scene => SimShot::Scene,
            ShotKind::Dark => SimShot::Dark,
            ShotKind::Psf => SimShot::Point,
            ShotKind::Background => SimShot::Background,
        }
    }

    /// The `rollcam calibrate` flag that takes a folder of these shots.
    fn calibrate_flag(self) -> Option<&'static str> {
        match self {
            ShotKind::Scene => None,
            ShotKind::Dark => Some("--dark"),
            ShotKind::Psf => Some("--psf-shots"),
            ShotKind::Background => Some("--background"),
        }
    }
}

/// The check of PSF shots written beside them.
pub const PSF_CHECK_FILE: &str = "psf-check.json";

impl CaptureArgs {
    pub fn settings(&self) -> CameraSettings {
        CameraSettings {
            exposure_us: self.exposure_us,
            line_time_us: self.line_time_us,
            frame_rate_hz: self.frame_rate_hz,
            shutter: self.shutter,
            roi: self.roi,
            binning: self.binning.map(|b| Binning { horizontal: b, vertical: b }),
            pixel_format: self.pixel_format,
            trigger: self.trigger.clone(),
            exposure_output_line: self.exposure_output_line.clone(),
        }
    }
}

pub fn run(args: CaptureArgs) -> Result<()> {
    for (flag, value) in [
        ("--exposure-us", args.exposure_us),
        ("--line-time-us", args.line_time_us),
        ("--frame-rate-hz", args.frame_rate_hz),
        ("--led-phase-us", args.led_phase_us),
    ] {
        if let Some(v) = value.filter(|v| !v.is_finite()) {
            bail!("{flag} = {v}: expected a finite number");
        }
    }
    crate::cli::common::claim_out(
        &args.out,
        &args.force,
        &["capture.json", "psf.tiff", "capture.toml", PSF_CHECK_FILE],
        &[("the LED description (--led-json)", args.led_json.as_deref())],
    )?;
    let key = args.keys.request(&args.camera, args.timeout_ms)?;
    if key.is_some() && args.kind != ShotKind::Scene {
        bail!("--keyframe-camera: key frames go with scene captures; expected no --kind {:?}", args.kind);
    }
    let mut cam = open_camera(&CameraTarget::parse(&args.camera)?, CameraOptions::default())?;
    cam.set_shot(args.kind.sim_shot());
    let mut cfg = match &key {
        None => capture(cam.camera(), &args)?,
        Some(key) => {
            let (cfg, main) = capture_keyed(cam, &args, key)?;
            cam = main;
            cfg
        }
    };
    let keyed = |cfg| if key.is_some() { rollcam::lab::keycam::with_recorded_keyframes(&args.out, 0, cfg) } else { Ok(cfg) };
    let out = args.out.display();
    let in_out = |file: &str| args.out.join(file).display().to_string();
    if let Some(flag) = args.kind.calibrate_flag() {
        // The simulated camera knows where its sensor clips (the full well, below the
        // ADC's full scale): the PSF check judges the shots against that.
        if let Some(Ok(simulated)) = cam.simulated_config() {
            cfg.saturation_level = simulated.saturation_level;
        }
        if let Some(table) = cfg.camera.as_mut() {
            table.insert("shot".into(), format!("{:?}", args.kind).to_lowercase().into());
        }
        rollcam::io::write_text_atomic(&args.out.join("capture.toml"), &cfg.to_toml())?;
        if args.kind == ShotKind::Psf {
            check_psf_shots(&args.out, cfg.saturation_level)?;
        }
        println!("calibration shots: rollcam calibrate {flag} {out} ... --out calib/");
        return Ok(());
    }
    // The simulated camera (`sim:led-array`, `sim:moving-disc`): besides the frames,
    // the capture folder gets the diffuser's PSF (`psf.tiff`) and its timing and dark
    // level (`capture.toml`), so every frame can be reconstructed.
    if let Some(calibration) = cam.calibration() {
        let (psf, cfg) = calibration?;
        let cfg = keyed(cfg)?;
        rollcam::lab::simcam::write_calibration(&args.out, &psf, &cfg)?;
        println!(
            "wrote psf.tiff and capture.toml beside the frames: reconstruct with rollcam reconstruct --raw {} --psf {} --config {} --out rec/",
            in_out("frame_000000.tiff"),
            in_out("psf.tiff"),
            in_out("capture.toml")
        );
    } else {
        let cfg = keyed(cfg)?;
        rollcam::io::write_text_atomic(&args.out.join("capture.toml"), &cfg.to_toml())?;
        println!(
            "wrote capture.toml (the settings the camera applied): reconstruct with rollcam reconstruct --raw {} --config {} --calibration calib/ --out rec/ (or --psf PSF in place of --calibration)",
            in_out("frame_000000.tiff"),
            in_out("capture.toml")
        );
    }
    Ok(())
}

/// Read the PSF shots just recorded in `dir`, print their check and write it beside
/// them ([`PSF_CHECK_FILE`]).
fn check_psf_shots(dir: &std::path::Path, saturation_level: Option<f64>) -> Result<()> {
    let reader = CaptureReader::open(dir)?;
    let mut frames = Vec::new();
    for i in 0..reader.len() {
        let f = reader.read_frame(i)?;
        let (w, h) = (f.meta.width as usize, f.meta.height as usize);
        let pixels: Vec<f32> = f.pixels.iter().map(|&v| f32::from(v)).collect();
        frames.push(ndarray::Array3::from_shape_vec((h, w, 1), pixels).context("a frame of width x height samples")?);
    }
    let Some(check) = rollcam::analysis::psf_check::check_psf_shots(&frames, saturation_level) else {
        anyhow::bail!("{}: no light above the dark in the PSF shots: is the point source on?", dir.display());
    };
    println!("{}", check.summary());
    for a in &check.advice {
        println!("psf shot: {a}");
    }
    rollcam::io::write_text_atomic(&dir.join(PSF_CHECK_FILE), &serde_json::to_string_pretty(&check)?)?;
    Ok(())
}

/// Record `args.frames` frames from an open camera into `args.out`; the capture
/// description of what the camera applied, checked before any frame is recorded (a
/// field the camera does not report is refused by name).
pub fn capture(cam: &mut dyn Camera, args: &CaptureArgs) -> Result<CaptureConfig> {
    let (applied, cfg) = configure(cam, args)?;
    record(cam, args, applied, Vec::new())?;
    Ok(cfg)
}

/// [`capture`] with the key-frame camera `key` fired beside the main camera `cam`; the
/// main camera back.
fn capture_keyed(mut cam: OpenCamera, args: &CaptureArgs, key: &KeyCameraRequest) -> Result<(CaptureConfig, OpenCamera)> {
    let (applied, cfg) = configure(cam.camera(), args)?;
    // The key frames' windows are on the time axis of the frames' description: the
    // simulated camera's own, else what the camera applied.
    let described = match cam.calibration() {
        Some(c) => c?.1,
        None => cfg.clone(),
    };
    let mut keyed = KeyedCamera::open(cam, key, &described, &args.out)?;
    let plan = keyed.plan();
    let starts: Vec<String> = plan.starts_us.iter().map(|s| format!("{s}")).collect();
    println!(
        "key frames: {} per raw frame from {} at {} us, exposure {} us ({} trigger, {} times): keyframe_NNNNNN_JJ.tiff and frame_NNNNNN.toml beside each raw frame",
        starts.len(),
        keyed.key_name(),
        starts.join(", "),
        plan.exposure_us,
        key.trigger,
        match key.clock() {
            KeyClock::Shared => "measured",
            KeyClock::Commanded => "commanded",
        }
    );
    let main = keyed.info().spec();
    record(&mut keyed, args, applied, vec![key.trigger_link(&main)])?;
    Ok((cfg, keyed.into_main()))
}

/// Configure the camera with the flags: what it applied and the capture description of
/// that, checked, with the recording's estimate printed and checked.
fn configure(cam: &mut dyn Camera, args: &CaptureArgs) -> Result<(AppliedSettings, CaptureConfig)> {
    let applied = cam.configure(&args.settings())?;
    let (w, h) = applied.image_size();
    let cfg = capture_config(h as usize, w as usize, &applied, &CaptureOverrides::default()).with_context(|| format!("camera {}", args.camera))?;
    cfg.validate().with_context(|| format!("camera {}: the timing it applied", args.camera))?;
    let estimate = RecordingEstimate::new(&applied, args.frames);
    println!("{}", estimate.describe());
    estimate.check(&args.out, free_bytes_for(&args.out), args.yes)?;
    Ok((applied, cfg))
}

/// Record the frames from the configured camera.
fn record(cam: &mut dyn Camera, args: &CaptureArgs, applied: AppliedSettings, trigger_links: Vec<TriggerLink>) -> Result<()> {
    let led = args.led_json.as_deref().map(read_led_json).transpose()?;
    let req = RecordingRequest {
        settings: args.settings(),
        frames: args.frames,
        out: args.out.clone(),
        led_phase_us: args.led_phase_us,
        led,
        frame_timeout: Duration::from_millis(args.timeout_ms),
        trigger_links,
    };
    let recorded = record_configured(cam, &req, applied)?;
    println!("recorded {recorded} frame{} to {}", if recorded == 1 { "" } else { "s" }, args.out.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;
    use rollcam_hw::camera::replay::{ReplayCamera, ReplayFaults, ReplayOptions};
    use rollcam_hw::camera::simulated::{FrameRenderer, RenderError, SimulatedCamera, SimulatedConfig};
    use rollcam_hw::camera::{AppliedSettings, FrameStatus, SensorGeometry};

    #[derive(Parser)]
    struct CaptureCli {
        #[command(flatten)]
        args: CaptureArgs,
    }

    fn args(list: &[&str]) -> CaptureArgs {
        CaptureCli::parse_from(std::iter::once("capture").chain(list.iter().copied())).args
    }

    struct Ramp;
    impl FrameRenderer for Ramp {
        fn geometry(&self) -> SensorGeometry {
            SensorGeometry { width: 16, height: 8, max_bit_depth: 16 }
        }
        fn render(&mut self, i: u64, s: &AppliedSettings) -> std::result::Result<Vec<u16>, RenderError> {
            let (w, h) = s.image_size();
            Ok((0..w * h).map(|p| (p as u64 + i) as u16).collect())
        }
    }

    #[test]
    fn cli_flags_become_settings() {
        let a = args(&[
            "--camera",
            "aravis:Fake_1",
            "--frames",
            "3",
            "--out",
            "/tmp/x",
            "--exposure-us",
            "2000",
            "--line-time-us",
            "12.5",
            "--shutter",
            "rolling",
            "--roi",
            "0,0,64,32",
            "--trigger",
            "hardware:Line0:falling",
            "--pixel-format",
            "mono16",
            "--binning",
            "2",
        ]);
        let s = a.settings();
        assert_eq!(s.exposure_us, Some(2000.0));
        assert_eq!(s.line_time_us, Some(12.5));
        assert_eq!(s.shutter, Some(CameraShutter::Rolling));
        assert_eq!(s.roi, Some(Roi { x: 0, y: 0, width: 64, height: 32 }));
        assert_eq!(s.pixel_format, Some(PixelFormat::Mono16));
        assert_eq!(s.binning, Some(Binning { horizontal: 2, vertical: 2 }));
        assert_eq!(s.trigger, Some(Trigger::Hardware { line: "Line0".into(), edge: rollcam_hw::camera::Edge::Falling }));
    }

    #[test]
    fn capture_records_every_frame_then_disconnect_keeps_recorded_frames() {
        let tmp = tempfile::tempdir().unwrap();
        let src = tmp.path().join("src");
        let mut sim = SimulatedCamera::new(Ramp, SimulatedConfig::default());
        let a = args(&["--camera", "sim:sim0", "--frames", "5", "--out", src.to_str().unwrap(), "--exposure-us", "500", "--led-phase-us", "4"]);
        capture(&mut sim, &a).unwrap();
        let r = CaptureReader::open(&src).unwrap();
        assert_eq!(r.len(), 5);
        assert_eq!(r.session().applied.as_ref().unwrap().exposure_us, 500.0);
        assert_eq!(r.session().sync.led_phase_us, Some(4.0));

        // Replaying it through a camera that vanishes before frame 3.
        let dst = tmp.path().join("dst");
        let faults = ReplayFaults { disconnect_at: Some(3), ..Default::default() };
        let mut replay = ReplayCamera::open(&src, ReplayOptions { faults, ..Default::default() }).unwrap();
        let a = args(&["--camera", "replay:src", "--frames", "5", "--out", dst.to_str().unwrap(), "--timeout-ms", "200"]);
        let e = format!("{:#}", capture(&mut replay, &a).unwrap_err());
        assert!(e.contains("after 3 of 5 frames") && e.contains("disconnected"), "{e}");
        let r2 = CaptureReader::open(&dst).unwrap();
        assert_eq!(r2.len(), 3);
        for i in 0..3 {
            let (orig, copy) = (r.read_frame(i).unwrap(), r2.read_frame(i).unwrap());
            assert_eq!(copy.pixels, orig.pixels);
            assert_eq!(copy.meta.status, FrameStatus::Complete);
        }
        let end = r2.session().end.clone().unwrap();
        assert_eq!(end.outcome, "error");
        assert!(end.error.unwrap().contains("disconnected"));
    }

    #[test]
    fn out_of_range_setting_is_refused_before_anything_is_recorded() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("cap");
        let mut sim = SimulatedCamera::new(Ramp, SimulatedConfig::default());
        let a = args(&["--camera", "sim:sim0", "--frames", "2", "--out", out.to_str().unwrap(), "--exposure-us", "0.01"]);
        let e = capture(&mut sim, &a).unwrap_err().to_string();
        assert!(e.contains("out of range [1, 1000000] us"), "{e}");
        assert!(!out.join("capture.json").exists());
    }
}
