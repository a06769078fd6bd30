//! TIFF files as `--raw`/`--psf` (one image, or a chosen page) and as a stack.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rollcam::io::budget::LimitSource;
use rollcam::io::{decode_image_bytes, decode_image_page, decode_stack_bytes, ByteBudget};
use std::path::Path;

const BUDGET: ByteBudget = ByteBudget { limit_bytes: 256 << 20, source: LimitSource::Environment };

fuzz_target!(|data: &[u8]| {
    let name = Path::new("fuzz.tiff");
    let _ = decode_image_bytes(name, data, &BUDGET);
    let _ = decode_image_page(name, data, Some(2), &BUDGET);
    if let Ok(video) = decode_stack_bytes(name, data, &BUDGET) {
        assert!(video.len() > 0);
    }
});
