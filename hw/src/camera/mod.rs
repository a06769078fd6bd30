//! Camera abstraction: one trait, several backends.
//!
//! A [`Camera`] is owned by one thread at a time (`Send`, not `Sync`). The
//! life cycle is `open` → [`Camera::configure`] → [`Camera::start`] →
//! [`Camera::next_frame`]… → [`Camera::stop`]. Every [`Frame`] carries
//! [`FrameMeta`]: ids, device and host timestamps, a [`FrameStatus`] and the
//! [`AppliedSettings`] read back from the device when acquisition started.
//!
//! Backends:
//! * [`aravis`] (feature `aravis`): GenICam cameras (GigE Vision, USB3 Vision)
//!   through the system libaravis, with per-vendor [`profile::CameraProfile`]s.
//! * [`replay`]: plays back a capture folder written by [`crate::record`],
//!   with data-driven fault injection.
//! * [`simulated`]: frames produced by a [`simulated::FrameRenderer`].
//!
//! The items live in one file each and are re-exported here: [`types`] (settings,
//! geometry, frames: plain data, in `rollcam-files` beside the capture folder that
//! records them), [`error`] ([`CameraError`], [`check_range`]), [`device`] (the
//! trait), [`stream`] (host clock, [`GapFiller`], [`bytes_to_u16`]) and [`spec`]
//! ([`CameraSpec`], [`open()`]).

#[cfg(feature = "aravis")]
pub mod aravis;
pub mod device;
pub mod error;
pub mod profile;
pub mod replay;
pub mod simulated;
pub mod spec;
pub mod stream;
pub use rollcam_files::frame as types;

pub use device::Camera;
pub use error::{check_range, CameraError};
pub use spec::{open, CameraSpec};
pub use stream::{bytes_to_u16, host_now_ns, GapFiller};
pub use types::{
    AppliedSettings, Binning, CameraInfo, CameraSettings, CameraShutter, Capabilities, Edge, Frame, FrameMeta, FrameStatus, PixelFormat, Roi, SensorGeometry,
    Trigger,
};
