//! Software model of the LED pulse controller.
//!
//! [`Device`] is the protocol state machine plus a timing model (pure, driven
//! by an explicit clock in microseconds). [`Emulator`] runs a `Device` on one
//! end of a serial link (a thread reading and answering lines), with fault
//! injection for tests. [`LinkedEmulator`] creates a pseudo-terminal pair and
//! publishes the slave path as a symlink so any program can open it as if it
//! were the board.

use std::io;
use std::os::fd::{AsRawFd, RawFd};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serialport::SerialPort;

use super::protocol::{
    decode_frame, encode_frame, escape_bytes, ChannelConfig, ChannelReadback, Command, DeviceInfo, DeviceStatus, ErrorCode, FrameError, LineAssembler,
    LineEvent, Reply, RunState, TriggerMode, CHANNELS, PROTOCOL_VERSION,
};

/// What the emulated device says about itself in `ID`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Identity {
    pub hardware: String,
    pub firmware: String,
    pub tick_ns: u32,
}

impl Default for Identity {
    fn default() -> Self {
        Identity { hardware: "emu".into(), firmware: env!("CARGO_PKG_VERSION").into(), tick_ns: 1000 }
    }
}

/// One triggered run: the configuration snapshot taken at the trigger.
#[derive(Debug, Clone, PartialEq)]
pub struct Run {
    /// Device clock at the trigger, microseconds.
    pub t0_us: u64,
    pub trigger: TriggerMode,
    /// Configuration of each enabled channel (None = disabled).
    pub channels: Vec<Option<ChannelConfig>>,
    /// Microseconds after the trigger at which STOP forced outputs low.
    pub stopped_after_us: Option<u64>,
}

/// A level change on an output.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LevelChange {
    /// Microseconds after the trigger.
    pub t_us: u64,
    pub rising: bool,
}

impl Run {
    /// Output level of `channel` at `t_us` microseconds after the trigger.
    pub fn level_at(&self, channel: u8, t_us: u64) -> bool {
        if self.stopped_after_us.is_some_and(|s| t_us >= s) {
            return false;
        }
        match self.channels.get(channel as usize) {
            Some(Some(cfg)) => cfg.level_at(t_us),
            _ => false,
        }
    }

    /// Edges of `channel` in `[0, until_us)` microseconds after the trigger.
    pub fn edges(&self, channel: u8, until_us: u64) -> Vec<LevelChange> {
        let mut out = Vec::new();
        let Some(Some(cfg)) = self.channels.get(channel as usize) else {
            return out;
        };
        let stop = self.stopped_after_us.unwrap_or(u64::MAX).min(until_us);
        let mut k: u64 = 0;
        loop {
            if cfg.pulse_count.is_some_and(|n| k >= n as u64) {
                break;
            }
            let rise = cfg.phase_us as u64 + k * cfg.period_us as u64;
            if rise >= stop {
                break;
            }
            out.push(LevelChange { t_us: rise, rising: true });
            let fall = rise + cfg.width_us as u64;
            if fall >= stop {
                if self.stopped_after_us.is_some_and(|s| s < until_us) {
                    out.push(LevelChange { t_us: self.stopped_after_us.unwrap(), rising: false });
                }
                break;
            }
            out.push(LevelChange { t_us: fall, rising: false });
            k += 1;
        }
        out
    }

