//! `capture.toml`: the flat description of one raw capture (sensor geometry, timing,
//! shutter mode, downsampling, binning, dark level, saturation level, calibration), read by `reconstruct` and written
//! by `simulate` and the recorders. `rows`, `cols` and `line_time_us` describe the raw
//! image as given, before any downsampling the tool applies.

use crate::model::shutter::{ShutterMode, Timing, TimingError};
use serde::{Deserialize, Serialize};

/// Which grid the video is solved on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Fov {
    /// The video has the sensor's size (after downsampling).
    #[default]
    Sensor,
    /// The video covers every scene point whose PSF reaches the sensor:
    /// (2M-1) x (2N-1) for an M x N sensor.
    Full,
}

impl std::str::FromStr for Fov {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "sensor" => Ok(Fov::Sensor),
            "full" => Ok(Fov::Full),
            _ => Err(format!("unknown field of view '{s}': expected sensor or full")),
        }
    }
}

/// One capture's description. Unknown keys are refused, so a typo never passes
/// silently; free-form tables `[simulation]`, `[scene]`, `[sync]` and `[camera]` carry provenance.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CaptureConfig {
    /// Raw sensor rows.
    pub rows: usize,
    /// Raw sensor columns.
    pub cols: usize,
    /// Raw line time, microseconds.
    pub line_time_us: f64,
    /// Exposure of every row, microseconds.
    pub exposure_us: f64,
    /// Required: a camera's shutter mode is never guessed.
    pub shutter: ShutterMode,
    /// Spatial downsampling factor d (box mean of d x d raw pixels, raw and PSF alike).
    #[serde(default = "one")]
    pub downsample: usize,
    /// Temporal binning b: frames of b effective line times.
    #[serde(default = "one")]
    pub binning: usize,
    /// Black offset subtracted from raw and PSF (counts); estimated when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dark_level: Option<f64>,
    /// Raw value at which pixels clip (counts), e.g. 4095 for a 12-bit sensor; else
    /// the calibration's, a pile at the raw's maximum, or the file's full scale.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub saturation_level: Option<f64>,
    /// The bench calibration this capture uses (`[calibration] dir = "..."`, relative
    /// to the capture description's folder).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration: Option<CalibrationRef>,
    /// Optional per-raw-row start times, microseconds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub row_start_us: Option<Vec<f64>>,
    #[serde(default)]
    pub fov: Fov,
    /// Key frames from a second, global-shutter camera (`[[keyframes]]` tables).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub keyframes: Vec<crate::model::keyframe::KeyFrameRef>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulation: Option<toml::Table>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scene: Option<toml::Table>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sync: Option<toml::Table>,
    /// Provenance of a recorded capture: the camera and the settings it applied (ROI,
    /// camera binning, pixel format, trigger), as it reported them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<toml::Table>,
}

/// `[calibration]` of a capture description.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationRef {
    /// The calibration folder (made by `rollcam calibrate`).
    pub dir: String,
}

fn one() -> usize {
    1
}

/// The length a still's one frame is labelled with when neither its line time nor its
/// exposure is known, microseconds. It weighs nothing: a still's weights are 1.
pub const STILL_TIME_US: f64 = 1.0;

/// A still's (line time, exposure) from what a description gives: a global shutter's
/// image is one frame whatever they are ([`crate::model::shutter::Timing::is_still`]),
/// so both are optional; the one given stands for the other, and with neither the frame
/// is [`STILL_TIME_US`] long.
pub fn still_times(line_time_us: Option<f64>, exposure_us: Option<f64>) -> (f64, f64) {
    let line = line_time_us.or(exposure_us).unwrap_or(STILL_TIME_US);
    (line, exposure_us.unwrap_or(line))
}

#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("{path}: cannot read: {source}")]
    Read { path: String, source: std::io::Error },
    #[error("{path}: {message}")]
    Parse { path: String, message: String },
    #[error("{path}: {source}")]
    Timing { path: String, source: TimingError },
}

