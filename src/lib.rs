//! rollcam: video from one rolling-shutter photograph taken through a diffuser.
//!
//! Layers (each one concept): [`shutter`] (timing and exact shutter weights),
//! [`capture`] (the capture description file), [`conv`] (planned FFT convolution),
//! [`model`] (the imaging operator `A`), [`op`] (the operator trait), [`tv`] (total
//! variation and its proximal map), [`fista`] (solvers), [`lipschitz`] (step sizes),
//! [`resample`] (box downsampling), [`sim`] (the physical simulator: diffuser PSF,
//! scenes, continuous-time rolling-shutter capture, noise).

pub mod capture;
pub mod conv;
pub mod model;
pub mod op;
pub mod resample;
pub mod shutter;
pub mod sim;
pub mod tv;
pub mod fista;
pub mod lipschitz;
