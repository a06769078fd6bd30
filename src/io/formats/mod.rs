//! Image file formats behind one trait, [`ImageFormat`], and one registry, [`FORMATS`].
//!
//! Every reader and writer of images and videos asks `format_for` which format a file
//! is: the extension names it ([`format_named`]), and the magic bytes must agree
//! ([`ImageFormat::sniff`]). A new format is one file in this folder implementing
//! [`ImageFormat`] and one line in [`FORMATS`]; `src/io/FORMATS.md` says how.

pub(crate) mod dng;
pub(crate) mod image_format;
pub(crate) mod jpeg;
pub(crate) mod npy;
pub(crate) mod png;
pub mod raw;
pub(crate) mod tiff;

use std::path::Path;

use ndarray::{Array4, ArrayD, ArrayView4};

use super::budget::ByteBudget;
use super::error::IoError;
use image_format::extension;
pub use image_format::{ImageFormat, StackWriter};

/// Every format read and written, in the order messages list them. The one
/// registration of a format.
pub static FORMATS: &[&dyn ImageFormat] = &[&tiff::Tiff, &dng::Dng, &png::Png, &jpeg::Jpeg, &npy::Npy];

/// Files that are no registered format, named when one comes under a format's name.
const OTHER_SIGNATURES: &[(&str, &[u8])] = &[("GIF", b"GIF8"), ("BMP", b"BM")];

/// What a format is wanted for: decides which formats an unknown name is told of.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Use {
    /// One image ([`read_image`](super::read_image)).
    Image,
    /// A video: a file or a folder of numbered images ([`read_stack`](super::read_stack)).
    Stack,
    /// Writing a video ([`write_stack`]).
    Write,
}

/// The registered format `path`'s extension names (any case), if any.
pub fn format_named(path: &Path) -> Option<&'static dyn ImageFormat> {
    let ext = extension(path);
    FORMATS.iter().copied().find(|f| f.extensions().contains(&ext.as_str()))
}

/// What the first bytes of a file are, in words for messages: a registered format's
/// name, another known format's, "an empty file" or "of unknown type".
pub fn content_name(bytes: &[u8]) -> &'static str {
    if let Some(f) = FORMATS.iter().find(|f| f.sniff(bytes)) {
        f.name()
    } else if let Some((name, _)) = OTHER_SIGNATURES.iter().find(|(_, magic)| bytes.starts_with(magic)) {
        name
    } else if bytes.is_empty() {
        "an empty file"
    } else {
        "of unknown type"
    }
}

/// The one place a file's format is decided: the format its extension names
/// ([`IoError::UnknownExtension`] listing those `wanted` takes, otherwise), and, given
/// the file's bytes, their magic must be that format's ([`IoError::WrongMagic`] naming
/// what they are, otherwise: a file is never read as another format than its name says).
pub(crate) fn format_for(path: &Path, bytes: Option<&[u8]>, wanted: Use) -> Result<&'static dyn ImageFormat, IoError> {
    if wanted == Use::Image && bytes.is_none() && path.is_dir() {
        return Err(IoError::unexpected(path, format!("an image file ({})", expected_names(wanted)), "a folder"));
    }
    let format = format_named(path).ok_or_else(|| IoError::UnknownExtension { path: path.to_path_buf(), expected: expected_names(wanted) })?;
    if let Some(bytes) = bytes {
        check_magic(path, bytes, format)?;
    }
    Ok(format)
}

/// Fails with [`IoError::WrongMagic`] unless `bytes` start like a `format` file.
pub(crate) fn check_magic(path: &Path, bytes: &[u8], format: &dyn ImageFormat) -> Result<(), IoError> {
    if format.sniff(bytes) {
        Ok(())
    } else {
        Err(IoError::WrongMagic { path: path.to_path_buf(), named: format.name(), found: content_name(bytes) })
    }
}

/// The names a file wanted for `wanted` may have: ".tif, .tiff, .png, .jpg, .jpeg or .npy".
fn expected_names(wanted: Use) -> String {
    let mut names: Vec<String> =
        FORMATS.iter().filter(|f| wanted != Use::Write || f.writer().is_some()).flat_map(|f| f.extensions().iter().map(|e| format!(".{e}"))).collect();
    if wanted == Use::Stack {
        names.push("a directory of numbered images".into());
    }
    match names.split_last() {
        Some((last, rest)) if !rest.is_empty() => format!("{} or {last}", rest.join(", ")),
        _ => names.concat(),
    }
}

