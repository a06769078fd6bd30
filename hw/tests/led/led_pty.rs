//! Host driver <-> emulator over a real pseudo-terminal pair.

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use rollcam_hw::led::protocol::{encode_frame, Command};
use rollcam_hw::led::{ChannelConfig, Emulator, ErrorCode, Identity, LedController, LedError, LinkOptions, LinkedEmulator, RunState, TriggerMode};
use serialport::{SerialPort, TTYPort};

fn opts(timeout_ms: u64, retries: u32) -> LinkOptions {
    LinkOptions { baud: 115_200, reply_timeout: Duration::from_millis(timeout_ms), retries, ..LinkOptions::default() }
}

/// Emulator on the master end, driver on the slave end.
fn setup(timeout_ms: u64, retries: u32) -> (Emulator, LedController) {
    let (master, slave) = TTYPort::pair().expect("pty pair");
    let name = slave.name().unwrap_or_else(|| "pty".into());
    let emu = Emulator::spawn(master, Identity::default()).unwrap();
    let ctl = LedController::from_port(Box::new(slave), name, opts(timeout_ms, retries));
    (emu, ctl)
}

#[test]
fn identify_round_trip() {
    let (_emu, mut ctl) = setup(500, 0);
    let info = ctl.identify().unwrap();
    assert_eq!(info.name, "rollcam-led");
    assert_eq!(info.protocol, 1);
    assert_eq!(info.channels, 4);
    assert_eq!(info.hardware, "emu");
}

#[test]
fn configure_arm_trigger_status_and_waveform() {
    let (emu, mut ctl) = setup(500, 0);
    let periods = [2640u32, 1980, 1320, 660];
    for (c, p) in periods.iter().enumerate() {
        let cfg = ChannelConfig::with_duty(*p, 0.5).unwrap().phase(100 * c as u32);
        ctl.configure(c as u8, cfg).unwrap();
    }
    for (c, p) in periods.iter().enumerate() {
        let r = ctl.channel(c as u8).unwrap();
        assert!(r.enabled);
        assert_eq!(r.config.period_us, *p);
        assert_eq!(r.config.width_us, p / 2);
        assert_eq!(r.config.phase_us, 100 * c as u32);
    }
    let st = ctl.status().unwrap();
    assert_eq!(st.state, RunState::Idle);
    assert_eq!(st.enabled, vec![true; 4]);

    ctl.arm(TriggerMode::Software).unwrap();
    let st = ctl.status().unwrap();
    assert_eq!(st.state, RunState::Armed);
    assert_eq!(st.trigger, Some(TriggerMode::Software));

    let before = emu.now_us();
    ctl.trigger().unwrap();
    let after = emu.now_us();
    std::thread::sleep(Duration::from_millis(20));
    let st = ctl.status().unwrap();
    assert_eq!(st.state, RunState::Running);
    assert!(st.t_us >= 20_000, "t_us {} counts from the trigger", st.t_us);

    {
        let dev = emu.device();
        let run = dev.last_run().expect("triggered");
        assert!(run.t0_us >= before && run.t0_us <= after);
        // Channel 1: 1980 us square wave, first rise at 100 us.
        let e = run.edges(1, 5000);
        let t: Vec<(u64, bool)> = e.iter().map(|e| (e.t_us, e.rising)).collect();
        assert_eq!(&t[..4], &[(100, true), (1090, false), (2080, true), (3070, false)]);
        assert!(dev.level_at(3, 300) && !dev.level_at(3, 299) && !dev.level_at(3, 630));
    }
    ctl.stop().unwrap();
    assert_eq!(ctl.status().unwrap().state, RunState::Idle);
    let stopped = emu.device().last_run().unwrap().stopped_after_us.unwrap();
    assert!(stopped >= 20_000);
    assert!(!emu.device().level_at(0, stopped + 1), "outputs low after STOP");
}

