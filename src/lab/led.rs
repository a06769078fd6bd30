//! The LED pulse controller on the bench (`rollcam led`): which serial port is the
//! controller ([`guess_port`]), a channel's pulses from a period and a duty or width
//! ([`channel_config`]), the state of the controller and every channel ([`snapshot`]),
//! one-line descriptions ([`describe`], [`armed_for`]), and serving an emulated
//! controller on a pseudo-terminal with edges on its trigger input ([`serve_emulator`]).
//! The driver and the emulator are the hardware crate's (`rollcam_hw::led`).

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Receiver;
use std::time::Duration;

use anyhow::{bail, Context};
use rollcam_hw::led::{available_ports, ChannelConfig, ChannelReadback, DeviceStatus, LedController, LedError, LinkedEmulator, TriggerMode};
use serde::Serialize;

/// The only USB serial port that looks like an Arduino; an error naming the ports
/// when there is none or several.
pub fn guess_port() -> anyhow::Result<String> {
    let ports = available_ports().context("listing serial ports")?;
    let likely: Vec<_> = ports.iter().filter(|p| p.likely_controller).collect();
    match likely.as_slice() {
        [one] => {
            tracing::info!("using {} ({})", one.path, one.description);
            Ok(one.path.clone())
        }
        [] => bail!(
            "no --port given and no Arduino-like USB serial port found (ports: {})",
            if ports.is_empty() { "none".to_string() } else { ports.iter().map(|p| p.path.clone()).collect::<Vec<_>>().join(", ") }
        ),
        many => bail!("no --port given and several candidates: {}", many.iter().map(|p| p.path.clone()).collect::<Vec<_>>().join(", ")),
    }
}

/// A channel's pulses: `width_us` high time if given, else `duty` of the period
/// (default 0.5, strictly between 0 and 1).
pub fn channel_config(period_us: u32, duty: Option<f64>, width_us: Option<u32>, phase_us: u32, count: Option<u32>) -> anyhow::Result<ChannelConfig> {
    let width_us = match (width_us, duty) {
        (Some(w), _) => w,
        (None, d) => {
            let d = d.unwrap_or(0.5);
            if !(d > 0.0 && d < 1.0) {
                bail!("--duty {d} must be strictly between 0 and 1");
            }
            (period_us as f64 * d).round() as u32
        }
    };
    Ok(ChannelConfig { period_us, width_us, phase_us, pulse_count: count })
}

/// One line per channel: `ch0 on  period_us=.. width_us=.. duty=.. phase_us=.. count=..`.
pub fn describe(r: &ChannelReadback) -> String {
    let c = &r.config;
    format!(
        "ch{} {} period_us={} width_us={} duty={:.3} phase_us={} count={}",
        r.channel,
        if r.enabled { "on " } else { "off" },
        c.period_us,
        c.width_us,
        c.duty(),
        c.phase_us,
        c.pulse_count.map(|n| n.to_string()).unwrap_or_else(|| "continuous".into())
    )
}

/// What an armed controller waits for, in words.
pub fn armed_for(trigger: TriggerMode) -> &'static str {
    match trigger {
        TriggerMode::Software => "a software trigger (`rollcam led trigger`)",
        TriggerMode::Rising => "a rising edge on the trigger input",
        TriggerMode::Falling => "a falling edge on the trigger input",
    }
}

/// The run state and every channel's configuration.
#[derive(Clone, Debug, Serialize)]
pub struct Snapshot {
    pub status: DeviceStatus,
    pub channels: Vec<ChannelReadback>,
}

/// Ask the controller for its state, then for each of its channels.
pub fn snapshot(ctl: &mut LedController) -> Result<Snapshot, LedError> {
    let status = ctl.status()?;
    let channels = (0..status.enabled.len() as u8).map(|c| ctl.channel(c)).collect::<Result<Vec<_>, _>>()?;
    Ok(Snapshot { status, channels })
}

/// Serve an emulated controller linked at `link` until `stop` is set: each edge from
/// `edges` (true: rising) goes to its trigger input, and `on_edge(rising, fired)` says
/// whether it started the waveform. Fails when the emulator stops by itself.
pub fn serve_emulator(
    linked: &LinkedEmulator,
    link: &Path,
    stop: &AtomicBool,
    edges: &Receiver<bool>,
    mut on_edge: impl FnMut(bool, bool),
) -> anyhow::Result<()> {
    while !stop.load(Ordering::SeqCst) {
        while let Ok(rising) = edges.try_recv() {
            let fired = linked.emulator().input_edge(rising);
            on_edge(rising, fired);
        }
        if !linked.emulator().is_running() {
            bail!("emulator on {} stopped unexpectedly", link.display());
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn duty_or_width_gives_the_high_time() {
        assert_eq!(channel_config(1000, None, None, 0, None).unwrap().width_us, 500);
        assert_eq!(
            channel_config(1000, Some(0.25), None, 7, Some(3)).unwrap(),
            ChannelConfig { period_us: 1000, width_us: 250, phase_us: 7, pulse_count: Some(3) }
        );
        assert_eq!(channel_config(1000, None, Some(40), 0, None).unwrap().width_us, 40);
        let e = channel_config(1000, Some(1.0), None, 0, None).unwrap_err().to_string();
        assert_eq!(e, "--duty 1 must be strictly between 0 and 1");
    }
}