/// A TOML error's message after its line and column (1-based), where it has a place.
pub fn toml_error_at(text: &str, e: &toml::de::Error) -> String {
    match e.span() {
        Some(span) => {
            let before = text.get(..span.start).unwrap_or(text);
            let line = before.matches('\n').count() + 1;
            let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
            format!("line {line}, column {column}: {}", e.message())
        }
        None => e.message().to_string(),
    }
}

impl CaptureConfig {
    pub fn new(rows: usize, cols: usize, line_time_us: f64, exposure_us: f64, shutter: ShutterMode) -> Self {
        CaptureConfig {
            rows,
            cols,
            line_time_us,
            exposure_us,
            shutter,
            downsample: 1,
            binning: 1,
            dark_level: None,
            saturation_level: None,
            calibration: None,
            row_start_us: None,
            fov: Fov::Sensor,
            keyframes: Vec::new(),
            simulation: None,
            scene: None,
            sync: None,
            camera: None,
        }
    }

    /// Parse and validate the text of a `capture.toml`; `origin` (the file) starts
    /// every error message. Reading the file is `crate::io`'s (`CaptureConfig::load`).
    /// A still (`shutter = "global"`) may leave out its times ([`still_times`]).
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let parse = |e: toml::de::Error| ConfigError::Parse { path: origin.to_string(), message: toml_error_at(text, &e) };
        let mut table: toml::Table = toml::from_str(text).map_err(parse)?;
        if table.get("shutter").and_then(|v| v.as_str()) == Some(ShutterMode::Global.name()) && !table.contains_key("row_start_us") {
            let time = |key: &str| table.get(key).and_then(|v| v.as_float().or_else(|| v.as_integer().map(|i| i as f64)));
            let (line_time_us, exposure_us) = still_times(time("line_time_us"), time("exposure_us"));
            table.entry("line_time_us").or_insert(line_time_us.into());
            table.entry("exposure_us").or_insert(exposure_us.into());
        }
        // The table is parsed already: what is left are field errors. The table has lost
        // their place; the text read straight into the description finds the same error
        // with its line and column (a still's added times aside, the same content).
        let cfg: CaptureConfig = toml::Value::Table(table).try_into().map_err(|e: toml::de::Error| {
            let message = match toml::from_str::<CaptureConfig>(text) {
                Err(at) if at.message() == e.message() && at.span().is_some() => toml_error_at(text, &at),
                _ => e.message().to_string(),
            };
            ConfigError::Parse { path: origin.to_string(), message }
        })?;
        cfg.validate().map_err(|source| ConfigError::Timing { path: origin.to_string(), source })?;
        Ok(cfg)
    }

    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).expect("capture config serialises")
    }

    pub fn timing(&self) -> Timing {
        Timing {
            raw_rows: self.rows,
            line_time_us: self.line_time_us,
            exposure_us: self.exposure_us,
            mode: self.shutter,
            downsample: self.downsample,
            binning: self.binning,
            row_start_us: self.row_start_us.clone(),
        }
    }

    pub fn validate(&self) -> Result<(), TimingError> {
        if self.cols == 0 {
            return Err(TimingError::Invalid { field: "cols", value: "0".into(), expected: "at least 1 column".into() });
        }
        if self.cols > crate::model::shutter::MAX_SENSOR_SIDE {
            return Err(TimingError::Invalid {
                field: "cols",
                value: self.cols.to_string(),
                expected: format!("at most {} columns (no sensor is larger)", crate::model::shutter::MAX_SENSOR_SIDE),
            });
        }
        if self.downsample > self.cols {
            return Err(TimingError::Invalid {
                field: "downsample",
                value: self.downsample.to_string(),
                expected: format!("at most the column count ({})", self.cols),
            });
        }
        if let Some(d) = self.dark_level {
            if !d.is_finite() || d < 0.0 {
                return Err(TimingError::Invalid { field: "dark_level", value: d.to_string(), expected: "a non-negative count".into() });
            }
        }
        if let Some(v) = self.saturation_level {
            if !(v.is_finite() && v > 0.0) {
                return Err(TimingError::Invalid { field: "saturation_level", value: v.to_string(), expected: "a positive count".into() });
            }
        }
        for (i, k) in self.keyframes.iter().enumerate() {
            k.validate(i)?;
        }
        self.timing().validate()
    }

    /// Sensor size after downsampling (rows, cols).
    pub fn grid(&self) -> (usize, usize) {
        (self.rows / self.downsample, self.cols / self.downsample)
    }
}