#[test]
fn finite_count_finishes_and_edge_trigger() {
    let (emu, mut ctl) = setup(500, 0);
    ctl.configure(2, ChannelConfig::square(1000).count(Some(3))).unwrap();
    ctl.arm(TriggerMode::Rising).unwrap();
    // TRIG is still allowed as a forced trigger, but a falling edge must not fire a RISE arm.
    assert!(!emu.input_edge(false));
    assert_eq!(ctl.status().unwrap().state, RunState::Armed);
    assert!(emu.input_edge(true));
    std::thread::sleep(Duration::from_millis(10));
    let st = ctl.status().unwrap();
    assert_eq!(st.state, RunState::Done, "3 pulses of 1 ms are over after 10 ms");
    assert_eq!(st.trigger, Some(TriggerMode::Rising));
    let run = emu.device().last_run().unwrap().clone();
    assert_eq!(run.edges(2, 1_000_000).len(), 6);
}

#[test]
fn out_of_range_rejected_with_code() {
    let (emu, mut ctl) = setup(500, 0);
    let bad = ChannelConfig { period_us: 50, width_us: 25, phase_us: 0, pulse_count: None };
    // Host-side validation refuses before sending.
    assert!(matches!(ctl.configure(0, bad), Err(LedError::Config { .. })));
    // The device refuses too when the host check is bypassed.
    match ctl.configure_unchecked(0, bad) {
        Err(LedError::Nak { code, port, .. }) => {
            assert_eq!(code, ErrorCode::Range);
            assert_eq!(port, ctl.port_name());
        }
        other => panic!("expected NAK RANGE, got {other:?}"),
    }
    assert!(!emu.device().channel(0).unwrap().0, "rejected config not applied");
    // ARM with nothing enabled, TRIG while idle: STATE.
    match ctl.arm(TriggerMode::Software) {
        Err(LedError::Nak { code: ErrorCode::State, .. }) => {}
        other => panic!("expected NAK STATE, got {other:?}"),
    }
    assert!(matches!(ctl.trigger(), Err(LedError::Nak { code: ErrorCode::State, .. })));
    let msg = ctl.trigger().unwrap_err().to_string();
    assert!(msg.contains(ctl.port_name()) && msg.contains("TRIG") && msg.contains("STATE"), "{msg}");
}

/// Raw access: emulator on master, test writes bytes on the slave directly.
fn raw_setup() -> (Emulator, TTYPort) {
    let (master, mut slave) = TTYPort::pair().unwrap();
    slave.set_timeout(Duration::from_millis(50)).unwrap();
    let emu = Emulator::spawn(master, Identity::default()).unwrap();
    (emu, slave)
}

fn read_lines(port: &mut TTYPort, n: usize, within: Duration) -> Vec<String> {
    let end = Instant::now() + within;
    let mut acc = Vec::new();
    let mut buf = [0u8; 256];
    while Instant::now() < end && acc.iter().filter(|&&b| b == b'\n').count() < n {
        match port.read(&mut buf) {
            Ok(k) => acc.extend_from_slice(&buf[..k]),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
            Err(e) => panic!("{e}"),
        }
    }
    String::from_utf8_lossy(&acc).lines().map(|s| s.to_string()).collect()
}

#[test]
fn corrupted_line_never_acted_on() {
    let (emu, mut raw) = raw_setup();
    let good = encode_frame(11, "CFG 0 1980 990 0 0");
    // Flip one bit in each position of the payload in turn; none may be executed.
    let bytes = good.as_bytes();
    for i in 1..bytes.len() - 1 {
        let mut m = bytes.to_vec();
        m[i] ^= 0x01;
        if m[i] == b'\n' || m[i] == b'$' {
            continue;
        }
        raw.write_all(&m).unwrap();
        let lines = read_lines(&mut raw, 1, Duration::from_millis(500));
        assert_eq!(lines.len(), 1, "a NAK for flipped byte {i}");
        assert!(lines[0].starts_with("$0 NAK "), "flipped byte {i}: {:?}", lines[0]);
    }
    assert!(emu.device().executed().is_empty(), "{:?}", emu.device().executed());
    assert!(!emu.device().channel(0).unwrap().0);
    // The intact line is executed.
    raw.write_all(bytes).unwrap();
    let lines = read_lines(&mut raw, 1, Duration::from_millis(500));
    assert_eq!(lines, vec![encode_frame(11, "ACK").trim_end().to_string()]);
    assert_eq!(emu.device().channel(0).unwrap().1.period_us, 1980);
}

