//! Format-dispatching readers for images and stacks.

use std::cmp::Ordering;
use std::path::{Path, PathBuf};

use ndarray::{s, Array3, Array4, Axis};

use super::budget::ByteBudget;
use super::error::IoError;
use super::format::{describe_shape, extension, read_bytes};
use super::npy::{decode_npy, npy_to_video};
use super::png::decode_png;
use super::tiff_io::{count_pages, decode_tiff, tiff_limits, Pages};

const IMAGE_EXTENSIONS: &str = ".tif, .tiff, .png or .npy";

/// Reads one image as (row, col, channel) f32 raw counts, channel count 1 or 3.
///
/// The format follows the extension and must agree with the file's magic bytes:
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
    if !matches!(extension(path).as_str(), "tif" | "tiff" | "png" | "npy") {
        return Err(IoError::UnknownExtension { path: path.to_path_buf(), expected: IMAGE_EXTENSIONS });
    }
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
    let path = name;
    let ext = extension(path);
    if ext != "tif" && ext != "tiff" {
        if let Some(p) = page.filter(|&p| p != 1) {
            return Err(IoError::unexpected(path, "page 1 (the file holds one image)", format!("page {p} requested")));
        }
    }
    match ext.as_str() {
        "tif" | "tiff" => {
            let which = match page {
                None => match count_pages(path, bytes)? {
                    1 => Pages::One(0),
                    n => return Err(IoError::PageRequired { path: path.to_path_buf(), pages: n }),
                },
                Some(0) => return Err(IoError::unexpected(path, "a page number from 1 (pages are counted from 1)", "page 0")),
                Some(p) => Pages::One(p - 1),
            };
            let mut t = decode_tiff(path, bytes, which, budget)?;
            Ok(t.pages.swap_remove(0))
        }
        "png" => decode_png(path, bytes, budget),
        "npy" => {
            let a = decode_npy(path, bytes, budget)?;
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
        _ => Err(IoError::UnknownExtension { path: path.to_path_buf(), expected: IMAGE_EXTENSIONS }),
    }
}

/// Decodes an in-memory stack file as [`read_stack`] reads it from disk (`.tif`/`.tiff`
/// all pages, `.npy` 3 or 4 axes, `.png` one frame), the format following `name`'s
/// extension; sizes checked against `budget` before allocation.
pub fn decode_stack_bytes(name: &Path, bytes: &[u8], budget: &ByteBudget) -> Result<Array4<f32>, IoError> {
    let path = name;
    match extension(path).as_str() {
        "tif" | "tiff" => {
            let t = decode_tiff(path, bytes, Pages::All, budget)?;
            let names: Vec<String> = (0..t.pages.len()).map(|i| format!("page {}", i + 1)).collect();
            let video = stack_frames(path, &t.pages, &names)?;
            Ok(regroup_imagej_channels(video, t.description.as_deref()))
        }
        "npy" => npy_to_video(path, decode_npy(path, bytes, budget)?),
        "png" => Ok(decode_png(path, bytes, budget)?.insert_axis(Axis(0))),
        _ => Err(IoError::UnknownExtension { path: path.to_path_buf(), expected: ".tif, .tiff, .npy, .png or a directory of numbered images" }),
    }
}

