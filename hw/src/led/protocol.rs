//! Wire protocol of the LED pulse controller (pure: no I/O).
//!
//! See `hw/firmware/PROTOCOL.md` for the normative description. Every line is
//!
//! ```text
//! $<seq> <body>*<HH>\n
//! ```
//!
//! where `<HH>` is the CRC-8 (polynomial 0x07, init 0x00, no reflection, no
//! final XOR: "CRC-8/SMBUS") of the bytes strictly between `$` and `*`, written
//! as two hexadecimal digits. The constants here mirror
//! `hw/firmware/protocol.h`; a test checks that both agree.

use std::collections::BTreeMap;
use std::fmt;

use serde::{Deserialize, Serialize};

/// Protocol version reported by `ID` (`proto=`).
pub const PROTOCOL_VERSION: u32 = 1;
/// Longest line in either direction, including `$` and the final `\n`.
pub const MAX_LINE: usize = 120;
/// Number of output channels of the controller.
pub const CHANNELS: u8 = 4;
/// Shortest period accepted by `CFG`.
pub const MIN_PERIOD_US: u32 = 100;
/// Longest period accepted by `CFG`.
pub const MAX_PERIOD_US: u32 = 10_000_000;
/// Shortest high time and shortest low time within one period.
pub const MIN_WIDTH_US: u32 = 10;
/// Largest delay between the trigger and the first rising edge.
pub const MAX_PHASE_US: u32 = 10_000_000;
/// Largest finite pulse count (`0` means continuous).
pub const MAX_COUNT: u32 = 1_000_000;
/// Largest sequence number a host may use; `0` is reserved for the device.
pub const MAX_SEQ: u16 = 65_535;

/// CRC-8/SMBUS: polynomial 0x07, init 0x00, MSB first, no final XOR.
/// Check value: `crc8(b"123456789") == 0xF4`.
pub fn crc8(bytes: &[u8]) -> u8 {
    let mut crc: u8 = 0;
    for &b in bytes {
        crc ^= b;
        for _ in 0..8 {
            crc = if crc & 0x80 != 0 { (crc << 1) ^ 0x07 } else { crc << 1 };
        }
    }
    crc
}

/// Builds a complete line `$<seq> <body>*HH\n`.
pub fn encode_frame(seq: u16, body: &str) -> String {
    let inner = format!("{seq} {body}");
    format!("${inner}*{:02X}\n", crc8(inner.as_bytes()))
}

/// A decoded, checksum-verified line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WireFrame {
    /// Sequence number (0 = device message not tied to a request).
    pub seq: u16,
    /// Text between the sequence number and `*`.
    pub body: String,
    /// The CRC carried by the line.
    pub crc: u8,
}

/// Why a line could not be decoded. None of these is ever acted upon.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    #[error("checksum mismatch: line carries {carried:02X}, content gives {computed:02X}")]
    Crc { carried: u8, computed: u8 },
    #[error("malformed line: {0}")]
    Malformed(&'static str),
    #[error("line longer than {MAX_LINE} bytes")]
    Oversize,
}

/// Decodes one line (with or without the trailing `\n` / `\r\n`).
pub fn decode_frame(line: &[u8]) -> Result<WireFrame, FrameError> {
    let mut line = line;
    if line.len() > MAX_LINE {
        return Err(FrameError::Oversize);
    }
    while let Some((&last, rest)) = line.split_last() {
        if last == b'\n' || last == b'\r' {
            line = rest;
        } else {
            break;
        }
    }
    let Some(rest) = line.strip_prefix(b"$") else {
        return Err(FrameError::Malformed("does not start with '$'"));
    };
    if rest.iter().any(|&b| !(0x20..0x7f).contains(&b)) {
        return Err(FrameError::Malformed("non-printable byte"));
    }
    let star = rest.iter().rposition(|&b| b == b'*').ok_or(FrameError::Malformed("no '*' before the checksum"))?;
    let (inner, tail) = (&rest[..star], &rest[star + 1..]);
    if tail.len() != 2 {
        return Err(FrameError::Malformed("checksum is not two hex digits"));
    }
    if !tail.iter().all(|b| b.is_ascii_hexdigit()) {
        return Err(FrameError::Malformed("checksum is not two hex digits"));
    }
    let carried = u8::from_str_radix(std::str::from_utf8(tail).expect("hex digits"), 16).expect("two hex digits fit in u8");
    let computed = crc8(inner);
    if carried != computed {
        return Err(FrameError::Crc { carried, computed });
    }
    // inner is printable ASCII, hence valid UTF-8.
    let inner = std::str::from_utf8(inner).expect("printable ASCII");
    let (seq_txt, body) = match inner.split_once(' ') {
        Some((s, b)) => (s, b.trim_start_matches(' ')),
        None => (inner, ""),
    };
    let seq = parse_decimal(seq_txt).filter(|&v| v <= MAX_SEQ as u32).ok_or(FrameError::Malformed("bad sequence number"))? as u16;
    if body.is_empty() {
        return Err(FrameError::Malformed("empty body"));
    }
    Ok(WireFrame { seq, body: body.to_string(), crc: carried })
}

