//! JPEG (`.jpg`, `.jpeg`): decoding 8-bit grey or RGB (and 12/16-bit lossless grey)
//! through the `jpeg-decoder` crate, the raws and PSFs of lensless cameras built on
//! consumer sensors. Read only: lossy, so a video is never written as JPEG.

use std::io::Cursor;
use std::path::Path;

use jpeg_decoder::{Decoder, PixelFormat};
use ndarray::Array3;

use super::image_format::{one_image, read_bytes, ImageFormat};
use crate::io::budget::{array_bytes, ByteBudget};
use crate::io::error::IoError;

/// The JPEG format.
pub(crate) struct Jpeg;

impl ImageFormat for Jpeg {
    fn name(&self) -> &'static str {
        "JPEG"
    }

    fn extensions(&self) -> &'static [&'static str] {
        &["jpg", "jpeg"]
    }

    fn sniff(&self, bytes: &[u8]) -> bool {
        bytes.starts_with(&[0xff, 0xd8, 0xff])
    }

    fn decode_image(&self, path: &Path, bytes: &[u8], page: Option<usize>, budget: &ByteBudget) -> Result<Array3<f32>, IoError> {
        one_image(path, page)?;
        decode_jpeg(path, bytes, budget)
    }

    fn sample_bits(&self, path: &Path) -> Option<u32> {
        let bytes = read_bytes(path).ok()?;
        let mut dec = Decoder::new(Cursor::new(bytes));
        dec.read_info().ok()?;
        match dec.info()?.pixel_format {
            PixelFormat::L8 | PixelFormat::RGB24 => Some(8),
            PixelFormat::L16 => Some(16),
            PixelFormat::CMYK32 => None,
        }
    }
}

/// Decodes an in-memory JPEG into (row, col, channel) counts as stored (8-bit 0..255;
/// lossless 16-bit grey 0..65535). The header's size is checked against `budget` (the
/// decoded samples plus their f32 copy) before anything is decoded; CMYK is refused.
fn decode_jpeg(path: &Path, bytes: &[u8], budget: &ByteBudget) -> Result<Array3<f32>, IoError> {
    let err = |e: jpeg_decoder::Error| match e {
        jpeg_decoder::Error::Io(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            IoError::Truncated { path: path.to_path_buf(), format: "JPEG", detail: "file ends early".into() }
        }
        other => IoError::malformed(path, "JPEG", other),
    };
    let mut dec = Decoder::new(Cursor::new(bytes));
    dec.read_info().map_err(err)?;
    let info = dec.info().ok_or_else(|| IoError::malformed(path, "JPEG", "no frame header"))?;
    let (h, w) = (usize::from(info.height), usize::from(info.width));
    let ch = match info.pixel_format {
        PixelFormat::L8 | PixelFormat::L16 => 1,
        PixelFormat::RGB24 => 3,
        PixelFormat::CMYK32 => return Err(IoError::unexpected(path, "a grey or RGB image", "CMYK (4 channels)")),
    };
    check_declared_size(path, w, h, bytes.len())?;
    let decoded = array_bytes(&[h, w, info.pixel_format.pixel_bytes()], 1);
    let samples = array_bytes(&[h, w, ch], 4);
    budget
        .check(|| format!("{w} x {h} pixels {:?} (the decoded samples plus their f32 copy)", info.pixel_format), decoded.saturating_add(samples))
        .map_err(|source| IoError::TooLarge { path: path.to_path_buf(), source: Box::new(source) })?;
    dec.set_max_decoding_buffer_size(usize::try_from(budget.limit_bytes).unwrap_or(usize::MAX));
    let raw = dec.decode().map_err(err)?;
    let values: Vec<f32> = match info.pixel_format {
        PixelFormat::L16 => raw.chunks_exact(2).map(|b| f32::from(u16::from_ne_bytes([b[0], b[1]]))).collect(),
        _ => raw.into_iter().map(f32::from).collect(),
    };
    Array3::from_shape_vec((h, w, ch), values).map_err(|e| IoError::malformed(path, "JPEG", e))
}

