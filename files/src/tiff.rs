//! The one TIFF codec of the workspace: counting and decoding pages (classic and
//! BigTIFF, either byte order) under size limits, writing single images and
//! ImageJ-compatible float stacks, and the 16-bit grey frames of a capture folder.
//!
//! It works on bytes and sample vectors and names no file: each caller puts its path and
//! its own error type around a [`TiffProblem`] (the main crate's `TIFF` image format in
//! `src/io/formats/tiff.rs`, the capture folder in [`crate::capture`]).

use std::io::{Cursor, Read, Seek, Write};

use tiff::decoder::{Decoder, DecodingResult, Limits};
use tiff::encoder::{colortype, TiffEncoder};
use tiff::tags::Tag;
use tiff::ColorType;

/// The encoder's and decoder's own error (an I/O error of the writer included).
pub use tiff::TiffError;

/// What is wrong with a TIFF's content, without the file's name (the caller adds it).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TiffProblem {
    /// The file ends before the data its headers describe.
    #[error("truncated TIFF ({0})")]
    Truncated(String),
    /// The file is malformed (the decoder's message attached).
    #[error("invalid TIFF: {0}")]
    Malformed(String),
    /// Valid TIFF, but not what the caller reads (channels, sample type, a page).
    #[error("expected {expected}, found {found}")]
    Unexpected { expected: String, found: String },
}

fn unexpected(expected: &str, found: String) -> TiffProblem {
    TiffProblem::Unexpected { expected: expected.to_string(), found }
}

/// Whether `bytes` start like a TIFF file (classic or BigTIFF, either byte order).
pub fn is_tiff(bytes: &[u8]) -> bool {
    [b"II*\0", b"MM\0*", b"II+\0", b"MM\0+"].iter().any(|m| bytes.starts_with(*m))
}

