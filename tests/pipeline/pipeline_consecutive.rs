//! `rollcam run --consecutive`: the stream of raw frames as one continuous video. The
//! session's `sequence/video.npy` must be byte-identical to what
//! `reconstruct-sequence --mode streaming` makes of the recorded raw folder with the same
//! flags; a dropped frame shows up as flagged gap frames with the later captures at
//! their true times; `--resume` rebuilds the stream from the recorded raws; the modes
//! that break the order are refused.

use crate::support::pipeline_common;

use pipeline_common::{assert_consistent, counter, rollcam, session, text};
use std::path::{Path, PathBuf};

/// Four 32 x 40 dual-shutter captures (K = 18 frames of 100 us), continuous readout
/// (1600 us apart: 2 frames shared by neighbours), device timestamps in the sidecars.
fn simulate(dir: &Path) -> PathBuf {
    let cap = dir.join("cap");
    let o = rollcam(
        &[
            "simulate",
            "--out",
            cap.to_str().unwrap(),
            "--rows",
            "32",
            "--cols",
            "40",
            "--line-time-us",
            "100",
            "--exposure-us",
            "300",
            "--captures",
            "4",
            "--leds",
            "2",
            "--period-us",
            "1300,900",
            "--no-noise",
        ],
        dir,
    );
    assert!(o.status.success(), "{}", text(&o));
    cap
}

const SOLVER: [&str; 4] = ["--tau", "0.01", "--iters", "20"];

/// `run --consecutive` on a replay of `cap` into `out`.
fn run_consecutive(cap: &Path, out: &Path, extra: &[&str], cache: &Path) {
    let camera = format!("replay:{}", cap.display());
    let mut args = vec!["run", "--camera", &camera, "--out", out.to_str().unwrap(), "--consecutive"];
    args.extend(SOLVER);
    args.extend(extra);
    let o = rollcam(&args, cache);
    assert!(o.status.success(), "{}", text(&o));
}

/// `reconstruct-sequence --mode streaming` on the session's recorded raw folder.
fn reference(session_dir: &Path, out: &Path, cache: &Path) -> serde_json::Value {
    let raw = session_dir.join("raw");
    let (psf, cfg) = (session_dir.join("psf.tiff"), session_dir.join("capture.toml"));
    let mut args = vec![
        "reconstruct-sequence",
        raw.to_str().unwrap(),
        "--psf",
        psf.to_str().unwrap(),
        "--config",
        cfg.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--mode",
        "streaming",
    ];
    args.extend(SOLVER);
    let o = rollcam(&args, cache);
    assert!(o.status.success(), "{}", text(&o));
    serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap()
}

