//! TIFF (`.tif`, `.tiff`) as an image format: reading (one page, or all pages as a
//! video) and writing (single images, ImageJ-compatible float stacks). The codec itself
//! is `rollcam_files::tiff` (the capture folder's frames use it too); this file adapts
//! it to arrays, the byte budget and [`IoError`].

use std::path::Path;

use ndarray::{s, Array3, Array4, ArrayView3, ArrayView4, Axis};
use rollcam_files::tiff::{self as codec, PageShape, TiffError, TiffPages, TiffProblem};

use super::image_format::{one_image, read_bytes, stack_frames, ImageFormat, StackWriter};
use super::raw::{decode_raw, is_cfa_tiff, is_cfa_tiff_file, is_dng, read_raw_info, RawInfo};
use crate::io::atomic::write_atomic;
use crate::io::budget::ByteBudget;
use crate::io::error::IoError;

/// The TIFF format (classic and BigTIFF, either byte order).
pub(crate) struct Tiff;

impl ImageFormat for Tiff {
    fn name(&self) -> &'static str {
        "TIFF"
    }

    fn extensions(&self) -> &'static [&'static str] {
        &["tif", "tiff"]
    }

    /// A TIFF that is not a DNG (whose own format reads it).
    fn sniff(&self, bytes: &[u8]) -> bool {
        codec::is_tiff(bytes) && !is_dng(bytes)
    }

    /// 8/16-bit unsigned or 32/64-bit float samples, grey or RGB (grey+alpha, RGBA,
    /// palette, planar RGB refused). `None` takes a single-page file only. A CFA TIFF
    /// (a Bayer raw: PhotometricInterpretation 32803) reads as colour on the half grid
    /// (`raw.rs`).
    fn decode_image(&self, path: &Path, bytes: &[u8], page: Option<usize>, budget: &ByteBudget) -> Result<Array3<f32>, IoError> {
        if is_cfa_tiff(bytes) {
            one_image(path, page)?;
            return Ok(decode_raw(path, "TIFF", bytes, budget)?.0);
        }
        let which = match page {
            None => match codec::count_pages(bytes).map_err(|p| problem(path, p))? {
                1 => Pages::One(0),
                n => return Err(IoError::PageRequired { path: path.to_path_buf(), pages: n }),
            },
            Some(0) => return Err(IoError::unexpected(path, "a page number from 1 (pages are counted from 1)", "page 0")),
            Some(p) => Pages::One(p - 1),
        };
        let mut t = decode_tiff(path, bytes, which, budget)?;
        Ok(t.pages.swap_remove(0))
    }

    /// One frame per page, every page the same size and channels (the error names the
    /// first page that differs). A stack whose first page carries an ImageJ description
    /// with `channels=C > 1` over grey pages (as [`write_tiff_stack_f32`] writes it) is
    /// regrouped into C channels, pages in (frame, channel) order.
    fn decode_stack(&self, path: &Path, bytes: &[u8], budget: &ByteBudget) -> Result<Array4<f32>, IoError> {
        if is_cfa_tiff(bytes) {
            return Ok(self.decode_image(path, bytes, None, budget)?.insert_axis(Axis(0)));
        }
        let t = decode_tiff(path, bytes, Pages::All, budget)?;
        let names: Vec<String> = (0..t.pages.len()).map(|i| format!("page {}", i + 1)).collect();
        let video = stack_frames(path, &t.pages, &names)?;
        Ok(regroup_imagej_channels(video, t.description.as_deref()))
    }

    fn sample_bits(&self, path: &Path) -> Option<u32> {
        let file = std::fs::File::open(path).ok()?;
        let len = file.metadata().ok()?.len();
        codec::unsigned_sample_bits(std::io::BufReader::new(file), len, ByteBudget::system().limit_bytes).or_else(|| self.raw_info(path).map(|i| i.bits))
    }

    /// Reads the whole file only when its first directory says it is a CFA raw.
    fn raw_info(&self, path: &Path) -> Option<RawInfo> {
        if !is_cfa_tiff_file(path) {
            return None;
        }
        read_raw_info(path, "TIFF", &read_bytes(path).ok()?).ok()
    }

    fn writer(&self) -> Option<StackWriter> {
        Some(|path, video| write_tiff_stack_f32(path, video))
    }
}

