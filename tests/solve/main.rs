//! The solvers and what they reconstruct: one interface, stiff cases, recovery of
//! known videos, the scene declaration, the still start, the noise rule and the tau
//! search, the static + dynamic model, and the benchmark's pieces. One test binary (`cargo test --test
//! solve`); each module is one theme, some run the real binary.

#[path = "../support/mod.rs"]
mod support;

mod admm_split;
mod cuda;
mod fit_report;
mod keyframes;
mod noise_weight;
mod perf_bench;
mod perf_equivalence;
mod preconditioner;
mod recovery_model;
mod scene_reconstruct;
mod sequence_recovery;
mod solvers_interface;
mod solvers_restart_haar;
mod solvers_scene;
mod solvers_tv_prox;
mod static_background;
mod stiff_data;
mod stiff_optics;
mod stiff_precision;
mod stiff_strong_regularisation;
mod stiff_timing;
mod still_start;
mod tau_search;
