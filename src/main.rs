//! The `rollcam` command: a thin layer over the library.

// `!(x > 0.0)` and the like are deliberate: they reject NaN with the bad values.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod cli;

use clap::{Parser, Subcommand};
use std::io::IsTerminal;
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "rollcam", version, about = "Video from one rolling-shutter photograph taken through a diffuser")]
struct Cli {
    #[command(subcommand)]
    command: CliCommand,
}

#[derive(Subcommand)]
enum CliCommand {
    /// Simulate, reconstruct and check a flashing-LED scene with no hardware and no files.
    Demo(cli::demo::DemoArgs),
    /// Simulate a rolling-shutter capture of a known scene through a diffuser.
    Simulate(cli::simulate::SimulateArgs),
    /// Reconstruct a video from a raw capture, its PSF and its timing.
    Reconstruct(cli::reconstruct::ReconstructArgs),
    /// Projections, temporal spectra in Hz and resolution of a reconstructed video.
    Analyze(cli::analyze::AnalyzeArgs),
    /// A bench calibration folder from dark frames, point-source shots and background frames.
    Calibrate(cli::calibrate::CalibrateArgs),
    /// Reproduce an experiment in simulation, or on the bench with --camera and --led (led-sweep).
    Experiment(cli::experiment::ExperimentArgs),
    /// Run several solvers on one capture: error against run time, time-to-reach table.
    Compare(cli::compare::CompareArgs),
    /// List GenICam cameras and USB devices.
    Devices(cli::devices::DevicesArgs),
    /// Record frames from a camera into a capture folder.
    Capture(cli::capture::CaptureArgs),
    /// LED pulse controller: configure, arm, trigger, status, or emulate one.
    Led(cli::led::LedArgs),
    /// Time the reconstruction on synthetic presets (JSON lines; --all --markdown FILE).
    Bench(cli::bench::BenchArgs),
    /// Reconstruct the consecutive raw frames of a capture folder as one continuous video.
    ReconstructSequence(cli::sequence::SequenceArgs),
    /// Live page of a bench session folder on localhost (session.json and previews).
    Serve(cli::serve::ServeArgs),
    /// See a result folder's videos (reconstruct, compare, reconstruct-sequence, led-sweep) in the browser on localhost.
    View(cli::view::ViewArgs),
    /// Live bench session: record every frame raw, reconstruct each as it comes (--resume DIR finishes one).
    Run(Box<cli::run::RunArgs>),
}

fn init_logging() {
    // On a terminal the progress bars speak; elsewhere the logs do, as plain lines (no
    // timestamp, no colour codes): a file or a pipe that wants times adds its own.
    let terminal = std::io::stderr().is_terminal();
    let default = if terminal { "warn" } else { "info" };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default));
    let logs = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).with_ansi(terminal).with_target(false);
    if terminal {
        logs.init();
    } else {
        logs.without_time().init();
    }
}

fn main() -> ExitCode {
    // A reader that closes the pipe early (`rollcam analyze DIR | head -1`) ends the
    // process quietly, as Unix tools do, instead of a panic at the next print. The
    // live page's sockets are unaffected: the standard library sends on them with
    // MSG_NOSIGNAL.
    #[cfg(unix)]
    // SAFETY: called once before any thread starts; SIG_DFL is a valid disposition.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    init_logging();
    let cli = Cli::parse();
    let splits = matches!(&cli.command, CliCommand::Reconstruct(_) | CliCommand::Bench(_));
    let result = cli::common::refuse_mpi_launch(splits).and_then(|()| match cli.command {
        CliCommand::Demo(a) => cli::demo::run(a),
        CliCommand::Simulate(a) => cli::simulate::run(a),
        CliCommand::Reconstruct(a) => cli::reconstruct::run(a),
        CliCommand::Analyze(a) => cli::analyze::run(a),
        CliCommand::Calibrate(a) => cli::calibrate::run(a),
        CliCommand::Experiment(a) => cli::experiment::run(a),
        CliCommand::Compare(a) => cli::compare::run(a),
        CliCommand::Led(a) => cli::led::run(a),
        CliCommand::Devices(a) => cli::devices::run(a),
        CliCommand::Capture(a) => cli::capture::run(a),
        CliCommand::Bench(a) => cli::bench::run(a),
        CliCommand::ReconstructSequence(a) => cli::sequence::run(a),
        CliCommand::Serve(a) => cli::serve::run(a),
        CliCommand::View(a) => cli::view::run(a),
        CliCommand::Run(a) => cli::run::run(*a),
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", cli::common::error_text(&e));
            ExitCode::FAILURE
        }
    }
}