fn bytes(p: &Path) -> Vec<u8> {
    std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

fn usizes(v: &serde_json::Value) -> Vec<usize> {
    v.as_array().unwrap_or_else(|| panic!("not an array: {v}")).iter().map(|x| x.as_u64().unwrap() as usize).collect()
}

#[test]
fn the_stream_equals_the_streaming_reconstruction_and_resume_rebuilds_it() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = simulate(tmp.path());
    let out = tmp.path().join("s");
    run_consecutive(&cap, &out, &[], tmp.path());
    let s = session(&out);
    assert_consistent(&s);
    assert_eq!((counter(&s, "captured"), counter(&s, "reconstructed"), counter(&s, "dropped")), (4, 4, 0), "{}", s["counters"]);
    assert_eq!(s["config"]["consecutive"]["warm_start"], true);

    let refdir = tmp.path().join("ref");
    let r = reference(&out, &refdir, tmp.path());
    let seq = out.join("sequence");
    assert!(bytes(&seq.join("video.npy")) == bytes(&refdir.join("video.npy")), "the live stream's video differs from reconstruct-sequence --mode streaming");
    assert_eq!(bytes(&seq.join("coverage.csv")), bytes(&refdir.join("coverage.csv")));
    let live: serde_json::Value = serde_json::from_slice(&bytes(&seq.join("summary.json"))).unwrap();
    assert_eq!(live["video_shape"], r["video_shape"]);
    assert_eq!(live["solves"].as_array().unwrap().len(), 4);

    // Per capture: its frames on the global grid, as the reference placed them.
    let k = r["frames_per_capture"].as_u64().unwrap() as usize;
    assert_eq!(k, 18);
    for (c, f) in s["frames"].as_array().unwrap().iter().enumerate() {
        let o = r["captures"][c]["offset_frames"].as_u64().unwrap() as usize;
        assert_eq!(usizes(&f["sequence_frames"]["frames"]), vec![o, o + k], "capture {c}: {}", f["sequence_frames"]);
        assert_eq!(f["sequence_frames"]["capture"], c);
        assert!(usizes(&f["sequence_frames"]["gap_frames_before"]).is_empty());
        assert_eq!(f["video"], "sequence/video.npy");
        assert!(out.join(format!("rec/frame_{c:06}/summary.json")).is_file());
    }
    let st = &s["sequence"];
    assert_eq!(st["captures"], 4);
    assert_eq!(st["frames"], r["video_shape"][0]);
    assert!(usizes(&st["gap_frames"]).is_empty());
    // The session ended with nothing pending: every frame is final.
    let last_offset = r["captures"][3]["offset_frames"].as_u64().unwrap();
    assert_eq!(st["final_frames"], st["frames"], "{st}");
    assert_eq!(live["live"]["final_frames"], st["frames"]);

    // As if the process had died after capture 1: captures 2 and 3 pending, the
    // continuous video gone. --resume re-feeds 0 and 1, then reconstructs 2 and 3.
    let original = bytes(&seq.join("video.npy"));
    let mut s = session(&out);
    for f in &mut s["frames"].as_array_mut().unwrap()[2..] {
        f["status"] = "recorded".into();
        f["video"] = serde_json::Value::Null;
        f["sequence_frames"] = serde_json::Value::Null;
    }
    s["state"] = "running".into();
    s["sequence"] = serde_json::Value::Null;
    std::fs::write(out.join("session.json"), serde_json::to_vec(&s).unwrap()).unwrap();
    std::fs::remove_dir_all(&seq).unwrap();
    // A resume while another process holds the session is refused before the stream
    // is rebuilt (the rebuild solved every window first, then found the lock taken).
    {
        let _held = rollcam::lab::pipeline::lock::SessionLock::acquire(&out).unwrap();
        let o = rollcam(&["run", "--resume", out.to_str().unwrap()], tmp.path());
        assert!(!o.status.success());
        assert!(String::from_utf8_lossy(&o.stderr).contains("in use by process"), "{}", text(&o));
        assert!(!String::from_utf8_lossy(&o.stdout).contains("rebuilding"), "{}", text(&o));
    }
    // Order matters: two workers are refused.
    let o = rollcam(&["run", "--resume", out.to_str().unwrap(), "--workers", "2"], tmp.path());
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--workers 1"), "{}", text(&o));
    let o = rollcam(&["run", "--resume", out.to_str().unwrap()], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let s = session(&out);
    assert_consistent(&s);
    assert_eq!((counter(&s, "reconstructed"), s["state"].as_str().unwrap()), (4, "finished"));
    assert!(bytes(&seq.join("video.npy")) == original, "the resumed stream differs from the uninterrupted one");
    assert_eq!(s["sequence"]["final_frames"], s["sequence"]["frames"]);
    assert_eq!(usizes(&s["frames"][3]["sequence_frames"]["frames"]), usizes(&serde_json::json!([last_offset, last_offset as usize + k])));
}

#[test]
fn a_dropped_frame_is_a_flagged_gap_not_a_shifted_time_axis() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = simulate(tmp.path());
    let out = tmp.path().join("s");
    run_consecutive(&cap, &out, &["--replay-drop", "1", "--outputs", "video"], tmp.path());
    let s = session(&out);
    assert_consistent(&s);
    assert_eq!((counter(&s, "captured"), counter(&s, "reconstructed"), counter(&s, "dropped")), (3, 3, 1), "{}", s["counters"]);
    let frames = s["frames"].as_array().unwrap();
    assert_eq!(frames.iter().map(|f| f["sequence"].as_u64().unwrap()).collect::<Vec<_>>(), vec![0, 2, 3]);
    // Captures 1600 us = 16 frames apart: the one after the drop starts at frame 32.
    let place: Vec<Vec<usize>> = frames.iter().map(|f| usizes(&f["sequence_frames"]["frames"])).collect();
    assert_eq!(place, vec![vec![0, 18], vec![32, 50], vec![48, 66]]);
    let gap: Vec<usize> = (18..32).collect();
    assert_eq!(usizes(&frames[1]["sequence_frames"]["gap_frames_before"]), gap);
    assert_eq!(usizes(&s["sequence"]["gap_frames"]), gap);
    assert_eq!(s["sequence"]["frames"], 66);

    let refdir = tmp.path().join("ref");
    let r = reference(&out, &refdir, tmp.path());
    assert_eq!(usizes(&r["gap_frames"]), gap);
    let seq = out.join("sequence");
    assert!(bytes(&seq.join("video.npy")) == bytes(&refdir.join("video.npy")), "video differs from reconstruct-sequence --mode streaming");
    let cov = String::from_utf8(bytes(&seq.join("coverage.csv"))).unwrap();
    assert_eq!(cov.lines().filter(|l| l.split(',').nth(3) == Some("1")).count(), 14, "{cov}");
    // --outputs video: no TIFF stack, no contact sheet.
    assert!(!seq.join("video.tiff").exists() && !seq.join("contact.png").exists());
}

#[test]
fn modes_that_break_the_order_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let fix = pipeline_common::fixture("led-505hz");
    let camera = format!("replay:{}", fix.display());
    for (extra, needle) in [(vec!["--live"], "--live"), (vec!["--workers", "2"], "--workers 1")] {
        let out = tmp.path().join(format!("s{}", extra.len()));
        let mut args = vec!["run", "--camera", &camera, "--out", out.to_str().unwrap(), "--consecutive"];
        args.extend(extra.iter());
        let o = rollcam(&args, tmp.path());
        assert!(!o.status.success(), "{}", text(&o));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("--consecutive") && err.contains(needle), "{err}");
        assert!(!out.exists(), "nothing is created before the refusal");
    }
}

/// The continuous video is the plain one: a scene declaration in the capture's
/// capture.toml is named in a warning, not silently left out.
#[test]
fn a_scene_declaration_is_reported_as_not_applied() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = simulate(tmp.path());
    let toml_path = cap.join("capture.toml");
    let original = std::fs::read_to_string(&toml_path).unwrap();
    assert!(original.contains("\n[scene]\n"), "{original}");
    let camera = format!("replay:{}", cap.display());
    let run = |out: &str| {
        let out = tmp.path().join(out);
        let mut args = vec!["run", "--camera", &camera, "--out", out.to_str().unwrap(), "--consecutive"];
        args.extend(SOLVER);
        let o = rollcam(&args, tmp.path());
        assert!(o.status.success(), "{}", text(&o));
        text(&o)
    };
    assert!(!run("plain").contains("not applied"));
    std::fs::write(&toml_path, original.replace("\n[scene]\n", "\n[scene]\nstatic_background = true\n")).unwrap();
    let t = run("declared");
    assert!(t.contains("[scene] declaration is not applied by --consecutive"), "{t}");
}
