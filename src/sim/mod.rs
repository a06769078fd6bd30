//! Physical simulator: a synthetic diffuser PSF ([`psf`]), time-varying scenes
//! ([`scene`]) and the rolling-shutter capture integrated in continuous time at raw
//! resolution, with sensor noise ([`expose`]).
//!
//! The simulator never uses the reconstruction's discrete operator: each raw row
//! integrates the scene, seen through the PSF, over its own exposure window
//! `[s_i, s_i + T_e)` (from [`crate::model::shutter::Timing::raw_row_starts_us`]). The
//! ground-truth video is the scene integrated over each frame interval on the
//! reconstruction grid, so that `A(truth)` can be compared with the raw image.

pub mod expose;
pub mod psf;
pub mod scene;
pub mod sequence;

pub use crate::model::resample::box_downsample;
pub use expose::{simulate, NoiseModel, Simulation};
pub use psf::{lenslet_psf, LensletParams};
pub use scene::{ImageStack, LedArray, MovingDisc, Scene};
pub use sequence::{readout_period_us, simulate_sequence, SequenceSimulation, TimeShifted};

use crate::model::shutter::TimingError;

/// Errors of the simulator, each naming what was expected.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error("PSF has {got} values: expected rows x cols of the capture = {rows} x {cols} = {}", rows * cols)]
    PsfSize { rows: usize, cols: usize, got: usize },
    #[error("PSF value at (row {row}, col {col}) is {value}: expected finite values")]
    PsfNotFinite { row: usize, col: usize, value: f32 },
    #[error("scene is {got_rows} x {got_cols} pixels: expected the raw sensor size {rows} x {cols}")]
    SceneSize { rows: usize, cols: usize, got_rows: usize, got_cols: usize },
    #[error(
        "scene radiance at (row {row}, col {col}) integrates to a non-finite value: expected finite photo-electrons"
    )]
    SceneNotFinite { row: usize, col: usize },
    #[error("capture timing: {0}")]
    Timing(#[from] TimingError),
    #[error("{field} = {value}: expected {expected}")]
    Invalid { field: &'static str, value: String, expected: String },
}

pub(crate) fn invalid(field: &'static str, value: impl std::fmt::Display, expected: impl Into<String>) -> SimError {
    SimError::Invalid { field, value: value.to_string(), expected: expected.into() }
}
