//! `rollcam run` under faults injected by the replay camera and the pipeline's test
//! hooks: dropped frame, truncated buffer, stall, disconnect mid-session, slow worker,
//! worker panic, full disk, Ctrl-C (once: drain; twice: checkpoint), and the LED
//! controller emulator. Nothing recorded is ever lost and the counters add up.

use crate::support::pipeline_common;
use pipeline_common::*;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn replay(extra: &[&str], out: &Path, cache: &Path) -> std::process::Output {
    let fix = fixture("led-505hz");
    let cam = format!("replay:{}", fix.display());
    let mut args = vec!["run", "--camera", cam.as_str(), "--out", out.to_str().unwrap(), "--iters", "15"];
    args.extend_from_slice(extra);
    rollcam(&args, cache)
}

fn same_raw(out: &Path, seq: u64) -> bool {
    let name = format!("frame_{seq:06}.tiff");
    std::fs::read(out.join("raw").join(&name)).unwrap() == std::fs::read(fixture("led-505hz").join(&name)).unwrap()
}

#[test]
fn dropped_frame_is_counted_and_the_rest_go_through() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("s");
    let o = replay(&["--replay-drop", "1"], &out, tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let s = session(&out);
    assert_consistent(&s);
    assert_eq!((counter(&s, "captured"), counter(&s, "dropped"), counter(&s, "reconstructed")), (2, 1, 2), "{}", s["counters"]);
    assert_eq!(s["dropped_frames"], serde_json::json!([1]));
    assert_eq!(statuses(&s), vec![(0, "reconstructed".into()), (2, "reconstructed".into())]);
    // The gap is on record (sidecar, no image); the others are byte-identical.
    let side: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("raw/frame_000001.json")).unwrap()).unwrap();
    assert_eq!(side["status"], "dropped");
    assert!(!out.join("raw/frame_000001.tiff").exists());
    assert!(same_raw(&out, 0) && same_raw(&out, 2));
}

#[test]
fn truncated_frame_is_recorded_but_not_reconstructed() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("s");
    let o = replay(&["--replay-truncate", "1"], &out, tmp.path());
    // The run fails (a frame is incomplete) and says which and that no retry helps.
    assert!(!o.status.success(), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("1 frame(s) failed") && err.contains("arrived incomplete") && err.contains("sequence 1") && !err.contains("--retry-failed"), "{err}");
    let s = session(&out);
    assert_consistent(&s);
    assert_eq!((counter(&s, "recorded"), counter(&s, "reconstructed"), counter(&s, "failed"), counter(&s, "incomplete")), (3, 2, 1, 1));
    let f = &s["frames"][1];
    assert_eq!(f["status"], "failed");
    assert_eq!(f["incomplete"], true);
    assert!(f["error"].as_str().unwrap().contains("1536 of 3072 samples"), "{}", f["error"]);
    // What arrived is on disk exactly: the first half as recorded, the rest zero.
    let got = rollcam::io::read_image(out.join("raw/frame_000001.tiff")).unwrap();
    let want = rollcam::io::read_image(fixture("led-505hz").join("frame_000001.tiff")).unwrap();
    let (g, w): (Vec<f32>, Vec<f32>) = (got.iter().cloned().collect(), want.iter().cloned().collect());
    assert_eq!(g[..1536], w[..1536]);
    assert!(g[1536..].iter().all(|&v| v == 0.0));
    assert!(same_raw(&out, 0) && same_raw(&out, 2));
    // Resume leaves it alone: nothing pending.
    assert!(s["pending"].as_array().unwrap().is_empty());
}

#[test]
fn stall_is_waited_out_or_ends_the_session_past_the_limit() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("wait");
    let o = replay(&["--replay-stall", "1:1500", "--timeout-ms", "300"], &out, tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let s = session(&out);
    assert_consistent(&s);
    assert_eq!(counter(&s, "reconstructed"), 3);
    assert!(String::from_utf8_lossy(&o.stderr).contains("no frame from the camera yet"), "{}", text(&o));

    let out = tmp.path().join("limit");
    let o = replay(&["--replay-stall", "1:60000", "--timeout-ms", "200", "--stall-limit-s", "0.6"], &out, tmp.path());
    assert!(!o.status.success(), "{}", text(&o));
    let s = session(&out);
    assert_consistent(&s);
    assert_eq!(s["state"], "failed");
    assert!(s["stop_reason"].as_str().unwrap().contains("no frame for"), "{}", s["stop_reason"]);
    assert_eq!((counter(&s, "recorded"), counter(&s, "reconstructed")), (1, 1));
}

#[test]
fn disconnect_mid_session_keeps_and_reconstructs_what_was_recorded() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("s");
    let o = replay(&["--replay-disconnect-at", "2"], &out, tmp.path());
    assert!(!o.status.success(), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("disconnected") && err.contains("every recorded frame is in"), "{err}");
    let s = session(&out);
    assert_consistent(&s);
    assert_eq!(s["state"], "failed");
    assert!(s["stop_reason"].as_str().unwrap().contains("disconnected"));
    assert_eq!((counter(&s, "recorded"), counter(&s, "reconstructed")), (2, 2));
    assert!(same_raw(&out, 0) && same_raw(&out, 1));
    assert!(s["finished_utc"].is_string());
}

