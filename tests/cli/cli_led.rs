//! `rollcam led emulate` in a child process, driven by `rollcam led --port <link> ...`.

use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_rollcam");

struct Emulator(Child);

impl Drop for Emulator {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn led(link: &Path, args: &[&str]) -> Output {
    Command::new(BIN).arg("led").arg("--port").arg(link).args(args).output().expect("run rollcam")
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn led_cli_against_emulator() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("ttyLED");
    let child =
        Command::new(BIN).args(["led", "emulate", "--link"]).arg(&link).stdin(Stdio::piped()).stdout(Stdio::null()).stderr(Stdio::null()).spawn().unwrap();
    let mut emu = Emulator(child);
    let t = Instant::now();
    while std::fs::symlink_metadata(&link).is_err() {
        assert!(t.elapsed() < Duration::from_secs(10), "emulator link never appeared");
        assert!(emu.0.try_wait().unwrap().is_none(), "emulator exited early");
        std::thread::sleep(Duration::from_millis(20));
    }

    let o = led(&link, &["identify"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("rollcam-led protocol 1"), "{}", stdout(&o));

    let o = led(&link, &["set", "0", "--period-us", "1980", "--duty", "0.5"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("ch0 on  period_us=1980 width_us=990"), "{}", stdout(&o));

    let o = led(&link, &["set", "2", "--period-us", "660", "--width-us", "100", "--phase-us", "50", "--count", "7"]);
    assert!(o.status.success(), "{}", stderr(&o));

    // Out of range: refused, exit status non-zero, the message says why.
    let o = led(&link, &["set", "1", "--period-us", "50", "--duty", "0.5"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("period_us 50"), "{}", stderr(&o));

    let o = led(&link, &["status"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let s = stdout(&o);
    assert!(s.contains("state=IDLE"), "{s}");
    assert!(s.contains("ch0 on  period_us=1980 width_us=990 duty=0.500 phase_us=0 count=continuous"), "{s}");
    assert!(s.contains("ch1 off"), "{s}");
    assert!(s.contains("ch2 on  period_us=660 width_us=100 duty=0.152 phase_us=50 count=7"), "{s}");

    // Trigger before arming: the device refuses with STATE.
    let o = led(&link, &["trigger"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("STATE"), "{}", stderr(&o));

    assert!(led(&link, &["arm"]).status.success());
    assert!(led(&link, &["trigger"]).status.success());
    let o = led(&link, &["--json", "status"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v["status"]["state"], "running");
    assert_eq!(v["status"]["trigger"], "software");
    assert_eq!(v["channels"][0]["config"]["period_us"], 1980);

    let o = led(&link, &["sync"]);
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v["channels"].as_array().unwrap().len(), 2);
    assert_eq!(v["channels"][1]["channel"], 2);
    assert_eq!(v["channels"][1]["phase_us"], 50);

    assert!(led(&link, &["stop"]).status.success());
    assert!(stdout(&led(&link, &["status"])).contains("state=IDLE"));

    // Trigger-input edge typed on the emulator's stdin starts an ARM FALL run.
    assert!(led(&link, &["arm", "--trigger", "fall"]).status.success());
    {
        use std::io::Write;
        let stdin = emu.0.stdin.as_mut().unwrap();
        stdin.write_all(b"rise\n").unwrap();
        stdin.flush().unwrap();
        std::thread::sleep(Duration::from_millis(200));
        assert!(stdout(&led(&link, &["status"])).contains("state=ARMED trigger=FALL"), "rising edge ignored");
        stdin.write_all(b"fall\n").unwrap();
        stdin.flush().unwrap();
    }
    let t = Instant::now();
    loop {
        let s = stdout(&led(&link, &["status"]));
        if s.contains("state=RUNNING trigger=FALL") {
            break;
        }
        assert!(t.elapsed() < Duration::from_secs(5), "falling edge did not start the run: {s}");
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(led(&link, &["stop"]).status.success());

    // Missing port: clear error naming it.
    let o = led(&dir.path().join("nope"), &["status"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("nope") && stderr(&o).contains("not found"), "{}", stderr(&o));

    // SIGTERM: the emulator exits and removes its link.
    let pid = emu.0.id().to_string();
    assert!(Command::new("kill").args(["-TERM", &pid]).status().unwrap().success());
    let t = Instant::now();
    loop {
        if let Some(st) = emu.0.try_wait().unwrap() {
            assert!(st.success(), "emulator exit status {st}");
            break;
        }
        assert!(t.elapsed() < Duration::from_secs(5), "emulator ignored SIGTERM");
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(std::fs::symlink_metadata(&link).is_err(), "link left behind");
}
