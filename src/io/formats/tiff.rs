//! TIFF (`.tif`, `.tiff`): reading (one page, or all pages as a video) and writing
//! (single images, ImageJ-compatible float stacks).

use std::io::{Cursor, Seek, Write};
use std::path::Path;

use ndarray::{s, Array3, Array4, ArrayView3, ArrayView4, Axis};
use tiff::decoder::{Decoder, DecodingResult, Limits};
use tiff::encoder::{colortype, TiffEncoder};
use tiff::tags::Tag;
use tiff::{ColorType, TiffError};

use super::image_format::{stack_frames, ImageFormat, StackWriter};
use crate::io::atomic::write_atomic;
use crate::io::budget::{array_bytes, ByteBudget};
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

    fn sniff(&self, bytes: &[u8]) -> bool {
        [b"II*\0", b"MM\0*", b"II+\0", b"MM\0+"].iter().any(|m| bytes.starts_with(*m))
    }

    /// 8/16-bit unsigned or 32/64-bit float samples, grey or RGB (grey+alpha, RGBA,
    /// palette, planar RGB refused). `None` takes a single-page file only.
    fn decode_image(&self, path: &Path, bytes: &[u8], page: Option<usize>, budget: &ByteBudget) -> Result<Array3<f32>, IoError> {
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

    /// One frame per page, every page the same size and channels (the error names the
    /// first page that differs). A stack whose first page carries an ImageJ description
    /// with `channels=C > 1` over grey pages (as [`write_tiff_stack_f32`] writes it) is
    /// regrouped into C channels, pages in (frame, channel) order.
    fn decode_stack(&self, path: &Path, bytes: &[u8], budget: &ByteBudget) -> Result<Array4<f32>, IoError> {
        let t = decode_tiff(path, bytes, Pages::All, budget)?;
        let names: Vec<String> = (0..t.pages.len()).map(|i| format!("page {}", i + 1)).collect();
        let video = stack_frames(path, &t.pages, &names)?;
        Ok(regroup_imagej_channels(video, t.description.as_deref()))
    }

    fn sample_bits(&self, path: &Path) -> Option<u32> {
        let file = std::fs::File::open(path).ok()?;
        let len = file.metadata().ok()?.len();
        let mut dec = Decoder::new(std::io::BufReader::new(file)).ok()?.with_limits(tiff_limits(len, &ByteBudget::system()));
        if matches!(dec.find_tag_unsigned::<u16>(Tag::SampleFormat), Ok(Some(3))) {
            return None;
        }
        match dec.colortype().ok()? {
            ColorType::Gray(b) | ColorType::RGB(b) => Some(u32::from(b)),
            _ => None,
        }
    }

    fn writer(&self) -> Option<StackWriter> {
        Some(|path, video| write_tiff_stack_f32(path, video))
    }
}

/// One decoded TIFF: its pages as (row, col, channel) images, and the first page's
/// ImageDescription when it has one.
struct TiffPages {
    pub pages: Vec<Array3<f32>>,
    pub description: Option<String>,
}

fn truncated(path: &Path, detail: impl Into<String>) -> IoError {
    IoError::Truncated { path: path.to_path_buf(), format: "TIFF", detail: detail.into() }
}

/// Maps a decoder error; an unexpected end of file becomes [`IoError::Truncated`].
fn map_tiff_err(path: &Path, e: TiffError, context: &str) -> IoError {
    match e {
        TiffError::IoError(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => truncated(path, format!("{context}: file ends early")),
        other => IoError::malformed(path, "TIFF", format!("{context}: {other}")),
    }
}

/// Offset of the first image directory, from the header (classic and BigTIFF).
fn first_ifd_offset(bytes: &[u8]) -> Option<u64> {
    let le = bytes.get(0..2)? == b"II";
    let u16_at = |o: usize| -> Option<u16> {
        let b: [u8; 2] = bytes.get(o..o + 2)?.try_into().ok()?;
        Some(if le { u16::from_le_bytes(b) } else { u16::from_be_bytes(b) })
    };
    match u16_at(2)? {
        42 => {
            let b: [u8; 4] = bytes.get(4..8)?.try_into().ok()?;
            Some(u64::from(if le { u32::from_le_bytes(b) } else { u32::from_be_bytes(b) }))
        }
        43 => {
            let b: [u8; 8] = bytes.get(8..16)?.try_into().ok()?;
            Some(if le { u64::from_le_bytes(b) } else { u64::from_be_bytes(b) })
        }
        _ => None,
    }
}

/// The value of `key=` in an ImageJ description.
fn imagej_value(description: &str, key: &str) -> Option<usize> {
    if !description.starts_with("ImageJ=") {
        return None;
    }
    description.lines().filter_map(|l| l.split_once('=')).find(|(k, _)| k.trim() == key).and_then(|(_, v)| v.trim().parse().ok())
}

/// Regroups the grey pages of an ImageJ stack of `channels=C` into C channels.
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

/// Which pages [`decode_tiff`] decodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Pages {
    /// Every page (a stack).
    All,
    /// The one page with this 0-based index.
    One(usize),
}

