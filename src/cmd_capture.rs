//! `rollcam capture`: configure a camera and record frames to a capture folder.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, Result};
use rollcam_hw::camera::{
    self, Binning, Camera, CameraError, CameraSettings, CameraSpec, PixelFormat, Roi, ShutterMode, Trigger,
};
use rollcam_hw::record::{CaptureSession, Recorder, SyncInfo, TriggerLink};

#[derive(clap::Args, Debug, Clone)]
pub struct CaptureArgs {
    /// Camera as backend:id, e.g. aravis:Fake_1, aravis:<device id or IP>, replay:<capture folder>.
    #[arg(long)]
    pub camera: String,
    /// Number of frames to record.
    #[arg(long, default_value_t = 1)]
    pub frames: u64,
    /// Output capture folder (created; must not already hold a capture).
    #[arg(long)]
    pub out: PathBuf,
    #[arg(long)]
    pub exposure_us: Option<f64>,
    /// Rolling-shutter row-to-row time.
    #[arg(long)]
    pub line_time_us: Option<f64>,
    #[arg(long)]
    pub frame_rate_hz: Option<f64>,
    /// global | rolling | dual
    #[arg(long)]
    pub shutter: Option<ShutterMode>,
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
}

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
    let spec: CameraSpec = args.camera.parse()?;
    let mut cam = camera::open(&spec).with_context(|| format!("opening camera {}", args.camera))?;
    capture(cam.as_mut(), &args)
}

/// Record `args.frames` frames from an open camera into `args.out`.
pub fn capture(cam: &mut dyn Camera, args: &CaptureArgs) -> Result<()> {
    let led = match &args.led_json {
        Some(p) => Some(
            serde_json::from_str::<serde_json::Value>(
                &std::fs::read_to_string(p).with_context(|| format!("reading LED settings {}", p.display()))?,
            )
            .with_context(|| format!("{}: expected JSON", p.display()))?,
        ),
        None => None,
    };
    let requested = args.settings();
    let geometry = cam.geometry()?;
    let applied = cam.configure(&requested)?;
    let mut session = CaptureSession::new(cam.info().clone());
    session.geometry = Some(geometry);
    session.requested = requested;
    session.applied = Some(applied.clone());
    session.frames_requested = Some(args.frames);
    session.sync = SyncInfo {
        led_phase_us: args.led_phase_us,
        line_time_us: applied.line_time_us,
        trigger_chain: applied
            .exposure_output_line
            .iter()
            .map(|line| TriggerLink {
                source: format!("{} {line} (ExposureActive)", cam.info().spec()),
                target: "led".into(),
                note: None,
            })
            .collect(),
        led,
        notes: None,
    };
    let mut rec = Recorder::create(&args.out, session)?;
    tracing::info!(out = %args.out.display(), frames = args.frames, "recording");
    let result = record_frames(cam, &mut rec, args, &applied);
    let stop = cam.stop();
    let recorded = rec.session().frames_recorded;
    let err_text = result.as_ref().err().map(|e| e.to_string());
    rec.finish(err_text.clone())?;
    match (result, stop) {
        (Err(e), _) => Err(anyhow::Error::new(e).context(format!(
            "capture stopped after {recorded} of {} frames; the recorded frames in {} are intact",
            args.frames,
            args.out.display()
        ))),
        (Ok(()), Err(e)) => Err(e.into()),
        (Ok(()), Ok(())) => {
            println!("recorded {recorded} frames to {}", args.out.display());
            Ok(())
        }
    }
}

fn record_frames(
    cam: &mut dyn Camera,
    rec: &mut Recorder,
    args: &CaptureArgs,
    applied: &camera::AppliedSettings,
) -> Result<(), CameraError> {
    cam.start()?;
    let timeout = Duration::from_millis(args.timeout_ms);
    let software = applied.trigger == Trigger::Software;
    let mut recorded = 0;
    while recorded < args.frames {
        if software {
            cam.software_trigger()?;
        }
        let frame = cam.next_frame(timeout)?;
        rec.write_frame(&frame)?;
        recorded += 1;
    }
    Ok(())
}
