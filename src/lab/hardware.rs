//! The one mapping between the hardware crate's types and the model's: shutter modes
//! both ways, the camera settings that take the captures a [`CaptureConfig`]
//! describes, the capture description of what a camera applied, the settings a
//! camera running a capture description reports, and the check that a capture
//! description agrees with what the camera applied.

use crate::model::capture::{still_times, CaptureConfig, CaptureOverrides};
use crate::model::shutter::ShutterMode;
use anyhow::{bail, Result};
use rollcam_hw::camera::{self as hw, AppliedSettings, Binning, CameraSettings, PixelFormat, Roi, Trigger};

/// The camera's shutter mode for a capture description's (None: cameras have no such
/// mode, e.g. centre-out dual).
pub fn camera_shutter(mode: ShutterMode) -> Option<hw::CameraShutter> {
    match mode {
        ShutterMode::Global => Some(hw::CameraShutter::Global),
        ShutterMode::Rolling => Some(hw::CameraShutter::Rolling),
        ShutterMode::Dual => Some(hw::CameraShutter::Dual),
        ShutterMode::DualCenterOut => None,
    }
}

/// The capture description's shutter mode for a camera's. A camera's dual mode reads
/// outside-in, like the paper's camera.
pub fn model_shutter(mode: hw::CameraShutter) -> ShutterMode {
    match mode {
        hw::CameraShutter::Global => ShutterMode::Global,
        hw::CameraShutter::Rolling => ShutterMode::Rolling,
        hw::CameraShutter::Dual => ShutterMode::Dual,
    }
}

/// Settings that make a camera take the captures `cfg` describes: its exposure, line
/// time and shutter mode (left unset for a mode cameras lack, see [`camera_shutter`]);
/// every other setting comes from `rest`.
pub fn camera_settings(cfg: &CaptureConfig, rest: CameraSettings) -> CameraSettings {
    CameraSettings { exposure_us: Some(cfg.exposure_us), line_time_us: Some(cfg.line_time_us), shutter: camera_shutter(cfg.shutter), ..rest }
}

/// Why the settings a camera applied give no capture description: a field it does
/// not report, which the command line must then give.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MappingError {
    #[error("the camera does not report its line time: give line_time_us (--line-time-us or --config)")]
    NoLineTime,
    #[error("the camera does not report its shutter mode: give shutter (--shutter or --config)")]
    NoShutter,
}

/// The level at which samples of `format` clip: the largest value of its bit depth.
pub fn saturation_level(format: PixelFormat) -> f64 {
    ((1u32 << format.bit_depth()) - 1) as f64
}

/// The capture description of a `rows x cols` frame taken with `applied`: the line
/// time, exposure and shutter mode it reports (`given`'s where it reports none; a
/// still needs no line time), the saturation level of its bit depth, the rest of what
/// it applied as the `[camera]` provenance table; then every value `given` sets (the
/// command line) over it, so a flag the camera contradicts is caught by
/// [`check_timing`]. Not yet validated.
pub fn capture_config(rows: usize, cols: usize, applied: &AppliedSettings, given: &CaptureOverrides) -> Result<CaptureConfig, MappingError> {
    let shutter = applied.shutter.map(model_shutter).or(given.shutter).ok_or(MappingError::NoShutter)?;
    let (line_time_us, exposure_us) = match applied.line_time_us.or(given.line_time_us) {
        Some(line) => (line, applied.exposure_us),
        None if shutter == ShutterMode::Global => still_times(None, Some(applied.exposure_us)),
        None => return Err(MappingError::NoLineTime),
    };
    let mut cfg = CaptureConfig::new(rows, cols, line_time_us, exposure_us, shutter);
    cfg.saturation_level = Some(saturation_level(applied.pixel_format));
    cfg.camera = Some(camera_table(applied));
    Ok(given.apply(cfg))
}

/// The `[camera]` table of a recorded capture: what the camera applied besides the
/// timing.
fn camera_table(applied: &AppliedSettings) -> toml::Table {
    let r = applied.roi;
    let mut t = toml::Table::new();
    t.insert("roi".into(), toml::Value::Array([r.x, r.y, r.width, r.height].map(|v| toml::Value::Integer(v.into())).to_vec()));
    t.insert("binning".into(), toml::Value::Array([applied.binning.horizontal, applied.binning.vertical].map(|v| toml::Value::Integer(v.into())).to_vec()));
    t.insert("pixel_format".into(), applied.pixel_format.genicam_name().into());
    t.insert("bit_depth".into(), i64::from(applied.pixel_format.bit_depth()).into());
    t.insert("trigger".into(), applied.trigger.to_string().into());
    if let Some(f) = applied.frame_rate_hz {
        t.insert("frame_rate_hz".into(), f.into());
    }
    t
}

/// What a camera taking exactly the captures `cfg` describes would report: its
/// timing, the full sensor (no binning), 16-bit samples, free-running at
/// `frame_rate_hz`.
pub fn applied_settings(cfg: &CaptureConfig, frame_rate_hz: Option<f64>) -> AppliedSettings {
    AppliedSettings {
        exposure_us: cfg.exposure_us,
        line_time_us: Some(cfg.line_time_us),
        frame_rate_hz,
        shutter: camera_shutter(cfg.shutter),
        roi: Roi { x: 0, y: 0, width: cfg.cols as u32, height: cfg.rows as u32 },
        binning: Binning::default(),
        pixel_format: PixelFormat::Mono16,
        trigger: Trigger::FreeRun,
        exposure_output_line: None,
    }
}