/// Strict unsigned decimal (1..=10 digits, no sign), `None` if not a number or > u32::MAX.
pub fn parse_decimal(s: &str) -> Option<u32> {
    if s.is_empty() || s.len() > 10 || !s.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    s.parse::<u64>().ok().filter(|&v| v <= u32::MAX as u64).map(|v| v as u32)
}

/// Error codes carried by `NAK`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum ErrorCode {
    /// Checksum mismatch (reply sequence number is 0).
    Crc = 1,
    /// Malformed frame (reply sequence number is 0).
    Frame = 2,
    /// Line longer than [`MAX_LINE`] (reply sequence number is 0).
    Oversize = 3,
    /// Unknown command word.
    Unknown = 4,
    /// Wrong number of arguments or a non-numeric argument.
    Args = 5,
    /// Argument outside the device limits.
    Range = 6,
    /// Command not allowed in the current state.
    State = 7,
}

impl ErrorCode {
    pub const ALL: [ErrorCode; 7] =
        [ErrorCode::Crc, ErrorCode::Frame, ErrorCode::Oversize, ErrorCode::Unknown, ErrorCode::Args, ErrorCode::Range, ErrorCode::State];
    pub fn code(self) -> u8 {
        self as u8
    }
    pub fn name(self) -> &'static str {
        match self {
            ErrorCode::Crc => "CRC",
            ErrorCode::Frame => "FRAME",
            ErrorCode::Oversize => "OVERSIZE",
            ErrorCode::Unknown => "UNKNOWN",
            ErrorCode::Args => "ARGS",
            ErrorCode::Range => "RANGE",
            ErrorCode::State => "STATE",
        }
    }
    pub fn from_code(code: u32) -> Option<ErrorCode> {
        ErrorCode::ALL.into_iter().find(|c| c.code() as u32 == code)
    }
    /// Framing errors mean the device never saw the command: resending is safe and useful.
    pub fn is_transmission_error(self) -> bool {
        matches!(self, ErrorCode::Crc | ErrorCode::Frame | ErrorCode::Oversize)
    }
}

impl fmt::Display for ErrorCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} ({})", self.name(), self.code())
    }
}

/// What starts the waveform once armed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TriggerMode {
    /// Waits for a `TRIG` command.
    Software,
    /// Waits for a rising edge on the trigger input (INT0 / D2).
    Rising,
    /// Waits for a falling edge on the trigger input.
    Falling,
}

impl TriggerMode {
    pub fn token(self) -> &'static str {
        match self {
            TriggerMode::Software => "SW",
            TriggerMode::Rising => "RISE",
            TriggerMode::Falling => "FALL",
        }
    }
    pub fn from_token(s: &str) -> Option<TriggerMode> {
        match s {
            "SW" => Some(TriggerMode::Software),
            "RISE" => Some(TriggerMode::Rising),
            "FALL" => Some(TriggerMode::Falling),
            _ => None,
        }
    }
}

/// Waveform of one channel, relative to the trigger instant (t = 0).
///
/// Channel output is low until `phase_us`; then each period starts with
/// `width_us` high followed by `period_us - width_us` low. `pulse_count`
/// `None` runs until `STOP`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ChannelConfig {
    pub period_us: u32,
    pub width_us: u32,
    pub phase_us: u32,
    /// `None` = continuous; `Some(n)` = exactly n pulses.
    pub pulse_count: Option<u32>,
}

