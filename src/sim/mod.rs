//! Physical simulator: a synthetic diffuser PSF ([`psf`]), time-varying scenes
//! ([`scene`]) and the rolling-shutter capture integrated in continuous time at raw
//! resolution, with sensor noise ([`expose`]).
//!
//! The simulator never uses the reconstruction's discrete operator: each raw row
//! integrates the scene, seen through the PSF, over its own exposure window
//! `[s_i, s_i + T_e)` (from [`crate::model::shutter::Timing::raw_row_starts_us`]). The
//! ground-truth video is the scene integrated over each frame interval on the
//! reconstruction grid, so that `A(truth)` can be compared with the raw image.
//!
//! [`setup`] builds simulations from plain parameters ([`setup::SimParams`]: the
//! flags of `rollcam simulate`, also used by `demo` and the simulated cameras);
//! [`error`] holds [`SimError`]. [`sensor`] is the bench around a set-up: a sensor
//! with fixed-pattern dark and hot and stuck pixels, a static background, and the
//! calibration shots (darks, point-source PSF shots, background frames) taken with it.
//! [`keyframe`] renders key frames of a second, global-shutter camera from the truth.

pub mod error;
pub mod expose;
pub mod keyframe;
pub mod psf;
pub mod scene;
pub mod sensor;
pub mod sequence;
pub mod setup;

pub use crate::model::resample::box_downsample;
pub use error::SimError;
pub use expose::{simulate, NoiseModel, Simulation};
pub use keyframe::{KeyFrameParams, KeyFramePlan, KeyFrames, KeyTime};
pub use psf::{lenslet_psf, LensletParams};
pub use scene::{ImageStack, LedArray, LedLine, MovingDisc, Scene};
pub use sensor::{BackgroundTexture, CalibrationShots, DefectMap, SensorDefects, SimulatedSensor};
pub use sequence::{readout_period_us, simulate_sequence, Consecutive, SequenceSimulation, TimeShifted};
pub use setup::{psf_counts, SimParams, SimSetup};
