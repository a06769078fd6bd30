//! What a file is: its extension, its bytes and the format its magic bytes announce, and
//! the words messages use for an image's shape.

use super::error::IoError;
use std::path::Path;

/// Lower-cased extension of `path`, or "" when it has none.
pub(crate) fn extension(path: &Path) -> String {
    path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase()).unwrap_or_default()
}

/// Reads a whole file, with the path in the error.
pub(crate) fn read_bytes(path: &Path) -> Result<Vec<u8>, IoError> {
    std::fs::read(path).map_err(|e| IoError::os(path, "cannot read", e))
}

/// The format the first bytes of a file announce.
pub(crate) fn sniff(bytes: &[u8]) -> &'static str {
    if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        "PNG"
    } else if [b"II*\0", b"MM\0*", b"II+\0", b"MM\0+"].iter().any(|m| bytes.starts_with(*m)) {
        // Classic TIFF and BigTIFF, either byte order.
        "TIFF"
    } else if bytes.starts_with(b"\x93NUMPY") {
        "NPY"
    } else if bytes.starts_with(b"GIF8") {
        "GIF"
    } else if bytes.starts_with(&[0xff, 0xd8, 0xff]) {
        "JPEG"
    } else if bytes.is_empty() {
        "an empty file"
    } else {
        "of unknown type"
    }
}

/// Fails with [`IoError::WrongMagic`] unless `bytes` start like a `named` file.
pub(crate) fn check_magic(path: &Path, bytes: &[u8], named: &'static str) -> Result<(), IoError> {
    let found = sniff(bytes);
    if found == named {
        Ok(())
    } else {
        Err(IoError::WrongMagic { path: path.to_path_buf(), named, found })
    }
}

/// Human description of an image shape used in messages: "480x640 grey".
pub(crate) fn describe_shape(rows: usize, cols: usize, channels: usize) -> String {
    let kind = match channels {
        1 => "grey".to_string(),
        3 => "RGB".to_string(),
        c => format!("{c} channels"),
    };
    format!("{rows}x{cols} (rows x cols) {kind}")
}
