//! docs/bench-guide.md, run: its commands in its order against libaravis' fake camera
//! and the LED emulator (calibrate refused there, the live step included), and its
//! rehearsal with the simulated camera (calibrate, the calibrated reconstruction and
//! the live step). Each command is taken from the guide as written (the test fails
//! when the guide changes it); the reconstructions get a short `--iters` besides.

use crate::support::pipeline_common;
use pipeline_common::*;
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

const GUIDE: &str = include_str!("../../docs/bench-guide.md");

/// The settings every shot shares, as the guide sets `name` (`CAM`, `SIM`).
fn var(name: &str) -> String {
    let line = GUIDE.lines().find_map(|l| l.strip_prefix(&format!("{name}=\""))).unwrap_or_else(|| panic!("the guide sets {name}"));
    line.trim_end_matches('"').to_string()
}

/// A command of the guide (checked to be there, verbatim), with `$CAM` and `$SIM`
/// expanded and any comment dropped, run in `dir`; its output.
fn step(dir: &Path, line: &str, extra: &[&str]) -> Output {
    assert!(GUIDE.lines().any(|l| l.starts_with(line)), "the guide has no line `{line}`");
    let expanded = line.replace("$CAM", &var("CAM")).replace("$SIM", &var("SIM"));
    let words: Vec<&str> = expanded.split_whitespace().collect();
    assert_eq!(words[0], "rollcam");
    Command::new(env!("CARGO_BIN_EXE_rollcam"))
        .args(&words[1..])
        .args(extra)
        .current_dir(dir)
        .env("ROLLCAM_CACHE_DIR", dir.join("cache"))
        .env("RUST_LOG", "warn")
        .output()
        .expect("run rollcam")
}

fn ok(o: Output) -> String {
    assert!(o.status.success(), "{}", text(&o));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

#[cfg(feature = "aravis")]
struct Emulator(Child);

#[cfg(feature = "aravis")]
impl Drop for Emulator {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[cfg(feature = "aravis")]
#[test]
fn the_bench_guide_runs_in_order() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // 2. PSF shot, with its check; 3. darks; 4. background.
    let psf = ok(step(dir, "rollcam capture $CAM --kind psf --frames 8 --out shots/psf/", &[]));
    assert!(psf.contains("psf shot (8 frames): peak") && psf.contains("of 65535 counts"), "{psf}");
    assert!(psf.contains("centroid x ") && psf.contains("(column, row, as --roi's x,y)"), "the centroid is labelled as --roi's x,y: {psf}");
    assert!(dir.join("shots/psf/psf-check.json").is_file());
    let dark = ok(step(dir, "rollcam capture $CAM --kind dark --frames 16 --out shots/dark/", &[]));
    assert!(dark.contains("rollcam calibrate --dark shots/dark/"), "{dark}");
    ok(step(dir, "rollcam capture $CAM --kind background --frames 8 --out shots/background/", &[]));
    for (kind, frames) in [("psf", 8), ("dark", 16), ("background", 8)] {
        assert_eq!(rollcam::io::read_stack(dir.join("shots").join(kind)).unwrap().dim().0, frames, "{kind}: the folder calibrate reads");
    }
    // 5. Calibrate: the fake camera shows the same picture capped or not, so its PSF
    // shots hold nothing above the dark, and calibrate says so.
    let o = step(dir, "rollcam calibrate --dark shots/dark/ --psf-shots shots/psf/ --background shots/background/ --out calib/", &[]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("PSF shots"), "{}", text(&o));
    // 6. The LED pulser: the emulator in the background, programmed, armed, its
    // settings recorded.
    let link = dir.join("ttyLED");
    let child = Command::new(env!("CARGO_BIN_EXE_rollcam"))
        .args(["led", "emulate", "--link", "./ttyLED"])
        .current_dir(dir)
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    assert!(GUIDE.contains("rollcam led emulate --link ./ttyLED &"));
    let mut emulator = Emulator(child);
    let t = Instant::now();
    while std::fs::symlink_metadata(&link).is_err() {
        assert!(t.elapsed() < Duration::from_secs(10), "the emulator's link never appeared");
        assert!(emulator.0.try_wait().unwrap().is_none(), "the emulator exited early");
        std::thread::sleep(Duration::from_millis(20));
    }
    ok(step(dir, "rollcam led --port ./ttyLED --ready-ms 0 set 0 --period-us 1980 --duty 0.5", &[]));
    ok(step(dir, "rollcam led --port ./ttyLED --ready-ms 0 arm --trigger rise", &[]));
    let sync = ok(step(dir, "rollcam led --port ./ttyLED --ready-ms 0 sync --trigger rise", &[]));
    assert!(GUIDE.contains("rollcam led --port ./ttyLED --ready-ms 0 sync --trigger rise > led.json"));
    std::fs::write(dir.join("led.json"), &sync).unwrap();
    // 7. Capture: the frame, capture.json with the LED settings, capture.toml; its hint
    // is step 8's command; then the pulser is disarmed.
    let captured = ok(step(dir, "rollcam capture $CAM --frames 1 --exposure-output-line Line1 --led-json led.json --out cap/", &[]));
    assert!(captured.contains("recorded 1 frame to cap/"), "{captured}");
    let step8 = "rollcam reconstruct --raw cap/frame_000000.tiff --config cap/capture.toml --calibration calib/ --out rec/";
    assert!(GUIDE.contains(step8));
    assert!(captured.contains(step8), "the capture's hint is step 8: {captured}");
    let cfg = rollcam::model::capture::CaptureConfig::load(&dir.join("cap/capture.toml")).unwrap();
    assert_eq!((cfg.rows, cfg.cols, cfg.exposure_us, cfg.line_time_us), (48, 64, 5000.0, 220.0));
    let reader = rollcam_hw::record::CaptureReader::open(dir.join("cap")).unwrap();
    assert!(reader.session().sync.led.is_some(), "the LED settings are recorded");
    ok(step(dir, "rollcam led --port ./ttyLED --ready-ms 0 stop", &[]));
    // 8. Reconstruct with no timing flag, a recorded PSF shot in place of calib/, as the
    // guide gives it for the fake camera.
    let out = ok(step(
        dir,
        "rollcam reconstruct --raw cap/frame_000000.tiff --config cap/capture.toml --psf shots/psf/frame_000000.tiff --out rec/",
        &["--iters", "20"],
    ));
    assert!(out.contains("estimated solve time") && out.contains("video: "), "{out}");
    let summary: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("rec/summary.json")).unwrap()).unwrap();
    assert_eq!(summary["capture"]["line_time_us"].as_f64(), Some(220.0));
    // The same, live: the pulser programmed and armed by the run through the emulator
    // still running, every frame recorded and reconstructed.
    assert!(GUIDE.contains(
        "rollcam run $CAM --calibration calib/ --led ./ttyLED --led-period-us 1980 --led-trigger rise --exposure-output-line Line1 --frames 3 --out session/"
    ));
    let live = step(
        dir,
        "rollcam run $CAM --psf shots/psf/frame_000000.tiff --led ./ttyLED --led-period-us 1980 --led-trigger rise --exposure-output-line Line1 --frames 3 --out session/",
        &["--iters", "5"],
    );
    assert!(live.status.success(), "{}", text(&live));
    let s = session(&dir.join("session"));
    assert_eq!((counter(&s, "recorded"), counter(&s, "reconstructed")), (3, 3), "{}", s["counters"]);
    assert!(dir.join("session/rec/frame_000000/video.tiff").is_file());
    drop(emulator);
}

