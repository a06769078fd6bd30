//! The command line end to end through the real binary: the commands, their files
//! and their refusals (MPI runs with feature `mpi`). One test binary (`cargo test
//! --test cli`); each module is one command or theme.

#[path = "../support/mod.rs"]
mod support;

mod analysis_cli;
mod bench_day;
mod calibrate_cli;
mod calibration_recovery;
mod cli_capture_sim;
mod cli_compare;
mod cli_core;
mod cli_led;
mod cli_raw;
mod hostile_input;
mod mpi_split;
mod sequence_cli;
mod simulate_defects;
mod simulate_keyframes;