#[test]
fn garbage_and_half_lines_tolerated_by_device() {
    let (emu, mut raw) = raw_setup();
    let mut stream = b"\x00\x7f\xffjunk\r\n".to_vec();
    stream.extend_from_slice(b"$5 CFG 1 66"); // half line, cut by the next '$'
    stream.extend_from_slice(encode_frame(6, "ID").as_bytes());
    let mut big = vec![b'$'];
    big.extend(std::iter::repeat(b'9').take(300));
    big.push(b'\n');
    stream.extend_from_slice(&big);
    stream.extend_from_slice(encode_frame(7, "STAT").as_bytes());
    raw.write_all(&stream).unwrap();
    let lines = read_lines(&mut raw, 3, Duration::from_millis(800));
    assert_eq!(lines.len(), 3, "{lines:?}");
    assert!(lines[0].starts_with("$6 ACK name=rollcam-led"), "{lines:?}");
    assert!(lines[1].starts_with("$0 NAK 3 OVERSIZE"), "{lines:?}");
    assert!(lines[2].starts_with("$7 ACK state=IDLE"), "{lines:?}");
    assert_eq!(emu.device().executed(), &[Command::Identify, Command::Status]);
}

#[test]
fn garbage_before_reply_tolerated_by_host() {
    let (emu, mut ctl) = setup(500, 0);
    emu.inject_garbage_before_next_reply(b"\xde\xad$1 ACK*00\n~~noise~~\n$9 half");
    let info = ctl.identify().unwrap();
    assert_eq!(info.name, "rollcam-led");
}

#[test]
fn retry_after_dropped_reply_is_idempotent() {
    let (emu, mut ctl) = setup(150, 2);
    ctl.configure(0, ChannelConfig::square(1000)).unwrap();
    ctl.arm(TriggerMode::Software).unwrap();
    emu.drop_next_replies(1);
    let t = Instant::now();
    ctl.trigger().unwrap();
    assert!(t.elapsed() >= Duration::from_millis(150), "the first reply was dropped, so a retry happened");
    let dev = emu.device();
    assert_eq!(dev.executed().iter().filter(|c| **c == Command::Trigger).count(), 1, "the retransmitted TRIG (same seq) must not trigger twice");
    drop(dev);
    assert!(emu.lines_seen() >= 4, "TRIG went on the wire twice");
    // A second, new TRIG (new seq) is a real command: rejected since already running.
    assert!(matches!(ctl.trigger(), Err(LedError::Nak { code: ErrorCode::State, .. })));
}

#[test]
fn silent_device_times_out_with_clear_error() {
    let (emu, mut ctl) = setup(100, 1);
    emu.set_silent(true);
    let t = Instant::now();
    let err = ctl.status().unwrap_err();
    let el = t.elapsed();
    assert!(el >= Duration::from_millis(200) && el < Duration::from_secs(2), "{el:?}");
    match &err {
        LedError::Silent { port, command, attempts, .. } => {
            assert_eq!(port, ctl.port_name());
            assert_eq!(command, "STAT");
            assert_eq!(*attempts, 2);
        }
        other => panic!("expected Silent, got {other:?}"),
    }
    assert!(err.to_string().contains(ctl.port_name()));
    emu.set_silent(false);
    assert_eq!(ctl.status().unwrap().state, RunState::Idle, "recovers once the device answers");
}

