//! The trait every image file format implements, [`ImageFormat`], and the helpers the
//! formats share. The registry of formats and the one dispatch are in the parent module.

use std::path::Path;

use ndarray::{Array3, Array4, ArrayView4, Axis};

use super::raw::RawInfo;
use crate::io::budget::ByteBudget;
use crate::io::error::IoError;

/// Writes a video (frame, row, col, channel) to a file of one format.
pub type StackWriter = fn(&Path, ArrayView4<'_, f32>) -> Result<(), IoError>;

/// One file format of images and videos. Pixel values come back as the raw counts
/// stored (see the module `io`); every error names the file.
pub trait ImageFormat: Sync {
    /// The name messages use: "TIFF".
    fn name(&self) -> &'static str;
    /// The extensions naming it, lower case, without the dot (any case matches).
    fn extensions(&self) -> &'static [&'static str];
    /// Whether `bytes` (a file's start) carry this format's magic bytes.
    fn sniff(&self, bytes: &[u8]) -> bool;
    /// Whether a folder read as a video ([`read_stack`](crate::io::read_stack) of a
    /// directory) takes files of this format as its frames.
    fn folder_frames(&self) -> bool {
        true
    }
    /// Decodes one image (row, col, channel) of an in-memory file whose magic bytes were
    /// checked. `page` is 1-based; `None` asks for the only image (a file of several is
    /// refused with [`IoError::PageRequired`]). A format of one image per file calls
    /// `one_image` first. Sizes are checked against `budget` before allocation.
    fn decode_image(&self, path: &Path, bytes: &[u8], page: Option<usize>, budget: &ByteBudget) -> Result<Array3<f32>, IoError>;
    /// Decodes an in-memory file as a video (frame, row, col, channel); by default its
    /// one image as one frame.
    fn decode_stack(&self, path: &Path, bytes: &[u8], budget: &ByteBudget) -> Result<Array4<f32>, IoError> {
        Ok(self.decode_image(path, bytes, None, budget)?.insert_axis(Axis(0)))
    }
    /// Bits of the file's unsigned integer samples (8 or 16), from its header alone;
    /// `None` for float samples or a file that cannot be read (the readers say why).
    fn sample_bits(&self, path: &Path) -> Option<u32>;
    /// For a Bayer raw (DNG, CFA TIFF): its header's pattern, sensor size, black and
    /// white levels; `None` for any other file or one that cannot be read.
    fn raw_info(&self, _path: &Path) -> Option<RawInfo> {
        None
    }
    /// How [`write_stack`](crate::io::write_stack) writes a video in this format, values unchanged; `None` for a
    /// format only read.
    fn writer(&self) -> Option<StackWriter> {
        None
    }
}

/// Lower-cased extension of `path`, or "" when it has none.
pub(crate) fn extension(path: &Path) -> String {
    path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase()).unwrap_or_default()
}

/// Reads a whole image file (a regular file of at most the process's byte budget,
/// [`crate::io::input::read_bounded`]), with the path in the error.
pub(crate) fn read_bytes(path: &Path) -> Result<Vec<u8>, IoError> {
    crate::io::input::read_bounded(path, crate::io::budget::ByteBudget::system().limit_bytes).map_err(|e| IoError::os(path, "cannot read", e))
}

/// For a format of one image per file: only page 1 (or no page) may be asked for.
pub(crate) fn one_image(path: &Path, page: Option<usize>) -> Result<(), IoError> {
    match page.filter(|&p| p != 1) {
        Some(p) => Err(IoError::unexpected(path, "page 1 (the file holds one image)", format!("page {p} requested"))),
        None => Ok(()),
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

/// Stacks equally shaped frames, naming the first that differs from frame 0.
pub(crate) fn stack_frames(path: &Path, frames: &[Array3<f32>], names: &[String]) -> Result<Array4<f32>, IoError> {
    let first = frames[0].dim();
    for (frame, name) in frames.iter().zip(names).skip(1) {
        let d = frame.dim();
        if d != first {
            return Err(IoError::ShapeMismatch {
                path: path.to_path_buf(),
                item: name.clone(),
                found: describe_shape(d.0, d.1, d.2),
                first: names[0].clone(),
                expected: describe_shape(first.0, first.1, first.2),
            });
        }
    }
    let views: Vec<_> = frames.iter().map(|f| f.view()).collect();
    ndarray::stack(Axis(0), &views).map_err(|e| IoError::malformed(path, "stack", e))
}