/// The full scale of an image file's samples: 255 for 8-bit and 65535 for 16-bit
/// unsigned samples (TIFF, PNG, NPY), `None` for float samples or a file that cannot
/// be read (the readers report that). Only the header is decoded.
pub fn sample_full_scale(path: impl AsRef<Path>) -> Option<f64> {
    let path = path.as_ref();
    let bits = match extension(path).as_str() {
        "tif" | "tiff" => {
            let file = std::fs::File::open(path).ok()?;
            let len = file.metadata().ok()?.len();
            let mut dec = tiff::decoder::Decoder::new(std::io::BufReader::new(file)).ok()?.with_limits(tiff_limits(len, &ByteBudget::system()));
            let float = matches!(dec.find_tag_unsigned::<u16>(tiff::tags::Tag::SampleFormat), Ok(Some(3)));
            if float {
                return None;
            }
            match dec.colortype().ok()? {
                tiff::ColorType::Gray(b) | tiff::ColorType::RGB(b) => b,
                _ => return None,
            }
        }
        "png" => {
            let reader = image::ImageReader::open(path).ok()?.with_guessed_format().ok()?;
            use image::ImageDecoder;
            match reader.into_decoder().ok()?.color_type() {
                image::ColorType::L8 | image::ColorType::Rgb8 => 8,
                image::ColorType::L16 | image::ColorType::Rgb16 => 16,
                _ => return None,
            }
        }
        "npy" => {
            let mut head = vec![0u8; 256];
            use std::io::Read;
            let n = std::fs::File::open(path).ok()?.read(&mut head).ok()?;
            let text = String::from_utf8_lossy(&head[..n]);
            if text.contains("'|u1'") {
                8
            } else if text.contains("'<u2'") || text.contains("'>u2'") {
                16
            } else {
                return None;
            }
        }
        _ => return None,
    };
    match bits {
        8 => Some(255.0),
        16 => Some(65535.0),
        _ => None,
    }
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
/// * a directory: every `.png`/`.tif`/`.tiff` file in it (hidden files skipped), in
///   natural order of names (`f2` before `f10`), each read with [`read_image`].
pub fn read_stack(path: impl AsRef<Path>) -> Result<Array4<f32>, IoError> {
    let path = path.as_ref();
    if path.is_dir() {
        return read_dir_stack(path);
    }
    match extension(path).as_str() {
        "tif" | "tiff" | "npy" | "png" => decode_stack_bytes(path, &read_bytes(path)?, &ByteBudget::system()),
        _ => Err(IoError::UnknownExtension { path: path.to_path_buf(), expected: ".tif, .tiff, .npy, .png or a directory of numbered images" }),
    }
}

/// Stacks equally shaped frames, naming the first that differs from frame 0.
fn stack_frames(path: &Path, frames: &[Array3<f32>], names: &[String]) -> Result<Array4<f32>, IoError> {
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

/// The value of `key=` in an ImageJ description.
fn imagej_value(description: &str, key: &str) -> Option<usize> {
    if !description.starts_with("ImageJ=") {
        return None;
    }
    description.lines().filter_map(|l| l.split_once('=')).find(|(k, _)| k.trim() == key).and_then(|(_, v)| v.trim().parse().ok())
}

fn regroup_imagej_channels(video: Array4<f32>, description: Option<&str>) -> Array4<f32> {
    let Some(c) = description.and_then(|d| imagej_value(d, "channels")) else {
        return video;
    };
    let (pages, rows, cols, ch) = video.dim();
    if c <= 1 || ch != 1 || pages % c != 0 {
        return video;
    }
    let frames = pages / c;
    let mut out = Array4::<f32>::zeros((frames, rows, cols, c));
    for f in 0..frames {
        for k in 0..c {
            out.slice_mut(s![f, .., .., k]).assign(&video.slice(s![f * c + k, .., .., 0]));
        }
    }
    out
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
        if matches!(extension(&p).as_str(), "png" | "tif" | "tiff") {
            files.push((name, p));
        }
    }
    if files.is_empty() {
        return Err(IoError::unexpected(dir, "numbered .png/.tif/.tiff images in the directory", "none"));
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

    #[test]
    fn imagej_values_are_parsed_only_from_imagej_descriptions() {
        let d = "ImageJ=1.11a\nimages=6\nchannels=3\nframes=2\n";
        assert_eq!(imagej_value(d, "channels"), Some(3));
        assert_eq!(imagej_value(d, "frames"), Some(2));
        assert_eq!(imagej_value(d, "slices"), None);
        assert_eq!(imagej_value("channels=3", "channels"), None);
    }
}
