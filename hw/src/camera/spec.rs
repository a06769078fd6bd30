//! A camera's command-line spec, `backend:id` ([`CameraSpec`]), and opening the camera
//! it names ([`open`]).

use std::str::FromStr;

#[cfg(feature = "aravis")]
use super::aravis;
use super::device::Camera;
use super::error::CameraError;
use super::replay;

/// `backend:id` as given on the command line, e.g. `aravis:Fake_1`, `replay:/data/cap1`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CameraSpec {
    pub backend: String,
    pub id: String,
}

impl FromStr for CameraSpec {
    type Err = CameraError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let (backend, id) = s
            .split_once(':')
            .ok_or_else(|| CameraError::Spec { spec: s.to_string(), message: "expected backend:id, e.g. aravis:Fake_1 or replay:/path/to/capture".into() })?;
        if backend.is_empty() || id.is_empty() {
            return Err(CameraError::Spec { spec: s.to_string(), message: "backend and id must both be non-empty".into() });
        }
        Ok(CameraSpec { backend: backend.to_ascii_lowercase(), id: id.to_string() })
    }
}
/// Open a camera from a spec (`aravis:<id>`, `replay:<dir>`). `sim` is provided by the
/// main crate, which owns the renderer.
pub fn open(spec: &CameraSpec) -> Result<Box<dyn Camera>, CameraError> {
    match spec.backend.as_str() {
        #[cfg(feature = "aravis")]
        "aravis" => Ok(Box::new(aravis::AravisCamera::open(&spec.id, &aravis::AravisOptions::default())?)),
        #[cfg(not(feature = "aravis"))]
        "aravis" => Err(CameraError::Spec {
            spec: format!("{}:{}", spec.backend, spec.id),
            message: "this build has no GenICam support; rebuild with `--features aravis`".into(),
        }),
        "replay" => Ok(Box::new(replay::ReplayCamera::open(&spec.id, replay::ReplayOptions::default())?)),
        other => {
            Err(CameraError::Spec { spec: format!("{}:{}", spec.backend, spec.id), message: format!("unknown backend '{other}'; expected aravis or replay") })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_camera_specs() {
        let spec: CameraSpec = "aravis:Fake_1".parse().unwrap();
        assert_eq!((spec.backend.as_str(), spec.id.as_str()), ("aravis", "Fake_1"));
        let spec: CameraSpec = "replay:/tmp/a:b".parse().unwrap();
        assert_eq!(spec.id, "/tmp/a:b");
        assert!("Fake_1".parse::<CameraSpec>().is_err());
    }
}
