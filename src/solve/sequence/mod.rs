//! Consecutive captures reconstructed as one continuous video.
//!
//! A capture folder (as the recorder writes it: a 16-bit TIFF and a JSON sidecar per
//! raw frame) holds `C` consecutive rolling-shutter raws. Each covers `K` video frames
//! of `T_f` (its shutter model); [`crate::model::time_grid`] places them on one global time grid from
//! their device timestamps or a given frame period, flags the frames no capture covers
//! (gap frames, left to the temporal TV) and measures the exposure weight every frame
//! gets. [`crate::model::stacked`] stacks the per-capture operators on slices of one long video
//! (overlapping captures add up). [`solve`] reconstructs the sequence jointly (one
//! FISTA solve), streaming (capture by capture over its frames plus an overlap with
//! the previous result, warm-started from it) or each capture separately (for
//! comparison); [`stream`] does the streaming solve fed capture by capture, for a
//! live pipeline. [`crate::io::sequence_input`] reads the folder; [`crate::io::sequence_output`]
//! writes the result.

pub mod error;
pub mod solve;
pub mod stream;

pub use crate::model::stacked::{Placed, SequenceModel};
pub use crate::model::time_grid::{TimeGrid, TimeSource};
pub use error::SequenceError;
pub use solve::{Mode, Sequence, SequenceVideo, SolveReport, Window};
pub use stream::{StreamStep, StreamWindows, Streamer};
