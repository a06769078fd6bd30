//! NumPy `.npy` files: float32, float64, uint8 or uint16 arrays read; float32 written.

use std::io::{Cursor, Read};
use std::path::Path;

use ndarray::{Array3, Array4, ArrayD, ArrayView4, Axis};
use ndarray_npy::{ReadNpyError, ReadNpyExt, WriteNpyExt};

use super::image_format::{one_image, ImageFormat, StackWriter};
use crate::io::atomic::write_atomic;
use crate::io::budget::{array_bytes, ByteBudget};
use crate::io::error::IoError;

/// The NumPy `.npy` format (versions 1 to 3).
pub(crate) struct Npy;

impl ImageFormat for Npy {
    fn name(&self) -> &'static str {
        "NPY"
    }

    fn extensions(&self) -> &'static [&'static str] {
        &["npy"]
    }

    fn sniff(&self, bytes: &[u8]) -> bool {
        bytes.starts_with(b"\x93NUMPY")
    }

    /// An array file, usually a video: not a frame of a folder of images.
    fn folder_frames(&self) -> bool {
        false
    }

    /// 2 axes (row, col) or 3 axes (row, col, channel), 1 or 3 channels.
    fn decode_image(&self, path: &Path, bytes: &[u8], page: Option<usize>, budget: &ByteBudget) -> Result<Array3<f32>, IoError> {
        one_image(path, page)?;
        let a = decode_array(path, bytes, budget)?;
        let a = match a.ndim() {
            2 => a.insert_axis(Axis(2)),
            3 => a,
            n => return Err(IoError::unexpected(path, "an array with 2 or 3 axes (row, col[, channel])", n.to_string())),
        };
        let ch = a.shape()[2];
        if ch != 1 && ch != 3 {
            return Err(IoError::unexpected(
                path,
                "a grey or RGB image: (row, col) or (row, col, channel) with 1 or 3 channels",
                format!("shape {:?}", a.shape()),
            ));
        }
        a.into_dimensionality().map_err(|e| IoError::malformed(path, "NPY", e))
    }

    /// 3 axes (frame, row, col) or 4 axes (frame, row, col, channel).
    fn decode_stack(&self, path: &Path, bytes: &[u8], budget: &ByteBudget) -> Result<Array4<f32>, IoError> {
        npy_to_video(path, decode_array(path, bytes, budget)?)
    }

    fn sample_bits(&self, path: &Path) -> Option<u32> {
        let mut head = vec![0u8; 256];
        let n = std::fs::File::open(path).ok()?.read(&mut head).ok()?;
        let text = String::from_utf8_lossy(&head[..n]);
        if text.contains("'|u1'") {
            Some(8)
        } else if text.contains("'<u2'") || text.contains("'>u2'") {
            Some(16)
        } else {
            None
        }
    }

    fn writer(&self) -> Option<StackWriter> {
        Some(|path, video| write_npy(path, video))
    }
}

/// What an npy header announces: the element type and the shape.
#[derive(Clone, Debug, PartialEq, Eq)]
struct NpyHeader {
    /// The `descr` entry, e.g. `<f4`.
    pub descr: String,
    pub shape: Vec<usize>,
    /// Bytes of one element (from `descr`).
    pub elem_bytes: usize,
    /// Where the data starts.
    pub data_offset: usize,
}

fn truncated(path: &Path, detail: impl Into<String>) -> IoError {
    IoError::Truncated { path: path.to_path_buf(), format: "NPY", detail: detail.into() }
}

