//! DNG (`.dng`): a TIFF with a DNGVersion tag whose raw is a Bayer (CFA) mosaic, read
//! as colour on the half grid by `raw.rs` (which the CFA TIFF of `tiff.rs` shares).
//! Read only: rollcam writes no raws (`raw::encode_raw` makes test fixtures).

use std::path::Path;

use ndarray::Array3;

use super::image_format::{one_image, read_bytes, ImageFormat};
use super::raw::{decode_raw, is_dng, read_raw_info, RawInfo};
use crate::io::budget::ByteBudget;
use crate::io::error::IoError;

/// The DNG format: uncompressed CFA raws (`raw.rs` says what is read and refused).
pub(crate) struct Dng;

impl ImageFormat for Dng {
    fn name(&self) -> &'static str {
        "DNG"
    }

    fn extensions(&self) -> &'static [&'static str] {
        &["dng"]
    }

    fn sniff(&self, bytes: &[u8]) -> bool {
        is_dng(bytes)
    }

    fn decode_image(&self, path: &Path, bytes: &[u8], page: Option<usize>, budget: &ByteBudget) -> Result<Array3<f32>, IoError> {
        one_image(path, page)?;
        Ok(decode_raw(path, "DNG", bytes, budget)?.0)
    }

    fn sample_bits(&self, path: &Path) -> Option<u32> {
        self.raw_info(path).map(|i| i.bits)
    }

    fn raw_info(&self, path: &Path) -> Option<RawInfo> {
        read_raw_info(path, "DNG", &read_bytes(path).ok()?).ok()
    }
}