#[test]
fn slow_worker_builds_a_backlog_and_catches_up_in_order() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("s");
    let o = replay(&["--queue", "1", "--worker-delay-ms", "700"], &out, tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let s = session(&out);
    assert_consistent(&s);
    assert_eq!(counter(&s, "reconstructed"), 3);
    // One worker, in order: each video is finished at least one delay after the
    // previous one, and frame 2 waited behind the others (two delays at least).
    let lat: Vec<f64> = (0..3).map(|i| s["frames"][i]["latency_ms"].as_f64().unwrap()).collect();
    let done: Vec<f64> = (0..3).map(|i| s["frames"][i]["host_timestamp_ns"].as_f64().unwrap() / 1e6 + lat[i]).collect();
    assert!(done[1] - done[0] >= 700.0 && done[2] - done[1] >= 700.0, "{done:?}");
    assert!(lat[2] >= 2.0 * 700.0, "{lat:?}");
    assert_eq!(s["latency_ms"]["max"].as_f64().unwrap(), lat.iter().cloned().fold(0.0, f64::max));
}

#[test]
fn worker_panic_fails_one_frame_and_the_session_goes_on() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("s");
    let o = replay(&["--test-panic-on-frame", "1"], &out, tmp.path());
    // The session goes on, and the run exits non-zero naming the failed frame.
    assert!(!o.status.success(), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("1 frame(s) failed") && err.contains("sequence 1") && err.contains("--retry-failed"), "{err}");
    let s = session(&out);
    assert_consistent(&s);
    assert_eq!(s["state"], "finished");
    assert_eq!(statuses(&s), vec![(0, "reconstructed".into()), (1, "failed".into()), (2, "reconstructed".into())]);
    assert!(s["frames"][1]["error"].as_str().unwrap().contains("worker panicked: test hook: deliberate panic on frame 1"), "{}", s["frames"][1]);
    assert!(s["errors"].as_array().unwrap().iter().any(|e| e.as_str().unwrap().starts_with("frame 1: worker panicked")));
    assert!(String::from_utf8_lossy(&o.stdout).contains("worker panicked"), "{}", text(&o));
    assert!(same_raw(&out, 1));

    // A plain resume leaves the failed frame alone (and still fails); --retry-failed
    // reconstructs it, and the run succeeds.
    let o = rollcam(&["run", "--resume", out.to_str().unwrap(), "--iters", "15"], tmp.path());
    assert!(!o.status.success(), "{}", text(&o));
    assert_eq!(statuses(&session(&out))[1], (1, "failed".into()));
    let o = rollcam(&["run", "--resume", out.to_str().unwrap(), "--retry-failed", "--iters", "15"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let s = session(&out);
    assert_consistent(&s);
    assert_eq!(statuses(&s), vec![(0, "reconstructed".into()), (1, "reconstructed".into()), (2, "reconstructed".into())]);
    assert!(out.join("rec/frame_000001/summary.json").is_file());
}

#[test]
fn full_disk_stops_recording_cleanly_and_says_so() {
    let tmp = tempfile::tempdir().unwrap();
    // A reserve larger than any disk: not even the first frame may be written.
    let out = tmp.path().join("reserve");
    let o = replay(&["--min-free-mb", "1000000000000"], &out, tmp.path());
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("disk full") && err.contains("--min-free-mb") && err.contains("recording stopped"), "{err}");
    let s = session(&out);
    assert_consistent(&s);
    assert_eq!(s["state"], "failed");
    assert!(s["stop_reason"].as_str().unwrap().starts_with("disk full"));
    assert_eq!(counter(&s, "recorded"), 0);
    assert!(counter(&s, "unrecorded") >= 1);
    assert_eq!(tiff_count(&out.join("raw")), 0);

    // The file system refuses a write (ENOSPC) at frame 1: frame 0 is safe and reconstructed.
    let out = tmp.path().join("enospc");
    let o = replay(&["--test-fail-write-at", "1"], &out, tmp.path());
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("disk full") && err.to_lowercase().contains("no space left on device"), "{err}");
    let s = session(&out);
    assert_consistent(&s);
    assert_eq!((counter(&s, "recorded"), counter(&s, "reconstructed")), (1, 1));
    assert!(counter(&s, "unrecorded") >= 1);
    assert!(same_raw(&out, 0));
    let cap: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("raw/capture.json")).unwrap()).unwrap();
    assert_eq!(cap["end"]["outcome"], "error");
}

