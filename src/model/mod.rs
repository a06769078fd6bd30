//! The paper's forward model: `b = sum_k S_k . crop(h * v_k)`.
//!
//! [`shutter`] turns timing (line time, exposure, shutter mode) into exact per-row
//! weights; [`capture`] is the capture description (capture.toml's fields, without the
//! file); [`prepare`] and [`resample`] make raw and PSF ready (dark level, downsampling,
//! normalisation); [`conv`] plans the FFT convolution; [`op`] is the operator interface and
//! [`data`] the data term beside it (observations, clipped pixels, ranks), [`mask`] which pixels it keeps; [`keyframe`] is the second, global-shutter camera's frames as a data term; [`noise`] measures a raw's noise from the raw;
//! [`rolling`] is the imaging operator `A`; [`scene`] restricts it to what a scene
//! declares; [`static_dynamic`] is the static + dynamic scene model (`v_k = s + d_k`); [`still`] is `A` on videos constant in time (one convolution); [`sensor`] holds the bench's sensor (per-pixel dark, defects, clipping,
//! background) and the masks they give the data term; [`time_grid`] and [`stacked`] place consecutive captures on one video;
//! [`ranks`] and [`split`] spread one problem's frames over several processes (MPI ranks).
//! Nothing here reads files or knows the hardware.

pub mod capture;
pub mod conv;
pub mod data;
pub mod keyframe;
pub mod mask;
pub mod noise;
pub mod op;
pub mod prepare;
pub mod ranks;
pub mod resample;
pub mod rolling;
pub mod scene;
pub mod sensor;
pub mod shutter;
pub mod split;
pub mod stacked;
pub mod static_dynamic;
pub mod still;
pub mod time_grid;