/// Values given besides a `capture.toml` (e.g. on a command line): each one that is
/// set replaces the file's. Plain data; nothing here reads a file or validates
/// ([`CaptureConfig::validate`] does, once the description is complete).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CaptureOverrides {
    pub line_time_us: Option<f64>,
    pub exposure_us: Option<f64>,
    pub shutter: Option<ShutterMode>,
    pub downsample: Option<usize>,
    pub binning: Option<usize>,
    pub dark_level: Option<f64>,
    pub saturation_level: Option<f64>,
    pub fov: Option<Fov>,
}

/// The fields a capture description needs that neither a file nor the overrides gave,
/// every one of them at once.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{} required without a capture description (a still, shutter = \"global\", needs no timing)", .fields.join(", "))]
pub struct MissingField {
    /// The fields' names in `capture.toml` (`line_time_us`, `exposure_us`, `shutter`),
    /// in that order.
    pub fields: Vec<&'static str>,
}

impl CaptureOverrides {
    /// `cfg` with every value set here replacing its own (the overrides win).
    pub fn apply(&self, mut cfg: CaptureConfig) -> CaptureConfig {
        if let Some(v) = self.line_time_us {
            cfg.line_time_us = v;
        }
        if let Some(v) = self.exposure_us {
            cfg.exposure_us = v;
        }
        if let Some(v) = self.shutter {
            cfg.shutter = v;
        }
        if let Some(v) = self.downsample {
            cfg.downsample = v;
        }
        if let Some(v) = self.binning {
            cfg.binning = v;
        }
        if let Some(v) = self.dark_level {
            cfg.dark_level = Some(v);
        }
        if let Some(v) = self.saturation_level {
            cfg.saturation_level = Some(v);
        }
        if let Some(v) = self.fov {
            cfg.fov = v;
        }
        cfg
    }

    /// Whether these values set `field` (its name in `capture.toml`: `downsample`), so
    /// that an error about it is the command line's, not the file's.
    pub fn sets(&self, field: &str) -> bool {
        match field {
            "line_time_us" => self.line_time_us.is_some(),
            "exposure_us" => self.exposure_us.is_some(),
            "shutter" => self.shutter.is_some(),
            "downsample" => self.downsample.is_some(),
            "binning" => self.binning.is_some(),
            "dark_level" => self.dark_level.is_some(),
            "saturation_level" => self.saturation_level.is_some(),
            "fov" => self.fov.is_some(),
            _ => false,
        }
    }