/// Decoder limits for a file of `file_len` bytes under `budget`. No single decoder
/// buffer may exceed the budget, nor 4096 times the file's length: no TIFF compression
/// (deflate ~1032:1, LZW ~2700:1, PackBits 64:1) inflates more than that, and a tag
/// announcing more values than the file could hold is refused before the decoder
/// reserves room for them.
fn tiff_limits(file_len: u64, budget: &ByteBudget) -> Limits {
    let cap = file_len.saturating_mul(4096).max(1 << 20).min(budget.limit_bytes);
    let cap = usize::try_from(cap).unwrap_or(usize::MAX);
    let mut limits = Limits::default();
    limits.decoding_buffer_size = cap;
    limits.intermediate_buffer_size = cap;
    limits.ifd_value_size = cap;
    limits
}

/// The number of pages (image directories) of an in-memory TIFF, walking the chain of
/// directories without decoding them. A chain that loops, or points past the end of the
/// file, is an error naming the page.
fn count_pages(path: &Path, bytes: &[u8]) -> Result<usize, IoError> {
    let len = bytes.len() as u64;
    let le = bytes.starts_with(b"II");
    let read = |o: u64, n: usize| -> Option<u64> {
        let o = usize::try_from(o).ok()?;
        let b = bytes.get(o..o.checked_add(n)?)?;
        let mut v = 0u64;
        for k in 0..n {
            let byte = if le { b[n - 1 - k] } else { b[k] };
            v = (v << 8) | u64::from(byte);
        }
        Some(v)
    };
    let big = read(2, 2) == Some(43);
    let (count_len, entry_len, offset_len) = if big { (8, 20, 8) } else { (2, 12, 4) };
    let Some(mut next) = first_ifd_offset(bytes) else {
        return Err(truncated(path, format!("header incomplete ({len} bytes)")));
    };
    let mut seen = std::collections::HashSet::new();
    let mut pages = 0usize;
    while next != 0 {
        if !seen.insert(next) {
            return Err(IoError::malformed(path, "TIFF", format!("the directory of page {} loops back to an earlier page", pages + 1)));
        }
        let Some(entries) = read(next, count_len) else {
            return Err(truncated(path, format!("the directory of page {} at byte {next} lies past the end of the file ({len} bytes)", pages + 1)));
        };
        let link = entries.checked_mul(entry_len).and_then(|e| e.checked_add(next + count_len as u64));
        let Some(following) = link.and_then(|l| read(l, offset_len)) else {
            return Err(truncated(
                path,
                format!("the directory of page {} ({entries} entries at byte {next}) runs past the end of the file ({len} bytes)", pages + 1),
            ));
        };
        pages += 1;
        next = following;
    }
    Ok(pages)
}

