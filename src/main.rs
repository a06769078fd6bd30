mod cmd_led;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "rollcam", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Commands,
}

#[derive(Subcommand)]
enum Commands {
    /// LED pulse controller: configure, arm, trigger, status, or emulate one.
    Led(cmd_led::LedArgs),
}

fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_writer(std::io::stderr)
        .init();
    match Cli::parse().command {
        Commands::Led(args) => cmd_led::run(args),
    }
}