/// Writes a video (frame, row, col, channel) in the format its name gives, values
/// unchanged: `.tif`/`.tiff` a float32 ImageJ stack
/// ([`write_tiff_stack_f32`](super::write_tiff_stack_f32)), `.npy` float32
/// ([`write_npy`](super::write_npy)). Atomic, like every writer here.
pub fn write_stack(path: impl AsRef<Path>, video: ArrayView4<f32>) -> Result<(), IoError> {
    let path = path.as_ref();
    let format = format_for(path, None, Use::Write)?;
    let Some(write) = format.writer() else {
        return Err(IoError::bad_input(path, format!("{} files are only read; a video is written as {}", format.name(), expected_names(Use::Write))));
    };
    write(path, video)
}

/// Decodes an in-memory `.npy` holding float32, float64, uint8 or uint16 values (any
/// number of axes) into f32 values, unchanged: its magic bytes first (naming what the
/// bytes are otherwise), then its header, then the array within `budget`.
pub fn decode_npy(path: &Path, bytes: &[u8], budget: &ByteBudget) -> Result<ArrayD<f32>, IoError> {
    check_magic(path, bytes, &npy::Npy)?;
    npy::decode_array(path, bytes, budget)
}

/// Reads a video from `.npy`: 3 axes (frame, row, col) become one channel, 4 axes
/// (frame, row, col, channel) must have 1 or 3 channels. Accepts float32, float64, uint8,
/// uint16; values are kept as stored.
pub fn read_npy(path: impl AsRef<Path>) -> Result<Array4<f32>, IoError> {
    let path = path.as_ref();
    let bytes = image_format::read_bytes(path)?;
    npy::npy_to_video(path, decode_npy(path, &bytes, &ByteBudget::system())?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::{read_stack, write_png, Display};
    use ndarray::{Array4, Axis};

    /// A one-frame file of every format, made by its own writer, and what it holds
    /// (`video`, except for a lossy format); a format only read needs its file made
    /// here (a new one fails until it is added).
    fn sample_file(dir: &Path, f: &dyn ImageFormat, video: &Array4<f32>) -> (std::path::PathBuf, Array4<f32>) {
        let path = dir.join(format!("sample.{}", f.extensions()[0]));
        match f.name() {
            _ if f.writer().is_some() => write_stack(&path, video.view()).unwrap(),
            "PNG" => write_png(&path, video.index_axis(Axis(0), 0), &Display::linear(0.0, 255.0)).unwrap(),
            "DNG" => {
                // A 4 x 4 RGGB mosaic: its half grid is 2 x 2 of R, mean G, B.
                let mosaic = ndarray::Array2::from_shape_fn((4, 4), |(r, c)| (r * 4 + c) as u16 * 10);
                let spec = raw::RawSpec {
                    mosaic: mosaic.view(),
                    pattern: raw::Bayer::Rggb,
                    bits: 16,
                    dng: true,
                    black_level: None,
                    white_level: None,
                    compression: 1,
                };
                std::fs::write(&path, raw::encode_raw(&spec)).unwrap();
                let held = Array4::from_shape_fn((1, 2, 2, 3), |(_, r, c, ch)| {
                    let at = |dr: usize, dc: usize| ((2 * r + dr) * 4 + 2 * c + dc) as f32 * 10.0;
                    [at(0, 0), (at(0, 1) + at(1, 0)) / 2.0, at(1, 1)][ch]
                });
                return (path, held);
            }
            "JPEG" => {
                let levels = [40, 200, 7];
                std::fs::write(&path, jpeg::tests::flat_blocks_jpeg(&levels)).unwrap();
                return (path, Array4::from_shape_fn((1, 8, 24, 1), |(_, _, c, _)| f32::from(levels[c / 8])));
            }
            other => panic!("no sample file for the read-only format {other}: add one here"),
        }
        (path, video.clone())
    }

    fn same(a: &Array4<f32>, b: &Array4<f32>) -> bool {
        a.dim() == b.dim() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
    }

    #[test]
    fn every_extension_names_one_format_in_any_case() {
        let mut seen = Vec::new();
        for f in FORMATS {
            for ext in f.extensions() {
                assert_eq!(ext.to_ascii_lowercase(), *ext, "{} lists {ext} not in lower case", f.name());
                assert!(!seen.contains(ext), ".{ext} names two formats");
                seen.push(*ext);
                for name in [format!("a.{ext}"), format!("A.{}", ext.to_ascii_uppercase())] {
                    assert_eq!(format_named(Path::new(&name)).map(|g| g.name()), Some(f.name()), "{name}");
                }
            }
        }
        assert!(format_named(Path::new("a.bmp")).is_none() && format_named(Path::new("tif")).is_none());
    }

    #[test]
    fn unknown_names_are_told_the_registered_extensions() {
        assert_eq!(expected_names(Use::Image), ".tif, .tiff, .dng, .png, .jpg, .jpeg or .npy");
        assert_eq!(expected_names(Use::Stack), ".tif, .tiff, .dng, .png, .jpg, .jpeg, .npy or a directory of numbered images");
        assert_eq!(expected_names(Use::Write), ".tif, .tiff or .npy");
        let e = format_for(Path::new("x.bmp"), None, Use::Image).err().unwrap().to_string();
        assert_eq!(e, "x.bmp: unknown file type (expected .tif, .tiff, .dng, .png, .jpg, .jpeg or .npy)");
    }

    /// Every format written through [`write_stack`] reads back through [`read_stack`]
    /// unchanged (floats bit for bit, NaN and infinities included), in grey and RGB.
    #[test]
    fn every_writable_format_round_trips_through_the_generic_writer_and_reader() {
        let dir = tempfile::tempdir().unwrap();
        let mut written = 0;
        for f in FORMATS.iter().filter(|f| f.writer().is_some()) {
            for ch in [1, 3] {
                let mut video = Array4::from_shape_fn((3, 4, 5, ch), |(k, r, c, h)| k as f32 * 100.0 + r as f32 * 1.5 - c as f32 * 0.25 + h as f32 / 3.0);
                video[[1, 2, 3, 0]] = f32::NAN;
                video[[2, 0, 0, ch - 1]] = f32::NEG_INFINITY;
                for ext in f.extensions() {
                    let path = dir.path().join(format!("v{ch}.{ext}"));
                    write_stack(&path, video.view()).unwrap();
                    assert!(same(&read_stack(&path).unwrap(), &video), "{}: {ch} channels as .{ext}", f.name());
                    written += 1;
                }
            }
        }
        assert!(written >= 6, "TIFF (two extensions) and NPY write");
    }

    /// Sniffing names a file's format from its bytes whatever its name, and a file is
    /// read only under its own format's name: under another's it is refused, naming both.
    #[test]
    fn the_bytes_name_the_format_and_a_mismatched_name_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let video = Array4::from_shape_fn((1, 3, 2, 1), |(_, r, c, _)| (r * 2 + c) as f32);
        for f in FORMATS {
            let (path, held) = sample_file(dir.path(), *f, &video);
            let bytes = std::fs::read(&path).unwrap();
            let sniffed: Vec<&str> = FORMATS.iter().filter(|g| g.sniff(&bytes)).map(|g| g.name()).collect();
            assert_eq!(sniffed, [f.name()], "the magic of {}", f.name());
            assert_eq!(content_name(&bytes), f.name());
            assert!(same(&read_stack(&path).unwrap(), &held), "{} sample", f.name());
            for other in FORMATS.iter().filter(|g| g.name() != f.name()) {
                let named = dir.path().join(format!("wrong.{}", other.extensions()[0]));
                std::fs::write(&named, &bytes).unwrap();
                let e = read_stack(&named).unwrap_err();
                assert!(matches!(e, IoError::WrongMagic { named: n, found, .. } if n == other.name() && found == f.name()), "{e:?}");
                let e = format_for(&named, Some(&bytes), Use::Image).err().unwrap().to_string();
                assert!(e.contains(&named.display().to_string()) && e.contains(other.name()) && e.contains(f.name()), "{e}");
            }
        }
        assert_eq!(content_name(b"GIF89a..."), "GIF");
        assert_eq!(content_name(b"BM6\x00"), "BMP");
        assert_eq!(content_name(&[0xff, 0xd8, 0xff, 0xe0]), "JPEG");
        assert_eq!(content_name(b""), "an empty file");
        assert_eq!(content_name(b"P5 4 4 255\n"), "of unknown type");
    }

    #[test]
    fn a_format_only_read_is_not_written_and_says_what_is() {
        let dir = tempfile::tempdir().unwrap();
        let video = Array4::<f32>::zeros((1, 2, 2, 1));
        for f in FORMATS.iter().filter(|f| f.writer().is_none()) {
            let path = dir.path().join(format!("v.{}", f.extensions()[0]));
            let e = write_stack(&path, video.view()).unwrap_err().to_string();
            assert!(e.starts_with(&path.display().to_string()) && e.contains(f.name()) && e.contains(".tif, .tiff or .npy"), "{e}");
            assert!(!path.exists());
        }
        let e = write_stack(dir.path().join("v.bmp"), video.view()).unwrap_err();
        assert!(matches!(&e, IoError::UnknownExtension { expected, .. } if expected == ".tif, .tiff or .npy"), "{e:?}");
    }
}
