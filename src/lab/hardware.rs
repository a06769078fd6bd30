//! The one mapping between the hardware crate's types and the model's: shutter modes
//! both ways, the camera settings that take the captures a [`CaptureConfig`]
//! describes, the capture description of what a camera applied, the settings a
//! camera running a capture description reports, and the check that a capture
//! description agrees with what the camera applied.

use crate::model::capture::CaptureConfig;
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

/// Why the settings a camera applied give no capture description.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MappingError {
    #[error("no line time applied")]
    NoLineTime,
}

/// The capture description of a `rows x cols` frame taken with `applied`: its line
/// time, exposure and shutter mode (rolling when the camera reports none). Not yet
/// validated: the caller adds what the camera does not know (dark level, downsampling,
/// binning) and validates.
pub fn capture_config(rows: usize, cols: usize, applied: &AppliedSettings) -> Result<CaptureConfig, MappingError> {
    let line_time_us = applied.line_time_us.ok_or(MappingError::NoLineTime)?;
    let shutter = model_shutter(applied.shutter.unwrap_or(hw::CameraShutter::Rolling));
    Ok(CaptureConfig::new(rows, cols, line_time_us, applied.exposure_us, shutter))
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
        assert_eq!(capture_config(48, 64, &applied).unwrap(), cfg);
        check_timing(&cfg, &applied, "test").unwrap();

        cfg.shutter = ShutterMode::DualCenterOut;
        assert_eq!(camera_settings(&cfg, CameraSettings::default()).shutter, None);
        let e = check_timing(&cfg, &applied, "test").unwrap_err().to_string();
        assert!(e.contains("shutter = dual-center-out"), "{e}");

        let silent = AppliedSettings { line_time_us: None, shutter: None, ..applied };
        assert_eq!(capture_config(48, 64, &silent), Err(MappingError::NoLineTime));
        let rolling = AppliedSettings { line_time_us: Some(10.0), ..silent };
        assert_eq!(capture_config(48, 64, &rolling).unwrap().shutter, ShutterMode::Rolling);
    }
}
