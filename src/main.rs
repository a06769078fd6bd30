//! The `rollcam` command: a thin layer over the library.

// `!(x > 0.0)` and the like are deliberate: they reject NaN with the bad values.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod cmd_analyze;
mod cmd_bench;
mod cmd_capture;
mod cmd_common;
mod cmd_compare;
mod cmd_demo;
mod cmd_devices;
mod cmd_experiment;
mod cmd_led;
mod cmd_reconstruct;
mod cmd_sequence;
mod cmd_serve;
mod cmd_run;
mod cmd_simulate;

use clap::{Parser, Subcommand};
use std::io::IsTerminal;
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "rollcam", version, about = "Video from one rolling-shutter photograph taken through a diffuser")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate, reconstruct and check a flashing-LED scene with no hardware and no files.
    Demo(cmd_demo::DemoArgs),
    /// Simulate a rolling-shutter capture of a known scene through a diffuser.
    Simulate(cmd_simulate::SimulateArgs),
    /// Reconstruct a video from a raw capture, its PSF and its timing.
    Reconstruct(cmd_reconstruct::ReconstructArgs),
    /// Projections, temporal spectra in Hz and resolution of a reconstructed video.
    Analyze(cmd_analyze::AnalyzeArgs),
    /// Reproduce an experiment in simulation, or on the bench with --camera and --led (led-sweep).
    Experiment(cmd_experiment::ExperimentArgs),
    /// Run several solvers on one capture: error against run time, time-to-reach table.
    Compare(cmd_compare::CompareArgs),
    /// List GenICam cameras and USB devices.
    Devices(cmd_devices::DevicesArgs),
    /// Record frames from a camera into a capture folder.
    Capture(cmd_capture::CaptureArgs),
    /// LED pulse controller: configure, arm, trigger, status, or emulate one.
    Led(cmd_led::LedArgs),
    /// Time the reconstruction on synthetic presets (JSON lines; --all --markdown FILE).
    Bench(cmd_bench::BenchArgs),
    /// Reconstruct the consecutive raw frames of a capture folder as one continuous video.
    ReconstructSequence(cmd_sequence::SequenceArgs),
    /// Live page of a bench session folder on localhost (session.json and previews).
    Serve(cmd_serve::ServeArgs),
    /// Live bench session: record every frame raw, reconstruct each as it comes (--resume DIR finishes one).
    Run(Box<cmd_run::RunArgs>),
}

fn init_logging() {
    // On a terminal the progress bars speak; elsewhere the logs do.
    let default = if std::io::stderr().is_terminal() { "warn" } else { "info" };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .with_target(false)
        .init();
}

fn main() -> ExitCode {
    init_logging();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Demo(a) => cmd_demo::run(a),
        Command::Simulate(a) => cmd_simulate::run(a),
        Command::Reconstruct(a) => cmd_reconstruct::run(a),
        Command::Analyze(a) => cmd_analyze::run(a),
        Command::Experiment(a) => cmd_experiment::run(a),
        Command::Compare(a) => cmd_compare::run(a),
        Command::Led(a) => cmd_led::run(a),
        Command::Devices(a) => cmd_devices::run(a),
        Command::Capture(a) => cmd_capture::run(a),
        Command::Bench(a) => cmd_bench::run(a),
        Command::ReconstructSequence(a) => cmd_sequence::run(a),
        Command::Serve(a) => cmd_serve::run(a),
        Command::Run(a) => cmd_run::run(*a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
