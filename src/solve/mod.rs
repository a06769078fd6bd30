//! Solving `min 0.5 ||A v - b||^2 + tau ||grad_xyt v||_1, v >= 0` without forming `A`.
//!
//! [`problem`] builds a capture's problem once (operator, tau, `A^T b`, cache key);
//! [`prox`] holds the proximal maps; [`optimize`] the shared solver types and the
//! solvers; [`lipschitz`] step sizes; [`metric`] the per-frame metric of the preconditioned gradient methods; [`trace`] the error against run time (an
//! observer); [`plan`] the one place a solve's mode and weight are decided; [`reconstruct`] one capture to one video, as its plan says ([`channel`]: one channel's solve and report); [`compare`] solvers side by
//! side on one problem; [`estimate`] a solve's time, before it starts; [`static_dynamic`] the static + dynamic scene model's solve; [`sequence`] consecutive captures as one video; [`split`] one capture solved by several processes (MPI ranks), each holding a block of frames; [`start`] where a video solve starts (the still image); [`support`] a sparse scene's support, from its still image; [`sources`] its light fitted as sources that change only in brightness; [`frames`] runs of frames (weak, unseen) as a person reads them; [`tau`] the TV weight as given, its scale and the static-frame rule; [`tau_search`] the TV weight chosen by held-out pixels. Nothing here reads files or knows the hardware.

pub mod channel;
pub mod compare;
pub mod estimate;
pub mod fit;
pub mod frames;
pub mod job;
pub mod keyframes;
pub mod lipschitz;
pub mod metric;
pub mod modes;
pub mod optimize;
pub mod plan;
pub mod problem;
pub mod prox;
pub mod reconstruct;
pub mod refusal;
pub mod scene;
pub mod sequence;
pub mod sources;
pub mod split;
pub mod start;
pub use modes::static_dynamic;
pub mod support;
pub mod tau;
pub mod tau_search;
pub mod trace;