#[test]
fn garbage_only_reports_garbage() {
    let (master, slave) = TTYPort::pair().unwrap();
    let name = slave.name().unwrap();
    let mut ctl = LedController::from_port(Box::new(slave), name, opts(100, 0));
    let noise = std::thread::spawn(move || {
        let mut m = master;
        for _ in 0..10 {
            let _ = m.write_all(b"\x55\xaaAT+GMR\r\nOK\r\n$3 ACK*7F\n");
            std::thread::sleep(Duration::from_millis(10));
        }
        m
    });
    let err = ctl.identify().unwrap_err();
    assert!(matches!(err, LedError::Garbage { .. }), "{err:?}");
    assert!(err.to_string().contains("unparseable"), "{err}");
    drop(noise.join());
}

#[test]
fn hang_up_gives_clear_error() {
    let (emu, mut ctl) = setup(300, 2);
    ctl.identify().unwrap();
    emu.shutdown(); // closes the device end
    let t = Instant::now();
    let err = ctl.status().unwrap_err();
    assert!(matches!(err, LedError::HungUp { .. }), "{err:?}");
    assert!(t.elapsed() < Duration::from_millis(300), "hang-up is detected, not waited out");
    assert!(err.to_string().contains(ctl.port_name()));
}

#[test]
fn open_errors_name_the_port() {
    let err = LedController::open("/dev/does-not-exist-rollcam", 115_200).err().unwrap();
    assert!(matches!(err, LedError::PortNotFound { .. }), "{err:?}");
    assert!(err.to_string().contains("/dev/does-not-exist-rollcam"));
}

#[test]
fn linked_emulator_refuses_an_existing_path_and_replaces_only_a_stale_pty_link() {
    let dir = tempfile::tempdir().unwrap();
    // A user's symlink was replaced, then deleted on exit.
    let mine = dir.path().join("mine");
    std::os::unix::fs::symlink("/etc/hostname", &mine).unwrap();
    let folder = dir.path().join("folder");
    std::fs::create_dir(&folder).unwrap();
    for path in [&mine, &folder] {
        let e = LinkedEmulator::create(path, Identity::default()).err().unwrap().to_string();
        assert!(e.contains("already exists") && e.contains("refusing"), "{e}");
    }
    assert_eq!(std::fs::read_link(&mine).unwrap(), std::path::Path::new("/etc/hostname"));
    // Left by a killed emulator: a link to a pseudo-terminal that is gone.
    let stale = dir.path().join("stale");
    std::os::unix::fs::symlink("/dev/pts/999999", &stale).unwrap();
    let linked = LinkedEmulator::create(&stale, Identity::default()).unwrap();
    assert_eq!(std::fs::read_link(&stale).unwrap(), linked.target());
}

#[test]
fn linked_emulator_open_by_path_twice_and_cleanup() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("ttyLED");
    let linked = LinkedEmulator::create(&link, Identity::default()).unwrap();
    assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
    let path = link.to_str().unwrap();
    {
        let mut ctl = LedController::open_with(path, opts(500, 1)).unwrap();
        ctl.configure(1, ChannelConfig::with_duty(1980, 0.5).unwrap()).unwrap();
    }
    {
        // A second process-like open after the first closed (exclusive lock released).
        let mut ctl = LedController::open_with(path, opts(500, 1)).unwrap();
        let sync = ctl.sync_summary(TriggerMode::Rising).unwrap();
        assert_eq!(sync.channels.len(), 1);
        assert_eq!(sync.channels[0].channel, 1);
        assert_eq!(sync.channels[0].config.period_us, 1980);
        let json = serde_json::to_value(&sync).unwrap();
        assert_eq!(json["channels"][0]["period_us"], 1980);
        assert_eq!(json["trigger"], "rising");
        assert_eq!(json["port"], path);
    }
    assert_eq!(linked.emulator().device().channel(1).unwrap().1.width_us, 990);
    drop(linked);
    assert!(std::fs::symlink_metadata(&link).is_err(), "link removed on drop");
}

