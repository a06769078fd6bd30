//! The [`Camera`] trait every backend implements.

use std::time::Duration;

use super::error::CameraError;
use rollcam_files::frame::{AppliedSettings, CameraInfo, CameraSettings, Capabilities, Frame, SensorGeometry};

/// One camera, driven from one thread.
pub trait Camera: Send {
    /// Identity of the open camera.
    fn info(&self) -> &CameraInfo;
    /// Full sensor size and depth.
    fn geometry(&mut self) -> Result<SensorGeometry, CameraError>;
    /// Ranges and choices the device reports.
    fn capabilities(&mut self) -> Result<Capabilities, CameraError>;
    /// Apply settings (only the `Some` fields) and return what the device reports back.
    /// Refused while streaming.
    fn configure(&mut self, settings: &CameraSettings) -> Result<AppliedSettings, CameraError>;
    /// Read the current settings back from the device.
    fn applied_settings(&mut self) -> Result<AppliedSettings, CameraError>;
    /// Start acquisition.
    fn start(&mut self) -> Result<(), CameraError>;
    /// Fire one software trigger (trigger mode must be [`Trigger::Software`](rollcam_files::frame::Trigger::Software)).
    fn software_trigger(&mut self) -> Result<(), CameraError>;
    /// Wait up to `timeout` for the next frame.
    fn next_frame(&mut self, timeout: Duration) -> Result<Frame, CameraError>;
    /// Stop acquisition. Idempotent.
    fn stop(&mut self) -> Result<(), CameraError>;
}
