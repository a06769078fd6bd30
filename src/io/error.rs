//! The error of the file-format layer.

use std::path::{Path, PathBuf};

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
    UnknownExtension { path: PathBuf, expected: String },
    /// The extension and the magic bytes at the start of the file disagree.
    #[error("{}: named as {named} but the file content is {found}", path.display())]
    WrongMagic { path: PathBuf, named: &'static str, found: &'static str },
    /// The file ends before the data its headers describe.
    #[error("{}: truncated {format} ({detail})", path.display())]
    Truncated { path: PathBuf, format: &'static str, detail: String },
    /// The content is valid for its format but not what the caller asked for
    /// (wrong channel count, dtype, number of axes, ...).
    #[error("{}: expected {expected}, found {found}", path.display())]
    Unexpected { path: PathBuf, expected: String, found: String },
    /// Pages of a stack (or files of a directory stack) disagree in shape.
    #[error("{}: {item} is {found}, but {first} is {expected}; every frame must have the same size and channels", path.display())]
    ShapeMismatch { path: PathBuf, item: String, found: String, first: String, expected: String },
    /// The file is malformed for its format (decoder message attached).
    #[error("{}: invalid {format}: {detail}", path.display())]
    Malformed { path: PathBuf, format: &'static str, detail: String },
    /// The size the file announces is over the byte budget (checked before allocating).
    /// Boxed: it would make every `Result<_, IoError>` twice as large.
    #[error("{}: {source}", path.display())]
    TooLarge {
        path: PathBuf,
        #[source]
        source: Box<super::budget::OverBudget>,
    },
    /// A single image was asked of a file that holds several pages.
    #[error("{}: holds {pages} pages where one image was expected (save the page wanted as a file of its own)", path.display())]
    PageRequired { path: PathBuf, pages: usize },
    /// The in-memory data cannot be written as asked (empty array, unsupported channels...).
    #[error("{}: cannot write: {detail}", path.display())]
    BadInput { path: PathBuf, detail: String },
}

impl IoError {
    /// The file or folder the error is about.
    pub fn path(&self) -> &Path {
        match self {
            IoError::Os { path, .. }
            | IoError::UnknownExtension { path, .. }
            | IoError::WrongMagic { path, .. }
            | IoError::Truncated { path, .. }
            | IoError::Unexpected { path, .. }
            | IoError::ShapeMismatch { path, .. }
            | IoError::Malformed { path, .. }
            | IoError::TooLarge { path, .. }
            | IoError::PageRequired { path, .. }
            | IoError::BadInput { path, .. } => path,
        }
    }

    pub(crate) fn os(path: &Path, action: &'static str, source: std::io::Error) -> Self {
        IoError::Os { path: path.to_path_buf(), action, source }
    }
    pub(crate) fn unexpected(path: &Path, expected: impl Into<String>, found: impl Into<String>) -> Self {
        IoError::Unexpected { path: path.to_path_buf(), expected: expected.into(), found: found.into() }
    }
    pub(crate) fn malformed(path: &Path, format: &'static str, detail: impl ToString) -> Self {
        IoError::Malformed { path: path.to_path_buf(), format, detail: detail.to_string() }
    }
    pub(crate) fn bad_input(path: &Path, detail: impl Into<String>) -> Self {
        IoError::BadInput { path: path.to_path_buf(), detail: detail.into() }
    }
}