    /// Whether some channel still produces pulses at `t_us` after the trigger.
    pub fn active_at(&self, t_us: u64) -> bool {
        if self.stopped_after_us.is_some_and(|s| t_us >= s) {
            return false;
        }
        self.channels.iter().flatten().any(|c| match c.end_us() {
            None => true,
            Some(end) => t_us < end,
        })
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Phase {
    Idle,
    Armed(TriggerMode),
    Triggered(Run),
}

/// The controller's protocol state machine and timing model.
#[derive(Debug)]
pub struct Device {
    identity: Identity,
    configs: [ChannelConfig; CHANNELS as usize],
    enabled: [bool; CHANNELS as usize],
    phase: Phase,
    history: Vec<Run>,
    last: Option<(u16, u8, Vec<u8>)>,
    assembler: LineAssembler,
    executed: Vec<Command>,
}

impl Device {
    pub fn new(identity: Identity) -> Device {
        Device {
            identity,
            configs: [ChannelConfig { period_us: 1000, width_us: 500, phase_us: 0, pulse_count: None }; CHANNELS as usize],
            enabled: [false; CHANNELS as usize],
            phase: Phase::Idle,
            history: Vec::new(),
            last: None,
            assembler: LineAssembler::new(),
            executed: Vec::new(),
        }
    }

    pub fn info(&self) -> DeviceInfo {
        DeviceInfo {
            name: "rollcam-led".into(),
            protocol: PROTOCOL_VERSION,
            firmware: self.identity.firmware.clone(),
            hardware: self.identity.hardware.clone(),
            channels: CHANNELS,
            tick_ns: self.identity.tick_ns,
        }
    }

    /// Feeds raw bytes received at `now_us`; returns the complete reply lines to send.
    pub fn feed(&mut self, bytes: &[u8], now_us: u64) -> Vec<Vec<u8>> {
        let events = self.assembler.push(bytes);
        events
            .into_iter()
            .filter_map(|ev| match ev {
                LineEvent::Line(l) => self.handle_line(&l, now_us),
                LineEvent::Oversize => {
                    tracing::debug!("emulator: oversize line discarded");
                    Some(encode_frame(0, &Reply::Nak(ErrorCode::Oversize).to_body()).into_bytes())
                }
            })
            .collect()
    }

    /// Handles one complete line (starting with `$`); returns the reply line.
    pub fn handle_line(&mut self, line: &[u8], now_us: u64) -> Option<Vec<u8>> {
        let frame = match decode_frame(line) {
            Ok(f) => f,
            Err(e) => {
                tracing::debug!("emulator: rejected line {}: {e}", escape_bytes(line));
                let code = match e {
                    FrameError::Crc { .. } => ErrorCode::Crc,
                    FrameError::Malformed(_) => ErrorCode::Frame,
                    FrameError::Oversize => ErrorCode::Oversize,
                };
                return Some(encode_frame(0, &Reply::Nak(code).to_body()).into_bytes());
            }
        };
        if frame.seq == 0 {
            return Some(encode_frame(0, &Reply::Nak(ErrorCode::Frame).to_body()).into_bytes());
        }
        if let Some((seq, crc, reply)) = &self.last {
            if *seq == frame.seq && *crc == frame.crc {
                tracing::debug!("emulator: duplicate seq {seq}, resending the cached reply");
                return Some(reply.clone());
            }
        }
        let reply = match Command::parse(&frame.body) {
            Err(code) => Reply::Nak(code),
            Ok(cmd) => self.execute(cmd, now_us),
        };
        let bytes = encode_frame(frame.seq, &reply.to_body()).into_bytes();
        self.last = Some((frame.seq, frame.crc, bytes.clone()));
        Some(bytes)
    }

    fn execute(&mut self, cmd: Command, now_us: u64) -> Reply {
        let reply = match &cmd {
            Command::Identify => Reply::Ack(self.info().to_payload()),
            Command::Configure { channel, config } => {
                if !self.may_configure(now_us) {
                    return Reply::Nak(ErrorCode::State);
                }
                self.settle_done();
                self.configs[*channel as usize] = *config;
                self.enabled[*channel as usize] = true;
                Reply::Ack(String::new())
            }
            Command::Off { channel } => {
                if !self.may_configure(now_us) {
                    return Reply::Nak(ErrorCode::State);
                }
                self.settle_done();
                self.enabled[*channel as usize] = false;
                Reply::Ack(String::new())
            }
            Command::Get { channel } => Reply::Ack(
                ChannelReadback { channel: *channel, enabled: self.enabled[*channel as usize], config: self.configs[*channel as usize] }.to_payload(),
            ),
            Command::Arm(mode) => {
                if self.run_state(now_us) == RunState::Running || !self.enabled.iter().any(|&e| e) {
                    return Reply::Nak(ErrorCode::State);
                }
                self.settle_done();
                self.phase = Phase::Armed(*mode);
                Reply::Ack(String::new())
            }
            Command::Trigger => {
                if !matches!(self.phase, Phase::Armed(_)) {
                    return Reply::Nak(ErrorCode::State);
                }
                self.fire(now_us);
                Reply::Ack(String::new())
            }
            Command::Stop => {
                self.stop(now_us);
                Reply::Ack(String::new())
            }
            Command::Status => Reply::Ack(self.status(now_us).to_payload()),
        };
        self.executed.push(cmd);
        reply
    }

    fn may_configure(&self, now_us: u64) -> bool {
        matches!(self.run_state(now_us), RunState::Idle | RunState::Done)
    }

    /// A finished run is archived when the device is reconfigured or re-armed.
    fn settle_done(&mut self) {
        if let Phase::Triggered(run) = std::mem::replace(&mut self.phase, Phase::Idle) {
            self.history.push(run);
        }
    }

    fn fire(&mut self, now_us: u64) {
        if let Phase::Armed(mode) = self.phase {
            let channels = (0..CHANNELS as usize).map(|c| self.enabled[c].then_some(self.configs[c])).collect();
            tracing::debug!("emulator: triggered ({}) at {now_us} us", mode.token());
            self.phase = Phase::Triggered(Run { t0_us: now_us, trigger: mode, channels, stopped_after_us: None });
        }
    }

    fn stop(&mut self, now_us: u64) {
        if let Phase::Triggered(mut run) = std::mem::replace(&mut self.phase, Phase::Idle) {
            run.stopped_after_us = Some(now_us.saturating_sub(run.t0_us));
            self.history.push(run);
        }
    }

    /// An edge on the trigger input at `now_us`; returns true if it started a run.
    pub fn input_edge(&mut self, rising: bool, now_us: u64) -> bool {
        let fires = matches!((&self.phase, rising), (Phase::Armed(TriggerMode::Rising), true) | (Phase::Armed(TriggerMode::Falling), false));
        if fires {
            self.fire(now_us);
        }
        fires
    }

    pub fn run_state(&self, now_us: u64) -> RunState {
        match &self.phase {
            Phase::Idle => RunState::Idle,
            Phase::Armed(_) => RunState::Armed,
            Phase::Triggered(run) if run.active_at(now_us.saturating_sub(run.t0_us)) => RunState::Running,
            Phase::Triggered(_) => RunState::Done,
        }
    }

    pub fn status(&self, now_us: u64) -> DeviceStatus {
        let (trigger, t_us) = match &self.phase {
            Phase::Idle => (None, 0),
            Phase::Armed(m) => (Some(*m), 0),
            Phase::Triggered(run) => (Some(run.trigger), now_us.saturating_sub(run.t0_us).min(u32::MAX as u64) as u32),
        };
        DeviceStatus { state: self.run_state(now_us), trigger, enabled: self.enabled.to_vec(), t_us }
    }

    /// The current run if triggered, else the most recent finished one.
    pub fn last_run(&self) -> Option<&Run> {
        match &self.phase {
            Phase::Triggered(run) => Some(run),
            _ => self.history.last(),
        }
    }

    /// Output level of `channel` at `t_us` after the last trigger (false if never triggered).
    pub fn level_at(&self, channel: u8, t_us: u64) -> bool {
        self.last_run().is_some_and(|r| r.level_at(channel, t_us))
    }

    /// Commands the device acted upon, in order (duplicates and rejected lines excluded).
    pub fn executed(&self) -> &[Command] {
        &self.executed
    }

    pub fn channel(&self, channel: u8) -> Option<(bool, ChannelConfig)> {
        let c = channel as usize;
        (c < CHANNELS as usize).then(|| (self.enabled[c], self.configs[c]))
    }
}

struct EmulatorShared {
    device: Mutex<Device>,
    clock: Instant,
    stop: AtomicBool,
    silent: AtomicBool,
    drop_replies: AtomicU32,
    delay_next_ms: AtomicU64,
    garbage: Mutex<Vec<u8>>,
    lines_seen: AtomicU64,
    replies_dropped: AtomicU64,
}

impl EmulatorShared {
    fn now_us(&self) -> u64 {
        self.clock.elapsed().as_micros() as u64
    }
}

/// Why the emulator thread ended.
#[derive(Debug)]
pub enum EmulatorExit {
    /// [`Emulator::shutdown`] or drop.
    Stopped,
    /// The other end of the link closed.
    HungUp,
    /// Any other I/O error.
    Io(io::Error),
}

/// A [`Device`] answering on a serial link from a background thread.
pub struct Emulator {
    shared: Arc<EmulatorShared>,
    thread: Option<JoinHandle<EmulatorExit>>,
}

fn is_hangup(e: &io::Error) -> bool {
    e.kind() == io::ErrorKind::BrokenPipe || e.raw_os_error() == Some(5 /* EIO */)
}

impl Emulator {
    /// Starts answering on `port` (the device end of the link). Replies are written
    /// without blocking: while the host does not read, they wait in a backlog of at most
    /// [`REPLY_BACKLOG_BYTES`], and replies that do not fit are dropped (counted in
    /// [`Emulator::replies_dropped`]), as a board's full transmit buffer would.
    pub fn spawn<P: SerialPort + AsRawFd + 'static>(mut port: P, identity: Identity) -> io::Result<Emulator> {
        port.set_timeout(Duration::from_millis(20))?;
        set_nonblocking(port.as_raw_fd())?;
        let shared = Arc::new(EmulatorShared {
            device: Mutex::new(Device::new(identity)),
            clock: Instant::now(),
            stop: AtomicBool::new(false),
            silent: AtomicBool::new(false),
            drop_replies: AtomicU32::new(0),
            delay_next_ms: AtomicU64::new(0),
            garbage: Mutex::new(Vec::new()),
            lines_seen: AtomicU64::new(0),
            replies_dropped: AtomicU64::new(0),
        });
        let sh = shared.clone();
        let thread = std::thread::Builder::new().name("led-emulator".into()).spawn(move || serve(port, sh))?;
        Ok(Emulator { shared, thread: Some(thread) })
    }

    /// Locks the device model (do not hold the guard across driver calls).
    pub fn device(&self) -> MutexGuard<'_, Device> {
        self.shared.device.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The emulator clock, microseconds since spawn.
    pub fn now_us(&self) -> u64 {
        self.shared.now_us()
    }

    /// Simulates an edge on the trigger input now; true if it started a run.
    pub fn input_edge(&self, rising: bool) -> bool {
        let now = self.now_us();
        self.device().input_edge(rising, now)
    }

    /// Executes the next `n` commands but does not send their replies.
    pub fn drop_next_replies(&self, n: u32) {
        self.shared.drop_replies.store(n, Ordering::SeqCst);
    }

    /// Executes the next command at once but sends its reply only after `delay`
    /// (a slow device: the host times out and retransmits meanwhile).
    pub fn delay_next_reply(&self, delay: Duration) {
        self.shared.delay_next_ms.store(delay.as_millis() as u64, Ordering::SeqCst);
    }

    /// While silent, received bytes are read and ignored: no reply, no action.
    pub fn set_silent(&self, silent: bool) {
        self.shared.silent.store(silent, Ordering::SeqCst);
    }

    /// Sends these bytes right before the next reply (line noise).
    pub fn inject_garbage_before_next_reply(&self, bytes: &[u8]) {
        self.shared.garbage.lock().unwrap().extend_from_slice(bytes);
    }

    /// Complete lines received so far (valid or not).
    pub fn lines_seen(&self) -> u64 {
        self.shared.lines_seen.load(Ordering::SeqCst)
    }

    /// Replies dropped because the host was not reading them (the backlog was full).
    pub fn replies_dropped(&self) -> u64 {
        self.shared.replies_dropped.load(Ordering::SeqCst)
    }

    /// Whether the serving thread is still running.
    pub fn is_running(&self) -> bool {
        self.thread.as_ref().is_some_and(|t| !t.is_finished())
    }

    /// Stops the thread and closes the device end of the link (the host sees a hang-up).
    pub fn shutdown(mut self) -> EmulatorExit {
        self.stop_thread()
    }

    fn stop_thread(&mut self) -> EmulatorExit {
        self.shared.stop.store(true, Ordering::SeqCst);
        match self.thread.take() {
            Some(t) => t.join().unwrap_or(EmulatorExit::Stopped),
            None => EmulatorExit::Stopped,
        }
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        self.stop_thread();
    }
}

/// Replies waiting for a host that does not read, at most (about a hundred replies);
/// beyond, new replies are dropped.
pub const REPLY_BACKLOG_BYTES: usize = 4096;

fn set_nonblocking(fd: RawFd) -> io::Result<()> {
    // SAFETY: fcntl on a descriptor the caller owns; only the status flags change.
    let flags = unsafe { libc::fcntl(fd, libc::F_GETFL) };
    if flags < 0 || unsafe { libc::fcntl(fd, libc::F_SETFL, flags | libc::O_NONBLOCK) } < 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(())
}

/// Writes what the link takes now of `backlog` (never waits) and removes it from the
/// backlog; an error only for a hang-up or another I/O failure.
fn flush_backlog(fd: RawFd, backlog: &mut Vec<u8>) -> io::Result<()> {
    while !backlog.is_empty() {
        // SAFETY: writes from a live buffer of the given length to the port's descriptor.
        let n = unsafe { libc::write(fd, backlog.as_ptr().cast(), backlog.len()) };
        if n < 0 {
            let e = io::Error::last_os_error();
            return match e.kind() {
                io::ErrorKind::WouldBlock => Ok(()),
                io::ErrorKind::Interrupted => continue,
                _ => Err(e),
            };
        }
        backlog.drain(..n as usize);
    }
    Ok(())
}

fn serve<P: SerialPort + AsRawFd>(mut port: P, sh: Arc<EmulatorShared>) -> EmulatorExit {
    let fd = port.as_raw_fd();
    let mut buf = [0u8; 256];
    let mut backlog: Vec<u8> = Vec::new();
    let mut dropping = false;
    loop {
        if sh.stop.load(Ordering::SeqCst) {
            return EmulatorExit::Stopped;
        }
        if let Err(e) = flush_backlog(fd, &mut backlog) {
            return if is_hangup(&e) { EmulatorExit::HungUp } else { EmulatorExit::Io(e) };
        }
        if backlog.is_empty() && dropping {
            dropping = false;
            tracing::info!("emulator: the host reads replies again ({} dropped so far)", sh.replies_dropped.load(Ordering::SeqCst));
        }
        let n = match port.read(&mut buf) {
            Ok(0) => return EmulatorExit::HungUp,
            Ok(n) => n,
            Err(e) if e.kind() == io::ErrorKind::TimedOut || e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) if is_hangup(&e) => {
                tracing::info!("emulator: host end closed");
                return EmulatorExit::HungUp;
            }
            Err(e) => return EmulatorExit::Io(e),
        };
        let newlines = buf[..n].iter().filter(|&&b| b == b'\n').count() as u64;
        sh.lines_seen.fetch_add(newlines, Ordering::SeqCst);
        if sh.silent.load(Ordering::SeqCst) {
            continue;
        }
        let replies = {
            let now = sh.now_us();
            let mut dev = sh.device.lock().unwrap_or_else(|p| p.into_inner());
            dev.feed(&buf[..n], now)
        };
        for reply in replies {
            let drop_it = sh.drop_replies.fetch_update(Ordering::SeqCst, Ordering::SeqCst, |d| d.checked_sub(1)).is_ok();
            if drop_it {
                tracing::debug!("emulator: dropping reply {}", escape_bytes(&reply));
                continue;
            }
            let delay_ms = sh.delay_next_ms.swap(0, Ordering::SeqCst);
            if delay_ms > 0 {
                std::thread::sleep(Duration::from_millis(delay_ms));
            }
            let garbage = std::mem::take(&mut *sh.garbage.lock().unwrap());
            if backlog.len() + garbage.len() + reply.len() > REPLY_BACKLOG_BYTES {
                sh.replies_dropped.fetch_add(1, Ordering::SeqCst);
                if !dropping {
                    dropping = true;
                    tracing::warn!("emulator: the host is not reading replies; dropping new ones until it does");
                }
                continue;
            }
            backlog.extend_from_slice(&garbage);
            backlog.extend_from_slice(&reply);
        }
        if let Err(e) = flush_backlog(fd, &mut backlog) {
            return if is_hangup(&e) { EmulatorExit::HungUp } else { EmulatorExit::Io(e) };
        }
    }
}