/// Why a [`ChannelConfig`] is outside the device limits.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ChannelConfigError {
    #[error("period_us {0} outside {MIN_PERIOD_US}..={MAX_PERIOD_US}")]
    Period(u32),
    #[error("width_us {width_us} must leave at least {MIN_WIDTH_US} us high and low within period_us {period_us}")]
    Width { width_us: u32, period_us: u32 },
    #[error("duty {0} must be within (0, 1)")]
    Duty(f64),
    #[error("phase_us {0} exceeds {MAX_PHASE_US}")]
    Phase(u32),
    #[error("pulse_count {0} outside 1..={MAX_COUNT} (use continuous instead of 0)")]
    Count(u32),
    #[error("channel {0} does not exist (the controller has {CHANNELS})")]
    Channel(u8),
}

impl ChannelConfig {
    /// Square wave (50 % duty), continuous, no phase offset.
    pub fn square(period_us: u32) -> ChannelConfig {
        ChannelConfig { period_us, width_us: period_us / 2, phase_us: 0, pulse_count: None }
    }

    /// Continuous wave with the given duty (0 < duty < 1), width rounded to 1 us.
    pub fn with_duty(period_us: u32, duty: f64) -> Result<ChannelConfig, ChannelConfigError> {
        if !(duty > 0.0 && duty < 1.0) {
            return Err(ChannelConfigError::Duty(duty));
        }
        let cfg = ChannelConfig { period_us, width_us: (period_us as f64 * duty).round() as u32, phase_us: 0, pulse_count: None };
        cfg.validate()?;
        Ok(cfg)
    }

    pub fn phase(mut self, phase_us: u32) -> Self {
        self.phase_us = phase_us;
        self
    }

    pub fn count(mut self, pulse_count: Option<u32>) -> Self {
        self.pulse_count = pulse_count;
        self
    }

    /// Duty cycle (high fraction of a period).
    pub fn duty(&self) -> f64 {
        self.width_us as f64 / self.period_us as f64
    }

    /// Checks the same limits the device checks (a NAK RANGE otherwise).
    pub fn validate(&self) -> Result<(), ChannelConfigError> {
        if !(MIN_PERIOD_US..=MAX_PERIOD_US).contains(&self.period_us) {
            return Err(ChannelConfigError::Period(self.period_us));
        }
        if self.width_us < MIN_WIDTH_US || self.period_us - self.width_us.min(self.period_us) < MIN_WIDTH_US {
            return Err(ChannelConfigError::Width { width_us: self.width_us, period_us: self.period_us });
        }
        if self.phase_us > MAX_PHASE_US {
            return Err(ChannelConfigError::Phase(self.phase_us));
        }
        if let Some(n) = self.pulse_count {
            if n == 0 || n > MAX_COUNT {
                return Err(ChannelConfigError::Count(n));
            }
        }
        Ok(())
    }

    /// Output level at `t_us` after the trigger (ignoring STOP).
    pub fn level_at(&self, t_us: u64) -> bool {
        let phase = self.phase_us as u64;
        if t_us < phase {
            return false;
        }
        let since = t_us - phase;
        let k = since / self.period_us as u64;
        if let Some(n) = self.pulse_count {
            if k >= n as u64 {
                return false;
            }
        }
        since % (self.period_us as u64) < self.width_us as u64
    }

    /// Instant (after the trigger) at which the last pulse ends; `None` if continuous.
    pub fn end_us(&self) -> Option<u64> {
        self.pulse_count.map(|n| self.phase_us as u64 + (n as u64 - 1) * self.period_us as u64 + self.width_us as u64)
    }
}

/// A request from host to device.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Command {
    Identify,
    Configure { channel: u8, config: ChannelConfig },
    Off { channel: u8 },
    Get { channel: u8 },
    Arm(TriggerMode),
    Trigger,
    Stop,
    Status,
}