/// Decodes the chosen pages of an in-memory TIFF file. Every size the file announces is
/// checked against `budget` before it is allocated: each page's decoded buffer and its
/// f32 copy, and the whole stack (twice its f32 size: the pages and the stacked video).
fn decode_tiff(path: &Path, bytes: &[u8], which: Pages, budget: &ByteBudget) -> Result<TiffPages, IoError> {
    let len = bytes.len() as u64;
    match first_ifd_offset(bytes) {
        Some(o) if o.saturating_add(2) <= len => {}
        Some(o) => return Err(truncated(path, format!("first image directory at byte {o} lies past the end of the file ({len} bytes)"))),
        None => return Err(truncated(path, format!("header incomplete ({len} bytes)"))),
    }
    let count = count_pages(path, bytes)?;
    let (first, last) = match which {
        Pages::All => (0, count),
        Pages::One(p) if p < count => (p, p + 1),
        Pages::One(p) => {
            return Err(IoError::unexpected(path, format!("a page from 1 to {count}"), format!("page {} requested; the file holds {count} page(s)", p + 1)))
        }
    };
    let mut dec = Decoder::new(Cursor::new(bytes)).map_err(|e| map_tiff_err(path, e, "page 1 directory"))?.with_limits(tiff_limits(len, budget));
    let description = dec.get_tag_ascii_string(Tag::ImageDescription).ok();
    for page in 0..first {
        dec.next_image().map_err(|e| map_tiff_err(path, e, &format!("page {} directory", page + 2)))?;
    }
    let mut pages = Vec::new();
    let mut held: u128 = 0;
    for page in first..last {
        if page > first {
            dec.next_image().map_err(|e| map_tiff_err(path, e, &format!("page {} directory", page + 1)))?;
        }
        let copies = if which == Pages::All { 2 } else { 1 };
        let remaining = (last - page) as u128;
        let img = decode_page(path, &mut dec, page, len, |shape, one_f32, decoded| {
            let need = held.saturating_add(one_f32.saturating_mul(remaining * copies)).saturating_add(decoded);
            let what = match which {
                Pages::One(_) => format!("page {} ({shape}, as f32 plus the decoded samples)", page + 1),
                Pages::All => format!("a stack of {count} pages (page {} is {shape}; the pages as f32, twice, plus one page's decoded samples)", page + 1),
            };
            budget.check(|| what, need).map_err(|source| IoError::TooLarge { path: path.to_path_buf(), source: Box::new(source) })
        })?;
        held = held.saturating_add(img.len() as u128 * 4);
        pages.push(img);
    }
    Ok(TiffPages { pages, description })
}

