//! `rollcam led ...`: drive the LED pulse controller, or emulate one.

use std::time::Duration;

use anyhow::Context;
use clap::{Args, Subcommand, ValueEnum};
use rollcam::lab::led::{armed_for, channel_config, describe, guess_port, serve_emulator, snapshot};
use rollcam_hw::led::{available_ports, LedController, LinkOptions, LinkedEmulator, TriggerMode};

#[derive(Args, Debug)]
pub struct LedArgs {
    /// Serial port of the controller (e.g. /dev/ttyACM0, or the link made by `led emulate`).
    /// If omitted, the only USB serial port that looks like an Arduino is used.
    #[arg(long, global = true)]
    pub port: Option<String>,
    /// Baud rate.
    #[arg(long, global = true, default_value_t = rollcam_hw::led::DEFAULT_BAUD)]
    pub baud: u32,
    /// Reply timeout per attempt, milliseconds (1 to 60000: at 0 no reply can arrive).
    #[arg(long, global = true, default_value_t = 300, value_parser = clap::value_parser!(u64).range(1..=60_000))]
    pub timeout_ms: u64,
    /// Retransmissions after a timeout (safe: the sequence number makes them idempotent).
    #[arg(long, global = true, default_value_t = 2)]
    pub retries: u32,
    /// After opening, how long to wait for the board to answer (an Arduino reboots
    /// when the port opens), milliseconds; 0 skips the wait.
    #[arg(long, global = true, default_value_t = 2500)]
    pub ready_ms: u64,
    /// Print results as JSON.
    #[arg(long, global = true)]
    pub json: bool,
    #[command(subcommand)]
    pub command: LedCommand,
}

#[derive(Subcommand, Debug)]
pub enum LedCommand {
    /// List serial ports on this machine.
    Ports,
    /// Ask the controller who it is (name, protocol, firmware, channels, tick).
    Identify,
    /// Configure and enable one channel.
    Set(SetArgs),
    /// Disable one channel.
    Off { channel: u8 },
    /// Arm: wait for a software trigger or an edge on the trigger input.
    Arm {
        #[arg(long, value_enum, default_value_t = TriggerArg::Sw)]
        trigger: TriggerArg,
    },
    /// Software trigger (the controller must be armed).
    Trigger,
    /// Stop: outputs low, back to idle (configuration kept).
    Stop,
    /// Run state and every channel's configuration.
    Status,
    /// JSON summary of the synchronisation (for capture metadata).
    Sync {
        #[arg(long, value_enum, default_value_t = TriggerArg::Rise)]
        trigger: TriggerArg,
    },
    /// Run a software controller on a pseudo-terminal linked at --link, until Ctrl-C.
    /// Typing `rise` or `fall` on standard input simulates an edge on the trigger input.
    Emulate {
        /// Path of the symlink to create (removed on exit).
        #[arg(long)]
        link: std::path::PathBuf,
    },
}

#[derive(Args, Debug)]
pub struct SetArgs {
    /// Channel number (0-3).
    pub channel: u8,
    /// Period in microseconds (100 to 10000000).
    #[arg(long)]
    pub period_us: u32,
    /// Duty cycle, 0 < duty < 1 (default 0.5).
    #[arg(long, conflicts_with = "width_us")]
    pub duty: Option<f64>,
    /// High time in microseconds (instead of --duty).
    #[arg(long)]
    pub width_us: Option<u32>,
    /// Delay from the trigger to the first rising edge, microseconds.
    #[arg(long, default_value_t = 0)]
    pub phase_us: u32,
    /// Number of pulses (default: continuous until stop).
    #[arg(long)]
    pub count: Option<u32>,
}

#[derive(ValueEnum, Clone, Copy, Debug)]
pub enum TriggerArg {
    /// `led trigger` command.
    Sw,
    /// Rising edge on the trigger input.
    Rise,
    /// Falling edge on the trigger input.
    Fall,
}

impl From<TriggerArg> for TriggerMode {
    fn from(t: TriggerArg) -> TriggerMode {
        match t {
            TriggerArg::Sw => TriggerMode::Software,
            TriggerArg::Rise => TriggerMode::Rising,
            TriggerArg::Fall => TriggerMode::Falling,
        }
    }
}