impl Command {
    /// The command word, for logs and error messages.
    pub fn word(&self) -> &'static str {
        match self {
            Command::Identify => "ID",
            Command::Configure { .. } => "CFG",
            Command::Off { .. } => "OFF",
            Command::Get { .. } => "GET",
            Command::Arm(_) => "ARM",
            Command::Trigger => "TRIG",
            Command::Stop => "STOP",
            Command::Status => "STAT",
        }
    }

    /// Body text as sent on the wire.
    pub fn to_body(&self) -> String {
        match self {
            Command::Configure { channel, config } => {
                format!("CFG {channel} {} {} {} {}", config.period_us, config.width_us, config.phase_us, config.pulse_count.unwrap_or(0))
            }
            Command::Off { channel } => format!("OFF {channel}"),
            Command::Get { channel } => format!("GET {channel}"),
            Command::Arm(mode) => format!("ARM {}", mode.token()),
            other => other.word().to_string(),
        }
    }

    /// Parses a body as the device does. Errors are the NAK codes the device sends.
    pub fn parse(body: &str) -> Result<Command, ErrorCode> {
        let mut words = body.split(' ').filter(|w| !w.is_empty());
        let word = words.next().ok_or(ErrorCode::Frame)?;
        let args: Vec<&str> = words.collect();
        let want = |n: usize| {
            if args.len() == n {
                Ok(())
            } else {
                Err(ErrorCode::Args)
            }
        };
        let num = |i: usize| -> Result<u32, ErrorCode> {
            let s = args[i];
            if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
                return Err(ErrorCode::Args);
            }
            parse_decimal(s).ok_or(ErrorCode::Range)
        };
        let chan = |i: usize| -> Result<u8, ErrorCode> {
            let c = num(i)?;
            if c >= CHANNELS as u32 {
                Err(ErrorCode::Range)
            } else {
                Ok(c as u8)
            }
        };
        match word {
            "ID" => want(0).map(|_| Command::Identify),
            "TRIG" => want(0).map(|_| Command::Trigger),
            "STOP" => want(0).map(|_| Command::Stop),
            "STAT" => want(0).map(|_| Command::Status),
            "OFF" => {
                want(1)?;
                Ok(Command::Off { channel: chan(0)? })
            }
            "GET" => {
                want(1)?;
                Ok(Command::Get { channel: chan(0)? })
            }
            "ARM" => {
                want(1)?;
                TriggerMode::from_token(args[0]).map(Command::Arm).ok_or(ErrorCode::Args)
            }
            "CFG" => {
                want(5)?;
                // Numeric syntax of every argument first, then ranges.
                let vals = (0..5).map(num).collect::<Result<Vec<u32>, _>>()?;
                if vals[0] >= CHANNELS as u32 {
                    return Err(ErrorCode::Range);
                }
                let count = vals[4];
                let config =
                    ChannelConfig { period_us: vals[1], width_us: vals[2], phase_us: vals[3], pulse_count: if count == 0 { None } else { Some(count) } };
                config.validate().map_err(|_| ErrorCode::Range)?;
                Ok(Command::Configure { channel: vals[0] as u8, config })
            }
            _ => Err(ErrorCode::Unknown),
        }
    }
}

/// A reply from device to host.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reply {
    /// `ACK` followed by an optional `key=value` payload.
    Ack(String),
    /// `NAK <code> <NAME>`.
    Nak(ErrorCode),
}

impl Reply {
    pub fn to_body(&self) -> String {
        match self {
            Reply::Ack(p) if p.is_empty() => "ACK".to_string(),
            Reply::Ack(p) => format!("ACK {p}"),
            Reply::Nak(c) => format!("NAK {} {}", c.code(), c.name()),
        }
    }

    pub fn parse(body: &str) -> Option<Reply> {
        if body == "ACK" {
            return Some(Reply::Ack(String::new()));
        }
        if let Some(p) = body.strip_prefix("ACK ") {
            return Some(Reply::Ack(p.to_string()));
        }
        let rest = body.strip_prefix("NAK ")?;
        let mut it = rest.split(' ');
        let code = ErrorCode::from_code(parse_decimal(it.next()?)?)?;
        Some(Reply::Nak(code))
    }
}

/// Parses a `key=value key=value` payload.
pub fn parse_kv(payload: &str) -> Result<BTreeMap<String, String>, String> {
    let mut map = BTreeMap::new();
    for item in payload.split(' ').filter(|w| !w.is_empty()) {
        let (k, v) = item.split_once('=').ok_or_else(|| format!("item '{item}' is not key=value"))?;
        map.insert(k.to_string(), v.to_string());
    }
    Ok(map)
}

fn kv_get<'a>(map: &'a BTreeMap<String, String>, key: &str) -> Result<&'a str, String> {
    map.get(key).map(|s| s.as_str()).ok_or_else(|| format!("missing '{key}='"))
}

fn kv_num(map: &BTreeMap<String, String>, key: &str) -> Result<u32, String> {
    let v = kv_get(map, key)?;
    parse_decimal(v).ok_or_else(|| format!("'{key}={v}' is not a number"))
}

/// What `ID` reports.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct DeviceInfo {
    pub name: String,
    pub protocol: u32,
    pub firmware: String,
    pub hardware: String,
    pub channels: u8,
    /// Hardware timer tick, nanoseconds (timing resolution).
    pub tick_ns: u32,
}

