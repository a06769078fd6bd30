//! Consecutive captures reconstructed as one continuous video.
//!
//! A capture folder (as the recorder writes it: a 16-bit TIFF and a JSON sidecar per
//! raw frame) holds `C` consecutive rolling-shutter raws. Each covers `K` video frames
//! of `T_f` (its shutter model); [`grid`] places them on one global time grid from
//! their device timestamps or a given frame period, flags the frames no capture covers
//! (gap frames, left to the temporal TV) and measures the exposure weight every frame
//! gets. [`model`] stacks the per-capture operators on slices of one long video
//! (overlapping captures add up). [`solve`] reconstructs the sequence jointly (one
//! FISTA solve), streaming (capture by capture over its frames plus an overlap with
//! the previous result, warm-started from it) or each capture separately (for
//! comparison); [`stream`] does the streaming solve fed capture by capture, for a
//! live pipeline. [`input`] reads the folder; [`output`] writes the result.

pub mod grid;
pub mod input;
pub mod model;
pub mod output;
pub mod solve;
pub mod stream;

pub use grid::{TimeGrid, TimeSource};
pub use input::{load_capture_folder, SequenceInput, Skipped};
pub use model::{Placed, SequenceModel};
pub use solve::{Mode, Sequence, SequenceVideo, SolveReport, Window};
pub use stream::{StreamStep, Streamer};

use crate::prepare::PrepareError;
use crate::reconstruct::ReconstructError;
use crate::shutter::TimingError;

/// Everything that can be wrong with a sequence, naming the file or field.
#[derive(Debug, thiserror::Error)]
pub enum SequenceError {
    #[error("{0}")]
    Capture(#[from] rollcam_hw::record::RecordError),
    #[error("{dir}: no complete raw frame to reconstruct ({found} sidecars, {skipped} skipped)")]
    NoFrames { dir: String, found: usize, skipped: usize },
    #[error("{file}: {got_cols} x {got_rows} pixels (width x height), expected {expected}")]
    Size { file: String, got_rows: u32, got_cols: u32, expected: String },
    #[error(
        "{file}: device_timestamp_ns is 0 (the camera gave no timestamp): pass --frame-period-us P to place the captures from their sequence numbers{hint}"
    )]
    NoTimestamps { file: String, hint: String },
    #[error("{file}: device_timestamp_ns = {got} is not after {prev_file}'s ({prev}): the timestamps are unreliable; pass --frame-period-us P")]
    TimestampOrder { file: String, got: u64, prev_file: String, prev: u64 },
    #[error("{what} = {value_us} us: shorter than {limit}: consecutive captures cannot start that close together")]
    Spacing { what: String, value_us: f64, limit: String },
    #[error("frame period {0} us (--frame-period-us): expected a positive, finite time in microseconds")]
    Period(f64),
    #[error(
        "a joint solve of {captures} captures ({frames} frames of {rows} x {cols}) needs {}, above the limit of {}: use --mode streaming (one video volume plus one window's solve) or raise --memory-limit-gb",
        bytes_text(*needed_bytes),
        bytes_text(*limit_bytes)
    )]
    Memory { captures: usize, frames: usize, rows: usize, cols: usize, needed_bytes: u64, limit_bytes: u64 },
    #[error("{what}: shape {got:?} does not match the sequence video's (frames, rows, cols) = {expected:?}")]
    TruthShape { what: String, got: Vec<usize>, expected: Vec<usize> },
    #[error("{0}")]
    Prepare(#[from] PrepareError),
    #[error("{0}")]
    Timing(#[from] TimingError),
    #[error("{0}")]
    Reconstruct(#[from] ReconstructError),
}

/// Bytes in GB, or MB below one GB.
fn bytes_text(b: u64) -> String {
    if b >= 1_000_000_000 {
        format!("{:.2} GB", b as f64 / 1e9)
    } else {
        format!("{:.2} MB", b as f64 / 1e6)
    }
}