/// Maps a decoder error; an unexpected end of file becomes [`TiffProblem::Truncated`].
fn decode_problem(e: TiffError, context: &str) -> TiffProblem {
    match e {
        TiffError::IoError(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => TiffProblem::Truncated(format!("{context}: file ends early")),
        other => TiffProblem::Malformed(format!("{context}: {other}")),
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
pub fn imagej_value(description: &str, key: &str) -> Option<usize> {
    if !description.starts_with("ImageJ=") {
        return None;
    }
    description.lines().filter_map(|l| l.split_once('=')).find(|(k, _)| k.trim() == key).and_then(|(_, v)| v.trim().parse().ok())
}

/// Decoder limits for a file of `file_len` bytes when no buffer may exceed
/// `limit_bytes`. No single decoder buffer may exceed that, nor 4096 times the file's
/// length: no TIFF compression (deflate ~1032:1, LZW ~2700:1, PackBits 64:1) inflates
/// more than that, and a tag announcing more values than the file could hold is refused
/// before the decoder reserves room for them.
fn limits(file_len: u64, limit_bytes: u64) -> Limits {
    let cap = file_len.saturating_mul(4096).max(1 << 20).min(limit_bytes);
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
pub fn count_pages(bytes: &[u8]) -> Result<usize, TiffProblem> {
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
        return Err(TiffProblem::Truncated(format!("header incomplete ({len} bytes)")));
    };
    let mut seen = std::collections::HashSet::new();
    let mut pages = 0usize;
    while next != 0 {
        if !seen.insert(next) {
            return Err(TiffProblem::Malformed(format!("the directory of page {} loops back to an earlier page", pages + 1)));
        }
        let Some(entries) = read(next, count_len) else {
            return Err(TiffProblem::Truncated(format!("the directory of page {} at byte {next} lies past the end of the file ({len} bytes)", pages + 1)));
        };
        let link = entries.checked_mul(entry_len).and_then(|e| e.checked_add(next + count_len as u64));
        let Some(following) = link.and_then(|l| read(l, offset_len)) else {
            return Err(TiffProblem::Truncated(format!(
                "the directory of page {} ({entries} entries at byte {next}) runs past the end of the file ({len} bytes)",
                pages + 1
            )));
        };
        pages += 1;
        next = following;
    }
    Ok(pages)
}

/// The shape of one page, read from its directory before its samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PageShape {
    pub width: u32,
    pub height: u32,
    /// 1 (grey) or 3 (RGB).
    pub channels: usize,
    /// Bits per sample: 8, 16, 32 or 64.
    pub bits: u8,
}

impl PageShape {
    /// Samples of the page (`width * height * channels`), as u128 (no overflow).
    pub fn samples(&self) -> u128 {
        u128::from(self.width) * u128::from(self.height) * self.channels as u128
    }

    /// Bytes the decoder holds for the page's samples.
    pub fn decoded_bytes(&self) -> u128 {
        self.samples().saturating_mul(u128::from(self.bits).div_ceil(8).max(1))
    }

    /// In words: `W x H pixels grey, B-bit samples`.
    pub fn describe(&self) -> String {
        let kind = if self.channels == 1 { "grey" } else { "RGB" };
        format!("{} x {} pixels {kind}, {}-bit samples", self.width, self.height, self.bits)
    }
}

/// The decoded samples of one page, row by row, channels interleaved.
#[derive(Clone, Debug, PartialEq)]
pub enum Samples {
    U8(Vec<u8>),
    U16(Vec<u16>),
    F32(Vec<f32>),
    F64(Vec<f64>),
}

impl Samples {
    pub fn len(&self) -> usize {
        match self {
            Samples::U8(v) => v.len(),
            Samples::U16(v) => v.len(),
            Samples::F32(v) => v.len(),
            Samples::F64(v) => v.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The sample type in words (`16-bit unsigned`).
    pub fn kind(&self) -> &'static str {
        match self {
            Samples::U8(_) => "8-bit unsigned",
            Samples::U16(_) => "16-bit unsigned",
            Samples::F32(_) => "32-bit float",
            Samples::F64(_) => "64-bit float",
        }
    }

    /// The first `n` samples as f32 (f64 rounded to the nearest f32).
    pub fn into_f32(self, n: usize) -> Vec<f32> {
        match self {
            Samples::U8(v) => v.into_iter().take(n).map(f32::from).collect(),
            Samples::U16(v) => v.into_iter().take(n).map(f32::from).collect(),
            Samples::F32(mut v) => {
                v.truncate(n);
                v
            }
            Samples::F64(v) => v.into_iter().take(n).map(|x| x as f32).collect(),
        }
    }
}

/// An in-memory TIFF, page by page: its page count and first description are read when
/// it is opened, then [`shape`](Self::shape) and [`read`](Self::read) decode the current
/// page and [`next_page`](Self::next_page) moves on. Pages are 0-based here and named
/// from 1 in messages.
pub struct TiffPages<'a> {
    dec: Decoder<Cursor<&'a [u8]>>,
    len: u64,
    count: usize,
    page: usize,
    description: Option<String>,
}

impl<'a> TiffPages<'a> {
    /// Checks the header and the chain of directories and opens the first page; no
    /// decoder buffer may exceed `limit_bytes`.
    pub fn open(bytes: &'a [u8], limit_bytes: u64) -> Result<Self, TiffProblem> {
        let len = bytes.len() as u64;
        match first_ifd_offset(bytes) {
            Some(o) if o.saturating_add(2) <= len => {}
            Some(o) => return Err(TiffProblem::Truncated(format!("first image directory at byte {o} lies past the end of the file ({len} bytes)"))),
            None => return Err(TiffProblem::Truncated(format!("header incomplete ({len} bytes)"))),
        }
        let count = count_pages(bytes)?;
        let mut dec = Decoder::new(Cursor::new(bytes)).map_err(|e| decode_problem(e, "page 1 directory"))?.with_limits(limits(len, limit_bytes));
        let description = dec.get_tag_ascii_string(Tag::ImageDescription).ok();
        Ok(TiffPages { dec, len, count, page: 0, description })
    }

    /// The number of pages.
    pub fn count(&self) -> usize {
        self.count
    }

    /// The first page's ImageDescription, when it has one.
    pub fn description(&self) -> Option<&str> {
        self.description.as_deref()
    }

    /// Moves to the next page.
    pub fn next_page(&mut self) -> Result<(), TiffProblem> {
        self.dec.next_image().map_err(|e| decode_problem(e, &format!("page {} directory", self.page + 2)))?;
        self.page += 1;
        Ok(())
    }

    /// The current page's shape: 8/16-bit unsigned or 32/64-bit float samples, grey or
    /// interleaved RGB, every strip (or tile) inside the file; anything else is refused
    /// by name (grey+alpha, RGBA, palette, packed depths, planar RGB).
    pub fn shape(&mut self) -> Result<PageShape, TiffProblem> {
        let (page, dec, file_len) = (self.page, &mut self.dec, self.len);
        let ctx = format!("page {}", page + 1);
        let (width, height) = dec.dimensions().map_err(|e| decode_problem(e, &ctx))?;
        // Checked before the decoder's colour type, which refuses grey+alpha without naming it.
        let samples = dec.find_tag_unsigned::<u16>(Tag::SamplesPerPixel).ok().flatten().unwrap_or(1);
        let at = if page == 0 { String::new() } else { format!(" on page {}", page + 1) };
        match samples {
            1 | 3 => {}
            2 => return Err(unexpected("a grey or RGB image", format!("grey+alpha (2 channels){at}"))),
            n => return Err(unexpected("a grey or RGB image", format!("{n} channels{at}"))),
        }
        let color = dec.colortype().map_err(|e| decode_problem(e, &ctx))?;
        let (channels, bits) = match color {
            ColorType::Gray(b) => (1, b),
            ColorType::RGB(b) => (3, b),
            ColorType::GrayA(_) => return Err(unexpected("a grey or RGB image", format!("grey+alpha (2 channels) on {ctx}"))),
            ColorType::RGBA(_) => return Err(unexpected("a grey or RGB image", format!("4 channels (RGBA) on {ctx}"))),
            other => return Err(unexpected("a grey or RGB image", format!("colour type {other:?} on {ctx}"))),
        };
        // Packed samples (1, 2, 4, 12-bit...) would decode to fewer values than pixels and read
        // as a truncated file: refuse them by their depth.
        if ![8, 16, 32, 64].contains(&bits) {
            return Err(unexpected("8/16-bit unsigned or 32/64-bit float samples", format!("{bits}-bit samples on {ctx}")));
        }
        if channels == 3 {
            if let Ok(Some(2u16)) = dec.find_tag_unsigned::<u16>(Tag::PlanarConfiguration) {
                return Err(unexpected("interleaved (chunky) RGB samples", format!("planar RGB on {ctx}")));
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
                    return Err(TiffProblem::Truncated(format!(
                        "{which}{unit} {k} missing: {unit} {k} of {n} needs bytes {o}..{}, the file has {file_len}",
                        o.saturating_add(c)
                    )));
                }
            }
        }
        Ok(PageShape { width, height, channels, bits })
    }

    /// Decodes the current page, whose [`shape`](Self::shape) is `shape`: at least
    /// `shape.samples()` values (fewer is a truncated file).
    pub fn read(&mut self, shape: &PageShape) -> Result<Samples, TiffProblem> {
        let ctx = format!("page {}", self.page + 1);
        let samples = match self.dec.read_image().map_err(|e| decode_problem(e, &ctx))? {
            DecodingResult::U8(v) => Samples::U8(v),
            DecodingResult::U16(v) => Samples::U16(v),
            DecodingResult::F32(v) => Samples::F32(v),
            DecodingResult::F64(v) => Samples::F64(v),
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
                return Err(unexpected("8/16-bit unsigned or float samples", format!("{kind} samples on {ctx}")));
            }
        };
        let expected = shape.samples();
        if (samples.len() as u128) < expected {
            return Err(TiffProblem::Truncated(format!("{ctx}: {} of {expected} samples decoded", samples.len())));
        }
        Ok(samples)
    }
}

