//! rollcam: video from one rolling-shutter photograph taken through a diffuser.
//!
//! Layers (each one concept): [`shutter`] (timing and exact shutter weights),
//! [`capture`] (the capture description file), [`conv`] (planned FFT convolution),
//! [`model`] (the imaging operator `A`), [`op`] (the operator trait), [`tv`] (total
//! variation and its proximal map), [`fista`] (FISTA), [`solver`] (one interface over FISTA, [`admm`], [`pgd`]; TV prox
//! variants in [`tv_dual`]), [`scene_spec`] (only what a scene needs), [`lipschitz`] (step sizes),
//! [`prepare`] (dark level, downsampling, PSF normalisation), [`trace`] (error against
//! run time), [`reconstruct`] (one capture to one video), [`io`] (file formats, figures),
//! [`sim`] (the physical simulator), [`analysis`] (time courses, spectra).

// `!(x > 0.0)` and the like are deliberate: they reject NaN with the bad values.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod analysis;
pub mod bench;
pub mod capture;
pub mod conv;
pub mod admm;
pub mod fista;
pub mod grad3;
pub mod io;
pub mod lipschitz;
pub mod live;
pub mod mfista;
pub mod model;
pub mod output;
pub mod pgd;
pub mod pipeline;
pub mod op;
pub mod prepare;
pub mod reconstruct;
pub mod scene_spec;
pub mod sequence;
pub mod solver;
pub mod resample;
pub mod shutter;
pub mod simcam;
pub mod sim;
pub mod trace;
pub mod tv;
pub mod tv_dual;
pub mod utc;
