pub mod placeholder {}

pub mod camera;
pub mod record;
#[cfg(feature = "usb")]
pub mod usb;