impl DeviceInfo {
    pub fn to_payload(&self) -> String {
        format!("name={} proto={} fw={} hw={} ch={} tick_ns={}", self.name, self.protocol, self.firmware, self.hardware, self.channels, self.tick_ns)
    }
    pub fn from_payload(p: &str) -> Result<DeviceInfo, String> {
        let m = parse_kv(p)?;
        Ok(DeviceInfo {
            name: kv_get(&m, "name")?.to_string(),
            protocol: kv_num(&m, "proto")?,
            firmware: kv_get(&m, "fw")?.to_string(),
            hardware: kv_get(&m, "hw")?.to_string(),
            channels: kv_num(&m, "ch")?.min(255) as u8,
            tick_ns: kv_num(&m, "tick_ns")?,
        })
    }
}

/// Device run state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RunState {
    /// Outputs low, configuration may change.
    Idle,
    /// Waiting for the trigger.
    Armed,
    /// Triggered, at least one channel still producing pulses.
    Running,
    /// Triggered, every channel has sent its pulse count.
    Done,
}

impl RunState {
    pub fn token(self) -> &'static str {
        match self {
            RunState::Idle => "IDLE",
            RunState::Armed => "ARMED",
            RunState::Running => "RUNNING",
            RunState::Done => "DONE",
        }
    }
    pub fn from_token(s: &str) -> Option<RunState> {
        [RunState::Idle, RunState::Armed, RunState::Running, RunState::Done].into_iter().find(|r| r.token() == s)
    }
}

/// What `STAT` reports.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct DeviceStatus {
    pub state: RunState,
    /// Trigger source while armed/running; `None` when idle.
    pub trigger: Option<TriggerMode>,
    /// Enabled flag per channel.
    pub enabled: Vec<bool>,
    /// Microseconds since the trigger (0 before any trigger).
    pub t_us: u32,
}

impl DeviceStatus {
    pub fn to_payload(&self) -> String {
        let en: String = self.enabled.iter().map(|&e| if e { '1' } else { '0' }).collect();
        format!("state={} arm={} en={} t_us={}", self.state.token(), self.trigger.map(|t| t.token()).unwrap_or("-"), en, self.t_us)
    }
    pub fn from_payload(p: &str) -> Result<DeviceStatus, String> {
        let m = parse_kv(p)?;
        let state = kv_get(&m, "state")?;
        let arm = kv_get(&m, "arm")?;
        let en = kv_get(&m, "en")?;
        if !en.bytes().all(|b| b == b'0' || b == b'1') {
            return Err(format!("'en={en}' is not a bit string"));
        }
        Ok(DeviceStatus {
            state: RunState::from_token(state).ok_or_else(|| format!("unknown state '{state}'"))?,
            trigger: if arm == "-" { None } else { Some(TriggerMode::from_token(arm).ok_or_else(|| format!("unknown arm mode '{arm}'"))?) },
            enabled: en.bytes().map(|b| b == b'1').collect(),
            t_us: kv_num(&m, "t_us")?,
        })
    }
}

/// What `GET <ch>` reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ChannelReadback {
    pub channel: u8,
    pub enabled: bool,
    pub config: ChannelConfig,
}

impl ChannelReadback {
    pub fn to_payload(&self) -> String {
        format!(
            "ch={} en={} period_us={} width_us={} phase_us={} count={}",
            self.channel,
            self.enabled as u8,
            self.config.period_us,
            self.config.width_us,
            self.config.phase_us,
            self.config.pulse_count.unwrap_or(0)
        )
    }
    pub fn from_payload(p: &str) -> Result<ChannelReadback, String> {
        let m = parse_kv(p)?;
        let count = kv_num(&m, "count")?;
        Ok(ChannelReadback {
            channel: kv_num(&m, "ch")?.min(255) as u8,
            enabled: kv_num(&m, "en")? != 0,
            config: ChannelConfig {
                period_us: kv_num(&m, "period_us")?,
                width_us: kv_num(&m, "width_us")?,
                phase_us: kv_num(&m, "phase_us")?,
                pulse_count: if count == 0 { None } else { Some(count) },
            },
        })
    }
}

/// Output of [`LineAssembler::push`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LineEvent {
    /// A complete line starting with `$`, without the trailing `\n`.
    Line(Vec<u8>),
    /// A line exceeded [`MAX_LINE`]; its bytes were discarded up to the next `\n`.
    Oversize,
}