/// The first page of an in-memory TIFF as (width, height, samples), whatever its sample
/// type (the capture folder's frames are 16-bit grey; the caller checks).
pub fn decode_first_page(bytes: &[u8]) -> Result<(u32, u32, Samples), TiffProblem> {
    let mut pages = TiffPages::open(bytes, u64::MAX)?;
    let shape = pages.shape()?;
    let samples = pages.read(&shape)?;
    Ok((shape.width, shape.height, samples))
}

/// Bits per sample of the first page of the TIFF `r` (`len` bytes) when its samples are
/// unsigned integers, grey or RGB; `None` for float samples or anything unreadable.
pub fn unsigned_sample_bits<R: Read + Seek>(r: R, len: u64, limit_bytes: u64) -> Option<u32> {
    let mut dec = Decoder::new(r).ok()?.with_limits(limits(len, limit_bytes));
    if matches!(dec.find_tag_unsigned::<u16>(Tag::SampleFormat), Ok(Some(3))) {
        return None;
    }
    match dec.colortype().ok()? {
        ColorType::Gray(b) | ColorType::RGB(b) => Some(u32::from(b)),
        _ => None,
    }
}

/// Writes one image of 16-bit samples (1 channel: grey, 3: RGB, interleaved).
pub fn write_u16<W: Write + Seek>(w: W, width: u32, height: u32, channels: usize, samples: &[u16]) -> Result<(), TiffError> {
    let mut enc = TiffEncoder::new(w)?;
    if channels == 1 {
        enc.write_image::<colortype::Gray16>(width, height, samples)
    } else {
        enc.write_image::<colortype::RGB16>(width, height, samples)
    }
}

