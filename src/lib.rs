//! rollcam: video from one rolling-shutter photograph taken through a diffuser.
//!
//! Layers (each one concept): [`shutter`] (timing and exact shutter weights),
//! [`capture`] (the capture description file), [`conv`] (planned FFT convolution),
//! [`model`] (the imaging operator `A`), [`op`] (the operator trait), [`tv`] (total
//! variation and its proximal map), [`fista`] (solvers), [`lipschitz`] (step sizes),
//! [`prepare`] (dark level, downsampling, PSF normalisation), [`trace`] (error against
//! run time), [`reconstruct`] (one capture to one video), [`io`] (file formats, figures),
//! [`sim`] (the physical simulator), [`analysis`] (time courses, spectra).

pub mod analysis;
pub mod bench;
pub mod capture;
pub mod conv;
pub mod fista;
pub mod io;
pub mod lipschitz;
pub mod model;
pub mod output;
pub mod op;
pub mod prepare;
pub mod reconstruct;
pub mod resample;
pub mod shutter;
pub mod simcam;
pub mod sim;
pub mod trace;
pub mod tv;
