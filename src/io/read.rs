//! The readers of images and videos, whatever their format: each asks
//! `formats::format_for` which registered format a file is, then has that format decode it.

use std::cmp::Ordering;
use std::path::{Path, PathBuf};

use ndarray::{Array3, Array4};

use super::budget::ByteBudget;
use super::error::IoError;
use super::formats::image_format::{read_bytes, stack_frames};
use super::formats::raw::RawInfo;
use super::formats::{format_for, format_named, Use, FORMATS};

/// Reads one image as (row, col, channel) f32 raw counts, channel count 1 or 3.
///
/// The format is the one of [`FORMATS`](super::FORMATS) the extension names, and must
/// agree with the file's magic bytes (`src/io/FORMATS.md` lists what each accepts):
/// * `.tif`/`.tiff`: a single-page file; 8/16-bit unsigned or 32/64-bit float samples,
///   grey or RGB (grey+alpha, RGBA, palette, planar RGB are refused). A file of several
///   pages is refused with [`IoError::PageRequired`] (how many pages, and that `--page N`
///   chooses one): use [`read_image_page`] to take one page;
/// * `.png`: 8/16-bit grey or RGB (alpha and palette are refused);
/// * `.npy`: 2 axes (row, col) or 3 axes (row, col, channel), float32/float64/uint8/uint16.
///
/// Values are not altered: NaN and infinities in float files come back as they are.
/// Every size the file announces is checked against [`ByteBudget::system`] before it is
/// allocated ([`IoError::TooLarge`] names the file and the figure).
pub fn read_image(path: impl AsRef<Path>) -> Result<Array3<f32>, IoError> {
    read_image_page(path, None)
}

/// Reads one image like [`read_image`], choosing the page of a multi-page TIFF.
///
/// `page` is **1-based** (the first page is `Some(1)`), as `--page N` on the command line.
/// `None` reads a single-image file and refuses a TIFF of several pages
/// ([`IoError::PageRequired`]); `Some(n)` out of 1..=pages is an error naming the page
/// count. For PNG and NPY files (always one image) only `None` and `Some(1)` are accepted.
pub fn read_image_page(path: impl AsRef<Path>, page: Option<usize>) -> Result<Array3<f32>, IoError> {
    let path = path.as_ref();
    format_for(path, None, Use::Image)?;
    decode_image_page(path, &read_bytes(path)?, page, &ByteBudget::system())
}

/// Decodes one in-memory image file as [`read_image`] reads it from disk: the format
/// follows `name`'s extension (`.tif`/`.tiff`, `.png`, `.npy`) and must agree with the
/// magic bytes; `name` is used only for that and for messages. Sizes are checked against
/// `budget` before anything is allocated. A multi-page TIFF is refused like
/// [`read_image`] does. For callers that hold the bytes already (and the fuzz targets).
pub fn decode_image_bytes(name: &Path, bytes: &[u8], budget: &ByteBudget) -> Result<Array3<f32>, IoError> {
    decode_image_page(name, bytes, None, budget)
}

/// [`decode_image_bytes`] with the page choice of [`read_image_page`] (1-based).
pub fn decode_image_page(name: &Path, bytes: &[u8], page: Option<usize>, budget: &ByteBudget) -> Result<Array3<f32>, IoError> {
    format_for(name, Some(bytes), Use::Image)?.decode_image(name, bytes, page, budget)
}

/// Decodes an in-memory stack file as [`read_stack`] reads it from disk (`.tif`/`.tiff`
/// all pages, `.npy` 3 or 4 axes, `.png` one frame), the format following `name`'s
/// extension and agreeing with the magic bytes; sizes checked against `budget` before
/// allocation.
pub fn decode_stack_bytes(name: &Path, bytes: &[u8], budget: &ByteBudget) -> Result<Array4<f32>, IoError> {
    format_for(name, Some(bytes), Use::Stack)?.decode_stack(name, bytes, budget)
}

/// The full scale of an image file's samples: a Bayer raw's WhiteLevel (else 2^bits - 1),
/// 255 for 8-bit and 65535 for 16-bit unsigned samples (TIFF, PNG, NPY), `None` for
/// float samples or a file that cannot be read (the readers report that). Only the
/// header is decoded.
pub fn sample_full_scale(path: impl AsRef<Path>) -> Option<f64> {
    let path = path.as_ref();
    let format = format_named(path)?;
    if let Some(info) = format.raw_info(path) {
        return Some(info.white_level);
    }
    match format.sample_bits(path)? {
        8 => Some(255.0),
        16 => Some(65535.0),
        _ => None,
    }
}

