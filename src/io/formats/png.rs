//! PNG (`.png`): decoding 8/16-bit grey or RGB, and 8-bit encoding for the pictures
//! of `display.rs` and `plot.rs`. Read only as data: a video is not written as PNG.

use std::io::{Cursor, Write};
use std::path::Path;

use image::codecs::png::PngEncoder;
use image::{DynamicImage, ExtendedColorType, ImageDecoder, ImageEncoder, ImageReader, Limits};
use ndarray::Array3;

use super::image_format::{one_image, ImageFormat};
use crate::io::budget::{array_bytes, ByteBudget};
use crate::io::error::IoError;

/// The PNG format.
pub(crate) struct Png;

impl ImageFormat for Png {
    fn name(&self) -> &'static str {
        "PNG"
    }

    fn extensions(&self) -> &'static [&'static str] {
        &["png"]
    }

    fn sniff(&self, bytes: &[u8]) -> bool {
        bytes.starts_with(b"\x89PNG\r\n\x1a\n")
    }

    fn decode_image(&self, path: &Path, bytes: &[u8], page: Option<usize>, budget: &ByteBudget) -> Result<Array3<f32>, IoError> {
        one_image(path, page)?;
        decode_png(path, bytes, budget)
    }

    fn sample_bits(&self, path: &Path) -> Option<u32> {
        let reader = ImageReader::open(path).ok()?.with_guessed_format().ok()?;
        match reader.into_decoder().ok()?.color_type() {
            image::ColorType::L8 | image::ColorType::Rgb8 => Some(8),
            image::ColorType::L16 | image::ColorType::Rgb16 => Some(16),
            _ => None,
        }
    }
}

/// Decodes an in-memory PNG (8/16-bit grey or RGB; palette images come back as RGB)
/// into (row, col, channel) raw counts. The size in the header is checked against
/// `budget` (the decoded samples plus their f32 copy) before anything is decoded, and the
/// decoder runs under limits from the same budget. The magic bytes were checked.
fn decode_png(path: &Path, bytes: &[u8], budget: &ByteBudget) -> Result<Array3<f32>, IoError> {
    check_palette(path, bytes)?;
    let err = |e: image::ImageError| match e {
        image::ImageError::IoError(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            IoError::Truncated { path: path.to_path_buf(), format: "PNG", detail: "file ends early".into() }
        }
        image::ImageError::Limits(l) => IoError::malformed(path, "PNG", format!("over the decoder's limits ({l})")),
        other => IoError::malformed(path, "PNG", other),
    };
    let mut limits = Limits::default();
    limits.max_alloc = Some(budget.limit_bytes);
    let mut reader = ImageReader::with_format(Cursor::new(bytes), image::ImageFormat::Png);
    reader.limits(limits);
    let decoder = reader.into_decoder().map_err(err)?;
    let (w, h) = decoder.dimensions();
    let colour = decoder.color_type();
    let samples = array_bytes(&[h as usize, w as usize, usize::from(colour.channel_count())], 1);
    let decoded = u128::from(decoder.total_bytes());
    budget
        .check(|| format!("{w} x {h} pixels {colour:?} (the decoded samples plus their f32 copy)"), decoded.saturating_add(samples.saturating_mul(4)))
        .map_err(|source| IoError::TooLarge { path: path.to_path_buf(), source: Box::new(source) })?;
    let img = DynamicImage::from_decoder(decoder).map_err(err)?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let (ch, values): (usize, Vec<f32>) = match img {
        DynamicImage::ImageLuma8(b) => (1, b.into_raw().into_iter().map(f32::from).collect()),
        DynamicImage::ImageLuma16(b) => (1, b.into_raw().into_iter().map(f32::from).collect()),
        DynamicImage::ImageRgb8(b) => (3, b.into_raw().into_iter().map(f32::from).collect()),
        DynamicImage::ImageRgb16(b) => (3, b.into_raw().into_iter().map(f32::from).collect()),
        DynamicImage::ImageLumaA8(_) | DynamicImage::ImageLumaA16(_) => {
            return Err(IoError::unexpected(path, "a grey or RGB image", "grey+alpha (2 channels)"))
        }
        DynamicImage::ImageRgba8(_) | DynamicImage::ImageRgba16(_) => return Err(IoError::unexpected(path, "a grey or RGB image", "4 channels (RGBA)")),
        other => return Err(IoError::unexpected(path, "an 8/16-bit grey or RGB image", format!("{:?}", other.color()))),
    };
    Array3::from_shape_vec((h, w, ch), values).map_err(|e| IoError::malformed(path, "PNG", e))
}