fn wait_for(out: &Path, what: &str, f: impl Fn(&serde_json::Value) -> bool) {
    let t0 = Instant::now();
    loop {
        if let Ok(bytes) = std::fs::read(out.join("session.json")) {
            if let Ok(s) = serde_json::from_slice::<serde_json::Value>(&bytes) {
                if f(&s) {
                    return;
                }
            }
        }
        assert!(t0.elapsed() < Duration::from_secs(120), "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn interrupt(child: &std::process::Child) {
    let st = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(st.success());
}

#[test]
fn ctrl_c_stops_acquisition_and_drains_the_queue() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("s");
    let child = Command::new(env!("CARGO_BIN_EXE_rollcam"))
        .args(["run", "--camera", "sim", "--sim-size", "48x64", "--downsample", "2", "--iters", "5", "--out", out.to_str().unwrap()])
        .env("ROLLCAM_CACHE_DIR", tmp.path())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // While it runs, session.json is refreshed: it says running and counts up.
    wait_for(&out, "two recorded frames", |s| s["state"] == "running" && s["counters"]["recorded"].as_u64().unwrap_or(0) >= 2);
    interrupt(&child);
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let s = session(&out);
    assert_consistent(&s);
    assert_eq!(s["state"], "stopped");
    assert!(s["stop_reason"].as_str().unwrap().contains("Ctrl-C"));
    // Drained: every recorded frame has its video.
    assert!(counter(&s, "recorded") >= 2);
    assert_eq!(counter(&s, "reconstructed"), counter(&s, "recorded"), "{}", s["counters"]);
    assert_eq!(tiff_count(&out.join("raw")) as u64, counter(&s, "recorded"));
}

#[test]
fn second_ctrl_c_leaves_the_queue_for_resume() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("s");
    let child = Command::new(env!("CARGO_BIN_EXE_rollcam"))
        .args(["run", "--camera", "sim", "--sim-size", "48x64", "--downsample", "2", "--iters", "5", "--worker-delay-ms", "30000"])
        .args(["--out", out.to_str().unwrap()])
        .env("ROLLCAM_CACHE_DIR", tmp.path())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    wait_for(&out, "two recorded frames", |s| s["counters"]["recorded"].as_u64().unwrap_or(0) >= 2);
    interrupt(&child);
    std::thread::sleep(Duration::from_millis(500));
    interrupt(&child);
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let s = session(&out);
    assert_consistent(&s);
    assert_eq!(s["state"], "stopped");
    assert!(s["stop_reason"].as_str().unwrap().contains("abandoned"), "{}", s["stop_reason"]);
    let recorded = counter(&s, "recorded");
    assert!(recorded >= 2);
    assert_eq!(counter(&s, "queued"), recorded, "{}", s["counters"]);
    assert_eq!(s["pending"].as_array().unwrap().len() as u64, recorded);

    // As a kill between two writes of session.json leaves it (the probe: "captured 0,
    // recorded 30"; 239 frames listed, 247 on disk): stale counters, the last frame
    // recorded but not listed.
    let mut stale = s.clone();
    stale["counters"]["captured"] = 0.into();
    let unlisted = stale["frames"].as_array_mut().unwrap().pop().unwrap();
    stale["state"] = "running".into();
    std::fs::write(out.join("session.json"), serde_json::to_vec(&stale).unwrap()).unwrap();

    let o = rollcam(&["run", "--resume", out.to_str().unwrap(), "--workers", "2"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let s = session(&out);
    assert_consistent(&s);
    assert_eq!(s["state"], "finished");
    assert_eq!(counter(&s, "reconstructed"), recorded);
    // The frame list and the counters are the disk's.
    let on_disk = std::fs::read_dir(out.join("raw"))
        .unwrap()
        .filter(|e| {
            let name = e.as_ref().unwrap().file_name().to_string_lossy().into_owned();
            name.starts_with("frame_") && name.ends_with(".json")
        })
        .count() as u64;
    assert_eq!(counter(&s, "recorded"), on_disk, "{}", s["counters"]);
    assert!(counter(&s, "captured") >= on_disk, "{}", s["counters"]);
    assert!(s["frames"].as_array().unwrap().iter().any(|f| f["sequence"] == unlisted["sequence"]));
}

#[test]
fn led_emulator_is_programmed_before_acquisition_and_recorded() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("s");
    let o = replay(&["--frames", "1", "--led", "emulator", "--led-period-us", "1980,2640", "--led-phase-us", "100"], &out, tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let s = session(&out);
    assert_consistent(&s);
    let led = &s["led"];
    assert_eq!(led["device"]["name"], "rollcam-led", "{led}");
    let ch = led["channels"].as_array().unwrap();
    assert_eq!(ch.len(), 2, "{led}");
    assert_eq!((ch[0]["period_us"].as_u64(), ch[0]["width_us"].as_u64(), ch[0]["phase_us"].as_u64()), (Some(1980), Some(990), Some(100)));
    assert_eq!(ch[1]["period_us"].as_u64(), Some(2640));
    let cap: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("raw/capture.json")).unwrap()).unwrap();
    assert_eq!(&cap["sync"]["led"], led);
    assert_eq!(cap["sync"]["led_phase_us"], 100.0);
    // A port that does not exist is a clear error before anything is recorded.
    let out = tmp.path().join("noport");
    let o = replay(&["--led", "/dev/ttyNOSUCH0"], &out, tmp.path());
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("/dev/ttyNOSUCH0"), "{}", text(&o));
    assert!(!out.exists());
}
