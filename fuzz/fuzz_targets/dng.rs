//! DNG raws (Bayer, read by `src/io/formats/raw.rs`, which CFA TIFFs share) as
//! `--raw`/`--psf`: colour on the half grid or an error, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rollcam::io::budget::LimitSource;
use rollcam::io::{decode_image_bytes, ByteBudget};
use std::path::Path;

const BUDGET: ByteBudget = ByteBudget { limit_bytes: 256 << 20, source: LimitSource::Environment };

fuzz_target!(|data: &[u8]| {
    if let Ok(image) = decode_image_bytes(Path::new("fuzz.dng"), data, &BUDGET) {
        let (rows, cols, ch) = image.dim();
        assert!(rows > 0 && cols > 0 && ch == 3);
    }
});