pub fn run(args: LedArgs) -> anyhow::Result<()> {
    match &args.command {
        LedCommand::Ports => return list_ports(args.json),
        LedCommand::Emulate { link } => return emulate(link),
        _ => {}
    }
    let port = match &args.port {
        Some(p) => p.clone(),
        None => guess_port()?,
    };
    let opts = LinkOptions {
        baud: args.baud,
        reply_timeout: Duration::from_millis(args.timeout_ms),
        retries: args.retries,
        ready_timeout: Duration::from_millis(args.ready_ms),
    };
    let mut ctl = LedController::open_with(&port, opts)?;
    match args.command {
        LedCommand::Identify => {
            let info = ctl.identify()?;
            if args.json {
                println!("{}", serde_json::to_string_pretty(&info)?);
            } else {
                println!(
                    "{port}: {} protocol {} firmware {} hardware {} channels {} tick {} ns",
                    info.name, info.protocol, info.firmware, info.hardware, info.channels, info.tick_ns
                );
            }
        }
        LedCommand::Set(s) => {
            let cfg = channel_config(s.period_us, s.duty, s.width_us, s.phase_us, s.count)?;
            ctl.configure(s.channel, cfg)?;
            let r = ctl.channel(s.channel)?;
            if args.json {
                println!("{}", serde_json::to_string_pretty(&r)?);
            } else {
                println!("{port}: {}", describe(&r));
            }
        }
        LedCommand::Off { channel } => {
            ctl.disable(channel)?;
            println!("{port}: ch{channel} off");
        }
        LedCommand::Arm { trigger } => {
            ctl.arm(trigger.into())?;
            let what = armed_for(trigger.into());
            println!("{port}: armed, waiting for {what}");
        }
        LedCommand::Trigger => {
            ctl.trigger()?;
            println!("{port}: triggered");
        }
        LedCommand::Stop => {
            ctl.stop()?;
            println!("{port}: stopped");
        }
        LedCommand::Status => {
            let snap = snapshot(&mut ctl)?;
            let (st, channels) = (&snap.status, &snap.channels);
            if args.json {
                let v = serde_json::json!({ "port": port, "status": st, "channels": channels });
                println!("{}", serde_json::to_string_pretty(&v)?);
            } else {
                println!("{port}: state={} trigger={} t_us={}", st.state.token(), st.trigger.map(|t| t.token()).unwrap_or("-"), st.t_us);
                for r in channels {
                    println!("  {}", describe(r));
                }
            }
        }
        LedCommand::Sync { trigger } => {
            let s = ctl.sync_summary(trigger.into())?;
            println!("{}", serde_json::to_string_pretty(&s)?);
        }
        LedCommand::Ports | LedCommand::Emulate { .. } => unreachable!("handled above"),
    }
    Ok(())
}

fn list_ports(json: bool) -> anyhow::Result<()> {
    let ports = available_ports().context("listing serial ports")?;
    if json {
        println!("{}", serde_json::to_string_pretty(&ports)?);
    } else if ports.is_empty() {
        println!("no serial ports found");
    } else {
        for p in ports {
            println!("{}\t{}{}", p.path, p.description, if p.likely_controller { "\t(likely controller)" } else { "" });
        }
    }
    Ok(())
}

fn emulate(link: &std::path::Path) -> anyhow::Result<()> {
    let stop = rollcam_hw::led::emulator::interrupt_flag();
    let linked = LinkedEmulator::create(link, Default::default())?;
    println!("emulating the LED controller on {} -> {} (Ctrl-C to stop)", linked.link().display(), linked.target().display());
    use std::io::{BufRead, Write};
    std::io::stdout().flush().ok();
    // Trigger-input edges from standard input ("rise" / "fall"), for rehearsing ARM RISE/FALL.
    let (tx, rx) = std::sync::mpsc::channel::<bool>();
    std::thread::spawn(move || {
        for line in std::io::stdin().lock().lines() {
            let Ok(line) = line else { break };
            match line.trim() {
                "rise" => tx.send(true).ok(),
                "fall" => tx.send(false).ok(),
                "" => None,
                other => {
                    eprintln!("unknown input '{other}' (type 'rise' or 'fall')");
                    None
                }
            };
        }
    });
    serve_emulator(&linked, link, stop, &rx, |rising, fired| {
        println!("trigger input: {} edge{}", if rising { "rising" } else { "falling" }, if fired { ", waveform started" } else { " (not armed for it)" });
        std::io::stdout().flush().ok();
    })?;
    drop(linked);
    println!("emulator stopped, {} removed", link.display());
    Ok(())
}
