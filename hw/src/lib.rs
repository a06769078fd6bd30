//! Hardware for the rollcam bench: cameras (GenICam through aravis, replay of recorded
//! captures, simulated), the recorder that puts every frame on disk first, USB
//! discovery, and the LED pulse controller.

pub mod camera;
pub mod input;
pub mod led;
pub mod record;
#[cfg(feature = "usb")]
pub mod usb;
