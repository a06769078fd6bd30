//! Replay camera: plays back a capture folder written by [`crate::record::Recorder`],
//! with optional fault injection ([`ReplayFaults`]) for testing consumers.

use std::path::Path;
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use super::device::Camera;
use super::error::CameraError;
use super::stream::{host_now_ns, GapFiller};
use crate::record::CaptureReader;
use rollcam_files::frame::{AppliedSettings, CameraInfo, CameraSettings, Capabilities, Frame, FrameStatus, SensorGeometry, Trigger};

/// How fast frames are handed out.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Pace {
    /// Reproduce the recorded host arrival times (relative to `start`).
    Recorded,
    /// Hand out each frame as soon as it is asked for.
    #[default]
    AsFastAsConsumed,
}

/// Faults to inject, by position of the frame in the recording (0-based).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ReplayFaults {
    /// These frames never arrive; the consumer sees a [`FrameStatus::Dropped`] frame
    /// (detected from the gap in frame ids).
    pub drop: Vec<u64>,
    /// These frames arrive with only the first half of their samples ([`FrameStatus::Incomplete`]).
    pub truncate: Vec<u64>,
    /// Before this frame, the device goes silent for this long.
    pub stall_at: Option<(u64, Duration)>,
    /// Before this frame, the device disappears: this and every later call fails
    /// with [`CameraError::Disconnected`].
    pub disconnect_at: Option<u64>,
}

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ReplayOptions {
    pub pace: Pace,
    pub faults: ReplayFaults,
}

/// A camera that replays a recorded capture folder.
pub struct ReplayCamera {
    info: CameraInfo,
    reader: CaptureReader,
    options: ReplayOptions,
    settings: AppliedSettings,
    geometry: SensorGeometry,
    streaming: bool,
    cursor: usize,
    started_at: Option<Instant>,
    stall_until: Option<Instant>,
    stall_done: bool,
    disconnected: bool,
    trigger_credits: u64,
    gaps: GapFiller,
}

impl ReplayCamera {
    /// Open a capture folder.
    pub fn open(dir: impl AsRef<Path>, options: ReplayOptions) -> Result<Self, CameraError> {
        let dir = dir.as_ref();
        let id = dir.display().to_string();
        if !dir.is_dir() {
            return Err(CameraError::NotFound { backend: "replay".into(), id, available: Vec::new() });
        }
        let reader = CaptureReader::open(dir)?;
        let settings = reader
            .session()
            .applied
            .clone()
            .or_else(|| reader.metas().first().map(|m| m.settings.clone()))
            .ok_or_else(|| CameraError::State { camera: format!("replay:{id}"), message: "capture holds no frames and no applied settings".into() })?;
        let recorded = &reader.session().camera;
        let geometry = reader.session().geometry.unwrap_or(SensorGeometry {
            width: settings.roi.x + settings.roi.width,
            height: settings.roi.y + settings.roi.height,
            max_bit_depth: settings.pixel_format.bit_depth(),
        });
        let info = CameraInfo {
            backend: "replay".into(),
            id,
            vendor: recorded.vendor.clone(),
            model: recorded.model.clone(),
            serial: recorded.serial.clone(),
            address: Some(dir.display().to_string()),
            protocol: Some(format!("replay of {}", recorded.spec())),
        };
        tracing::info!(camera = %info.spec(), frames = reader.len(), "opened replay");
        Ok(ReplayCamera {
            info,
            reader,
            options,
            settings,
            geometry,
            streaming: false,
            cursor: 0,
            started_at: None,
            stall_until: None,
            stall_done: false,
            disconnected: false,
            trigger_credits: 0,
            gaps: GapFiller::new(),
        })
    }

    /// Number of recorded frames.
    pub fn len(&self) -> usize {
        self.reader.len()
    }

    pub fn is_empty(&self) -> bool {
        self.reader.is_empty()
    }

    fn name(&self) -> String {
        self.info.spec()
    }

    fn mismatch(&self, setting: &str, requested: String, recorded: String) -> CameraError {
        CameraError::Unsupported { camera: self.name(), setting: setting.into(), value: requested, expected: format!("{recorded} (fixed by the recording)") }
    }

    fn disconnected_error(&self) -> CameraError {
        CameraError::Disconnected { camera: self.name(), detail: format!("device vanished before recorded frame {}", self.cursor) }
    }
}

fn same(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-6 * a.abs().max(b.abs()).max(1.0)
}

impl Camera for ReplayCamera {
    fn info(&self) -> &CameraInfo {
        &self.info
    }

    fn geometry(&mut self) -> Result<SensorGeometry, CameraError> {
        Ok(self.geometry)
    }

    fn capabilities(&mut self) -> Result<Capabilities, CameraError> {
        let s = &self.settings;
        Ok(Capabilities {
            exposure_range_us: Some((s.exposure_us, s.exposure_us)),
            line_time_range_us: s.line_time_us.map(|l| (l, l)),
            frame_rate_range_hz: s.frame_rate_hz.map(|f| (f, f)),
            shutter_modes: s.shutter.into_iter().collect(),
            pixel_formats: vec![s.pixel_format],
            max_binning: s.binning,
            software_trigger: s.trigger == Trigger::Software,
            hardware_trigger_lines: Vec::new(),
        })
    }

