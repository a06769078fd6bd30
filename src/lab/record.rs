//! Recording a capture folder from a camera (`rollcam capture`): configure the camera,
//! describe the session (geometry, requested and applied settings, the LED
//! synchronisation), record the frames (software-triggered when the camera waits for
//! it) and close the folder with the outcome, so that a failure keeps every frame
//! recorded before it.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context;
use rollcam_hw::camera::{AppliedSettings, Camera, CameraError, CameraSettings, Trigger};
use rollcam_hw::record::{CaptureSession, Recorder, SyncInfo, TriggerLink};

/// What to record, and how.
#[derive(Clone, Debug)]
pub struct RecordingRequest {
    /// Settings to apply to the camera.
    pub settings: CameraSettings,
    /// Number of frames to record.
    pub frames: u64,
    /// Output capture folder (created; must not already hold a capture).
    pub out: PathBuf,
    /// LED pulse start relative to the first row's exposure start, µs.
    pub led_phase_us: Option<f64>,
    /// The LED controller's settings, stored verbatim in capture.json.
    pub led: Option<serde_json::Value>,
    /// How long to wait for each frame before giving up.
    pub frame_timeout: Duration,
}

/// The LED controller's settings from a JSON file.
pub fn read_led_json(path: &Path) -> anyhow::Result<serde_json::Value> {
    serde_json::from_str::<serde_json::Value>(&crate::io::input::read_text(path).with_context(|| format!("reading LED settings {}", path.display()))?)
        .with_context(|| format!("{}: expected JSON", path.display()))
}

/// Record `req.frames` frames from an open camera into `req.out`; returns the number
/// recorded. On failure the folder is closed with the error and keeps the frames
/// recorded so far (the error says how many).
pub fn record_capture(cam: &mut dyn Camera, req: &RecordingRequest) -> anyhow::Result<u64> {
    let requested = req.settings.clone();
    let geometry = cam.geometry()?;
    let applied = cam.configure(&requested)?;
    let mut session = CaptureSession::new(cam.info().clone());
    session.geometry = Some(geometry);
    session.requested = requested;
    session.applied = Some(applied.clone());
    session.frames_requested = Some(req.frames);
    session.sync = SyncInfo {
        led_phase_us: req.led_phase_us,
        line_time_us: applied.line_time_us,
        trigger_chain: applied
            .exposure_output_line
            .iter()
            .map(|line| TriggerLink { source: format!("{} {line} (ExposureActive)", cam.info().spec()), target: "led".into(), note: None })
            .collect(),
        led: req.led.clone(),
        notes: None,
    };
    let mut rec = Recorder::create(&req.out, session)?;
    tracing::info!(out = %req.out.display(), frames = req.frames, "recording");
    let result = record_frames(cam, &mut rec, req, &applied);
    let stop = cam.stop();
    let recorded = rec.session().frames_recorded;
    let err_text = result.as_ref().err().map(|e| e.to_string());
    rec.finish(err_text.clone())?;
    match (result, stop) {
        (Err(e), _) => Err(anyhow::Error::new(e).context(format!(
            "capture stopped after {recorded} of {} frames; the recorded frames in {} are intact",
            req.frames,
            req.out.display()
        ))),
        (Ok(()), Err(e)) => Err(e.into()),
        (Ok(()), Ok(())) => Ok(recorded),
    }
}

fn record_frames(cam: &mut dyn Camera, rec: &mut Recorder, req: &RecordingRequest, applied: &AppliedSettings) -> Result<(), CameraError> {
    cam.start()?;
    let software = applied.trigger == Trigger::Software;
    let mut recorded = 0;
    while recorded < req.frames {
        if software {
            cam.software_trigger()?;
        }
        let frame = cam.next_frame(req.frame_timeout)?;
        rec.write_frame(&frame)?;
        recorded += 1;
    }
    Ok(())
}
