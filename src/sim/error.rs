//! [`SimError`], the simulator's errors, each naming what was expected.

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
    #[error("scene radiance at (row {row}, col {col}) integrates to a non-finite value: expected finite photo-electrons")]
    SceneNotFinite { row: usize, col: usize },
    #[error("capture timing: {0}")]
    Timing(#[from] TimingError),
    #[error("{field} = {value}: expected {expected}")]
    Invalid { field: &'static str, value: String, expected: String },
    #[error("{origin}: no light above the dark level {dark:.1}: expected a point-source image")]
    PsfNoLight { origin: String, dark: f64 },
}

pub(crate) fn invalid(field: &'static str, value: impl std::fmt::Display, expected: impl Into<String>) -> SimError {
    SimError::Invalid { field, value: value.to_string(), expected: expected.into() }
}