/// A `PLTE` chunk must hold 1 to 256 RGB entries (a multiple of 3 bytes). The `png`
/// decoder (0.18) panics on a palette whose length is not a multiple of 3, so the
/// chunks are walked and such a file refused before it is decoded. The walk stops at
/// `IEND` or where the bytes end; what else is wrong is the decoder's to report.
fn check_palette(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    let mut at = 8usize;
    while at + 8 <= bytes.len() {
        let len = u32::from_be_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]) as usize;
        let kind = &bytes[at + 4..at + 8];
        if kind == b"PLTE" && (len == 0 || len % 3 != 0 || len > 768) {
            return Err(IoError::malformed(
                path,
                "PNG",
                format!("a PLTE chunk of {len} bytes: expected 1 to 256 RGB entries (a multiple of 3 bytes, at most 768)"),
            ));
        }
        if kind == b"IEND" {
            break;
        }
        at = at.saturating_add(12).saturating_add(len);
    }
    Ok(())
}

/// Encodes 8-bit interleaved grey (1 channel) or RGB (3 channels) pixels as PNG.
pub(crate) fn encode_png8<W: Write>(path: &Path, w: W, rows: usize, cols: usize, channels: usize, pixels: &[u8]) -> Result<(), IoError> {
    let color = match channels {
        1 => ExtendedColorType::L8,
        3 => ExtendedColorType::Rgb8,
        c => return Err(IoError::bad_input(path, format!("expected 1 or 3 channels, found {c}"))),
    };
    if rows == 0 || cols == 0 {
        return Err(IoError::bad_input(path, format!("empty image {rows}x{cols}")));
    }
    let (r, c) = (
        u32::try_from(rows).map_err(|_| IoError::bad_input(path, "too many rows"))?,
        u32::try_from(cols).map_err(|_| IoError::bad_input(path, "too many columns"))?,
    );
    PngEncoder::new(w).write_image(pixels, c, r, color).map_err(|e| match e {
        image::ImageError::IoError(io) => IoError::os(path, "cannot write", io),
        other => IoError::bad_input(path, format!("PNG encoder: {other}")),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::budget::LimitSource;

    /// Found by the png fuzz target: a palette image whose PLTE chunk holds 11 bytes.
    /// The decoder panicked on it; it is refused, naming the chunk.
    #[test]
    fn a_palette_of_a_length_not_a_multiple_of_three_is_refused() {
        let bytes: &[u8] = &[
            137, 80, 78, 71, 13, 10, 26, 10, 0, 0, 0, 13, 73, 72, 68, 82, 0, 0, 0, 2, 0, 35, 0, 2, 8, 3, 0, 0, 0, 69, 104, 253, 22, 0, 0, 0, 11, 80, 76, 84,
            69, 57, 0, 0, 0, 255, 255, 255, 165, 217, 159, 221, 0, 0, 0, 12, 115, 115, 115, 115, 73, 68, 65, 84, 120, 156, 99, 113, 96, 0, 3, 43, 99, 24, 0, 0,
            0, 0, 0, 0, 239, 0, 203, 80, 0, 0, 0, 0, 73, 69, 78, 68, 174, 66, 96, 130,
        ];
        let budget = ByteBudget { limit_bytes: 256 << 20, source: LimitSource::Environment };
        let e = decode_png(Path::new("bad.png"), bytes, &budget).unwrap_err().to_string();
        assert!(e.contains("bad.png") && e.contains("PLTE chunk of 11 bytes"), "{e}");
    }
}
