//! The capture folder the recorder writes and replay reads: its format lives in
//! `rollcam-files` (the main crate reads capture folders too); re-exported here.

pub use rollcam_files::capture::*;