/// Splits a byte stream into lines, the same way the firmware does:
/// bytes before `$` are ignored; a `$` restarts the line (a half line is
/// dropped silently); `\n` ends it; a line longer than [`MAX_LINE`] is
/// discarded up to the next `\n` and reported once.
#[derive(Debug, Default, Clone)]
pub struct LineAssembler {
    buf: Vec<u8>,
    in_line: bool,
    overflow: bool,
    /// Bytes ignored outside of any line (garbage), for diagnostics.
    pub ignored: Vec<u8>,
}

impl LineAssembler {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn push(&mut self, bytes: &[u8]) -> Vec<LineEvent> {
        let mut out = Vec::new();
        for &b in bytes {
            if b == b'$' {
                if self.in_line && !self.overflow && !self.buf.is_empty() {
                    self.ignored.extend_from_slice(&self.buf);
                }
                self.buf.clear();
                self.buf.push(b);
                self.in_line = true;
                self.overflow = false;
            } else if b == b'\n' {
                if self.overflow {
                    out.push(LineEvent::Oversize);
                } else if self.in_line {
                    out.push(LineEvent::Line(std::mem::take(&mut self.buf)));
                }
                self.buf.clear();
                self.in_line = false;
                self.overflow = false;
            } else if self.in_line {
                if self.overflow {
                    continue;
                }
                // `\n` counts towards MAX_LINE, so content may be MAX_LINE - 1 bytes.
                if self.buf.len() + 1 >= MAX_LINE {
                    self.overflow = true;
                    self.buf.clear();
                } else {
                    self.buf.push(b);
                }
            } else {
                self.ignored.push(b);
            }
        }
        if self.ignored.len() > 4096 {
            let cut = self.ignored.len() - 4096;
            self.ignored.drain(..cut);
        }
        out
    }

    /// Forgets any partial line.
    pub fn reset(&mut self) {
        self.buf.clear();
        self.in_line = false;
        self.overflow = false;
    }
}

/// Printable rendering of raw bytes for logs and errors (`\xNN` for the rest).
pub fn escape_bytes(bytes: &[u8]) -> String {
    let mut s = String::new();
    for &b in bytes {
        match b {
            b'\n' => s.push_str("\\n"),
            b'\r' => s.push_str("\\r"),
            b'\\' => s.push_str("\\\\"),
            0x20..=0x7e => s.push(b as char),
            _ => s.push_str(&format!("\\x{b:02X}")),
        }
    }
    s
}

