//! capture.toml: parsing and validation. A description that validates must serialise
//! and read back as a valid description.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rollcam::model::capture::CaptureConfig;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let Ok(cfg) = CaptureConfig::from_toml_str(text, "capture.toml") else { return };
    let _ = cfg.grid();
    let again = CaptureConfig::from_toml_str(&cfg.to_toml(), "written capture.toml");
    assert!(again.is_ok(), "{:?}", again.err());
});