/// An emulator on a fresh pseudo-terminal whose slave path is published as a symlink.
/// Dropping it stops the emulator and removes the link.
pub struct LinkedEmulator {
    emulator: Option<Emulator>,
    link: PathBuf,
    target: PathBuf,
    // Kept open so the link survives hosts connecting and disconnecting.
    _slave: serialport::TTYPort,
}

/// Errors of [`LinkedEmulator::create`].
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    #[error("cannot create a pseudo-terminal pair: {0}")]
    Pty(#[from] serialport::Error),
    #[error("link path {0} already exists; refusing to replace it (only a link to a pseudo-terminal that is gone, left by an emulator that was killed, is replaced)")]
    Occupied(PathBuf),
    #[error("cannot create symlink {link} -> {target}: {source}")]
    Symlink { link: PathBuf, target: PathBuf, source: io::Error },
    #[error("cannot start the emulator thread: {0}")]
    Thread(io::Error),
}

impl LinkedEmulator {
    /// Creates the PTY pair, symlinks its slave at `link` and starts answering.
    /// Any existing path at `link` is refused, but for a link to a pseudo-terminal that
    /// is gone (left by a killed run), which is replaced.
    pub fn create(link: &Path, identity: Identity) -> Result<LinkedEmulator, LinkError> {
        let (master, slave) = serialport::TTYPort::pair()?;
        let target = PathBuf::from(slave.name().unwrap_or_default());
        let stale = || std::fs::read_link(link).is_ok_and(|t| t.starts_with("/dev/pts/") && !t.exists());
        match std::fs::symlink_metadata(link) {
            Ok(m) if m.file_type().is_symlink() && stale() => {
                let _ = std::fs::remove_file(link);
            }
            Ok(_) => return Err(LinkError::Occupied(link.to_path_buf())),
            Err(_) => {}
        }
        std::os::unix::fs::symlink(&target, link).map_err(|source| LinkError::Symlink { link: link.to_path_buf(), target: target.clone(), source })?;
        let emulator = match Emulator::spawn(master, identity) {
            Ok(e) => e,
            Err(e) => {
                let _ = std::fs::remove_file(link);
                return Err(LinkError::Thread(e));
            }
        };
        tracing::info!("emulator listening on {} -> {}", link.display(), target.display());
        Ok(LinkedEmulator { emulator: Some(emulator), link: link.to_path_buf(), target, _slave: slave })
    }

