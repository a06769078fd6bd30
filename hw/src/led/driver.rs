//! Host driver: talks to the controller (board or emulator) over a serial port.

use std::io::{self, Read, Write};
use std::path::Path;
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};
use serialport::SerialPort;

use super::protocol::{
    decode_frame, encode_frame, escape_bytes, ChannelConfig, ChannelConfigError, ChannelReadback, Command, DeviceInfo, DeviceStatus, ErrorCode, LineAssembler,
    LineEvent, Reply, TriggerMode, CHANNELS, MAX_SEQ, PROTOCOL_VERSION,
};

/// Default baud rate of the firmware.
pub const DEFAULT_BAUD: u32 = 115_200;

/// Link parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LinkOptions {
    pub baud: u32,
    /// How long to wait for the reply to one transmission.
    pub reply_timeout: Duration,
    /// Extra transmissions after the first (same sequence number, so safe).
    pub retries: u32,
    /// After opening a port by path, how long to keep asking `ID` until the
    /// device answers (an Arduino resets when the port opens and its
    /// bootloader ignores the UART for about 1-2 s). Zero skips the check.
    pub ready_timeout: Duration,
}

impl Default for LinkOptions {
    fn default() -> Self {
        LinkOptions { baud: DEFAULT_BAUD, reply_timeout: Duration::from_millis(300), retries: 2, ready_timeout: Duration::from_millis(2500) }
    }
}

/// Everything that can go wrong talking to the controller. Each names the port.
#[derive(Debug, thiserror::Error)]
pub enum LedError {
    #[error("serial port {port} not found{hint}")]
    PortNotFound { port: String, hint: String },
    #[error("permission denied opening serial port {port} (add the user to the 'dialout' group, or check the udev rules)")]
    PermissionDenied { port: String },
    #[error("serial port {port} is busy (already opened by another program?)")]
    PortBusy { port: String },
    #[error("cannot open serial port {port}: {source}")]
    Open {
        port: String,
        #[source]
        source: serialport::Error,
    },
    #[error("I/O error on serial port {port}: {source}")]
    Io {
        port: String,
        #[source]
        source: io::Error,
    },
    #[error("LED controller on {port} did not answer {command} (no reply after {attempts} attempt(s) of {timeout_ms} ms); is it powered, is this the right port and baud rate?")]
    Silent { port: String, command: String, attempts: u32, timeout_ms: u64 },
    #[error("LED controller on {port}: no valid reply to {command} after {attempts} attempt(s), only unparseable data (wrong baud rate or another device?): {sample}")]
    Garbage { port: String, command: String, attempts: u32, sample: String },
    #[error("serial port {port} hung up (device unplugged or emulator stopped)")]
    HungUp { port: String },
    #[error("LED controller on {port} rejected {command}: {code}{meaning}")]
    Nak { port: String, command: String, code: ErrorCode, meaning: &'static str },
    #[error("LED controller on {port} sent an unexpected reply to {command}: '{reply}' (expected {expected})")]
    UnexpectedReply { port: String, command: String, reply: String, expected: String },
    #[error("device on {port} is not a compatible LED controller: {found} (expected name=rollcam-led proto={PROTOCOL_VERSION})")]
    Incompatible { port: String, found: String },
    #[error("invalid configuration for channel {channel} on {port}: {source}")]
    Config {
        port: String,
        channel: u8,
        #[source]
        source: ChannelConfigError,
    },
}

fn nak_meaning(code: ErrorCode) -> &'static str {
    match code {
        ErrorCode::Range => " (argument outside the device limits)",
        ErrorCode::State => " (not allowed in the current state: STOP first, or configure a channel before ARM, or ARM before TRIG)",
        ErrorCode::Unknown => " (command unknown to this firmware)",
        ErrorCode::Args => " (wrong arguments)",
        _ => " (line damaged in transit)",
    }
}

/// A serial port found by [`available_ports`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PortInfo {
    pub path: String,
    /// "usb VID:PID manufacturer product", "pci", "bluetooth" or "unknown".
    pub description: String,
    /// USB ports whose VID matches boards commonly used for the controller
    /// (Arduino, CH340, FTDI, CP210x).
    pub likely_controller: bool,
}

/// Lists serial ports on this machine.
pub fn available_ports() -> Result<Vec<PortInfo>, serialport::Error> {
    let ports = serialport::available_ports()?;
    Ok(ports
        .into_iter()
        .map(|p| {
            let (description, likely) = match &p.port_type {
                serialport::SerialPortType::UsbPort(u) => (
                    format!("usb {:04x}:{:04x} {} {}", u.vid, u.pid, u.manufacturer.as_deref().unwrap_or(""), u.product.as_deref().unwrap_or(""))
                        .trim_end()
                        .to_string(),
                    matches!(u.vid, 0x2341 | 0x2a03 | 0x1a86 | 0x0403 | 0x10c4),
                ),
                serialport::SerialPortType::PciPort => ("pci".into(), false),
                serialport::SerialPortType::BluetoothPort => ("bluetooth".into(), false),
                serialport::SerialPortType::Unknown => ("unknown".into(), false),
            };
            PortInfo { path: p.port_name, description, likely_controller: likely }
        })
        .collect())
}