/// Decodes the decoder's current page (0-based `page`, named 1-based in messages).
/// `check(shape, f32_bytes, decoded_bytes)` is called with the page's size before
/// anything of that size is allocated.
fn decode_page<R: std::io::Read + Seek>(
    path: &Path,
    dec: &mut Decoder<R>,
    page: usize,
    file_len: u64,
    check: impl FnOnce(&str, u128, u128) -> Result<(), IoError>,
) -> Result<Array3<f32>, IoError> {
    let ctx = format!("page {}", page + 1);
    let (width, height) = dec.dimensions().map_err(|e| map_tiff_err(path, e, &ctx))?;
    // Checked before the decoder's colour type, which refuses grey+alpha without naming it.
    let samples = dec.find_tag_unsigned::<u16>(Tag::SamplesPerPixel).ok().flatten().unwrap_or(1);
    let at = if page == 0 { String::new() } else { format!(" on page {}", page + 1) };
    match samples {
        1 | 3 => {}
        2 => return Err(IoError::unexpected(path, "a grey or RGB image", format!("grey+alpha (2 channels){at}"))),
        n => return Err(IoError::unexpected(path, "a grey or RGB image", format!("{n} channels{at}"))),
    }
    let color = dec.colortype().map_err(|e| map_tiff_err(path, e, &ctx))?;
    let (channels, bits) = match color {
        ColorType::Gray(b) => (1, b),
        ColorType::RGB(b) => (3, b),
        ColorType::GrayA(_) => return Err(IoError::unexpected(path, "a grey or RGB image", format!("grey+alpha (2 channels) on {ctx}"))),
        ColorType::RGBA(_) => return Err(IoError::unexpected(path, "a grey or RGB image", format!("4 channels (RGBA) on {ctx}"))),
        other => return Err(IoError::unexpected(path, "a grey or RGB image", format!("colour type {other:?} on {ctx}"))),
    };
    // Packed samples (1, 2, 4, 12-bit...) would decode to fewer values than pixels and read
    // as a truncated file: refuse them by their depth.
    if ![8, 16, 32, 64].contains(&bits) {
        return Err(IoError::unexpected(path, "8/16-bit unsigned or 32/64-bit float samples", format!("{bits}-bit samples on {ctx}")));
    }
    if channels == 3 {
        if let Ok(Some(2u16)) = dec.find_tag_unsigned::<u16>(Tag::PlanarConfiguration) {
            return Err(IoError::unexpected(path, "interleaved (chunky) RGB samples", format!("planar RGB on {ctx}")));
        }
    }

    // Every strip (or tile) must lie inside the file; say which one is missing otherwise.
    let (off_tag, cnt_tag, unit) = if dec.find_tag(Tag::TileOffsets).ok().flatten().is_some() {
        (Tag::TileOffsets, Tag::TileByteCounts, "tile")
    } else {
        (Tag::StripOffsets, Tag::StripByteCounts, "strip")
    };
    if let (Ok(offsets), Ok(counts)) = (dec.get_tag_u64_vec(off_tag), dec.get_tag_u64_vec(cnt_tag)) {
        let n = offsets.len();
        for (k, (&o, &c)) in offsets.iter().zip(counts.iter()).enumerate() {
            if o.saturating_add(c) > file_len {
                let which = if page == 0 { String::new() } else { format!("{ctx}, ") };
                return Err(truncated(
                    path,
                    format!("{which}{unit} {k} missing: {unit} {k} of {n} needs bytes {o}..{}, the file has {file_len}", o.saturating_add(c)),
                ));
            }
        }
    }

    let samples = array_bytes(&[height as usize, width as usize, channels], 1);
    let kind = if channels == 1 { "grey" } else { "RGB" };
    let shape = format!("{width} x {height} pixels {kind}, {bits}-bit samples");
    check(&shape, samples.saturating_mul(4), samples.saturating_mul(u128::from(bits).div_ceil(8).max(1)))?;
    let data = dec.read_image().map_err(|e| map_tiff_err(path, e, &ctx))?;
    let values: Vec<f32> = match data {
        DecodingResult::U8(v) => v.into_iter().map(f32::from).collect(),
        DecodingResult::U16(v) => v.into_iter().map(f32::from).collect(),
        DecodingResult::F32(v) => v,
        DecodingResult::F64(v) => v.into_iter().map(|x| x as f32).collect(),
        other => {
            let kind = match other {
                DecodingResult::U32(_) => "unsigned 32-bit",
                DecodingResult::U64(_) => "unsigned 64-bit",
                DecodingResult::I8(_) => "signed 8-bit",
                DecodingResult::I16(_) => "signed 16-bit",
                DecodingResult::I32(_) => "signed 32-bit",
                DecodingResult::I64(_) => "signed 64-bit",
                _ => "unsupported",
            };
            return Err(IoError::unexpected(path, "8/16-bit unsigned or float samples", format!("{kind} samples on {ctx}")));
        }
    };
    let (rows, cols) = (height as usize, width as usize);
    let expected = rows * cols * channels;
    if values.len() < expected {
        return Err(truncated(path, format!("{ctx}: {} of {expected} samples decoded", values.len())));
    }
    let mut values = values;
    values.truncate(expected);
    Array3::from_shape_vec((rows, cols, channels), values).map_err(|e| IoError::malformed(path, "TIFF", format!("{ctx}: {e}")))
}

/// Writes one image as a 16-bit unsigned TIFF (grey or RGB). Values are rounded to the
/// nearest integer and clamped to 0..=65535; NaN becomes 0.
pub fn write_tiff_u16(path: impl AsRef<Path>, image: ArrayView3<f32>) -> Result<(), IoError> {
    let path = path.as_ref();
    let (rows, cols, ch) = checked_dims(path, image)?;
    let data: Vec<u16> = image.iter().map(|&v| v.round().clamp(0.0, 65535.0) as u16).collect();
    write_atomic(path, |w| {
        let mut enc = TiffEncoder::new(w).map_err(|e| enc_err(path, e))?;
        let r = if ch == 1 { enc.write_image::<colortype::Gray16>(cols, rows, &data) } else { enc.write_image::<colortype::RGB16>(cols, rows, &data) };
        r.map_err(|e| enc_err(path, e))
    })
}

