//! The library's requests, one per mode: what every front-end (the command line, the
//! Python module, the live bench worker, the LED sweep, the demo) asks for, and what it
//! gets back. A front-end only parses its inputs, builds a request, calls it and
//! reports the outcome.
//!
//! - [`capture`]: one capture to one video ([`capture::CaptureRequest`] ->
//!   [`capture::CaptureOutcome`]): prepare the raw and PSF, check the memory budget,
//!   report the sensor, build the problem, choose and resolve tau, solve every
//!   channel, write the folder when asked.
//! - [`split`]: one capture across MPI ranks ([`split::SplitRequest`]): every rank
//!   prepares, checks its machine's memory and solves its block of frames.
//! - [`compare`]: the solvers side by side on one channel ([`compare::CompareRequest`]
//!   -> [`compare::CompareOutcome`]): the weight resolved as for one capture, the
//!   declared problem and its Lipschitz constant built once, every run on it.
//! - [`stream`]: consecutive captures as they arrive ([`stream::StreamRequest`] ->
//!   [`stream::Stream`]): each prepared, placed and solved over its window, the weight
//!   resolved on the first.
//! - [`sequence`]: a folder of consecutive captures to one continuous video
//!   ([`sequence::SequenceRequest`] -> [`sequence::SequenceOutcome`]): read and place
//!   the captures, resolve tau once for all of them, check the truth and the memory
//!   limit, solve (joint, streaming or separate), write the folder.
//!
//! This layer sits above `io` (it reads and writes files) and below `analysis`, `lab`
//! and the command line, which call it.

pub mod capture;
pub mod compare;
pub mod sequence;
pub mod split;
pub mod stream;

// What a front-end hands a request and reads back, under the request layer's name: the
// settings it checks, the hooks a solve calls, the rows of its trace.
pub use crate::solve::estimate::estimate;
pub use crate::solve::optimize::{Device, SolverKind};
pub use crate::solve::plan::SolvePlan;
pub use crate::solve::problem::{InvalidSetting, SolveParams, SolveSettings, ValidSettings, DEFAULT_ALPHA, DEFAULT_ITERS, DEFAULT_OBJ_TOL};
pub use crate::solve::prox::tv_dual::TvProxChoice;
pub use crate::solve::reconstruct::Hooks;
pub use crate::solve::start::Start;
pub use crate::solve::tau::{parse_f32, Tau};
pub use crate::solve::trace::{TraceRow, ZERO_TRUTH};

use crate::io::{IoError, OverBudget};
use crate::model::prepare::PrepareError;
use crate::model::scene::SceneError;
use crate::solve::reconstruct::ReconstructError;
use crate::solve::sequence::SequenceError;

/// Why a request failed, naming the step.
#[derive(Debug, thiserror::Error)]
pub enum RequestError {
    #[error(transparent)]
    Setting(#[from] InvalidSetting),
    #[error(transparent)]
    Prepare(#[from] PrepareError),
    #[error("reconstruction failed: {0}")]
    Reconstruct(#[from] ReconstructError),
    /// Building a problem (before any solve).
    #[error("{0}")]
    Solve(ReconstructError),
    #[error("{0}")]
    Scene(#[from] SceneError),
    /// Reading or placing a sequence's captures.
    #[error(transparent)]
    Sequence(#[from] SequenceError),
    #[error("sequence reconstruction failed: {0}")]
    SequenceSolve(SequenceError),
    #[error(transparent)]
    Io(#[from] IoError),
    /// The solve would not fit the memory budget (boxed: it is large and rare).
    #[error("{0}")]
    Budget(#[from] Box<OverBudget>),
    /// An input that does not fit the request (e.g. a truth of another shape).
    #[error("{0}")]
    Invalid(String),
}