    /// The description these values give alone, for a raw of `rows x cols` with no
    /// `capture.toml`: the timing (`line_time_us`, then `exposure_us`) and the shutter are
    /// required (a still's times are optional: [`still_times`]), the rest takes the
    /// defaults of [`CaptureConfig::new`]. Not validated.
    pub fn config_without_file(&self, rows: usize, cols: usize) -> Result<CaptureConfig, MissingField> {
        if self.shutter == Some(ShutterMode::Global) {
            let (lt, ex) = still_times(self.line_time_us, self.exposure_us);
            return Ok(self.apply(CaptureConfig::new(rows, cols, lt, ex, ShutterMode::Global)));
        }
        match (self.line_time_us, self.exposure_us, self.shutter) {
            (Some(lt), Some(ex), Some(shutter)) => Ok(self.apply(CaptureConfig::new(rows, cols, lt, ex, shutter))),
            (lt, ex, shutter) => {
                let given = [("line_time_us", lt.is_some()), ("exposure_us", ex.is_some()), ("shutter", shutter.is_some())];
                Err(MissingField { fields: given.iter().filter(|(_, set)| !set).map(|(name, _)| *name).collect() })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_field_of_the_wrong_type_names_its_line_and_column() {
        let text = "rows = 32\ncols = 40\nline_time_us = \"abc\"\nexposure_us = 10.0\nshutter = \"rolling\"\n";
        let e = CaptureConfig::from_toml_str(text, "c.toml").unwrap_err().to_string();
        assert!(e.starts_with("c.toml: line 3, column 16") && e.contains("abc"), "{e}");
    }

    #[test]
    fn a_toml_syntax_error_names_its_line_and_column() {
        let text = "rows = 32\ncols = 40\nline_time_us = = 220\n";
        let e = CaptureConfig::from_toml_str(text, "c.toml").unwrap_err().to_string();
        assert!(e.starts_with("c.toml") && e.contains("line 3, column 16"), "{e}");
    }

    #[test]
    fn round_trip_and_defaults() {
        let text = "rows = 8\ncols = 6\nline_time_us = 10.0\nexposure_us = 30.0\nshutter = \"dual\"\n";
        let cfg: CaptureConfig = toml::from_str(text).unwrap();
        assert_eq!(cfg.downsample, 1);
        assert_eq!(cfg.binning, 1);
        assert_eq!(cfg.shutter, ShutterMode::Dual);
        let back: CaptureConfig = toml::from_str(&cfg.to_toml()).unwrap();
        assert_eq!(back, cfg);
    }

    #[test]
    fn typo_is_refused_with_its_name() {
        let text = "rows = 8\ncols = 6\nline_time_us = 10.0\nexposure_us = 30.0\nexposure = 3\n";
        let e = CaptureConfig::from_toml_str(text, "capture.toml").unwrap_err().to_string();
        assert!(e.contains("capture.toml") && e.contains("exposure"), "{e}");
    }

    #[test]
    fn overrides_win_over_the_file() {
        let text = "rows = 8\ncols = 6\nline_time_us = 10.0\nexposure_us = 30.0\nshutter = \"dual\"\ndark_level = 4.0\n";
        let file = CaptureConfig::from_toml_str(text, "capture.toml").unwrap();
        let o = CaptureOverrides { exposure_us: Some(40.0), shutter: Some(ShutterMode::Rolling), binning: Some(2), fov: Some(Fov::Full), ..Default::default() };
        let cfg = o.apply(file.clone());
        assert_eq!((cfg.rows, cfg.cols, cfg.line_time_us, cfg.exposure_us), (8, 6, 10.0, 40.0));
        assert_eq!((cfg.shutter, cfg.downsample, cfg.binning, cfg.dark_level, cfg.fov), (ShutterMode::Rolling, 1, 2, Some(4.0), Fov::Full));
        // Nothing set: the file as it is.
        assert_eq!(CaptureOverrides::default().apply(file.clone()), file);
        let all = CaptureOverrides {
            line_time_us: Some(5.0),
            exposure_us: Some(15.0),
            shutter: None,
            downsample: Some(2),
            binning: None,
            dark_level: Some(1.5),
            saturation_level: None,
            fov: None,
        };
        let cfg = all.apply(file);
        assert_eq!((cfg.line_time_us, cfg.exposure_us, cfg.downsample, cfg.dark_level), (5.0, 15.0, 2, Some(1.5)));
        assert!(cfg.validate().is_ok());
    }

    #[test]
    fn without_a_file_the_missing_timing_is_named() {
        let none = CaptureOverrides::default();
        assert_eq!(none.config_without_file(8, 6).unwrap_err(), MissingField { fields: vec!["line_time_us", "exposure_us", "shutter"] });
        let lt = CaptureOverrides { line_time_us: Some(10.0), ..Default::default() };
        let e = lt.config_without_file(8, 6).unwrap_err();
        assert_eq!(e.fields, ["exposure_us", "shutter"]);
        assert!(e.to_string().contains("exposure_us, shutter"), "{e}");
        let o = CaptureOverrides { line_time_us: Some(10.0), exposure_us: Some(30.0), downsample: Some(2), ..Default::default() };
        assert_eq!(o.config_without_file(8, 6).unwrap_err(), MissingField { fields: vec!["shutter"] });
        let o = CaptureOverrides { shutter: Some(ShutterMode::Dual), ..o };
        let cfg = o.config_without_file(8, 6).unwrap();
        assert_eq!(cfg, CaptureConfig { downsample: 2, ..CaptureConfig::new(8, 6, 10.0, 30.0, ShutterMode::Dual) });
        assert!(cfg.validate().is_ok());
    }

    #[test]
    fn a_still_needs_no_times() {
        let o = CaptureOverrides { shutter: Some(ShutterMode::Global), downsample: Some(2), ..Default::default() };
        let cfg = o.config_without_file(8, 6).unwrap();
        assert_eq!((cfg.line_time_us, cfg.exposure_us, cfg.downsample), (STILL_TIME_US, STILL_TIME_US, 2));
        assert!(cfg.validate().is_ok());
        // A real exposure far above the line time stays one frame of that exposure.
        let o = CaptureOverrides { exposure_us: Some(10_000.0), ..o };
        let cfg = o.config_without_file(8, 6).unwrap();
        assert_eq!(cfg.timing().weights().unwrap().frames(), 1);
        assert_eq!(cfg.timing().frame_time_us(), 10_000.0);
        let file = CaptureConfig::from_toml_str("rows = 8\ncols = 6\nshutter = \"global\"\nexposure_us = 500\n", "c.toml").unwrap();
        assert_eq!((file.line_time_us, file.exposure_us), (500.0, 500.0));
        // Other shutters still need both.
        let e = CaptureConfig::from_toml_str("rows = 8\ncols = 6\nshutter = \"rolling\"\nexposure_us = 500\n", "c.toml").unwrap_err().to_string();
        assert!(e.contains("line_time_us"), "{e}");
    }

    #[test]
    fn a_missing_shutter_is_refused_not_guessed() {
        let text = "rows = 8\ncols = 6\nline_time_us = 10.0\nexposure_us = 30.0\n";
        let e = CaptureConfig::from_toml_str(text, "capture.toml").unwrap_err().to_string();
        assert!(e.contains("capture.toml") && e.contains("shutter"), "{e}");
    }

    #[test]
    fn saturation_and_calibration_are_read_and_checked() {
        let base = "rows = 8\ncols = 6\nline_time_us = 10.0\nexposure_us = 30.0\nshutter = \"rolling\"\n";
        let cfg = CaptureConfig::from_toml_str(&format!("{base}saturation_level = 4095\n[calibration]\ndir = \"calib\"\n"), "c.toml").unwrap();
        assert_eq!(cfg.saturation_level, Some(4095.0));
        assert_eq!(cfg.calibration, Some(CalibrationRef { dir: "calib".into() }));
        assert_eq!(CaptureConfig::from_toml_str(&cfg.to_toml(), "back").unwrap(), cfg);
        let e = CaptureConfig::from_toml_str(&format!("{base}saturation_level = -1\n"), "c.toml").unwrap_err().to_string();
        assert!(e.contains("saturation_level"), "{e}");
        let e = CaptureConfig::from_toml_str(&format!("{base}[calibration]\nfolder = \"x\"\n"), "c.toml").unwrap_err().to_string();
        assert!(e.contains("folder"), "{e}");
    }

    #[test]
    fn impossible_timing_names_file_and_field() {
        let text = "rows = 8\ncols = 6\nline_time_us = 10.0\nexposure_us = 3.0\nshutter = \"dual\"\n";
        let e = CaptureConfig::from_toml_str(text, "capture.toml").unwrap_err().to_string();
        assert!(e.contains("capture.toml") && e.contains("exposure_us"), "{e}");
    }
}
