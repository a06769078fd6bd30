//! rollcam: video from one rolling-shutter photograph taken through a diffuser.
pub mod io;