    pub fn link(&self) -> &Path {
        &self.link
    }

    /// The pseudo-terminal the link points to (e.g. `/dev/pts/7`).
    pub fn target(&self) -> &Path {
        &self.target
    }

    pub fn emulator(&self) -> &Emulator {
        self.emulator.as_ref().expect("present until drop")
    }
}

impl Drop for LinkedEmulator {
    fn drop(&mut self) {
        if let Some(e) = self.emulator.take() {
            e.shutdown();
        }
        // Remove the link only if it is still ours.
        if std::fs::read_link(&self.link).is_ok_and(|t| t == self.target) {
            let _ = std::fs::remove_file(&self.link);
        }
    }
}

static INTERRUPTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    INTERRUPTED.store(true, Ordering::SeqCst);
}

/// Installs SIGINT/SIGTERM handlers that set the returned flag (for clean
/// shutdown of `rollcam led emulate`, so the link is removed).
pub fn interrupt_flag() -> &'static AtomicBool {
    // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
    unsafe {
        libc::signal(libc::SIGINT, on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t);
        libc::signal(libc::SIGTERM, on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t);
    }
    &INTERRUPTED
}

#[cfg(test)]
mod tests {
    use super::*;

    fn send(dev: &mut Device, seq: u16, body: &str, now: u64) -> Reply {
        let line = encode_frame(seq, body);
        let out = dev.feed(line.as_bytes(), now);
        assert_eq!(out.len(), 1, "one reply for {body}");
        let f = decode_frame(&out[0]).unwrap();
        assert_eq!(f.seq, seq);
        Reply::parse(&f.body).unwrap()
    }

