//! A calibration folder's record (`calibration.toml`, what `--calibration` reads first)
//! as any bytes: `load_calibration` refuses or reads it, never a panic, a hang or an
//! allocation past the budget (the arrays it names are absent: refused by name).
#![no_main]

use libfuzzer_sys::fuzz_target;
use rollcam::io::calibration::{load_calibration, RECORD_FILE};
use std::path::PathBuf;
use std::sync::OnceLock;

/// One folder per process, its record rewritten for every input.
fn folder() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("rollcam-fuzz-calibration-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    })
}

fuzz_target!(|data: &[u8]| {
    let dir = folder();
    std::fs::write(dir.join(RECORD_FILE), data).unwrap();
    if let Ok(cal) = load_calibration(dir) {
        assert!(cal.dark.is_none() && cal.psf.is_none() && cal.background.is_none(), "an array read from a folder that holds none");
    }
});
