//! Per-camera profiles: which GenICam feature implements which setting.
//!
//! Vendors name features differently (`ExposureTime` vs `ExposureTimeAbs`,
//! line time vs line rate, shutter enumeration values). A profile is a small TOML
//! file (see `hw/profiles/`); the built-in ones are compiled into the binary, and a
//! bench user can point at their own file.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::error::CameraError;
use rollcam_files::frame::CameraShutter;

/// A GenICam feature that implements a setting.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FeatureRef {
    pub feature: String,
    /// When true, a camera without this feature gets a warning instead of an error
    /// (as long as the setting is not requested).
    #[serde(default)]
    pub optional: bool,
}

/// Unit of the line-time feature.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LineTimeUnit {
    /// The feature holds the row-to-row time in microseconds.
    Us,
    /// The feature holds a line rate in Hz (line time = 1e6 / rate).
    Hz,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LineTimeRef {
    pub feature: String,
    pub unit: LineTimeUnit,
    #[serde(default)]
    pub optional: bool,
}

/// The shutter-mode enumeration and the entry names for each mode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShutterRef {
    pub feature: String,
    pub global: Option<String>,
    pub rolling: Option<String>,
    pub dual: Option<String>,
    #[serde(default)]
    pub optional: bool,
}

impl ShutterRef {
    pub fn entry(&self, mode: CameraShutter) -> Option<&str> {
        match mode {
            CameraShutter::Global => self.global.as_deref(),
            CameraShutter::Rolling => self.rolling.as_deref(),
            CameraShutter::Dual => self.dual.as_deref(),
        }
    }
    pub fn mode_of(&self, entry: &str) -> Option<CameraShutter> {
        CameraShutter::ALL.into_iter().find(|m| self.entry(*m) == Some(entry))
    }
}

fn default_frame_start() -> String {
    "FrameStart".into()
}
fn default_software() -> String {
    "Software".into()
}
fn default_rising() -> String {
    "RisingEdge".into()
}
fn default_falling() -> String {
    "FallingEdge".into()
}
fn default_any() -> String {
    "AnyEdge".into()
}
fn default_on() -> String {
    "On".into()
}
fn default_off() -> String {
    "Off".into()
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TriggerRef {
    pub selector: Option<String>,
    #[serde(default = "default_frame_start")]
    pub selector_value: String,
    pub mode: String,
    #[serde(default = "default_on")]
    pub mode_on: String,
    #[serde(default = "default_off")]
    pub mode_off: String,
    pub source: String,
    #[serde(default = "default_software")]
    pub software_source: String,
    pub activation: Option<String>,
    #[serde(default = "default_rising")]
    pub rising: String,
    #[serde(default = "default_falling")]
    pub falling: String,
    #[serde(default = "default_any")]
    pub any: String,
    /// Command feature that fires a software trigger.
    pub software: String,
}

/// Routing of the exposure-active signal to an output line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExposureOutputRef {
    pub line_selector: String,
    pub line_source: String,
    pub source_value: String,
    pub line_mode: Option<String>,
    pub line_mode_value: Option<String>,
}

/// Mapping of rollcam settings to one camera model's GenICam features.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraProfile {
    pub name: String,
    pub description: String,
    /// Picked automatically for devices whose vendor contains this (case-insensitive).
    pub match_vendor: Option<String>,
    /// ... and whose model contains this.
    pub match_model: Option<String>,
    pub exposure: FeatureRef,
    pub line_time: Option<LineTimeRef>,
    pub frame_rate: Option<FeatureRef>,
    /// Boolean feature set to true before writing the frame rate.
    pub frame_rate_enable: Option<FeatureRef>,
    pub shutter: Option<ShutterRef>,
    pub binning_horizontal: Option<FeatureRef>,
    pub binning_vertical: Option<FeatureRef>,
    pub pixel_format: FeatureRef,
    pub trigger: TriggerRef,
    pub exposure_output: Option<ExposureOutputRef>,
}

