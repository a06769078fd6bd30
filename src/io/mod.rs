//! File formats and figures.
//!
//! Conventions shared with the rest of rollcam:
//! * pixel data is `f32` in memory, holding the raw counts as stored
//!   (u8 0..255 and u16 0..65535 become the same numbers; nothing is normalised);
//! * an image is `Array3<f32>` with axes (row, col, channel), 1 (grey) or 3 (RGB) channels;
//! * a video is `Array4<f32>` with axes (frame, row, col, channel).
//!
//! Every writer goes through [`write_atomic`]: the bytes go to a temporary file in the
//! destination directory, which is flushed, fsynced and renamed over the destination, so a
//! reader never sees a half-written file. See `FORMATS.md` beside this file for the formats.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

pub mod cache;
mod capture_file;
mod display;
mod font;
mod npy;
pub mod output;
mod plot;
mod png;
mod read;
pub mod sequence_input;
pub mod sequence_output;
mod tiff_io;
pub mod utc;

pub use display::{write_contact_sheet, write_gif, write_png, Display, CONTACT_SHEET_MAX_FRAMES};
pub use npy::{read_npy, write_npy};
pub use plot::{plot_lines, PlotSpec, Series, SERIES_COLOURS};
pub use read::{read_image, read_stack};
pub use tiff_io::{write_tiff_f32, write_tiff_stack_f32, write_tiff_u16};

/// Errors of the file-format layer. Every message starts with the file it is about.
#[derive(Debug, thiserror::Error)]
pub enum IoError {
    /// The operating system refused an operation (missing file, permission, full disk...).
    #[error("{}: {action}: {source}", path.display())]
    Os {
        path: PathBuf,
        action: &'static str,
        #[source]
        source: std::io::Error,
    },
    /// The file's extension names no format this module reads or writes.
    #[error("{}: unknown file type (expected {expected})", path.display())]
    UnknownExtension { path: PathBuf, expected: &'static str },
    /// The extension and the magic bytes at the start of the file disagree.
    #[error("{}: named as {named} but the file content is {found}", path.display())]
    WrongMagic {
        path: PathBuf,
        named: &'static str,
        found: &'static str,
    },
    /// The file ends before the data its headers describe.
    #[error("{}: truncated {format} ({detail})", path.display())]
    Truncated {
        path: PathBuf,
        format: &'static str,
        detail: String,
    },
    /// The content is valid for its format but not what the caller asked for
    /// (wrong channel count, dtype, number of axes, ...).
    #[error("{}: expected {expected}, found {found}", path.display())]
    Unexpected {
        path: PathBuf,
        expected: String,
        found: String,
    },
    /// Pages of a stack (or files of a directory stack) disagree in shape.
    #[error("{}: {item} is {found}, but {first} is {expected}; every frame must have the same size and channels", path.display())]
    ShapeMismatch {
        path: PathBuf,
        item: String,
        found: String,
        first: String,
        expected: String,
    },
    /// The file is malformed for its format (decoder message attached).
    #[error("{}: invalid {format}: {detail}", path.display())]
    Malformed {
        path: PathBuf,
        format: &'static str,
        detail: String,
    },
    /// The in-memory data cannot be written as asked (empty array, unsupported channels...).
    #[error("{}: cannot write: {detail}", path.display())]
    BadInput { path: PathBuf, detail: String },
}

impl IoError {
    pub(crate) fn os(path: &Path, action: &'static str, source: std::io::Error) -> Self {
        IoError::Os {
            path: path.to_path_buf(),
            action,
            source,
        }
    }
    pub(crate) fn unexpected(path: &Path, expected: impl Into<String>, found: impl Into<String>) -> Self {
        IoError::Unexpected {
            path: path.to_path_buf(),
            expected: expected.into(),
            found: found.into(),
        }
    }
    pub(crate) fn malformed(path: &Path, format: &'static str, detail: impl ToString) -> Self {
        IoError::Malformed {
            path: path.to_path_buf(),
            format,
            detail: detail.to_string(),
        }
    }
    pub(crate) fn bad_input(path: &Path, detail: impl Into<String>) -> Self {
        IoError::BadInput {
            path: path.to_path_buf(),
            detail: detail.into(),
        }
    }
}

/// Write `text` to `path` atomically (see [`write_atomic`]).
pub fn write_text_atomic(path: &Path, text: &str) -> Result<(), IoError> {
    write_atomic(path, |w| {
        use std::io::Write;
        w.write_all(text.as_bytes()).map_err(|source| IoError::Os { path: path.to_path_buf(), action: "write", source })
    })
}

/// Writes a file atomically: `fill` writes into a buffered temporary file created in the
/// destination's directory; on success the file is flushed, fsynced and renamed onto `path`
/// (and the directory fsynced where the platform allows). On any error the temporary file
/// is removed and `path` is left as it was.
pub fn write_atomic<F>(path: &Path, fill: F) -> Result<(), IoError>
where
    F: FnOnce(&mut BufWriter<File>) -> Result<(), IoError>,
{
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path
        .file_name()
        .ok_or_else(|| IoError::bad_input(path, "the path names no file"))?;
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(name);
    static COUNTER: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    tmp_name.push(format!(".{}-{n}.tmp", std::process::id()));
    let tmp = dir.join(tmp_name);

    let result = (|| {
        let file = File::create(&tmp).map_err(|e| IoError::os(path, "cannot create temporary file", e))?;
        let mut w = BufWriter::new(file);
        fill(&mut w)?;
        w.flush().map_err(|e| IoError::os(path, "cannot write", e))?;
        let file = w
            .into_inner()
            .map_err(|e| IoError::os(path, "cannot write", e.into_error()))?;
        file.sync_all().map_err(|e| IoError::os(path, "cannot sync", e))?;
        drop(file);
        std::fs::rename(&tmp, path).map_err(|e| IoError::os(path, "cannot rename temporary file", e))?;
        #[cfg(unix)]
        if let Ok(d) = File::open(&dir) {
            let _ = d.sync_all();
        }
        Ok(())
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Lower-cased extension of `path`, or "" when it has none.
pub(crate) fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .unwrap_or_default()
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
        Err(IoError::WrongMagic {
            path: path.to_path_buf(),
            named,
            found,
        })
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