/// One decoded TIFF: its pages as (row, col, channel) images, and the first page's
/// ImageDescription when it has one.
struct DecodedTiff {
    pages: Vec<Array3<f32>>,
    description: Option<String>,
}

/// The codec's problem with the file at `path`, as an [`IoError`].
fn problem(path: &Path, p: TiffProblem) -> IoError {
    match p {
        TiffProblem::Truncated(detail) => IoError::Truncated { path: path.to_path_buf(), format: "TIFF", detail },
        TiffProblem::Malformed(detail) => IoError::malformed(path, "TIFF", detail),
        TiffProblem::Unexpected { expected, found } => IoError::unexpected(path, expected, found),
    }
}

/// Regroups the grey pages of an ImageJ stack of `channels=C` into C channels.
fn regroup_imagej_channels(video: Array4<f32>, description: Option<&str>) -> Array4<f32> {
    let Some(c) = description.and_then(|d| codec::imagej_value(d, "channels")) else {
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

/// Which pages [`decode_tiff`] decodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Pages {
    /// Every page (a stack).
    All,
    /// The one page with this 0-based index.
    One(usize),
}

/// Decodes the chosen pages of an in-memory TIFF file. Every size the file announces is
/// checked against `budget` before it is allocated: each page's decoded buffer and its
/// f32 copy, and the whole stack (twice its f32 size: the pages and the stacked video).
fn decode_tiff(path: &Path, bytes: &[u8], which: Pages, budget: &ByteBudget) -> Result<DecodedTiff, IoError> {
    let mut tiff = TiffPages::open(bytes, budget.limit_bytes).map_err(|p| problem(path, p))?;
    let count = tiff.count();
    let (first, last) = match which {
        Pages::All => (0, count),
        Pages::One(p) if p < count => (p, p + 1),
        Pages::One(p) => {
            return Err(IoError::unexpected(path, format!("a page from 1 to {count}"), format!("page {} requested; the file holds {count} page(s)", p + 1)))
        }
    };
    let description = tiff.description().map(str::to_string);
    for _ in 0..first {
        tiff.next_page().map_err(|p| problem(path, p))?;
    }
    let mut pages = Vec::new();
    let mut held: u128 = 0;
    for page in first..last {
        if page > first {
            tiff.next_page().map_err(|p| problem(path, p))?;
        }
        let shape = tiff.shape().map_err(|p| problem(path, p))?;
        let copies = if which == Pages::All { 2 } else { 1 };
        let remaining = (last - page) as u128;
        let one_f32 = shape.samples().saturating_mul(4);
        let need = held.saturating_add(one_f32.saturating_mul(remaining * copies)).saturating_add(shape.decoded_bytes());
        let what = || match which {
            Pages::One(_) => format!("page {} ({}, as f32 plus the decoded samples)", page + 1, shape.describe()),
            Pages::All => {
                format!("a stack of {count} pages (page {} is {}; the pages as f32, twice, plus one page's decoded samples)", page + 1, shape.describe())
            }
        };
        budget.check(what, need).map_err(|source| IoError::TooLarge { path: path.to_path_buf(), source: Box::new(source) })?;
        let img = page_array(path, &mut tiff, page, &shape)?;
        held = held.saturating_add(img.len() as u128 * 4);
        pages.push(img);
    }
    Ok(DecodedTiff { pages, description })
}

/// The current page's samples as a (row, col, channel) f32 image.
fn page_array(path: &Path, tiff: &mut TiffPages<'_>, page: usize, shape: &PageShape) -> Result<Array3<f32>, IoError> {
    let samples = tiff.read(shape).map_err(|p| problem(path, p))?;
    let (rows, cols, channels) = (shape.height as usize, shape.width as usize, shape.channels);
    let values = samples.into_f32(rows * cols * channels);
    Array3::from_shape_vec((rows, cols, channels), values).map_err(|e| IoError::malformed(path, "TIFF", format!("page {}: {e}", page + 1)))
}

/// Writes one image as a 16-bit unsigned TIFF (grey or RGB). Values are rounded to the
/// nearest integer and clamped to 0..=65535; NaN becomes 0.
pub fn write_tiff_u16(path: impl AsRef<Path>, image: ArrayView3<f32>) -> Result<(), IoError> {
    let path = path.as_ref();
    let (rows, cols, ch) = checked_dims(path, image)?;
    let data: Vec<u16> = image.iter().map(|&v| v.round().clamp(0.0, 65535.0) as u16).collect();
    write_atomic(path, |w| codec::write_u16(w, cols, rows, ch, &data).map_err(|e| enc_err(path, e)))
}

/// Writes one image as a 32-bit float TIFF (grey or RGB), values unchanged (NaN and
/// infinities included).
pub fn write_tiff_f32(path: impl AsRef<Path>, image: ArrayView3<f32>) -> Result<(), IoError> {
    let path = path.as_ref();
    let (rows, cols, ch) = checked_dims(path, image)?;
    let data: Vec<f32> = image.iter().copied().collect();
    write_atomic(path, |w| codec::write_f32(w, cols, rows, ch, &data).map_err(|e| enc_err(path, e)))
}

fn enc_err(path: &Path, e: TiffError) -> IoError {
    match e {
        TiffError::IoError(io) => IoError::os(path, "cannot write", io),
        other => IoError::bad_input(path, format!("TIFF encoder: {other}")),
    }
}

fn checked_dims(path: &Path, image: ArrayView3<f32>) -> Result<(u32, u32, usize), IoError> {
    let (rows, cols, ch) = image.dim();
    if rows == 0 || cols == 0 {
        return Err(IoError::bad_input(path, format!("empty image {rows}x{cols}")));
    }
    if ch != 1 && ch != 3 {
        return Err(IoError::bad_input(path, format!("expected 1 or 3 channels, found {ch}")));
    }
    let to_u32 = |n: usize| u32::try_from(n).map_err(|_| IoError::bad_input(path, format!("dimension {n} too large for TIFF")));
    Ok((to_u32(rows)?, to_u32(cols)?, ch))
}

/// [`write_tiff_stack_f32`] of a video whose frames are `frame_interval_us` apart:
/// ImageJ, Fiji and napari then show time, not frame numbers (`finterval`, seconds).
pub fn write_tiff_video_f32(path: impl AsRef<Path>, video: ArrayView4<f32>, frame_interval_us: f64) -> Result<(), IoError> {
    write_stack_described(path.as_ref(), video, Some(frame_interval_us))
}

/// Writes a video (frame, row, col, channel) as a multi-page float32 TIFF that ImageJ/Fiji
/// and napari open as a stack (hyperstack when there are several channels).
///
/// Every page is one grey float32 plane: `frames * channels` pages in (frame, channel)
/// order, because ImageJ does not open interleaved float RGB. The first page carries the
/// ImageJ ImageDescription (`images`, `channels`, `frames`, `hyperstack`, `mode`, and the
/// display range `min`/`max` over the finite values). ImageJ reads only the first
/// directory of its own stacks and assumes the planes follow each other in the file, so
/// all planes are written contiguously (one strip each) before the directories.
/// Classic TIFF: the planes must total less than 4 GiB.
pub fn write_tiff_stack_f32(path: impl AsRef<Path>, video: ArrayView4<f32>) -> Result<(), IoError> {
    write_stack_described(path.as_ref(), video, None)
}

fn write_stack_described(path: &Path, video: ArrayView4<f32>, frame_interval_us: Option<f64>) -> Result<(), IoError> {
    let (frames, rows, cols, ch) = video.dim();
    if frames == 0 {
        return Err(IoError::bad_input(path, "the video has no frames"));
    }
    let (rows32, cols32, _) = checked_dims(path, video.index_axis(Axis(0), 0))?;
    let plane_bytes = (rows * cols * 4) as u64;
    let total = plane_bytes * (frames * ch) as u64;
    if total + 4096 * (frames * ch) as u64 >= u64::from(u32::MAX) {
        return Err(IoError::bad_input(path, format!("{total} bytes of pixels exceed the 4 GiB limit of classic TIFF")));
    }
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for &v in video.iter().filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if lo > hi {
        (lo, hi) = (0.0, 0.0);
    }
    let description = codec::imagej_description(frames, ch, lo, hi, frame_interval_us.filter(|us| us.is_finite() && *us > 0.0));

    // Pages in (frame, channel) order.
    let fill = |k: usize, plane: &mut Vec<f32>| plane.extend(video.index_axis(Axis(0), k / ch).index_axis(Axis(2), k % ch).iter().copied());
    write_atomic(path, |w| codec::write_f32_planes(w, cols32, rows32, frames * ch, &description, fill).map_err(|e| enc_err(path, e)))
}
