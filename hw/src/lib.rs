//! Hardware for the rollcam bench: cameras (GenICam through aravis, replay of recorded
//! captures, simulated), the recorder that puts every frame on disk first, USB
//! discovery, and the LED pulse controller.
//!
//! The files it shares with the main crate (bounded reads, the capture folder, the frame
//! types, the TIFF codec) live in `rollcam-files`, below both.

pub mod camera;
pub mod led;
pub mod record;
#[cfg(feature = "usb")]
pub mod usb;
