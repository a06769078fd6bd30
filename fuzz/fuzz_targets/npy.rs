//! NumPy files as `--raw` (an image), `--truth` (a video) and any array.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rollcam::io::budget::LimitSource;
use rollcam::io::{decode_image_bytes, decode_npy, decode_stack_bytes, ByteBudget};
use std::path::Path;

const BUDGET: ByteBudget = ByteBudget { limit_bytes: 256 << 20, source: LimitSource::Environment };

fuzz_target!(|data: &[u8]| {
    let name = Path::new("fuzz.npy");
    if let Ok(a) = decode_npy(name, data, &BUDGET) {
        // Whatever decodes holds the data the header announced, and it was in the file.
        assert!(a.len() <= data.len());
    }
    let _ = decode_image_bytes(name, data, &BUDGET);
    let _ = decode_stack_bytes(name, data, &BUDGET);
});
