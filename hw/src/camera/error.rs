//! [`CameraError`], the errors of every camera backend, and the standard range check.

/// Errors from cameras. Each names the camera and, where relevant, the setting.
#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    #[error("camera {id} not found on {backend}{}", list_available(.available))]
    NotFound { backend: String, id: String, available: Vec<String> },
    #[error("camera {camera}: {feature} {value} {unit} out of range [{min}, {max}] {unit}")]
    OutOfRange { camera: String, feature: String, value: f64, min: f64, max: f64, unit: String },
    #[error("camera {camera}: {setting} = {value} not supported; expected {expected}")]
    Unsupported { camera: String, setting: String, value: String, expected: String },
    #[error("camera {camera}: feature {feature} (for {setting}) is not implemented by this camera (profile {profile})")]
    MissingFeature { camera: String, feature: String, setting: String, profile: String },
    #[error("camera {camera}: {context}: {message}")]
    Device { camera: String, context: String, message: String },
    #[error("camera {camera}: no frame within {timeout_ms} ms")]
    Timeout { camera: String, timeout_ms: u64 },
    #[error("camera {camera}: disconnected ({detail})")]
    Disconnected { camera: String, detail: String },
    #[error("camera {camera}: end of stream after {frames} frames")]
    EndOfStream { camera: String, frames: u64 },
    #[error("camera {camera}: {message}")]
    State { camera: String, message: String },
    #[error("camera profile {path}: {message}")]
    Profile { path: String, message: String },
    #[error("camera {camera}: renderer failed at frame {index}: {message}")]
    Render { camera: String, index: u64, message: String },
    #[error(transparent)]
    Record(#[from] crate::record::RecordError),
    #[error("camera spec '{spec}': {message}")]
    Spec { spec: String, message: String },
}

fn list_available(available: &[String]) -> String {
    if available.is_empty() {
        "; no cameras found".to_string()
    } else {
        format!("; available: {}", available.join(", "))
    }
}
/// Check a value against a range, producing the standard out-of-range error.
pub fn check_range(camera: &str, feature: &str, value: f64, range: (f64, f64), unit: &str) -> Result<(), CameraError> {
    if !value.is_finite() || value < range.0 || value > range.1 {
        return Err(CameraError::OutOfRange {
            camera: camera.to_string(),
            feature: feature.to_string(),
            value,
            min: range.0,
            max: range.1,
            unit: unit.to_string(),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn out_of_range_message_names_camera_feature_and_range() {
        let e = check_range("Fake_1", "ExposureTime", 5.0, (10.0, 10_000_000.0), "us").unwrap_err();
        assert_eq!(e.to_string(), "camera Fake_1: ExposureTime 5 us out of range [10, 10000000] us");
    }
}
