//! The files rollcam's two crates share, below both: the hardware crate (`rollcam-hw`)
//! records capture folders and the main crate (`rollcam`) reads them and writes images,
//! and both go through here. It depends on neither, so Cargo keeps the rule that a file
//! format reaches no camera, no solver and no result folder.
//!
//! - [`input`]: the one way an input file is read (a regular file, a bounded size);
//! - [`tiff`]: the one TIFF codec (pages, limits, ImageJ stacks, 16-bit frames);
//! - [`frame`]: camera settings and frames with their metadata, the data a capture
//!   folder records (plain serde data, no device access);
//! - [`capture`]: the capture folder, written crash-safe by [`capture::Recorder`] and
//!   read by [`capture::CaptureReader`].

pub mod capture;
pub mod frame;
pub mod input;
pub mod temp;
pub mod tiff;