/// Writes one image as a 32-bit float TIFF (grey or RGB), values unchanged (NaN and
/// infinities included).
pub fn write_tiff_f32(path: impl AsRef<Path>, image: ArrayView3<f32>) -> Result<(), IoError> {
    let path = path.as_ref();
    let (rows, cols, ch) = checked_dims(path, image)?;
    let data: Vec<f32> = image.iter().copied().collect();
    write_atomic(path, |w| {
        let mut enc = TiffEncoder::new(w).map_err(|e| enc_err(path, e))?;
        let r =
            if ch == 1 { enc.write_image::<colortype::Gray32Float>(cols, rows, &data) } else { enc.write_image::<colortype::RGB32Float>(cols, rows, &data) };
        r.map_err(|e| enc_err(path, e))
    })
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

/// The ImageJ ImageDescription written on the first page of a stack; with a frame
/// interval (microseconds), its `finterval` in seconds (`tunit=sec`) and the spatial
/// `unit` (pixel: the video has no length calibration).
fn imagej_description(frames: usize, channels: usize, min: f32, max: f32, frame_interval_us: Option<f64>) -> String {
    let time = frame_interval_us.map(|us| format!("unit=pixel\nfinterval={}\ntunit=sec\n", us * 1e-6)).unwrap_or_default();
    format!(
        "ImageJ=1.11a\nimages={}\nchannels={}\nframes={}\nhyperstack=true\nmode=grayscale\n{time}min={}\nmax={}\nloop=false\n",
        frames * channels,
        channels,
        frames,
        min,
        max
    )
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
    let description = imagej_description(frames, ch, lo, hi, frame_interval_us.filter(|us| us.is_finite() && *us > 0.0));

    write_atomic(path, |w| write_stack_pages(path, w, video, rows32, cols32, plane_bytes, &description))
}

fn write_stack_pages<W: Write + Seek>(
    path: &Path,
    w: W,
    video: ArrayView4<f32>,
    rows: u32,
    cols: u32,
    plane_bytes: u64,
    description: &str,
) -> Result<(), IoError> {
    let e = |err| enc_err(path, err);
    let (frames, _, _, ch) = video.dim();
    let mut enc = TiffEncoder::new(w).map_err(e)?;
    let mut offsets = Vec::with_capacity(frames * ch);
    {
        // The first directory also writes all pixel data, contiguously, before itself.
        let mut dir = enc.new_directory().map_err(e)?;
        let mut plane = Vec::with_capacity(rows as usize * cols as usize);
        for f in 0..frames {
            for c in 0..ch {
                plane.clear();
                plane.extend(video.index_axis(Axis(0), f).index_axis(Axis(2), c).iter().copied());
                offsets.push(dir.write_data(&plane[..]).map_err(e)?);
            }
        }
        write_plane_tags(&mut dir, rows, cols, offsets[0], plane_bytes, Some(description)).map_err(e)?;
        dir.finish().map_err(e)?;
    }
    for &off in &offsets[1..] {
        let mut dir = enc.new_directory().map_err(e)?;
        write_plane_tags(&mut dir, rows, cols, off, plane_bytes, None).map_err(e)?;
        dir.finish().map_err(e)?;
    }
    Ok(())
}

fn write_plane_tags<W: Write + Seek>(
    dir: &mut tiff::encoder::DirectoryEncoder<'_, W, tiff::encoder::TiffKindStandard>,
    rows: u32,
    cols: u32,
    offset: u64,
    plane_bytes: u64,
    description: Option<&str>,
) -> Result<(), TiffError> {
    dir.write_tag(Tag::NewSubfileType, 0u32)?;
    dir.write_tag(Tag::ImageWidth, cols)?;
    dir.write_tag(Tag::ImageLength, rows)?;
    dir.write_tag(Tag::BitsPerSample, 32u16)?;
    dir.write_tag(Tag::Compression, 1u16)?;
    dir.write_tag(Tag::PhotometricInterpretation, 1u16)?;
    if let Some(d) = description {
        dir.write_tag(Tag::ImageDescription, d)?;
    }
    dir.write_tag(Tag::StripOffsets, u32::try_from(offset)?)?;
    dir.write_tag(Tag::SamplesPerPixel, 1u16)?;
    dir.write_tag(Tag::RowsPerStrip, rows)?;
    dir.write_tag(Tag::StripByteCounts, u32::try_from(plane_bytes)?)?;
    dir.write_tag(Tag::SampleFormat, 3u16)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn imagej_values_are_parsed_only_from_imagej_descriptions() {
        let d = "ImageJ=1.11a\nimages=6\nchannels=3\nframes=2\n";
        assert_eq!(imagej_value(d, "channels"), Some(3));
        assert_eq!(imagej_value(d, "frames"), Some(2));
        assert_eq!(imagej_value(d, "slices"), None);
        assert_eq!(imagej_value("channels=3", "channels"), None);
    }
}
