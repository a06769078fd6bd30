//! rollcam: video from one rolling-shutter photograph taken through a diffuser.
//!
//! One folder per layer; each layer uses only the layers above it in this list:
//!
//! - [`model`]: the paper's forward model. Timing to exact shutter weights, the capture
//!   description, PSF and raw preparation, planned FFT convolution, the imaging operator
//!   `A`, scene restrictions, consecutive captures stacked on one time grid. No files,
//!   no hardware.
//! - [`solve`]: a [`solve::problem::Problem`] built once from a prepared capture (tau
//!   resolved once, the operator and its cache key built in one place), prox maps
//!   (TV Haar, TV dual), the optimisers (FISTA, MFISTA, PGD, ADMM) over their shared
//!   types, Lipschitz constants, the error-against-run-time trace, sequences.
//! - [`sim`]: the physical simulator (scenes, synthetic PSFs, exposure, noise) and the
//!   set-ups of `simulate`, `demo` and the simulated camera.
//! - [`io`]: file formats, capture.toml and output folders, the Lipschitz cache; capture
//!   folders read through the crate `rollcam_files` (below the hardware crate and this
//!   one), never through the hardware crate, which only `lab` and the commands name.
//! - [`request`]: the library's requests, one per mode (one capture, a sequence of
//!   captures): what every front-end calls.
//! - [`analysis`]: videos to figures and reports (time courses, spectra, LED sweep).
//! - [`perf`]: timing and memory of the reconstruction on synthetic presets.
//! - [`cluster`]: several processes on one capture: the MPI implementation of the
//!   model's `Ranks` (cargo feature `mpi`) and how a launcher's processes know it.
//! - [`lab`]: the bench: the live pipeline and a session assembled from plain data, the
//!   live page, the simulated cameras, simulated captures written as a bench gives
//!   them, and the one mapping between the hardware crate's types and the model's.
//!
//! The command-line tool (`src/cli/`, `src/main.rs`) only parses, validates once and
//! reports. A capture flows `io` (raw, PSF, capture.toml) -> [`request::capture`]:
//! `model::prepare` -> `solve::problem::Problem` -> `solve::reconstruct` (tau resolved
//! once, the optimiser with the trace as its observer) -> `io::output` (video,
//! summary.json) -> `analysis`.

// `!(x > 0.0)` and the like are deliberate: they reject NaN with the bad values.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod analysis;
pub mod cluster;
pub mod io;
pub mod lab;
pub mod model;
pub mod perf;
pub mod request;
pub mod sim;
pub mod solve;
