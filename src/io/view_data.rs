//! The compact form in which the viewer sends a video (or one image) to its page:
//! 16-bit levels over the finite range of the data, which the page decodes back to
//! counts (`lo + q (hi - lo) / 65535`) with a typed array, no image codec involved.
//!
//! Layout (all little-endian):
//!
//! | bytes | content |
//! | --- | --- |
//! | 0..4 | `RCQ1` |
//! | 4..8 | `u32` length `H` of the header, a multiple of 8 |
//! | 8..8+H | JSON header, space-padded: `shape` [frames, rows, cols, channels], `lo`, `hi` (finite min and max; equal when flat), `non_finite` (how many values were NaN or infinite; sent as level 0) |
//! | 8+H.. | `u16` levels, C order (frame, row, col, channel) |
//!
//! The quantisation step is `(hi - lo) / 65535`: a display at 8 bits over any range
//! of at least 1/256 of the data's range sees no difference from the f32 values.

use ndarray::ArrayView4;

/// The four magic bytes.
pub const VIEW_MAGIC: &[u8; 4] = b"RCQ1";

/// `video` (frame, row, col, channel) in the compact form above.
pub fn encode_levels_u16(video: ArrayView4<f32>) -> Vec<u8> {
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    let mut non_finite = 0usize;
    for &v in video.iter() {
        if v.is_finite() {
            lo = lo.min(v);
            hi = hi.max(v);
        } else {
            non_finite += 1;
        }
    }
    if lo > hi {
        (lo, hi) = (0.0, 0.0);
    }
    let shape = video.shape();
    let mut header = serde_json::json!({"shape": shape, "lo": lo, "hi": hi, "non_finite": non_finite}).to_string().into_bytes();
    header.resize(header.len().div_ceil(8) * 8, b' ');
    let mut out = Vec::with_capacity(8 + header.len() + 2 * video.len());
    out.extend_from_slice(VIEW_MAGIC);
    out.extend_from_slice(&(header.len() as u32).to_le_bytes());
    out.extend_from_slice(&header);
    let span = f64::from(hi) - f64::from(lo);
    let scale = if span > 0.0 { 65535.0 / span } else { 0.0 };
    for &v in video.iter() {
        let q = if v.is_finite() { ((f64::from(v) - f64::from(lo)) * scale).round().clamp(0.0, 65535.0) as u16 } else { 0 };
        out.extend_from_slice(&q.to_le_bytes());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array4;

    fn decode(bytes: &[u8]) -> (serde_json::Value, Vec<f64>) {
        assert_eq!(&bytes[..4], VIEW_MAGIC);
        let h = u32::from_le_bytes(bytes[4..8].try_into().unwrap()) as usize;
        assert_eq!(h % 8, 0);
        let header: serde_json::Value = serde_json::from_slice(&bytes[8..8 + h]).unwrap();
        let (lo, hi) = (header["lo"].as_f64().unwrap(), header["hi"].as_f64().unwrap());
        let values = bytes[8 + h..].chunks(2).map(|c| lo + f64::from(u16::from_le_bytes([c[0], c[1]])) * (hi - lo) / 65535.0).collect();
        (header, values)
    }

    #[test]
    fn levels_decode_to_the_values_within_one_step() {
        let video = Array4::from_shape_fn((3, 4, 5, 1), |(f, r, c, _)| 100.0 + 7.5 * f as f32 - 3.25 * r as f32 + 0.001 * c as f32);
        let (header, values) = decode(&encode_levels_u16(video.view()));
        assert_eq!(header["shape"], serde_json::json!([3, 4, 5, 1]));
        let (lo, hi) = (header["lo"].as_f64().unwrap(), header["hi"].as_f64().unwrap());
        let min = video.iter().cloned().fold(f32::INFINITY, f32::min);
        let max = video.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
        assert_eq!((lo, hi), (f64::from(min), f64::from(max)));
        assert_eq!(min, 100.0 - 3.25 * 3.0);
        let step = (hi - lo) / 65535.0;
        for (v, d) in video.iter().zip(&values) {
            assert!((f64::from(*v) - d).abs() <= step / 2.0 + 1e-9, "{v} {d}");
        }
    }

    #[test]
    fn non_finite_and_flat_data_are_sent_not_lost() {
        let mut video = Array4::from_elem((1, 2, 2, 1), 4.0f32);
        video[[0, 0, 1, 0]] = f32::NAN;
        let (header, values) = decode(&encode_levels_u16(video.view()));
        assert_eq!(header["non_finite"], 1);
        assert_eq!((header["lo"].as_f64(), header["hi"].as_f64()), (Some(4.0), Some(4.0)));
        assert_eq!(values, vec![4.0; 4]);
    }
}