#[test]
fn the_guides_rehearsal_with_the_simulated_camera_calibrates_and_runs_live() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // The calibration shots: a point source judged against the sensor's full well, no
    // light with the cap on or the LEDs off.
    let psf = ok(step(dir, "rollcam capture $SIM --kind psf --frames 8 --out shots/psf/", &[]));
    assert!(psf.contains("psf shot (8 frames): peak") && psf.contains("of 15096 counts (50%)"), "{psf}");
    assert!(!psf.contains("under 30%"), "the point source is bright enough: {psf}");
    ok(step(dir, "rollcam capture $SIM --kind dark --frames 16 --out shots/dark/", &[]));
    ok(step(dir, "rollcam capture $SIM --kind background --frames 8 --out shots/background/", &[]));
    let dark = rollcam::io::read_stack(dir.join("shots/dark")).unwrap();
    let shot = rollcam::io::read_stack(dir.join("shots/psf")).unwrap();
    let peak = |a: &ndarray::Array4<f32>| a.iter().cloned().fold(0.0f32, f32::max);
    assert!(peak(&dark) < 200.0 && peak(&shot) > 5000.0, "dark peak {}, PSF shot peak {}", peak(&dark), peak(&shot));
    // Calibrate succeeds, and its PSF is the camera's diffuser: it matches the PSF the
    // simulated camera writes beside a scene (same diffuser, same seed) to within the
    // shots' noise.
    let cal = ok(step(dir, "rollcam calibrate --dark shots/dark/ --psf-shots shots/psf/ --background shots/background/ --out calib/", &[]));
    assert!(cal.contains("PSF: 8 shots"), "{cal}");
    ok(step(dir, "rollcam capture $SIM --frames 1 --out cap/", &[]));
    let calibrated = rollcam::io::read_image(dir.join("calib/psf.tiff")).unwrap();
    let written = rollcam::io::read_image(dir.join("cap/psf.tiff")).unwrap();
    let unit = |a: &ndarray::Array3<f32>, floor: f32| {
        let v: Vec<f64> = a.iter().map(|&x| (x - floor).max(0.0) as f64).collect();
        let s: f64 = v.iter().sum();
        v.into_iter().map(|x| x / s).collect::<Vec<f64>>()
    };
    let written_dark = written.iter().cloned().fold(f32::INFINITY, f32::min);
    let (a, b) = (unit(&calibrated, 0.0), unit(&written, written_dark));
    let diff: f64 = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).sum();
    assert!(diff < 0.05, "the calibrated PSF differs from the camera's by {diff:.3} (L1 of unit-sum PSFs)");
    // Step 8 with calib/, then the live step with it.
    let out = ok(step(dir, "rollcam reconstruct --raw cap/frame_000000.tiff --config cap/capture.toml --calibration calib/ --out rec/", &["--iters", "20"]));
    assert!(out.contains("video: "), "{out}");
    assert!(dir.join("rec/summary.json").is_file());
    let live = step(dir, "rollcam run $SIM --calibration calib/ --frames 3 --out session/", &["--iters", "5"]);
    assert!(live.status.success(), "{}", text(&live));
    let s = session(&dir.join("session"));
    assert_eq!((counter(&s, "recorded"), counter(&s, "reconstructed")), (3, 3), "{}", s["counters"]);
    // The live step reconstructs with the calibrated PSF, not the simulator's own.
    let psf_source = s["config"]["psf_source"].as_str().unwrap_or_default().to_string();
    assert!(psf_source.ends_with("psf.tiff") && psf_source.contains("calib"), "{}", s["config"]);
    // The session's own copy is the calibrated PSF (the simulator's would differ by its
    // dark floor and the shots' noise).
    let used = rollcam::io::read_image(dir.join("session/psf.tiff")).unwrap();
    assert_eq!(used, calibrated, "the session's psf.tiff is not calib/psf.tiff");
}