    #[test]
    fn state_machine_and_waveform() {
        let mut d = Device::new(Identity::default());
        assert_eq!(send(&mut d, 1, "ARM SW", 0), Reply::Nak(ErrorCode::State));
        assert_eq!(send(&mut d, 2, "TRIG", 0), Reply::Nak(ErrorCode::State));
        assert_eq!(send(&mut d, 3, "CFG 1 1000 250 100 3", 0), Reply::Ack(String::new()));
        assert_eq!(send(&mut d, 4, "ARM SW", 0), Reply::Ack(String::new()));
        assert_eq!(send(&mut d, 5, "CFG 1 1000 250 100 3", 10), Reply::Nak(ErrorCode::State));
        assert_eq!(send(&mut d, 6, "TRIG", 5_000), Reply::Ack(String::new()));
        assert_eq!(d.run_state(5_000 + 2_000), RunState::Running);
        assert_eq!(d.run_state(5_000 + 2_350), RunState::Done);
        let run = d.last_run().unwrap().clone();
        assert_eq!(run.t0_us, 5_000);
        let e = run.edges(1, 10_000);
        let want: Vec<(u64, bool)> = vec![(100, true), (350, false), (1100, true), (1350, false), (2100, true), (2350, false)];
        assert_eq!(e.iter().map(|e| (e.t_us, e.rising)).collect::<Vec<_>>(), want);
        assert!(!d.level_at(1, 99) && d.level_at(1, 100) && d.level_at(1, 349) && !d.level_at(1, 350));
        assert!(!d.level_at(0, 100), "channel 0 was never enabled");
        assert_eq!(send(&mut d, 7, "STOP", 6_000), Reply::Ack(String::new()));
        assert_eq!(d.run_state(6_000), RunState::Idle);
    }