/// Inverse of [`escape_bytes`] (also accepts `\t`); used by the test-vector file.
pub fn unescape_bytes(s: &str) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    let b = s.as_bytes();
    let mut i = 0;
    while i < b.len() {
        if b[i] != b'\\' {
            out.push(b[i]);
            i += 1;
            continue;
        }
        match b.get(i + 1) {
            Some(b'n') => out.push(b'\n'),
            Some(b'r') => out.push(b'\r'),
            Some(b't') => out.push(b'\t'),
            Some(b'\\') => out.push(b'\\'),
            Some(b'x') => {
                let hex = s.get(i + 2..i + 4).ok_or("truncated \\x escape")?;
                out.push(u8::from_str_radix(hex, 16).map_err(|_| format!("bad \\x{hex}"))?);
                i += 4;
                continue;
            }
            _ => return Err(format!("bad escape at byte {i} of '{s}'")),
        }
        i += 2;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc8_check_value() {
        assert_eq!(crc8(b"123456789"), 0xF4);
        assert_eq!(crc8(b""), 0x00);
    }

    #[test]
    fn crc8_detects_every_single_bit_flip_and_swap() {
        let line = b"42 CFG 0 1980 990 0 0";
        let good = crc8(line);
        for i in 0..line.len() {
            for bit in 0..8 {
                let mut m = line.to_vec();
                m[i] ^= 1 << bit;
                assert_ne!(crc8(&m), good, "flip byte {i} bit {bit}");
            }
            if i + 1 < line.len() && line[i] != line[i + 1] {
                let mut m = line.to_vec();
                m.swap(i, i + 1);
                assert_ne!(crc8(&m), good, "swap {i}");
            }
        }
    }

    #[test]
    fn frame_round_trip() {
        for (seq, body) in [(1u16, "ID"), (65535, "CFG 3 10000000 5000000 0 12"), (7, "ACK state=IDLE arm=- en=0000 t_us=0")] {
            let line = encode_frame(seq, body);
            assert!(line.ends_with('\n'));
            let f = decode_frame(line.as_bytes()).unwrap();
            assert_eq!(f.seq, seq);
            assert_eq!(f.body, body);
        }
        // CRLF tolerated, lower-case hex accepted.
        let line = encode_frame(3, "STAT").replace('\n', "\r\n").to_lowercase().replace("stat", "STAT");
        assert_eq!(decode_frame(line.as_bytes()).unwrap().body, "STAT");
    }

    #[test]
    fn frame_rejects_corruption() {
        let line = encode_frame(9, "CFG 0 1980 990 0 0");
        let bytes = line.as_bytes();
        for i in 1..bytes.len() - 1 {
            let mut m = bytes.to_vec();
            m[i] ^= 0x04;
            let r = decode_frame(&m);
            assert!(r.is_err(), "corrupted byte {i} accepted: {:?}", String::from_utf8_lossy(&m));
        }
        let mut m = bytes.to_vec();
        let n = m.len();
        m[n - 2] = if m[n - 2] == b'0' { b'1' } else { b'0' };
        assert!(matches!(decode_frame(&m), Err(FrameError::Crc { .. })));
    }

    #[test]
    fn frame_rejects_malformed() {
        for bad in [&b"ID*00"[..], b"$1 ID", b"$1 ID*0", b"$1 ID*ZZ", b"$1 I\x01D*00", b"$"] {
            assert!(matches!(decode_frame(bad), Err(FrameError::Malformed(_))), "{bad:?}");
        }
        // Sequence number out of range, with a valid CRC.
        let inner = "70000 ID";
        let line = format!("${inner}*{:02X}", crc8(inner.as_bytes()));
        assert_eq!(decode_frame(line.as_bytes()), Err(FrameError::Malformed("bad sequence number")));
        let long = format!("$1 {}*00", "A".repeat(MAX_LINE));
        assert_eq!(decode_frame(long.as_bytes()), Err(FrameError::Oversize));
    }

    #[test]
    fn command_round_trip() {
        let cmds = [
            Command::Identify,
            Command::Configure { channel: 2, config: ChannelConfig::square(1980).phase(330).count(Some(5)) },
            Command::Configure { channel: 0, config: ChannelConfig::with_duty(2640, 0.25).unwrap() },
            Command::Off { channel: 3 },
            Command::Get { channel: 1 },
            Command::Arm(TriggerMode::Software),
            Command::Arm(TriggerMode::Rising),
            Command::Arm(TriggerMode::Falling),
            Command::Trigger,
            Command::Stop,
            Command::Status,
        ];
        for c in cmds {
            assert_eq!(Command::parse(&c.to_body()), Ok(c.clone()), "{}", c.to_body());
        }
    }

    #[test]
    fn command_errors() {
        assert_eq!(Command::parse("FOO"), Err(ErrorCode::Unknown));
        assert_eq!(Command::parse("id"), Err(ErrorCode::Unknown));
        assert_eq!(Command::parse("ID 1"), Err(ErrorCode::Args));
        assert_eq!(Command::parse("CFG 0 1980 990 0"), Err(ErrorCode::Args));
        assert_eq!(Command::parse("CFG 0 1980 x 0 0"), Err(ErrorCode::Args));
        assert_eq!(Command::parse("CFG 0 -5 2 0 0"), Err(ErrorCode::Args));
        assert_eq!(Command::parse("CFG 4 1980 990 0 0"), Err(ErrorCode::Range));
        assert_eq!(Command::parse("CFG 0 99 40 0 0"), Err(ErrorCode::Range));
        assert_eq!(Command::parse("CFG 0 10000001 40 0 0"), Err(ErrorCode::Range));
        assert_eq!(Command::parse("CFG 0 1000 995 0 0"), Err(ErrorCode::Range));
        assert_eq!(Command::parse("CFG 0 1000 5 0 0"), Err(ErrorCode::Range));
        assert_eq!(Command::parse("CFG 0 1000 500 10000001 0"), Err(ErrorCode::Range));
        assert_eq!(Command::parse("CFG 0 1000 500 0 1000001"), Err(ErrorCode::Range));
        assert_eq!(Command::parse("CFG 0 1000 500 0 99999999999"), Err(ErrorCode::Range));
        assert_eq!(Command::parse("ARM NOW"), Err(ErrorCode::Args));
        assert_eq!(Command::parse("GET 9"), Err(ErrorCode::Range));
    }

    #[test]
    fn reply_and_payload_round_trips() {
        for r in [Reply::Ack(String::new()), Reply::Ack("a=1 b=2".into()), Reply::Nak(ErrorCode::Range)] {
            assert_eq!(Reply::parse(&r.to_body()), Some(r.clone()));
        }
        assert_eq!(Reply::parse("NAK 99 X"), None);
        assert_eq!(Reply::parse("HELLO"), None);
        let info = DeviceInfo { name: "rollcam-led".into(), protocol: 1, firmware: "0.1.0".into(), hardware: "uno".into(), channels: 4, tick_ns: 500 };
        assert_eq!(DeviceInfo::from_payload(&info.to_payload()), Ok(info));
        let st = DeviceStatus { state: RunState::Running, trigger: Some(TriggerMode::Rising), enabled: vec![true, false, false, true], t_us: 123_456 };
        assert_eq!(DeviceStatus::from_payload(&st.to_payload()), Ok(st));
        let rep = ChannelReadback { channel: 1, enabled: true, config: ChannelConfig::square(660).count(Some(3)) };
        assert_eq!(ChannelReadback::from_payload(&rep.to_payload()), Ok(rep));
        assert!(DeviceStatus::from_payload("state=FOO arm=- en=0 t_us=0").is_err());
        assert!(DeviceInfo::from_payload("name=x proto=1").is_err());
    }

    #[test]
    fn assembler_handles_garbage_half_lines_and_oversize() {
        let mut a = LineAssembler::new();
        let l1 = encode_frame(1, "ID");
        let mut stream = b"\x00\xffnoise\n".to_vec();
        stream.extend_from_slice(b"$1 CF"); // half line, superseded by the next '$'
        stream.extend_from_slice(l1.as_bytes());
        let ev = a.push(&stream);
        assert_eq!(ev, vec![LineEvent::Line(l1.trim_end().as_bytes().to_vec())]);
        assert!(a.ignored.starts_with(b"\x00\xffnoise"));

        // Split across pushes, byte by byte.
        let l2 = encode_frame(2, "STAT");
        let mut got = Vec::new();
        for b in l2.as_bytes() {
            got.extend(a.push(&[*b]));
        }
        assert_eq!(got, vec![LineEvent::Line(l2.trim_end().as_bytes().to_vec())]);

        // Oversize then a valid line.
        let mut big = b"$".to_vec();
        big.extend(std::iter::repeat(b'A').take(MAX_LINE * 2));
        big.push(b'\n');
        big.extend_from_slice(l1.as_bytes());
        let ev = a.push(&big);
        assert_eq!(ev, vec![LineEvent::Oversize, LineEvent::Line(l1.trim_end().as_bytes().to_vec())]);

        // Exactly MAX_LINE bytes including '\n' is fine; one more is not.
        let fit = format!("$1 {}", "A".repeat(MAX_LINE - 4));
        assert_eq!(fit.len(), MAX_LINE - 1);
        assert_eq!(a.push(format!("{fit}\n").as_bytes()).len(), 1);
        assert!(matches!(a.push(format!("{fit}A\n").as_bytes())[..], [LineEvent::Oversize]));
    }

    #[test]
    fn config_validation_and_waveform() {
        assert!(ChannelConfig::square(1980).validate().is_ok());
        assert!(ChannelConfig::with_duty(1980, 1.0).is_err());
        assert!(ChannelConfig::with_duty(1980, 0.0).is_err());
        assert_eq!(ChannelConfig::with_duty(1980, 0.25).unwrap().width_us, 495);
        assert!(ChannelConfig::square(1980).count(Some(0)).validate().is_err());
        let c = ChannelConfig { period_us: 1000, width_us: 300, phase_us: 250, pulse_count: Some(2) };
        let high: Vec<u64> = (0..3000).filter(|&t| c.level_at(t)).collect();
        assert_eq!(high.len(), 600);
        assert_eq!(high[0], 250);
        assert_eq!(*high.last().unwrap(), 1549);
        assert_eq!(c.end_us(), Some(1550));
    }

    #[test]
    fn escape_round_trip() {
        let raw = b"$1 ID*00\r\n\x00\xff\\";
        let e = escape_bytes(raw);
        assert_eq!(unescape_bytes(&e).unwrap(), raw.to_vec());
        assert!(unescape_bytes("\\q").is_err());
    }
}
