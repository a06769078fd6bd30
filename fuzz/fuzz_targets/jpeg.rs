//! JPEG files as `--raw`/`--psf` and as a one-frame stack.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rollcam::io::budget::LimitSource;
use rollcam::io::{decode_image_bytes, ByteBudget};
use std::path::Path;

const BUDGET: ByteBudget = ByteBudget { limit_bytes: 256 << 20, source: LimitSource::Environment };

fuzz_target!(|data: &[u8]| {
    if let Ok(image) = decode_image_bytes(Path::new("fuzz.jpg"), data, &BUDGET) {
        let (rows, cols, ch) = image.dim();
        assert!(rows > 0 && cols > 0 && (ch == 1 || ch == 3));
    }
});
