//! Reading `capture.toml` (the description itself is `crate::model::capture`).

use crate::model::capture::{CaptureConfig, CaptureOverrides, ConfigError, MissingField};
use anyhow::{anyhow, Result};
use std::path::Path;

impl CaptureConfig {
    /// Read and validate a `capture.toml`; errors start with the file's path.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let p = path.display().to_string();
        let text = crate::io::input::read_text(path).map_err(|source| ConfigError::Read { path: p.clone(), source })?;
        CaptureConfig::from_toml_str(&text, &p)
    }
}

/// A capture description: the `capture.toml` given (if any) with
/// `overrides` replacing its values, or, without one, the overrides alone for the
/// raw image size (`shape`: rows, cols); validated. Messages name the command-line
/// flags (`rollcam reconstruct`, `reconstruct-sequence` and `run` share it).
pub fn resolve_capture(config: Option<&Path>, overrides: &CaptureOverrides, shape: (usize, usize)) -> Result<CaptureConfig> {
    let cfg = match config {
        Some(p) => overrides.apply(CaptureConfig::load(p)?),
        None => overrides.config_without_file(shape.0, shape.1).map_err(|m| anyhow!("{}", missing_description(&m)))?,
    };
    // A file is valid alone (`load`): what fails now is a flag's value, or a flag with the file.
    cfg.validate().map_err(|e| {
        let crate::model::shutter::TimingError::Invalid { field, value, expected } = &e;
        match config {
            _ if overrides.sets(field) => anyhow!("--{} = {value}: expected {expected}", field.replace('_', "-")),
            Some(p) => anyhow!("{} with the command line's flags: {e}", p.display()),
            None => anyhow!("the command line's capture description: {e}"),
        }
    })?;
    Ok(cfg)
}

/// The one message for a capture with no description: the file to give, every flag
/// missing in its place, and the still that needs none of them.
pub fn missing_description(missing: &MissingField) -> String {
    let flags: Vec<String> = missing.fields.iter().map(|f| format!("--{}", f.replace('_', "-"))).collect();
    format!(
        "no capture description: give --config FILE (the capture.toml `rollcam capture` writes beside its frames), or describe the capture with flags (missing: {}); a still (one image, no timing) needs only --shutter global",
        flags.join(", ")
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_file_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("capture.toml");
        let e = CaptureConfig::load(&p).unwrap_err().to_string();
        assert!(e.contains("capture.toml") && e.contains("cannot read"), "{e}");
    }

    #[test]
    fn a_file_with_a_typo_is_refused_with_its_path() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("capture.toml");
        std::fs::write(&p, "rows = 8\ncols = 6\nline_time_us = 10.0\nexposure_us = 30.0\nexposure = 3\n").unwrap();
        let e = CaptureConfig::load(&p).unwrap_err().to_string();
        assert!(e.contains(&p.display().to_string()) && e.contains("exposure"), "{e}");
    }
}