#[test]
fn late_reply_and_its_duplicate_are_handled() {
    let (emu, mut ctl) = setup(100, 3);
    ctl.configure(3, ChannelConfig::square(660)).unwrap();
    ctl.arm(TriggerMode::Software).unwrap();
    // The reply to TRIG comes after the host's timeout: the host resends (same seq),
    // the device answers the resend from its cache; the host takes the first reply.
    emu.delay_next_reply(Duration::from_millis(180));
    ctl.trigger().unwrap();
    assert_eq!(emu.device().executed().iter().filter(|c| **c == Command::Trigger).count(), 1, "late reply + retransmission must not trigger twice");
    // The duplicate reply still in flight is stale for the next command and ignored.
    let st = ctl.status().unwrap();
    assert_eq!(st.state, RunState::Running);
    assert_eq!(st.enabled, vec![false, false, false, true]);
    ctl.stop().unwrap();
    assert_eq!(ctl.status().unwrap().state, RunState::Idle);
}

#[test]
fn open_waits_for_a_booting_device_then_gives_up_clearly() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("ttyBOOT");
    let linked = LinkedEmulator::create(&link, Identity::default()).unwrap();
    let path = link.to_str().unwrap();
    let o = LinkOptions { ready_timeout: Duration::from_millis(1500), ..opts(200, 0) };
    // Silent for 400 ms, like an Arduino bootloader after the port opens.
    linked.emulator().set_silent(true);
    std::thread::scope(|s| {
        s.spawn(|| {
            std::thread::sleep(Duration::from_millis(400));
            linked.emulator().set_silent(false);
        });
        let t = Instant::now();
        let mut ctl = LedController::open_with(path, o).expect("opens once the device answers");
        assert!(t.elapsed() >= Duration::from_millis(350), "{:?}", t.elapsed());
        assert_eq!(ctl.status().unwrap().state, RunState::Idle);
    });
    // Never answers: a Silent error naming the port, after about ready_timeout.
    linked.emulator().set_silent(true);
    let t = Instant::now();
    let err = LedController::open_with(path, LinkOptions { ready_timeout: Duration::from_millis(600), ..o }).err().expect("silent device");
    assert!(matches!(err, LedError::Silent { .. }), "{err:?}");
    assert!(err.to_string().contains(path));
    assert!(t.elapsed() >= Duration::from_millis(600) && t.elapsed() < Duration::from_secs(3));
}

#[test]
fn a_host_that_does_not_read_replies_loses_replies_not_the_emulator() {
    let (emu, mut raw) = raw_setup();
    // 5000 commands without reading a reply: the emulator stopped ("stopped
    // unexpectedly") after about 2000, its reply write timing out on the full link.
    let sent = 5000u16;
    raw.set_timeout(Duration::from_secs(5)).unwrap();
    for seq in 1..=sent {
        raw.write_all(encode_frame(seq, "STAT").as_bytes()).unwrap();
    }
    let end = Instant::now() + Duration::from_secs(20);
    while emu.lines_seen() < u64::from(sent) && Instant::now() < end {
        std::thread::sleep(Duration::from_millis(10));
    }
    assert_eq!(emu.lines_seen(), u64::from(sent), "every command was read");
    assert!(emu.is_running(), "the emulator is alive");
    // Now read: the replies that waited, then silence.
    raw.set_timeout(Duration::from_millis(200)).unwrap();
    let mut waited = Vec::new();
    let mut buf = [0u8; 4096];
    loop {
        match raw.read(&mut buf) {
            Ok(k) => waited.extend_from_slice(&buf[..k]),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => break,
            Err(e) => panic!("{e}"),
        }
    }
    let waited = String::from_utf8_lossy(&waited).lines().count() as u64;
    assert!(emu.replies_dropped() > 0, "the host read nothing, so some replies were dropped");
    assert_eq!(waited + emu.replies_dropped(), u64::from(sent), "each reply was either delivered whole or dropped");
    // A fresh command is answered correctly.
    raw.write_all(encode_frame(sent + 1, "ID").as_bytes()).unwrap();
    let lines = read_lines(&mut raw, 1, Duration::from_secs(2));
    assert_eq!(lines.len(), 1, "{lines:?}");
    assert!(lines[0].starts_with(&format!("${} ACK name=rollcam-led", sent + 1)), "{lines:?}");
    assert!(emu.is_running());
}