/// Profiles shipped with rollcam: (file name, TOML text).
pub const BUILTIN_PROFILES: &[(&str, &str)] = &[
    ("aravis-fake.toml", include_str!("../../profiles/aravis-fake.toml")),
    ("pco-edge.toml", include_str!("../../profiles/pco-edge.toml")),
    ("generic-sfnc.toml", include_str!("../../profiles/generic-sfnc.toml")),
];

impl CameraProfile {
    /// Parse a profile; `origin` names the file in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Self, CameraError> {
        toml::from_str(text).map_err(|e| CameraError::Profile { path: origin.to_string(), message: e.to_string() })
    }

    /// Load a profile from a TOML file.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, CameraError> {
        let path = path.as_ref();
        let profile_err = |message: String| CameraError::Profile { path: path.display().to_string(), message };
        let bytes = rollcam_files::input::read_bounded(path, rollcam_files::input::MAX_TEXT_BYTES).map_err(|e| profile_err(e.to_string()))?;
        let text = String::from_utf8(bytes).map_err(|e| profile_err(format!("not UTF-8 text: {e}")))?;
        Self::parse(&text, &path.display().to_string())
    }

    /// All built-in profiles.
    pub fn builtins() -> Vec<CameraProfile> {
        BUILTIN_PROFILES.iter().map(|(file, text)| Self::parse(text, file).expect("built-in profiles are checked by tests")).collect()
    }

    /// Built-in profile by name (`aravis-fake`, `pco-edge`, `generic-sfnc`).
    pub fn builtin(name: &str) -> Result<Self, CameraError> {
        Self::builtins().into_iter().find(|p| p.name == name).ok_or_else(|| CameraError::Profile {
            path: name.to_string(),
            message: format!("no built-in profile of that name; built-in: {}", Self::builtins().iter().map(|p| p.name.clone()).collect::<Vec<_>>().join(", ")),
        })
    }

    /// Profile for a device: the first built-in whose vendor and model patterns
    /// match, else `generic-sfnc`.
    pub fn for_device(vendor: &str, model: &str) -> Self {
        let contains = |hay: &str, needle: &Option<String>| needle.as_ref().map_or(true, |n| hay.to_ascii_lowercase().contains(&n.to_ascii_lowercase()));
        let all = Self::builtins();
        all.iter()
            .find(|p| (p.match_vendor.is_some() || p.match_model.is_some()) && contains(vendor, &p.match_vendor) && contains(model, &p.match_model))
            .or_else(|| all.iter().find(|p| p.name == "generic-sfnc"))
            .cloned()
            .expect("generic-sfnc is built in")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtin_profiles_parse_and_match_devices() {
        let all = CameraProfile::builtins();
        assert_eq!(all.len(), BUILTIN_PROFILES.len());
        assert_eq!(CameraProfile::for_device("Aravis", "Fake").name, "aravis-fake");
        assert_eq!(CameraProfile::for_device("PCO", "pco.edge 4.2 USB").name, "pco-edge");
        assert_eq!(CameraProfile::for_device("Basler", "acA1920-155um").name, "generic-sfnc");
        let fake = CameraProfile::builtin("aravis-fake").unwrap();
        assert_eq!(fake.exposure.feature, "ExposureTimeAbs");
        assert_eq!(fake.shutter.as_ref().unwrap().mode_of("Dual"), Some(CameraShutter::Dual));
        assert!(CameraProfile::builtin("nope").unwrap_err().to_string().contains("aravis-fake"));
    }

    #[test]
    fn unknown_keys_are_rejected_with_the_file_name() {
        let text = BUILTIN_PROFILES[0].1.replace("[exposure]", "[exposure]\nfeatur = \"X\"");
        let err = CameraProfile::parse(&text, "my.toml").unwrap_err().to_string();
        assert!(err.contains("my.toml") && err.contains("featur"), "{err}");
    }
}