/// Parses the header of an in-memory `.npy` (versions 1 to 3) without reading the data:
/// the element type must be float32, float64, uint8 or uint16 and the data the shape
/// announces must be in the file.
fn parse_npy_header(path: &Path, bytes: &[u8]) -> Result<NpyHeader, IoError> {
    let (len_bytes, start): (usize, usize) = match bytes.get(6) {
        Some(1) => (2, 10),
        Some(2 | 3) => (4, 12),
        Some(v) => return Err(IoError::malformed(path, "NPY", format!("format version {v} (expected 1, 2 or 3)"))),
        None => return Err(truncated(path, "header incomplete")),
    };
    let Some(len) = bytes.get(8..8 + len_bytes) else {
        return Err(truncated(path, "header incomplete"));
    };
    let header_len = len.iter().rev().fold(0usize, |acc, &b| (acc << 8) | usize::from(b));
    let Some(text) = bytes.get(start..start.saturating_add(header_len)) else {
        return Err(truncated(path, format!("the header announces {header_len} bytes, the file holds {}", bytes.len())));
    };
    let text = std::str::from_utf8(text).map_err(|_| IoError::malformed(path, "NPY", "the header is not text"))?;
    let raw_descr = dict_value(text, "descr").ok_or_else(|| IoError::malformed(path, "NPY", "the header has no 'descr' entry"))?;
    let descr = match raw_descr.strip_prefix('\'').and_then(|v| v.split('\'').next()) {
        Some(d) => d.to_string(),
        None => {
            let shown: String = raw_descr.chars().take(60).collect();
            return Err(IoError::unexpected(
                path,
                "an array of float32, float64, uint8 or uint16 (a plain dtype)",
                format!("a structured dtype (descr {shown}...): save one field as its own array"),
            ));
        }
    };
    let elem_bytes = match descr.as_str() {
        "<f4" | ">f4" | "=f4" => 4,
        "<f8" | ">f8" | "=f8" => 8,
        "|u1" | "<u1" | ">u1" | "=u1" => 1,
        "<u2" | ">u2" | "=u2" => 2,
        other => return Err(IoError::unexpected(path, "an array of float32, float64, uint8 or uint16", format!("dtype {other}"))),
    };
    let shape_text = dict_value(text, "shape")
        .and_then(|v| v.strip_prefix('('))
        .and_then(|v| v.split(')').next())
        .ok_or_else(|| IoError::malformed(path, "NPY", "the header has no 'shape' tuple"))?;
    let shape = shape_text
        .split(',')
        .map(str::trim)
        .filter(|t| !t.is_empty())
        .map(|t| t.parse::<usize>().map_err(|_| IoError::malformed(path, "NPY", format!("shape ({shape_text}): {t:?} is not an axis length"))))
        .collect::<Result<Vec<_>, _>>()?;
    let data_offset = start + header_len;
    let need = array_bytes(&shape, elem_bytes);
    let have = (bytes.len() - data_offset) as u128;
    if need > have {
        return Err(truncated(path, format!("the header announces shape {shape:?} of {descr} ({need} bytes of data), the file holds {have} bytes of data")));
    }
    Ok(NpyHeader { descr, shape, elem_bytes, data_offset })
}

/// The text after `'key':` in a header dict, trimmed.
fn dict_value<'a>(text: &'a str, key: &str) -> Option<&'a str> {
    let at = text.find(&format!("'{key}'"))? + key.len() + 2;
    Some(text[at..].trim_start().strip_prefix(':')?.trim_start())
}

/// Decodes an in-memory `.npy` whose magic bytes were checked
/// ([`decode_npy`](crate::io::decode_npy) checks them) holding float32, float64, uint8 or
/// uint16 values (any number of axes, C or Fortran order) into f32 values, unchanged in
/// value. The header is
/// checked first ([`parse_npy_header`]): the data it announces must be in the file, and
/// the array (as stored and as f32) within `budget`, before anything is allocated.
pub(crate) fn decode_array(path: &Path, bytes: &[u8], budget: &ByteBudget) -> Result<ArrayD<f32>, IoError> {
    let header = parse_npy_header(path, bytes)?;
    budget
        .check_array(|| format!("an array of shape {:?} ({}, plus its f32 copy)", header.shape, header.descr), &header.shape, header.elem_bytes + 4)
        .map_err(|source| IoError::TooLarge { path: path.to_path_buf(), source: Box::new(source) })?;
    let err = |e: ReadNpyError| match e {
        ReadNpyError::MissingData => truncated(path, "the data is shorter than the header announces"),
        ReadNpyError::Io(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => truncated(path, "file ends early"),
        other => IoError::malformed(path, "NPY", other),
    };
    macro_rules! attempt {
        ($t:ty, $conv:expr) => {
            match ArrayD::<$t>::read_npy(Cursor::new(bytes)) {
                // A Fortran-order array (NumPy's save of a transposed image) is
                // returned in standard layout, what every reader of it assumes.
                Ok(a) => return Ok(a.as_standard_layout().mapv($conv)),
                Err(ReadNpyError::WrongDescriptor(_)) => {}
                Err(e) => return Err(err(e)),
            }
        };
    }
    match header.elem_bytes {
        4 => attempt!(f32, |v| v),
        8 => attempt!(f64, |v| v as f32),
        1 => attempt!(u8, f32::from),
        _ => attempt!(u16, f32::from),
    }
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
