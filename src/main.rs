use clap::{Parser, Subcommand};

mod cmd_capture;
mod cmd_devices;

#[derive(Parser)]
#[command(name = "rollcam", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// List GenICam cameras and USB devices.
    Devices(cmd_devices::DevicesArgs),
    /// Record frames from a camera into a capture folder.
    Capture(cmd_capture::CaptureArgs),
}

fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .init();
    match Cli::parse().command {
        Command::Devices(a) => cmd_devices::run(a),
        Command::Capture(a) => cmd_capture::run(a),
    }
}