/// Refuse a capture description that contradicts what the camera applied: exposure,
/// line time, shutter mode (within 0.1%) and the image size. `origin` names the
/// configuration (file or command line) in the message.
pub fn check_timing(cfg: &CaptureConfig, applied: &AppliedSettings, origin: &str) -> Result<()> {
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-3 * a.abs().max(b.abs());
    if !close(applied.exposure_us, cfg.exposure_us) {
        bail!("{origin}: exposure_us = {} contradicts the camera, which applied an exposure of {} us", cfg.exposure_us, applied.exposure_us);
    }
    match applied.line_time_us {
        Some(l) if !close(l, cfg.line_time_us) => {
            bail!("{origin}: line_time_us = {} contradicts the camera, which applied a line time of {l} us", cfg.line_time_us)
        }
        Some(_) => {}
        None => tracing::warn!("the camera does not report its line time; trusting line_time_us = {} from {origin}", cfg.line_time_us),
    }
    if let Some(s) = applied.shutter {
        if camera_shutter(cfg.shutter) != Some(s) {
            bail!("{origin}: shutter = {} contradicts the camera, whose shutter mode is {s}", cfg.shutter.name());
        }
    }
    let (w, h) = applied.image_size();
    if (h as usize, w as usize) != (cfg.rows, cfg.cols) {
        bail!("{origin}: rows = {}, cols = {} contradict the camera, which delivers {h} x {w} images (rows x cols; set --roi to match)", cfg.rows, cfg.cols);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shutter_modes_map_both_ways() {
        for mode in ShutterMode::ALL {
            match camera_shutter(mode) {
                Some(c) => {
                    assert_eq!(model_shutter(c), mode, "{mode} -> {c} -> back");
                    assert_eq!(c.as_str(), mode.name(), "same name on both sides");
                }
                None => assert_eq!(mode, ShutterMode::DualCenterOut),
            }
        }
        for c in hw::CameraShutter::ALL {
            assert_eq!(camera_shutter(model_shutter(c)), Some(c), "{c} -> model -> back");
        }
        assert_eq!(camera_shutter(ShutterMode::Dual), Some(hw::CameraShutter::Dual));
        assert_eq!(model_shutter(hw::CameraShutter::Global), ShutterMode::Global);
    }

    #[test]
    fn settings_and_capture_description_round_trip() {
        let mut cfg = CaptureConfig::new(48, 64, 220.0, 660.0, ShutterMode::Dual);
        let rest = CameraSettings { trigger: Some(Trigger::Software), frame_rate_hz: Some(20.0), ..CameraSettings::default() };
        let s = camera_settings(&cfg, rest);
        assert_eq!((s.exposure_us, s.line_time_us, s.shutter), (Some(660.0), Some(220.0), Some(hw::CameraShutter::Dual)));
        assert_eq!((s.trigger, s.frame_rate_hz, s.roi), (Some(Trigger::Software), Some(20.0), None));

        let applied = applied_settings(&cfg, Some(50.0));
        assert_eq!(applied.image_size(), (64, 48));
        let described = capture_config(48, 64, &applied, &CaptureOverrides::default()).unwrap();
        assert_eq!((described.saturation_level, described.camera.as_ref().map(|c| c["bit_depth"].clone())), (Some(65535.0), Some(16.into())));
        assert_eq!(CaptureConfig { saturation_level: None, camera: None, ..described }, cfg);
        check_timing(&cfg, &applied, "test").unwrap();

        cfg.shutter = ShutterMode::DualCenterOut;
        assert_eq!(camera_settings(&cfg, CameraSettings::default()).shutter, None);
        let e = check_timing(&cfg, &applied, "test").unwrap_err().to_string();
        assert!(e.contains("shutter = dual-center-out"), "{e}");

        // What the camera does not report is refused by name, unless given.
        let none = CaptureOverrides::default();
        let silent = AppliedSettings { line_time_us: None, shutter: None, ..applied };
        assert_eq!(capture_config(48, 64, &silent, &none), Err(MappingError::NoShutter));
        assert!(MappingError::NoShutter.to_string().contains("--shutter"));
        let rolling = CaptureOverrides { shutter: Some(ShutterMode::Rolling), ..none.clone() };
        assert_eq!(capture_config(48, 64, &silent, &rolling), Err(MappingError::NoLineTime));
        assert!(MappingError::NoLineTime.to_string().contains("--line-time-us"));
        let given = CaptureOverrides { line_time_us: Some(10.0), downsample: Some(2), ..rolling };
        let cfg = capture_config(48, 64, &silent, &given).unwrap();
        assert_eq!((cfg.shutter, cfg.line_time_us, cfg.exposure_us, cfg.downsample), (ShutterMode::Rolling, 10.0, 660.0, 2));
        // A global shutter is a still: no line time needed.
        let global = AppliedSettings { shutter: Some(hw::CameraShutter::Global), ..silent };
        let cfg = capture_config(48, 64, &global, &none).unwrap();
        assert!(cfg.timing().is_still() && cfg.validate().is_ok());
    }
}