/// Summary of the LED synchronisation for the capture metadata.
///
/// t = 0 is the trigger instant: the trigger-input edge (e.g. the camera's
/// exposure-active output, so t = 0 is the start of the first row's exposure
/// up to the camera's own output latency) or the `TRIG` command. Channel `c`
/// then rises first at `phase_us` and repeats every `period_us`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LedSync {
    pub port: String,
    pub device: DeviceInfo,
    /// Trigger source used for this capture.
    pub trigger: TriggerMode,
    /// Enabled channels with their waveform.
    pub channels: Vec<ChannelSync>,
}

/// One enabled channel inside [`LedSync`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ChannelSync {
    pub channel: u8,
    #[serde(flatten)]
    pub config: ChannelConfig,
}

/// Host side of the protocol.
pub struct LedController {
    port: Box<dyn SerialPort>,
    name: String,
    opts: LinkOptions,
    seq: u16,
    assembler: LineAssembler,
    #[cfg(unix)]
    exclusive_fd: Option<std::os::unix::io::RawFd>,
}

fn initial_seq() -> u16 {
    // Varies between processes so that a command repeated by a new process is
    // not mistaken for a retransmission of the previous process's last command.
    let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.subsec_nanos() as u64 ^ d.as_secs()).unwrap_or(0);
    let mixed = nanos ^ (std::process::id() as u64).wrapping_mul(2_654_435_761);
    1 + (mixed % MAX_SEQ as u64) as u16
}

fn map_open_error(port: &str, e: serialport::Error) -> LedError {
    match e.kind() {
        serialport::ErrorKind::Io(io::ErrorKind::NotFound) => LedError::PortNotFound { port: port.into(), hint: port_hint() },
        serialport::ErrorKind::Io(io::ErrorKind::PermissionDenied) => LedError::PermissionDenied { port: port.into() },
        serialport::ErrorKind::NoDevice => LedError::PortBusy { port: port.into() },
        _ => LedError::Open { port: port.into(), source: e },
    }
}

fn port_hint() -> String {
    match available_ports() {
        Ok(p) if p.is_empty() => " (no serial ports found on this machine)".into(),
        Ok(p) => format!(" (available: {})", p.iter().map(|p| p.path.as_str()).collect::<Vec<_>>().join(", ")),
        Err(_) => String::new(),
    }
}

fn is_hangup(e: &io::Error) -> bool {
    e.kind() == io::ErrorKind::BrokenPipe || e.raw_os_error() == Some(5 /* EIO */)
}

impl LedController {
    /// Opens the controller at `path` (e.g. `/dev/ttyACM0`, or an emulator link).
    pub fn open(path: &str, baud: u32) -> Result<LedController, LedError> {
        Self::open_with(path, LinkOptions { baud, ..LinkOptions::default() })
    }

    pub fn open_with(path: &str, opts: LinkOptions) -> Result<LedController, LedError> {
        if std::fs::metadata(Path::new(path)).is_err() && std::fs::symlink_metadata(path).is_err() {
            return Err(LedError::PortNotFound { port: path.into(), hint: port_hint() });
        }
        let builder = serialport::new(path, opts.baud).timeout(Duration::from_millis(50));
        #[cfg(unix)]
        {
            use std::os::unix::io::AsRawFd;
            let native = builder.open_native().map_err(|e| map_open_error(path, e))?;
            let fd = native.as_raw_fd();
            let mut c = Self::from_port(Box::new(native), path, opts);
            c.exclusive_fd = Some(fd);
            c.discard_input();
            c.wait_ready(opts.ready_timeout)?;
            Ok(c)
        }
        #[cfg(not(unix))]
        {
            let port = builder.open().map_err(|e| map_open_error(path, e))?;
            let mut c = Self::from_port(port, path, opts);
            c.discard_input();
            c.wait_ready(opts.ready_timeout)?;
            Ok(c)
        }
    }

    /// Wraps an already open port (e.g. one end of `TTYPort::pair()`).
    pub fn from_port(port: Box<dyn SerialPort>, name: impl Into<String>, opts: LinkOptions) -> LedController {
        LedController {
            port,
            name: name.into(),
            opts,
            seq: initial_seq(),
            assembler: LineAssembler::new(),
            #[cfg(unix)]
            exclusive_fd: None,
        }
    }

