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
    /// More links of the trigger chain (the key-frame camera's), after the LED's.
    pub trigger_links: Vec<TriggerLink>,
}

/// Bytes of one recorded frame besides its 2-byte samples: the TIFF's header and tags
/// and the JSON sidecar (186 and about 650 bytes on the fake camera's frames), rounded
/// up to a file system block.
pub const FRAME_OVERHEAD_BYTES: u64 = 4096;

/// Above this many estimated seconds (an hour) a recording is refused unless the user
/// confirms (`--yes`).
pub const CONFIRM_RECORDING_S: f64 = 3600.0;

/// What a recording will take, estimated before its first frame from the settings the
/// camera applied: the disk (every frame a 16-bit TIFF and a sidecar) and the time.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordingEstimate {
    pub frames: u64,
    /// Bytes one frame takes on disk.
    pub frame_bytes: u64,
    /// Bytes the frames take on disk (saturating).
    pub bytes: u64,
    /// Seconds at the applied frame rate; without one, the exposure and readout of each
    /// frame (a lower bound: a trigger may be slower).
    pub seconds: f64,
    /// Whether `seconds` is a lower bound (no frame rate applied).
    pub at_least: bool,
}

impl RecordingEstimate {
    pub fn new(applied: &AppliedSettings, frames: u64) -> RecordingEstimate {
        let (w, h) = applied.image_size();
        let frame_bytes = u64::from(w) * u64::from(h) * 2 + FRAME_OVERHEAD_BYTES;
        let bytes = frames.saturating_mul(frame_bytes);
        let (seconds, at_least) = match applied.frame_rate_hz.filter(|r| r.is_finite() && *r > 0.0) {
            Some(rate) => (frames as f64 / rate, false),
            None => {
                let readout_us = applied.line_time_us.unwrap_or(0.0) * f64::from(h);
                (frames as f64 * (applied.exposure_us + readout_us).max(0.0) / 1e6, true)
            }
        };
        RecordingEstimate { frames, frame_bytes, bytes, seconds, at_least }
    }

    /// One line: the frames, the time and the disk.
    pub fn describe(&self) -> String {
        format!(
            "recording {} frame{}: {}about {} and {} on disk",
            self.frames,
            if self.frames == 1 { "" } else { "s" },
            if self.at_least { "at least " } else { "" },
            crate::solve::estimate::human_duration(self.seconds),
            human_bytes(self.bytes)
        )
    }

    /// Refuse what the disk of `out` cannot hold (`free`: its free bytes, `None`
    /// unknown), and a recording beyond [`CONFIRM_RECORDING_S`] unless `confirmed`.
    pub fn check(&self, out: &Path, free: Option<u64>, confirmed: bool) -> anyhow::Result<()> {
        if let Some(free) = free.filter(|&f| f < self.bytes) {
            anyhow::bail!(
                "{}: the file system has {} free, the {} frames need about {} ({} bytes per frame): record fewer frames (--frames), a smaller --roi or --binning, or choose another --out",
                out.display(),
                human_bytes(free),
                self.frames,
                human_bytes(self.bytes),
                self.frame_bytes
            );
        }
        if self.seconds > CONFIRM_RECORDING_S && !confirmed {
            anyhow::bail!(
                "--frames = {}: the recording would take {}about {}, beyond an hour: give --yes to start it, or record fewer frames",
                self.frames,
                if self.at_least { "at least " } else { "" },
                crate::solve::estimate::human_duration(self.seconds)
            );
        }
        Ok(())
    }
}

/// Bytes in the decimal unit a person reads them in (kB, MB, GB, TB).
pub fn human_bytes(bytes: u64) -> String {
    let b = bytes as f64;
    match bytes {
        0..=999 => format!("{bytes} B"),
        1_000..=999_999 => format!("{:.1} kB", b / 1e3),
        1_000_000..=999_999_999 => format!("{:.1} MB", b / 1e6),
        1_000_000_000..=999_999_999_999 => format!("{:.1} GB", b / 1e9),
        _ => format!("{:.1} TB", b / 1e12),
    }
}

/// Bytes free on the file system that holds `dir`, or would hold it (its nearest
/// existing ancestor); `None` where that cannot be read.
pub fn free_bytes_for(dir: &Path) -> Option<u64> {
    let absolute = std::path::absolute(dir).ok()?;
    absolute.ancestors().find(|d| d.is_dir()).and_then(|d| crate::lab::pipeline::writer::free_bytes(d).ok())
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
    let applied = cam.configure(&req.settings)?;
    record_configured(cam, req, applied)
}

/// [`record_capture`] on a camera already configured with `req.settings`, which
/// applied `applied` (configured once: a second configuration repeats its work and its
/// report).
pub fn record_configured(cam: &mut dyn Camera, req: &RecordingRequest, applied: AppliedSettings) -> anyhow::Result<u64> {
    let requested = req.settings.clone();
    let geometry = cam.geometry()?;
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
            .chain(req.trigger_links.iter().cloned())
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

#[cfg(test)]
mod tests {
    use super::*;
    use rollcam_hw::camera::{Binning, PixelFormat, Roi};

    fn applied(frame_rate_hz: Option<f64>) -> AppliedSettings {
        AppliedSettings {
            exposure_us: 1000.0,
            line_time_us: Some(10.0),
            frame_rate_hz,
            shutter: None,
            roi: Roi { x: 0, y: 0, width: 512, height: 512 },
            binning: Binning { horizontal: 1, vertical: 1 },
            pixel_format: PixelFormat::Mono8,
            trigger: Trigger::FreeRun,
            exposure_output_line: None,
        }
    }

    #[test]
    fn a_recording_is_estimated_and_refused_when_the_disk_or_the_clock_cannot_take_it() {
        // The probe's case: a million 512 x 512 frames at 25 fps.
        let e = RecordingEstimate::new(&applied(Some(25.0)), 1_000_000);
        assert_eq!(e.bytes, 1_000_000 * (512 * 512 * 2 + FRAME_OVERHEAD_BYTES));
        assert_eq!(e.seconds, 40_000.0);
        assert!(e.describe().contains("about 11.1 h and 528.4 GB on disk"), "{}", e.describe());
        let out = Path::new("/data/cap");
        let full = e.check(out, Some(100_000_000_000), true).unwrap_err().to_string();
        assert!(full.contains("/data/cap") && full.contains("100.0 GB free") && full.contains("528.4 GB"), "{full}");
        let long = e.check(out, Some(u64::MAX), false).unwrap_err().to_string();
        assert!(long.contains("--frames = 1000000") && long.contains("11.1 h") && long.contains("--yes"), "{long}");
        assert!(e.check(out, Some(u64::MAX), true).is_ok());
        assert!(e.check(out, None, true).is_ok());
        // Ten frames: nothing to ask.
        assert!(RecordingEstimate::new(&applied(Some(25.0)), 10).check(out, Some(10_000_000), false).is_ok());
        // No frame rate: the exposure and the readout bound it from below.
        let bound = RecordingEstimate::new(&applied(None), 1000);
        assert!(bound.at_least && (bound.seconds - 1000.0 * (1000.0 + 5120.0) / 1e6).abs() < 1e-9);
        assert!(bound.describe().contains("at least about"));
        assert!(free_bytes_for(&std::env::temp_dir().join("not-yet/made")).is_some_and(|f| f > 0));
    }
}
