//! Shared protocol vectors (hw/firmware/vectors.txt) run against the Rust
//! emulator and against the firmware's protocol engine compiled for the host.

use std::path::{Path, PathBuf};
use std::process::Command;

use rollcam_hw::led::emulator::{Device, Identity};
use rollcam_hw::led::protocol::{self, decode_frame, unescape_bytes};

fn firmware_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("firmware")
}

struct Vector {
    line: usize,
    send: Vec<u8>,
    expect: Option<String>,
}

fn vectors() -> Vec<Vector> {
    let text = std::fs::read_to_string(firmware_dir().join("vectors.txt")).unwrap();
    let mut out = Vec::new();
    for (i, l) in text.lines().enumerate() {
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let (send, expect) = l.split_once(" => ").unwrap_or_else(|| panic!("line {}: no ' => '", i + 1));
        out.push(Vector { line: i + 1, send: unescape_bytes(send).unwrap(), expect: (expect != "-").then(|| expect.to_string()) });
    }
    out
}

#[test]
fn vectors_file_is_well_formed() {
    let v = vectors();
    assert!(v.len() >= 60, "{} vectors", v.len());
    for x in &v {
        if let Some(e) = &x.expect {
            decode_frame(e.as_bytes()).unwrap_or_else(|err| panic!("line {}: expected reply invalid: {err}", x.line));
        }
    }
    // Every error code appears at least once.
    for code in protocol::ErrorCode::ALL {
        let needle = format!(" NAK {} {}*", code.code(), code.name());
        assert!(v.iter().any(|x| x.expect.as_deref().is_some_and(|e| e.contains(&needle))), "{needle}");
    }
}

#[test]
fn emulator_matches_vectors() {
    let mut dev = Device::new(Identity { hardware: "test".into(), firmware: "0.1.0".into(), tick_ns: 500 });
    let mut failures = Vec::new();
    for v in vectors() {
        let replies = dev.feed(&v.send, 0);
        let got: String = replies.iter().map(|r| String::from_utf8_lossy(r).into_owned()).collect();
        let want = v.expect.as_ref().map(|e| format!("{e}\n")).unwrap_or_default();
        if got != want {
            failures.push(format!("line {}: expected {:?} got {:?}", v.line, want, got));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn firmware_header_constants_match_rust() {
    let h = std::fs::read_to_string(firmware_dir().join("protocol.h")).unwrap();
    let get = |name: &str| -> u64 {
        let l = h.lines().find(|l| l.starts_with(&format!("#define {name} "))).unwrap_or_else(|| panic!("{name} missing from protocol.h"));
        let v = l.split_whitespace().nth(2).unwrap().trim_end_matches("UL");
        v.parse().unwrap()
    };
    assert_eq!(get("PROTOCOL_VERSION"), protocol::PROTOCOL_VERSION as u64);
    assert_eq!(get("MAX_LINE"), protocol::MAX_LINE as u64);
    assert_eq!(get("CHANNELS"), protocol::CHANNELS as u64);
    assert_eq!(get("MIN_PERIOD_US"), protocol::MIN_PERIOD_US as u64);
    assert_eq!(get("MAX_PERIOD_US"), protocol::MAX_PERIOD_US as u64);
    assert_eq!(get("MIN_WIDTH_US"), protocol::MIN_WIDTH_US as u64);
    assert_eq!(get("MAX_PHASE_US"), protocol::MAX_PHASE_US as u64);
    assert_eq!(get("MAX_COUNT"), protocol::MAX_COUNT as u64);
    assert_eq!(get("MAX_SEQ"), protocol::MAX_SEQ as u64);
    for code in protocol::ErrorCode::ALL {
        assert_eq!(get(&format!("E_{}", code.name())), code.code() as u64, "{}", code.name());
    }
}

fn have(tool: &str) -> bool {
    Command::new(tool).arg("--version").output().is_ok_and(|o| o.status.success())
}

#[test]
fn firmware_protocol_engine_matches_vectors() {
    if !have("cc") {
        eprintln!("SKIPPED: no C compiler 'cc' on this machine; the firmware engine was not checked");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let exe = dir.path().join("host_test");
    let fw = firmware_dir();
    let out = Command::new("cc")
        .args(["-std=c99", "-Wall", "-Wextra", "-Werror", "-O1", "-DHW_NAME=\"test\"", "-DTICK_NS=500", "-o"])
        .arg(&exe)
        .arg(fw.join("host_test.c"))
        .arg(fw.join("proto.c"))
        .output()
        .unwrap();
    assert!(out.status.success(), "cc failed:\n{}", String::from_utf8_lossy(&out.stderr));
    let run = Command::new(&exe).arg(fw.join("vectors.txt")).output().unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    let n = vectors().len();
    assert!(run.status.success(), "firmware engine disagrees with vectors:\n{stdout}");
    assert!(stdout.contains(&format!("{n} passed, 0 failed")), "{stdout}");
}

#[test]
fn firmware_builds_for_atmega328p() {
    if !have("avr-gcc") || !have("make") {
        eprintln!("SKIPPED: avr-gcc or make not installed; firmware not built");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new("make").arg("-C").arg(firmware_dir()).arg(format!("BUILD={}", dir.path().display())).arg("EXTRA_CFLAGS=-Werror").output().unwrap();
    assert!(out.status.success(), "firmware build failed:\n{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    let hex = std::fs::read_to_string(dir.path().join("rollcam-led.hex")).unwrap();
    assert!(hex.lines().count() > 100 && hex.lines().all(|l| l.starts_with(':')));
}

#[test]
fn firmware_timing_in_simavr() {
    let simavr_header = Path::new("/usr/include/simavr/sim_avr.h").exists();
    if !have("avr-gcc") || !have("make") || !have("cc") || !simavr_header {
        eprintln!("SKIPPED: needs avr-gcc, make, cc and libsimavr-dev; firmware timing not simulated");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new("make").arg("-C").arg(firmware_dir()).arg(format!("BUILD={}", dir.path().display())).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let exe = dir.path().join("sim_test");
    let cc = Command::new("cc").args(["-std=gnu99", "-O1", "-o"]).arg(&exe).arg(firmware_dir().join("sim/sim_test.c")).arg("-lsimavr").output().unwrap();
    assert!(cc.status.success(), "{}", String::from_utf8_lossy(&cc.stderr));
    let run = Command::new(&exe).arg(dir.path().join("rollcam-led.elf")).output().unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    eprintln!("{stdout}");
    assert!(run.status.success(), "firmware timing check failed:\n{stdout}");
    assert!(stdout.contains(" passed, 0 failed"), "{stdout}");
    assert!(stdout.contains("isolated edges"), "{stdout}");
}