    /// Sends `ID` until the device answers or `timeout` passes (zero: no check).
    /// Returns the last error if it never answers; an incompatible device is
    /// reported at once.
    pub fn wait_ready(&mut self, timeout: Duration) -> Result<Option<DeviceInfo>, LedError> {
        if timeout.is_zero() {
            return Ok(None);
        }
        let saved = self.opts;
        self.opts.reply_timeout = saved.reply_timeout.min(Duration::from_millis(250));
        self.opts.retries = 0;
        let deadline = Instant::now() + timeout;
        let result = loop {
            match self.identify() {
                Ok(info) => break Ok(Some(info)),
                Err(e @ (LedError::Silent { .. } | LedError::Garbage { .. })) => {
                    if Instant::now() >= deadline {
                        break Err(e);
                    }
                    tracing::debug!(port = %self.name, "waiting for the device to boot: {e}");
                }
                Err(e) => break Err(e),
            }
        };
        self.opts = saved;
        result
    }

    fn discard_input(&mut self) {
        // Boards that reset on open (Arduino) may print boot noise; stale emulator replies too.
        let _ = self.port.clear(serialport::ClearBuffer::Input);
    }

    pub fn port_name(&self) -> &str {
        &self.name
    }

    fn next_seq(&mut self) -> u16 {
        self.seq = if self.seq == MAX_SEQ { 1 } else { self.seq + 1 };
        self.seq
    }

    fn io_err(&self, e: io::Error) -> LedError {
        if is_hangup(&e) {
            LedError::HungUp { port: self.name.clone() }
        } else {
            LedError::Io { port: self.name.clone(), source: e }
        }
    }

