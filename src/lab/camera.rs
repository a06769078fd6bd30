//! Opening the camera a spec names, whatever its kind: `sim:<scene>` (the simulated
//! bench of `rollcam capture`, [`crate::lab::simcam::capture_camera`]) or a backend of
//! the hardware crate (`aravis:<id>`, `replay:<folder>`). Used by `rollcam capture`
//! and the Python module.

use crate::lab::simcam::{self, SimRenderer};
use crate::model::capture::CaptureConfig;
use anyhow::Context;
use ndarray::Array3;
use rollcam_hw::camera::simulated::SimulatedCamera;
use rollcam_hw::camera::{self as hw, Camera, CameraSpec};

/// An open camera: simulated ones also know their calibration.
pub enum BenchCamera {
    Simulated(Box<SimulatedCamera<SimRenderer>>),
    Device(Box<dyn Camera>),
}

impl BenchCamera {
    /// Open the camera `spec` names (`sim:led-array`, `sim:moving-disc`,
    /// `aravis:Fake_1`, `replay:DIR`, ...).
    pub fn open(spec: &str) -> anyhow::Result<BenchCamera> {
        let parsed: CameraSpec = spec.parse()?;
        if parsed.backend == "sim" {
            return Ok(BenchCamera::Simulated(Box::new(simcam::capture_camera(&parsed.id)?)));
        }
        Ok(BenchCamera::Device(hw::open(&parsed).with_context(|| format!("opening camera {spec}"))?))
    }

    pub fn camera(&mut self) -> &mut dyn Camera {
        match self {
            BenchCamera::Simulated(c) => c.as_mut(),
            BenchCamera::Device(c) => c.as_mut(),
        }
    }

    /// A simulated camera's calibration with its current settings (the PSF as
    /// recorded, counts, and the capture description of its frames); `None` for a
    /// device, whose calibration is measured on the bench.
    pub fn calibration(&mut self) -> Option<anyhow::Result<(Array3<f32>, CaptureConfig)>> {
        match self {
            BenchCamera::Simulated(c) => Some(simcam::calibration(c)),
            BenchCamera::Device(_) => None,
        }
    }
}
