//! The library's requests, one per mode: what every front-end (the command line, the
//! Python module, the live bench worker, the LED sweep, the demo) asks for, and what it
//! gets back. A front-end only parses its inputs, builds a request, calls it and
//! reports the outcome.
//!
//! - [`capture`]: one capture to one video ([`capture::CaptureRequest`] ->
//!   [`capture::CaptureOutcome`]): prepare the raw and PSF, build the problem, choose
//!   and resolve tau, solve every channel, write the folder when asked.
//! - [`sequence`]: a folder of consecutive captures to one continuous video
//!   ([`sequence::SequenceRequest`] -> [`sequence::SequenceOutcome`]): read and place
//!   the captures, resolve tau once for all of them, check the truth and the memory
//!   limit, solve (joint, streaming or separate), write the folder.
//!
//! This layer sits above `io` (it reads and writes files) and below `analysis`, `lab`
//! and the command line, which call it.

pub mod capture;
pub mod sequence;

use crate::io::IoError;
use crate::model::prepare::PrepareError;
use crate::solve::problem::InvalidSetting;
use crate::solve::reconstruct::ReconstructError;
use crate::solve::sequence::SequenceError;

/// Why a request failed, naming the step.
#[derive(Debug, thiserror::Error)]
pub enum RequestError {
    #[error("{0}")]
    Setting(#[from] InvalidSetting),
    #[error("{0}")]
    Prepare(#[from] PrepareError),
    #[error("reconstruction failed: {0}")]
    Reconstruct(#[from] ReconstructError),
    /// Reading or placing a sequence's captures.
    #[error("{0}")]
    Sequence(#[from] SequenceError),
    #[error("sequence reconstruction failed: {0}")]
    SequenceSolve(SequenceError),
    #[error("{0}")]
    Io(#[from] IoError),
    /// An input that does not fit the request (e.g. a truth of another shape).
    #[error("{0}")]
    Invalid(String),
}
