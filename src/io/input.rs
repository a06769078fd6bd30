//! The one way an input file is read: it must be a regular file (a FIFO, a device such
//! as `/dev/zero`, a socket or a folder is refused before it is opened, so nothing
//! blocks), and it is read with a bounded size (a file past the bound is refused, not
//! read into memory). Every reader of an input file goes through here. The check itself
//! lives in `rollcam_files::input` (the capture-folder reader there needs it too).

use std::path::Path;

pub use rollcam_files::input::{read_bounded, MAX_TEXT_BYTES};

/// [`read_bounded`] of a UTF-8 text of at most [`MAX_TEXT_BYTES`].
pub fn read_text(path: &Path) -> std::io::Result<String> {
    String::from_utf8(read_bounded(path, MAX_TEXT_BYTES)?).map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, format!("not UTF-8 text: {e}")))
}