    fn configure(&mut self, req: &CameraSettings) -> Result<AppliedSettings, CameraError> {
        if self.streaming {
            return Err(CameraError::State { camera: self.name(), message: "cannot configure while streaming".into() });
        }
        let s = &self.settings;
        if let Some(v) = req.exposure_us {
            if !same(v, s.exposure_us) {
                return Err(self.mismatch("exposure_us", v.to_string(), s.exposure_us.to_string()));
            }
        }
        if let Some(v) = req.line_time_us {
            if s.line_time_us.map_or(true, |l| !same(v, l)) {
                return Err(self.mismatch("line_time_us", v.to_string(), format!("{:?}", s.line_time_us)));
            }
        }
        if let Some(v) = req.frame_rate_hz {
            if s.frame_rate_hz.map_or(true, |l| !same(v, l)) {
                return Err(self.mismatch("frame_rate_hz", v.to_string(), format!("{:?}", s.frame_rate_hz)));
            }
        }
        if let Some(v) = req.shutter {
            if s.shutter != Some(v) {
                return Err(self.mismatch("shutter", v.to_string(), format!("{:?}", s.shutter)));
            }
        }
        if let Some(v) = req.roi {
            if s.roi != v {
                return Err(self.mismatch("roi", format!("{v:?}"), format!("{:?}", s.roi)));
            }
        }
        if let Some(v) = req.binning {
            if s.binning != v {
                return Err(self.mismatch("binning", format!("{v:?}"), format!("{:?}", s.binning)));
            }
        }
        if let Some(v) = req.pixel_format {
            if s.pixel_format != v {
                return Err(self.mismatch("pixel_format", v.to_string(), s.pixel_format.to_string()));
            }
        }
        if let Some(v) = &req.trigger {
            if &s.trigger != v {
                return Err(self.mismatch("trigger", v.to_string(), s.trigger.to_string()));
            }
        }
        Ok(self.settings.clone())
    }

    fn applied_settings(&mut self) -> Result<AppliedSettings, CameraError> {
        Ok(self.settings.clone())
    }

    fn start(&mut self) -> Result<(), CameraError> {
        if self.disconnected {
            return Err(self.disconnected_error());
        }
        self.streaming = true;
        self.cursor = 0;
        self.started_at = Some(Instant::now());
        self.stall_until = None;
        self.stall_done = false;
        self.trigger_credits = 0;
        self.gaps.reset();
        Ok(())
    }

    fn software_trigger(&mut self) -> Result<(), CameraError> {
        if self.settings.trigger != Trigger::Software {
            return Err(CameraError::State {
                camera: self.name(),
                message: format!("software trigger sent but the recording used trigger {}", self.settings.trigger),
            });
        }
        self.trigger_credits += 1;
        Ok(())
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Frame, CameraError> {
        if !self.streaming {
            return Err(CameraError::State { camera: self.name(), message: "next_frame called before start".into() });
        }
        if let Some(f) = self.gaps.pop() {
            return Ok(f);
        }
        let deadline = Instant::now() + timeout;
        let timeout_err = |cam: &Self| CameraError::Timeout { camera: cam.name(), timeout_ms: timeout.as_millis() as u64 };
        loop {
            if self.disconnected {
                return Err(self.disconnected_error());
            }
            if self.cursor >= self.reader.len() {
                return Err(CameraError::EndOfStream { camera: self.name(), frames: self.cursor as u64 });
            }
            let idx = self.cursor as u64;
            if self.options.faults.disconnect_at == Some(idx) {
                self.disconnected = true;
                tracing::warn!(camera = %self.name(), frame = idx, "replay fault: disconnect");
                return Err(self.disconnected_error());
            }
            if let Some((at, stall)) = self.options.faults.stall_at {
                if at == idx && !self.stall_done {
                    let until = *self.stall_until.get_or_insert_with(|| Instant::now() + stall);
                    if until > deadline {
                        std::thread::sleep(deadline.saturating_duration_since(Instant::now()));
                        return Err(timeout_err(self));
                    }
                    std::thread::sleep(until.saturating_duration_since(Instant::now()));
                    self.stall_done = true;
                }
            }
            if self.settings.trigger == Trigger::Software && self.trigger_credits == 0 {
                std::thread::sleep(deadline.saturating_duration_since(Instant::now()));
                return Err(timeout_err(self));
            }
            let recorded = self.reader.read_frame(self.cursor)?;
            if self.options.pace == Pace::Recorded {
                let first = self.reader.metas()[0].host_timestamp_ns;
                let offset = Duration::from_nanos(recorded.meta.host_timestamp_ns.saturating_sub(first));
                let due = self.started_at.expect("set by start") + offset;
                if due > deadline {
                    std::thread::sleep(deadline.saturating_duration_since(Instant::now()));
                    return Err(timeout_err(self));
                }
                std::thread::sleep(due.saturating_duration_since(Instant::now()));
            }
            self.cursor += 1;
            if self.settings.trigger == Trigger::Software {
                self.trigger_credits -= 1;
            }
            if self.options.faults.drop.contains(&idx) {
                tracing::debug!(camera = %self.name(), frame = idx, "replay fault: drop");
                continue;
            }
            let mut frame = recorded;
            frame.meta.camera = self.name();
            frame.meta.host_timestamp_ns = host_now_ns();
            if self.options.faults.truncate.contains(&idx) && frame.meta.status != FrameStatus::Dropped {
                let keep = frame.pixels.len() / 2;
                frame.pixels.truncate(keep);
                frame.meta.valid_pixels = keep as u64;
                frame.meta.status = FrameStatus::Incomplete;
                tracing::debug!(camera = %self.name(), frame = idx, "replay fault: truncate");
            }
            return Ok(self.gaps.push(frame));
        }
    }

    fn stop(&mut self) -> Result<(), CameraError> {
        self.streaming = false;
        Ok(())
    }
}
