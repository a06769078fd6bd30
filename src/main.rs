//! The `rollcam` command: a thin layer over the library.

mod cmd_bench;
mod cmd_common;
mod cmd_led;
mod cmd_reconstruct;

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
    /// Reconstruct a video from a raw capture, its PSF and its timing.
    Reconstruct(cmd_reconstruct::ReconstructArgs),
    /// LED pulse controller: configure, arm, trigger, status, or emulate one.
    Led(cmd_led::LedArgs),
    /// Time the reconstruction on synthetic presets (JSON lines; --all --markdown FILE).
    Bench(cmd_bench::BenchArgs),
}

fn init_logging() {
    // On a terminal the progress bars speak; elsewhere the logs do.
    let default = if std::io::stderr().is_terminal() { "warn" } else { "info" };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default));
    tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).with_target(false).init();
}

fn main() -> ExitCode {
    init_logging();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Reconstruct(a) => cmd_reconstruct::run(a),
        Command::Led(a) => cmd_led::run(a),
        Command::Bench(a) => cmd_bench::run(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
