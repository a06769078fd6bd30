//! Opening the camera a spec names, whatever its kind, in one place ([`open_camera`]):
//! the simulated camera (`sim`, `sim:<scene>`, [`crate::lab::simcam`]), a recorded
//! capture folder played back (`replay:<folder>`) or a device of the hardware crate
//! (`aravis:<id>`). Every command that opens a camera (`rollcam capture`, `rollcam
//! run`, the LED sweep, the Python module) goes through it.

use crate::lab::simcam::{self, SceneSource, SimCamera, SimCameraSpec, SimScene, SimShot};
use crate::model::capture::CaptureConfig;
use anyhow::{anyhow, Context};
use ndarray::Array3;
use rollcam_hw::camera::replay::{ReplayCamera, ReplayOptions};
use rollcam_hw::camera::{self as hw, Camera, CameraError, CameraSpec};
use std::path::PathBuf;

/// What a camera spec names: `sim` or `sim:<scene>`, `replay:<capture folder>`, or a
/// device (`aravis:<id>`, ...).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum CameraTarget {
    /// The simulated camera; `id` is the scene named in the spec (empty for plain `sim`).
    Simulated { id: String },
    /// A recorded capture folder, played back.
    Replay(PathBuf),
    /// A device, opened through [`rollcam_hw::camera::open`].
    Device(CameraSpec),
}

impl CameraTarget {
    /// Parse a camera spec: `sim`, or `backend:id`.
    pub fn parse(text: &str) -> Result<CameraTarget, CameraError> {
        let spec: CameraSpec = if text == "sim" { CameraSpec { backend: "sim".into(), id: String::new() } } else { text.parse()? };
        Ok(match spec.backend.as_str() {
            "sim" => CameraTarget::Simulated { id: spec.id },
            "replay" => CameraTarget::Replay(PathBuf::from(spec.id)),
            _ => CameraTarget::Device(spec),
        })
    }

    /// The spec as given (`sim:<scene>`, `replay:<folder>`, `backend:id`).
    pub fn spec(&self) -> String {
        match self {
            CameraTarget::Simulated { id } if id.is_empty() => "sim".into(),
            CameraTarget::Simulated { id } => format!("sim:{id}"),
            CameraTarget::Replay(dir) => format!("replay:{}", dir.display()),
            CameraTarget::Device(spec) => format!("{}:{}", spec.backend, spec.id),
        }
    }
}

/// What opening a camera takes besides its spec.
#[derive(Debug, Default)]
pub struct CameraOptions {
    /// The simulated camera, with its scene resolved by the caller from the spec's;
    /// `None`: the scene the spec names (plain `sim`: led-array) on the default
    /// sensor and timing ([`SimCameraSpec::new`]).
    pub simulated: Option<SimCameraSpec>,
    /// A replayed recording's pace and injected faults.
    pub replay: ReplayOptions,
}

/// An open camera: the simulated one also knows its calibration.
pub enum OpenCamera {
    Simulated(Box<SimCamera>),
    /// A device or a replayed recording.
    Device(Box<dyn Camera>),
}

/// Open the camera `target` names, with `options` for the simulated camera and
/// replays. Errors name the spec.
pub fn open_camera(target: &CameraTarget, options: CameraOptions) -> anyhow::Result<OpenCamera> {
    let name = target.spec();
    Ok(match target {
        CameraTarget::Simulated { id } => {
            let spec = match options.simulated {
                Some(spec) => spec,
                None => {
                    let scene: SimScene = (if id.is_empty() { "led-array" } else { id.as_str() }).parse().map_err(|e: String| anyhow!("camera {name}: {e}"))?;
                    SimCameraSpec::new(SceneSource::Catalogue(scene))
                }
            };
            OpenCamera::Simulated(Box::new(simcam::open(spec).with_context(|| format!("opening camera {name}"))?))
        }
        CameraTarget::Replay(dir) => OpenCamera::Device(Box::new(ReplayCamera::open(dir, options.replay).with_context(|| format!("opening camera {name}"))?)),
        CameraTarget::Device(spec) => OpenCamera::Device(hw::open(spec).with_context(|| format!("opening camera {name}"))?),
    })
}

impl OpenCamera {
    pub fn camera(&mut self) -> &mut dyn Camera {
        match self {
            OpenCamera::Simulated(c) => c.as_mut(),
            OpenCamera::Device(c) => c.as_mut(),
        }
    }

    /// What the simulated camera shows from the next frame on (a dark, a point source,
    /// the background or the scene); a device shows what is in front of it (the cap,
    /// the source are the user's), so this changes nothing there.
    pub fn set_shot(&mut self, shot: SimShot) {
        if let OpenCamera::Simulated(c) = self {
            c.renderer_mut().set_shot(shot);
        }
    }

    /// The simulated camera's calibration with its current settings (the PSF as
    /// recorded, counts, and the capture description of its frames); `None` for a
    /// device, whose calibration is measured on the bench.
    pub fn calibration(&mut self) -> Option<anyhow::Result<(Array3<f32>, CaptureConfig)>> {
        match self {
            OpenCamera::Simulated(c) => Some(simcam::calibration(c)),
            OpenCamera::Device(_) => None,
        }
    }

    /// A simulated camera's capture description ([`simcam::capture_config`]) without
    /// its PSF; `None` for a device.
    pub fn simulated_config(&mut self) -> Option<anyhow::Result<CaptureConfig>> {
        match self {
            OpenCamera::Simulated(c) => Some(simcam::capture_config(c)),
            OpenCamera::Device(_) => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_specs_name_their_target() {
        assert_eq!(CameraTarget::parse("sim").unwrap(), CameraTarget::Simulated { id: String::new() });
        assert_eq!(CameraTarget::parse("sim:moving-disc").unwrap(), CameraTarget::Simulated { id: "moving-disc".into() });
        assert_eq!(CameraTarget::parse("replay:/data/a:b").unwrap(), CameraTarget::Replay(PathBuf::from("/data/a:b")));
        assert_eq!(CameraTarget::parse("aravis:Fake_1").unwrap(), CameraTarget::Device(CameraSpec { backend: "aravis".into(), id: "Fake_1".into() }));
        assert!(CameraTarget::parse("Fake_1").is_err());
        for spec in ["sim", "sim:led-array", "replay:/data/a:b", "aravis:Fake_1"] {
            assert_eq!(CameraTarget::parse(spec).unwrap().spec(), spec);
        }
    }

    #[test]
    fn the_simulated_camera_opens_by_scene_name() {
        let mut cam = open_camera(&CameraTarget::parse("sim").unwrap(), CameraOptions::default()).unwrap();
        assert_eq!(cam.camera().info().spec(), "sim:led-array");
        let (psf, cfg) = cam.calibration().expect("simulated").unwrap();
        assert_eq!((psf.dim(), cfg.rows, cfg.cols), ((128, 160, 1), 128, 160));
        let e = open_camera(&CameraTarget::parse("sim:spiral").unwrap(), CameraOptions::default()).err().unwrap().to_string();
        assert!(e.contains("camera sim:spiral: unknown simulated scene 'spiral'"), "{e}");
        let e = open_camera(&CameraTarget::parse("replay:/no/such/folder").unwrap(), CameraOptions::default()).err().unwrap();
        assert!(e.to_string().contains("opening camera replay:/no/such/folder"), "{e}");
        assert!(e.downcast_ref::<CameraError>().is_some(), "{e:#}");
    }
}
