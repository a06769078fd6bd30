//! NumPy `.npy` files.

use std::io::Cursor;
use std::path::Path;

use ndarray::{Array4, ArrayD, ArrayView4, Axis};
use ndarray_npy::{ReadNpyError, ReadNpyExt, WriteNpyExt};

use super::atomic::write_atomic;
use super::error::IoError;
use super::format::{check_magic, read_bytes};

/// Decodes an in-memory `.npy` holding float32, float64, uint8 or uint16 values (any
/// number of axes, C or Fortran order) into f32 values, unchanged in value.
pub(crate) fn decode_npy(path: &Path, bytes: &[u8]) -> Result<ArrayD<f32>, IoError> {
    check_magic(path, bytes, "NPY")?;
    let err = |e: ReadNpyError| match e {
        ReadNpyError::MissingData => {
            IoError::Truncated { path: path.to_path_buf(), format: "NPY", detail: "the data is shorter than the header announces".into() }
        }
        ReadNpyError::Io(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            IoError::Truncated { path: path.to_path_buf(), format: "NPY", detail: "file ends early".into() }
        }
        other => IoError::malformed(path, "NPY", other),
    };
    macro_rules! attempt {
        ($t:ty, $conv:expr) => {
            match ArrayD::<$t>::read_npy(Cursor::new(bytes)) {
                Ok(a) => return Ok(a.mapv($conv)),
                Err(ReadNpyError::WrongDescriptor(_)) => {}
                Err(e) => return Err(err(e)),
            }
        };
    }
    attempt!(f32, |v| v);
    attempt!(f64, |v| v as f32);
    attempt!(u8, f32::from);
    attempt!(u16, f32::from);
    Err(IoError::unexpected(path, "an array of float32, float64, uint8 or uint16", format!("dtype {}", npy_descr(bytes).unwrap_or_else(|| "unknown".into()))))
}

/// The `descr` entry of an npy header, for error messages.
fn npy_descr(bytes: &[u8]) -> Option<String> {
    let head = std::str::from_utf8(bytes.get(10..bytes.len().min(4096))?).ok()?;
    let start = head.find("'descr'")? + "'descr'".len();
    let rest = &head[start..];
    let q1 = rest.find('\'')? + 1;
    let q2 = rest[q1..].find('\'')?;
    Some(rest[q1..q1 + q2].to_string())
}

/// Reads a video from `.npy`: 3 axes (frame, row, col) become one channel, 4 axes
/// (frame, row, col, channel) must have 1 or 3 channels. Accepts float32, float64, uint8,
/// uint16; values are kept as stored.
pub fn read_npy(path: impl AsRef<Path>) -> Result<Array4<f32>, IoError> {
    let path = path.as_ref();
    let bytes = read_bytes(path)?;
    npy_to_video(path, decode_npy(path, &bytes)?)
}

pub(crate) fn npy_to_video(path: &Path, a: ArrayD<f32>) -> Result<Array4<f32>, IoError> {
    let a = match a.ndim() {
        3 => a.insert_axis(Axis(3)),
        4 => a,
        n => return Err(IoError::unexpected(path, "float32 array with 3 or 4 axes (frame, row, col[, channel])", n.to_string())),
    };
    let ch = a.shape()[3];
    if ch != 1 && ch != 3 {
        return Err(IoError::unexpected(path, "1 or 3 channels on the last axis", format!("{ch} channels")));
    }
    a.into_dimensionality().map_err(|e| IoError::malformed(path, "NPY", e))
}

/// Writes a video as float32 `.npy` (C order, little-endian), axes (frame, row, col) when
/// there is one channel, (frame, row, col, channel) otherwise.
pub fn write_npy(path: impl AsRef<Path>, video: ArrayView4<f32>) -> Result<(), IoError> {
    let path = path.as_ref();
    let shape = video.shape().to_vec();
    let data = if shape[3] == 1 { video.index_axis(Axis(3), 0).into_dyn().to_owned() } else { video.into_dyn().to_owned() };
    write_atomic(path, |w| {
        data.write_npy(w).map_err(|e| match e {
            ndarray_npy::WriteNpyError::Io(io) => IoError::os(path, "cannot write", io),
            other => IoError::bad_input(path, format!("npy encoder: {other}")),
        })
    })
}