    #[test]
    fn edge_trigger_and_stop_cuts_waveform() {
        let mut d = Device::new(Identity::default());
        send(&mut d, 1, "CFG 0 660 330 0 0", 0);
        send(&mut d, 2, "ARM FALL", 0);
        assert!(!d.input_edge(true, 100), "rising edge must not fire a FALL arm");
        assert!(d.input_edge(false, 200));
        assert_eq!(d.run_state(1_000_000), RunState::Running);
        send(&mut d, 3, "STOP", 200 + 1000);
        let run = d.last_run().unwrap();
        assert_eq!(run.stopped_after_us, Some(1000));
        let e = run.edges(0, 5000);
        assert_eq!(e.last().unwrap(), &LevelChange { t_us: 990, rising: false });
        assert!(run.edges(0, 5000).iter().all(|e| e.t_us <= 1000));
        assert!(!run.level_at(0, 1320));
    }

    #[test]
    fn duplicate_seq_is_not_executed_twice() {
        let mut d = Device::new(Identity::default());
        send(&mut d, 1, "CFG 0 1000 500 0 0", 0);
        send(&mut d, 2, "ARM SW", 0);
        let line = encode_frame(3, "TRIG");
        let a = d.feed(line.as_bytes(), 100);
        let b = d.feed(line.as_bytes(), 200);
        assert_eq!(a, b);
        assert_eq!(d.executed().iter().filter(|c| **c == Command::Trigger).count(), 1);
        assert_eq!(d.last_run().unwrap().t0_us, 100);
        // Same seq, different command: executed.
        assert_eq!(send(&mut d, 3, "STOP", 300), Reply::Ack(String::new()));
    }
}
