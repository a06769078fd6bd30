//! What can be wrong with a sequence, naming the file or field.

use crate::model::prepare::PrepareError;
use crate::model::shutter::TimingError;
use crate::solve::reconstruct::ReconstructError;

/// Everything that can be wrong with a sequence, naming the file or field.
#[derive(Debug, thiserror::Error)]
pub enum SequenceError {
    /// Reading the capture folder failed (the recorder's own message).
    #[error("{0}")]
    Capture(String),
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

/// Captures must start at least one video frame time (`tf`) and one exposure (`te`)
/// apart: closer, two of them would start in the same video frame, or a row would
/// start its next exposure before the last one ended.
pub fn check_spacing(what: String, value_us: f64, tf: f64, te: f64) -> Result<(), SequenceError> {
    let tol = 1e-9 * tf.max(te);
    if value_us + tol < tf {
        return Err(SequenceError::Spacing { what, value_us, limit: format!("one video frame time T_f = {tf} us") });
    }
    if value_us + tol < te {
        return Err(SequenceError::Spacing {
            what,
            value_us,
            limit: format!("the exposure ({te} us): a row would start its next exposure before the last one ended"),
        });
    }
    Ok(())
}