    /// Sends one command and returns the ACK payload. Retransmits (same
    /// sequence number) on timeout or on a framing NAK.
    pub fn transact(&mut self, cmd: &Command) -> Result<String, LedError> {
        let body = cmd.to_body();
        let seq = self.next_seq();
        let line = encode_frame(seq, &body);
        let attempts = 1 + self.opts.retries;
        let mut junk: Vec<u8> = Vec::new();
        self.assembler.reset();
        self.assembler.ignored.clear();
        let mut buf = [0u8; 256];
        for attempt in 1..=attempts {
            if attempt > 1 {
                tracing::warn!(port = %self.name, "retrying {body} (seq {seq}), attempt {attempt}/{attempts}");
            }
            tracing::trace!(port = %self.name, "-> {}", escape_bytes(line.as_bytes()));
            self.port.write_all(line.as_bytes()).map_err(|e| self.io_err(e))?;
            let deadline = Instant::now() + self.opts.reply_timeout;
            'wait: loop {
                let now = Instant::now();
                if now >= deadline {
                    break 'wait;
                }
                let slice = (deadline - now).min(Duration::from_millis(50)).max(Duration::from_millis(1));
                self.port.set_timeout(slice).map_err(|e| self.io_err(e.into()))?;
                let n = match self.port.read(&mut buf) {
                    Ok(0) => return Err(LedError::HungUp { port: self.name.clone() }),
                    Ok(n) => n,
                    Err(e) if e.kind() == io::ErrorKind::TimedOut || e.kind() == io::ErrorKind::Interrupted => continue,
                    Err(e) => return Err(self.io_err(e)),
                };
                for ev in self.assembler.push(&buf[..n]) {
                    let raw = match ev {
                        LineEvent::Line(l) => l,
                        LineEvent::Oversize => {
                            junk.extend_from_slice(b"<oversize line>");
                            continue;
                        }
                    };
                    tracing::trace!(port = %self.name, "<- {}", escape_bytes(&raw));
                    let frame = match decode_frame(&raw) {
                        Ok(f) => f,
                        Err(e) => {
                            tracing::debug!(port = %self.name, "ignoring bad line ({e}): {}", escape_bytes(&raw));
                            junk.extend_from_slice(&raw);
                            continue;
                        }
                    };
                    let reply = Reply::parse(&frame.body);
                    if frame.seq == 0 {
                        if let Some(Reply::Nak(code)) = reply {
                            if code.is_transmission_error() {
                                tracing::warn!(port = %self.name, "device reports {code} for a line; resending {body}");
                                break 'wait;
                            }
                        }
                        junk.extend_from_slice(&raw);
                        continue;
                    }
                    if frame.seq != seq {
                        tracing::debug!(port = %self.name, "ignoring stale reply seq {} (waiting for {seq})", frame.seq);
                        continue;
                    }
                    return match reply {
                        Some(Reply::Ack(payload)) => Ok(payload),
                        Some(Reply::Nak(code)) => Err(LedError::Nak { port: self.name.clone(), command: body, code, meaning: nak_meaning(code) }),
                        None => Err(LedError::UnexpectedReply { port: self.name.clone(), command: body, reply: frame.body, expected: "ACK or NAK".into() }),
                    };
                }
            }
        }
        junk.extend_from_slice(&self.assembler.ignored);
        if junk.is_empty() {
            Err(LedError::Silent { port: self.name.clone(), command: body, attempts, timeout_ms: self.opts.reply_timeout.as_millis() as u64 })
        } else {
            junk.truncate(80);
            Err(LedError::Garbage { port: self.name.clone(), command: body, attempts, sample: escape_bytes(&junk) })
        }
    }

    fn unexpected(&self, cmd: &str, reply: &str, why: String) -> LedError {
        LedError::UnexpectedReply { port: self.name.clone(), command: cmd.into(), reply: reply.into(), expected: why }
    }

    /// `ID`: checks that this is a compatible controller.
    pub fn identify(&mut self) -> Result<DeviceInfo, LedError> {
        let p = self.transact(&Command::Identify)?;
        let info = DeviceInfo::from_payload(&p).map_err(|e| self.unexpected("ID", &p, e))?;
        if info.name != "rollcam-led" || info.protocol != PROTOCOL_VERSION {
            return Err(LedError::Incompatible { port: self.name.clone(), found: p });
        }
        Ok(info)
    }

    fn check_channel(&self, channel: u8) -> Result<(), LedError> {
        if channel >= CHANNELS {
            return Err(LedError::Config { port: self.name.clone(), channel, source: ChannelConfigError::Channel(channel) });
        }
        Ok(())
    }

    /// `CFG`: sets and enables one channel (validated here first).
    pub fn configure(&mut self, channel: u8, config: ChannelConfig) -> Result<(), LedError> {
        self.check_channel(channel)?;
        config.validate().map_err(|source| LedError::Config { port: self.name.clone(), channel, source })?;
        self.configure_unchecked(channel, config)
    }

    /// `CFG` without host-side validation (to exercise the device's own checks).
    pub fn configure_unchecked(&mut self, channel: u8, config: ChannelConfig) -> Result<(), LedError> {
        self.transact(&Command::Configure { channel, config }).map(|_| ())
    }

    /// `OFF`: disables one channel.
    pub fn disable(&mut self, channel: u8) -> Result<(), LedError> {
        self.check_channel(channel)?;
        self.transact(&Command::Off { channel }).map(|_| ())
    }

    /// `GET`: reads one channel's configuration back.
    pub fn channel(&mut self, channel: u8) -> Result<ChannelReadback, LedError> {
        self.check_channel(channel)?;
        let p = self.transact(&Command::Get { channel })?;
        let r = ChannelReadback::from_payload(&p).map_err(|e| self.unexpected("GET", &p, e))?;
        if r.channel != channel {
            return Err(self.unexpected("GET", &p, format!("ch={channel}")));
        }
        Ok(r)
    }

    /// `ARM`: waits for `mode` (software `TRIG` or an input edge).
    pub fn arm(&mut self, mode: TriggerMode) -> Result<(), LedError> {
        self.transact(&Command::Arm(mode)).map(|_| ())
    }

    /// `TRIG`: starts an armed controller now.
    pub fn trigger(&mut self) -> Result<(), LedError> {
        self.transact(&Command::Trigger).map(|_| ())
    }

    /// `STOP`: outputs low, back to idle (configuration kept).
    pub fn stop(&mut self) -> Result<(), LedError> {
        self.transact(&Command::Stop).map(|_| ())
    }

    /// `STAT`.
    pub fn status(&mut self) -> Result<DeviceStatus, LedError> {
        let p = self.transact(&Command::Status)?;
        DeviceStatus::from_payload(&p).map_err(|e| self.unexpected("STAT", &p, e))
    }

    /// Identity plus every enabled channel, for the capture metadata.
    pub fn sync_summary(&mut self, trigger: TriggerMode) -> Result<LedSync, LedError> {
        let device = self.identify()?;
        let mut channels = Vec::new();
        for c in 0..CHANNELS.min(device.channels) {
            let r = self.channel(c)?;
            if r.enabled {
                channels.push(ChannelSync { channel: c, config: r.config });
            }
        }
        Ok(LedSync { port: self.name.clone(), device, trigger, channels })
    }
}

impl Drop for LedController {
    fn drop(&mut self) {
        // Release TIOCEXCL so the next program (or the next `rollcam led`
        // invocation) can open the port; the emulator keeps the PTY open, so the
        // flag would otherwise outlive this process.
        #[cfg(unix)]
        if let Some(fd) = self.exclusive_fd {
            // SAFETY: fd belongs to self.port, which is still open here.
            unsafe {
                libc::ioctl(fd, libc::TIOCNXCL);
            }
        }
    }
}