/// A Bayer raw's black level (the DNG BlackLevel tag, counts: the mean of its values
/// when it gives one per cell), `None` for a file without one or another kind of file.
/// Only the header is decoded. The dark level of a raw when nothing else gives it.
pub fn sample_black_level(path: impl AsRef<Path>) -> Option<f64> {
    raw_info(path)?.black_level
}

/// A Bayer raw's header (pattern, sensor size, levels: [`RawInfo`]); `None` for any
/// other file or one that cannot be read.
pub fn raw_info(path: impl AsRef<Path>) -> Option<RawInfo> {
    let path = path.as_ref();
    format_named(path)?.raw_info(path)
}

/// Reads a video as (frame, row, col, channel) f32 raw counts.
///
/// * a multi-page `.tif`/`.tiff`: one frame per page; every page must share size and
///   channels (the error names the first page that differs). A stack whose first page
///   carries an ImageJ description with `channels=C > 1` over grey pages (as written by
///   [`write_tiff_stack_f32`](super::write_tiff_stack_f32)) is regrouped into C channels,
///   pages in (frame, channel) order;
/// * `.npy`: 3 axes (frame, row, col) or 4 axes (frame, row, col, channel);
/// * a `.png`: a single frame;
/// * a directory: every file in it of a format whose
///   [`folder_frames`](super::ImageFormat::folder_frames) is true (`.tif`/`.tiff`/`.png`;
///   hidden files skipped), in natural order of names (`f2` before `f10`), each read with
///   [`read_image`].
pub fn read_stack(path: impl AsRef<Path>) -> Result<Array4<f32>, IoError> {
    let path = path.as_ref();
    if path.is_dir() {
        return read_dir_stack(path);
    }
    format_for(path, None, Use::Stack)?;
    decode_stack_bytes(path, &read_bytes(path)?, &ByteBudget::system())
}

/// Compares file names so that digit runs compare as numbers ("f2" < "f10").
fn natural_cmp(a: &str, b: &str) -> Ordering {
    fn chunks(s: &str) -> Vec<(bool, &str)> {
        let mut out = Vec::new();
        let mut start = 0;
        let bytes = s.as_bytes();
        for i in 1..=bytes.len() {
            if i == bytes.len() || bytes[i].is_ascii_digit() != bytes[start].is_ascii_digit() {
                out.push((bytes[start].is_ascii_digit(), &s[start..i]));
                start = i;
            }
        }
        out
    }
    let (ca, cb) = (chunks(a), chunks(b));
    for ((da, sa), (db, sb)) in ca.iter().zip(cb.iter()) {
        let ord = if *da && *db {
            let (ta, tb) = (sa.trim_start_matches('0'), sb.trim_start_matches('0'));
            ta.len().cmp(&tb.len()).then_with(|| ta.cmp(tb)).then_with(|| sa.len().cmp(&sb.len()))
        } else {
            sa.cmp(sb)
        };
        if ord != Ordering::Equal {
            return ord;
        }
    }
    ca.len().cmp(&cb.len())
}

fn read_dir_stack(dir: &Path) -> Result<Array4<f32>, IoError> {
    let entries = std::fs::read_dir(dir).map_err(|e| IoError::os(dir, "cannot list directory", e))?;
    let mut files: Vec<(String, PathBuf)> = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| IoError::os(dir, "cannot list directory", e))?;
        let p = entry.path();
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') || !p.is_file() {
            continue;
        }
        if format_named(&p).is_some_and(|f| f.folder_frames()) {
            files.push((name, p));
        }
    }
    if files.is_empty() {
        let names: Vec<String> = FORMATS.iter().filter(|f| f.folder_frames()).flat_map(|f| f.extensions().iter().map(|e| format!(".{e}"))).collect();
        return Err(IoError::unexpected(dir, format!("numbered {} images in the directory", names.join("/")), "none"));
    }
    files.sort_by(|a, b| natural_cmp(&a.0, &b.0));
    let frames = files.iter().map(|(_, p)| read_image(p)).collect::<Result<Vec<_>, _>>()?;
    let names: Vec<String> = files.iter().map(|(n, _)| n.clone()).collect();
    stack_frames(dir, &frames, &names)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn natural_order_sorts_numbers_by_value() {
        let mut v = vec!["f10.png", "f2.png", "f1.png", "f010b.png", "g.png", "f02.png"];
        v.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(v, ["f1.png", "f2.png", "f02.png", "f10.png", "f010b.png", "g.png"]);
    }
}