/// Writes one image of 32-bit float samples (1 channel: grey, 3: RGB, interleaved).
pub fn write_f32<W: Write + Seek>(w: W, width: u32, height: u32, channels: usize, samples: &[f32]) -> Result<(), TiffError> {
    let mut enc = TiffEncoder::new(w)?;
    if channels == 1 {
        enc.write_image::<colortype::Gray32Float>(width, height, samples)
    } else {
        enc.write_image::<colortype::RGB32Float>(width, height, samples)
    }
}

/// The ImageJ ImageDescription written on the first page of a stack; with a frame
/// interval (microseconds), its `finterval` in seconds (`tunit=sec`) and the spatial
/// `unit` (pixel: the video has no length calibration).
pub fn imagej_description(frames: usize, channels: usize, min: f32, max: f32, frame_interval_us: Option<f64>) -> String {
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

/// Writes `planes` grey float32 planes of `width x height` as a multi-page TIFF that
/// ImageJ/Fiji and napari open as a stack; `fill(k, plane)` puts plane `k`'s samples
/// (row by row) into the emptied `plane`. The first page carries `description`. ImageJ
/// reads only the first directory of its own stacks and assumes the planes follow each
/// other in the file, so all planes are written contiguously (one strip each) before the
/// directories. Classic TIFF: the planes must total less than 4 GiB (the caller checks).
pub fn write_f32_planes<W: Write + Seek>(
    w: W,
    width: u32,
    height: u32,
    planes: usize,
    description: &str,
    mut fill: impl FnMut(usize, &mut Vec<f32>),
) -> Result<(), TiffError> {
    let plane_bytes = u64::from(width) * u64::from(height) * 4;
    let mut enc = TiffEncoder::new(w)?;
    let mut offsets = Vec::with_capacity(planes);
    {
        // The first directory also writes all pixel data, contiguously, before itself.
        let mut dir = enc.new_directory()?;
        let mut plane = Vec::with_capacity(width as usize * height as usize);
        for k in 0..planes {
            plane.clear();
            fill(k, &mut plane);
            offsets.push(dir.write_data(&plane[..])?);
        }
        write_plane_tags(&mut dir, height, width, offsets[0], plane_bytes, Some(description))?;
        dir.finish()?;
    }
    for &off in &offsets[1..] {
        let mut dir = enc.new_directory()?;
        write_plane_tags(&mut dir, height, width, off, plane_bytes, None)?;
        dir.finish()?;
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

    #[test]
    fn sixteen_bit_frames_and_float_stacks_read_back_with_their_pages() {
        let mut buf = Cursor::new(Vec::new());
        let pixels: Vec<u16> = (0..12).map(|k| k * 5000).collect();
        write_u16(&mut buf, 4, 3, 1, &pixels).unwrap();
        let bytes = buf.into_inner();
        assert!(is_tiff(&bytes));
        assert_eq!(decode_first_page(&bytes).unwrap(), (4, 3, Samples::U16(pixels)));
        // A file cut short names what is missing.
        let cut = &bytes[..bytes.len() / 2];
        assert!(matches!(decode_first_page(cut), Err(TiffProblem::Truncated(_))), "{:?}", decode_first_page(cut));

        let mut buf = Cursor::new(Vec::new());
        let d = imagej_description(3, 1, 0.0, 2.0, None);
        write_f32_planes(&mut buf, 2, 2, 3, &d, |k, plane| plane.extend([k as f32; 4])).unwrap();
        let bytes = buf.into_inner();
        assert_eq!(count_pages(&bytes).unwrap(), 3);
        let mut pages = TiffPages::open(&bytes, u64::MAX).unwrap();
        assert_eq!(pages.description(), Some(d.as_str()));
        for k in 0..3 {
            if k > 0 {
                pages.next_page().unwrap();
            }
            let shape = pages.shape().unwrap();
            assert_eq!(shape, PageShape { width: 2, height: 2, channels: 1, bits: 32 });
            assert_eq!(pages.read(&shape).unwrap(), Samples::F32(vec![k as f32; 4]));
        }
        assert!(pages.next_page().is_err());
    }
}
