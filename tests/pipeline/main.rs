//! The bench pipeline (`rollcam run`, the library pipeline, replay and simulated
//! cameras, faults), the live page and viewer in a headless Chromium, calibration and
//! solver choices reaching every solve, and the LED sweep. One test binary (`cargo test
//! --test pipeline`); each module is one theme.

#[path = "../support/mod.rs"]
mod support;

mod bench_guide;
mod calibration_commands;
mod experiment_led_sweep;
mod experiment_led_sweep_hw;
mod live_view;
mod pipeline_aravis;
mod pipeline_consecutive;
mod pipeline_faults;
mod pipeline_keyframes;
mod pipeline_library;
mod pipeline_outputs;
mod pipeline_replay;
mod pipeline_serve;
mod solver_choice;
mod view_page;