/// Refuses a header whose `width x height` pixels the file's `file_bytes` cannot hold.
/// Every 8 x 8 block of a Huffman-coded JPEG (baseline, progressive or lossless: the
/// ones the decoder reads) takes at least one bit of entropy-coded data, so a file
/// holds at most `8 x file_bytes` blocks. A header that declares more (333 bytes
/// announcing 65500 x 65500 pixels) is forged or cut, and the decoder would fill the
/// missing data with zeros at full size: refused before anything is allocated.
pub fn check_declared_size(path: &Path, width: usize, height: usize, file_bytes: usize) -> Result<(), IoError> {
    let blocks = (width.div_ceil(8) as u128) * (height.div_ceil(8) as u128);
    let holdable = (file_bytes as u128).saturating_mul(8);
    if blocks > holdable {
        return Err(IoError::malformed(
            path,
            "JPEG",
            format!(
                "the header declares {width} x {height} pixels ({blocks} blocks of 8 x 8), more than its {file_bytes} bytes can hold (at most {holdable} blocks, one bit each): expected a complete JPEG, this one is cut short or its header is forged"
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A baseline grey JPEG of one 8-row band of flat 8 x 8 blocks at `levels`: DC
    /// coefficients only, quantiser 1, so every decoder gives the levels back exactly.
    pub(crate) fn flat_blocks_jpeg(levels: &[u8]) -> Vec<u8> {
        let mut out = vec![0xff, 0xd8];
        let segment = |out: &mut Vec<u8>, marker: u8, body: &[u8]| {
            out.extend_from_slice(&[0xff, marker]);
            out.extend_from_slice(&((body.len() + 2) as u16).to_be_bytes());
            out.extend_from_slice(body);
        };
        let mut dqt = vec![0u8];
        dqt.extend([1u8; 64]);
        segment(&mut out, 0xdb, &dqt);
        let width = (8 * levels.len()) as u16;
        let mut sof = vec![8, 0, 8];
        sof.extend_from_slice(&width.to_be_bytes());
        sof.extend_from_slice(&[1, 1, 0x11, 0]);
        segment(&mut out, 0xc0, &sof);
        // DC: categories 0..=11, four-bit codes 0000..1011. AC: end of block only, code 0.
        let mut dc = vec![0x00, 0, 0, 0, 12];
        dc.extend([0u8; 12]);
        dc.extend(0..12u8);
        segment(&mut out, 0xc4, &dc);
        let mut ac = vec![0x10, 1];
        ac.extend([0u8; 15]);
        ac.push(0x00);
        segment(&mut out, 0xc4, &ac);
        segment(&mut out, 0xda, &[1, 1, 0x00, 0, 63, 0]);
        let mut bits: Vec<bool> = Vec::new();
        let push = |value: u32, n: u32, bits: &mut Vec<bool>| bits.extend((0..n).rev().map(|i| value >> i & 1 == 1));
        let mut previous = 0i32;
        for &level in levels {
            let dc = 8 * (i32::from(level) - 128);
            let diff = dc - previous;
            previous = dc;
            let category = 32 - diff.unsigned_abs().leading_zeros();
            push(category, 4, &mut bits);
            let extra = if diff >= 0 { diff } else { diff + (1 << category) - 1 };
            push(extra as u32, category, &mut bits);
            push(0, 1, &mut bits);
        }
        while bits.len() % 8 != 0 {
            bits.push(true);
        }
        for byte in bits.chunks(8).map(|b| b.iter().fold(0u8, |acc, &x| acc << 1 | u8::from(x))) {
            out.push(byte);
            if byte == 0xff {
                out.push(0);
            }
        }
        out.extend_from_slice(&[0xff, 0xd9]);
        out
    }

    #[test]
    fn an_eight_bit_grey_jpeg_reads_as_its_counts() {
        let levels = [0u8, 40, 128, 200, 255];
        let bytes = flat_blocks_jpeg(&levels);
        let img = Jpeg.decode_image(Path::new("hand.jpg"), &bytes, None, &ByteBudget::system()).unwrap();
        assert_eq!(img.dim(), (8, 40, 1));
        for ((_, c, _), &v) in img.indexed_iter() {
            assert_eq!(v, f32::from(levels[c / 8]), "column {c}");
        }
        let e = Jpeg.decode_image(Path::new("hand.jpg"), &bytes, Some(2), &ByteBudget::system()).unwrap_err().to_string();
        assert!(e.contains("hand.jpg") && e.contains("page 2"), "{e}");
        let e = Jpeg.decode_image(Path::new("cut.jpg"), &bytes[..bytes.len() / 2], None, &ByteBudget::system()).unwrap_err().to_string();
        assert!(e.starts_with("cut.jpg"), "{e}");
        let tiny = ByteBudget { limit_bytes: 100, ..ByteBudget::system() };
        let e = Jpeg.decode_image(Path::new("big.jpg"), &bytes, None, &tiny).unwrap_err();
        assert!(matches!(e, IoError::TooLarge { .. }), "{e:?}");
    }
}
