//! `simulate --captures` and `reconstruct-sequence` end to end, the simulated camera's
//! consecutive frames, and bad input: frames of different sizes, missing timestamps,
//! captures closer than one frame time, a joint solve over the memory limit.

use crate::support::cli;

use cli::{fails, json, ok, rollcam};
use std::path::{Path, PathBuf};

fn usizes(v: &serde_json::Value) -> Vec<usize> {
    v.as_array().unwrap().iter().map(|x| x.as_u64().unwrap() as usize).collect()
}

/// Three 32 x 40 dual-shutter captures (K = 18 frames of 100 us) 2000 us apart.
fn simulate(dir: &Path, name: &str) -> PathBuf {
    let cap = dir.join(name);
    ok(&rollcam(
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
            "3",
            "--frame-period-us",
            "2000",
            "--leds",
            "2",
            "--period-us",
            "1300,900",
            "--no-noise",
        ],
        dir,
    ));
    cap
}

#[test]
fn simulated_captures_reconstruct_as_one_video_with_gaps_flagged() {
    let dir = tempfile::tempdir().unwrap();
    let cap = simulate(dir.path(), "cap");
    for f in ["capture.json", "frame_000000.tiff", "frame_000002.json", "psf.tiff", "capture.toml", "truth.npy"] {
        assert!(cap.join(f).is_file(), "missing {f}");
    }
    assert_eq!(json(&cap.join("frame_000002.json"))["device_timestamp_ns"].as_u64(), Some(4_000_000));
    let c = cap.to_str().unwrap();
    let truth = cap.join("truth.npy");
    for mode in ["joint", "streaming", "separate"] {
        let rec = dir.path().join(format!("rec-{mode}"));
        let text = ok(&rollcam(
            &["reconstruct-sequence", c, "--out", rec.to_str().unwrap(), "--truth", truth.to_str().unwrap(), "--mode", mode, "--iters", "40"],
            dir.path(),
        ));
        assert!(text.contains("placed by device timestamps") && text.contains("4 gap frames"), "{text}");
        let s = json(&rec.join("summary.json"));
        assert_eq!(s["time_source"]["source"], "device-timestamps");
        assert_eq!(usizes(&s["video_shape"]), vec![58, 32, 40, 1]);
        assert_eq!(usizes(&s["gap_frames"]), vec![18, 19, 38, 39]);
        let offsets: Vec<u64> = s["captures"].as_array().unwrap().iter().map(|c| c["offset_frames"].as_u64().unwrap()).collect();
        assert_eq!(offsets, vec![0, 20, 40]);
        let coverage = s["coverage"].as_array().unwrap();
        assert_eq!(coverage.len(), 58);
        assert!(coverage.iter().enumerate().all(|(f, w)| (w.as_f64().unwrap() == 0.0) == [18, 19, 38, 39].contains(&f)));
        assert!(s["psnr_db"].as_f64().unwrap() > 20.0, "{mode}: {}", s["psnr_db"]);
        let solves = s["solves"].as_array().unwrap();
        let warm: Vec<bool> = solves.iter().map(|v| v["warm_start"].as_bool().unwrap()).collect();
        match mode {
            "joint" => assert_eq!(warm, vec![false]),
            "streaming" => assert_eq!(warm, vec![false, true, true]),
            _ => assert_eq!(warm, vec![false, false, false]),
        }
        for f in ["video.tiff", "video.npy", "contact.png", "trace.csv", "coverage.csv"] {
            assert!(rec.join(f).is_file(), "{mode}: missing {f}");
        }
        let csv = std::fs::read_to_string(rec.join("coverage.csv")).unwrap();
        assert!(csv.lines().nth(19).unwrap().starts_with("18,1800.000,0.000000,1,"), "{csv}");
    }
    // The frame period instead of the timestamps: the same grid, said so.
    let rec = dir.path().join("rec-period");
    let text = ok(&rollcam(&["reconstruct-sequence", c, "--out", rec.to_str().unwrap(), "--frame-period-us", "2000", "--iters", "5"], dir.path()));
    assert!(text.contains("a frame period of 2000 us"), "{text}");
    let s = json(&rec.join("summary.json"));
    assert_eq!(s["time_source"]["source"], "frame-period");
    assert_eq!(usizes(&s["gap_frames"]), vec![18, 19, 38, 39]);
}

/// `--l1` reaches a sequence's prior: the video changes with it (the same run without
/// it gives other bytes), in every mode; reweighted L1, which a sequence cannot take, is
/// refused by name.
#[test]
fn the_l1_weight_reaches_a_sequences_solve() {
    let dir = tempfile::tempdir().unwrap();
    let cap = simulate(dir.path(), "cap");
    let c = cap.to_str().unwrap();
    let run = |name: &str, extra: &[&str]| -> Vec<u8> {
        let rec = dir.path().join(name);
        let mut args = vec!["reconstruct-sequence", c, "--out", rec.to_str().unwrap(), "--iters", "15"];
        args.extend_from_slice(extra);
        ok(&rollcam(&args, dir.path()));
        std::fs::read(rec.join("video.npy")).unwrap()
    };
    for mode in ["joint", "streaming", "separate"] {
        let plain = run(&format!("{mode}-plain"), &["--mode", mode]);
        let again = run(&format!("{mode}-again"), &["--mode", mode]);
        assert_eq!(plain, again, "{mode}: the same run gives the same video");
        let sparse = run(&format!("{mode}-l1"), &["--mode", mode, "--l1", "0.5"]);
        assert_ne!(plain, sparse, "{mode}: --l1 0.5 left the video unchanged");
    }
    let rec = dir.path().join("reweight");
    let e = fails(&rollcam(&["reconstruct-sequence", c, "--out", rec.to_str().unwrap(), "--iters", "5", "--l1", "0.5", "--l1-reweight", "1"], dir.path()));
    assert!(e.contains("--l1-reweight = 1: expected 0 for consecutive captures"), "{e}");
}

#[test]
fn simulated_camera_frames_continue_in_time() {
    // The simulated camera at 70 Hz: frames 14285.7 us apart, 64.94 frames of 220 us,
    // so the second capture starts at frame 65 (residue -14.3 us) and shares one frame
    // with the first (K = 66).
    let dir = tempfile::tempdir().unwrap();
    let cap = dir.path().join("cap");
    ok(&rollcam(&["capture", "--camera", "sim:led-array", "--frames", "2", "--frame-rate-hz", "70", "--out", cap.to_str().unwrap()], dir.path()));
    let rec = dir.path().join("rec");
    ok(&rollcam(&["reconstruct-sequence", cap.to_str().unwrap(), "--out", rec.to_str().unwrap(), "--iters", "3"], dir.path()));
    let s = json(&rec.join("summary.json"));
    let offsets: Vec<u64> = s["captures"].as_array().unwrap().iter().map(|c| c["offset_frames"].as_u64().unwrap()).collect();
    assert_eq!(offsets, vec![0, 65]);
    let residue = s["max_residue_us"].as_f64().unwrap();
    assert!((residue - (65.0 * 220.0 - 1e6 / 70.0)).abs() < 0.01, "{residue}");
    assert_eq!(usizes(&s["shared_frames"]), vec![65]);
    assert!(usizes(&s["gap_frames"]).is_empty());
    assert_eq!(usizes(&s["video_shape"]), vec![131, 128, 160, 1]);
}

/// A sequence solves the plain video: a [scene] declaration in capture.toml is named
/// in a warning, not silently left out; provenance alone gives no warning.
#[test]
fn a_scene_declaration_is_reported_as_not_applied() {
    let dir = tempfile::tempdir().unwrap();
    let cap = simulate(dir.path(), "declared");
    let run = |out: &str| {
        let out = dir.path().join(out);
        rollcam(&["reconstruct-sequence", cap.to_str().unwrap(), "--out", out.to_str().unwrap(), "--iters", "2"], dir.path())
    };
    let plain = run("plain");
    ok(&plain);
    assert!(!String::from_utf8_lossy(&plain.stderr).contains("not applied"), "{}", String::from_utf8_lossy(&plain.stderr));
    let toml_path = cap.join("capture.toml");
    let text = std::fs::read_to_string(&toml_path).unwrap();
    assert!(text.contains("\n[scene]\n"), "{text}");
    std::fs::write(&toml_path, text.replace("\n[scene]\n", "\n[scene]\nstatic_background = true\n")).unwrap();
    let declared = run("declared-rec");
    ok(&declared);
    let err = String::from_utf8_lossy(&declared.stderr);
    assert!(err.contains("[scene] declaration is not applied by reconstruct-sequence") && err.contains("capture.toml"), "{err}");
}

#[test]
fn bad_sequences_are_refused_naming_the_file_or_field() {
    let dir = tempfile::tempdir().unwrap();
    let run = |cap: &Path, extra: &[&str]| {
        let out = dir.path().join("rec");
        // One output folder for every attempt: --force lets each write over the last.
        let mut args = vec!["reconstruct-sequence", cap.to_str().unwrap(), "--out", out.to_str().unwrap(), "--iters", "2", "--force"];
        args.extend_from_slice(extra);
        rollcam(&args, dir.path())
    };
    let edit = |path: &Path, key: &str, value: serde_json::Value| {
        let mut v = json(path);
        v[key] = value;
        std::fs::write(path, serde_json::to_string_pretty(&v).unwrap()).unwrap();
    };

    // A frame of another size.
    let cap = simulate(dir.path(), "sizes");
    let frame = cap.join("frame_000001.tiff");
    let bytes = rollcam_hw::record::encode_tiff16(36, 32, &vec![100u16; 36 * 32], &frame).unwrap();
    std::fs::write(&frame, bytes).unwrap();
    edit(&cap.join("frame_000001.json"), "width", 36.into());
    edit(&cap.join("frame_000001.json"), "valid_pixels", (36 * 32).into());
    let e = fails(&run(&cap, &[]));
    assert!(e.contains("frame_000001.tiff") && e.contains("36 x 32") && e.contains("expected 40 x 32"), "{e}");

    // No timestamps: refused without --frame-period-us, accepted with it.
    let cap = simulate(dir.path(), "stamps");
    for f in ["frame_000001.json", "frame_000002.json"] {
        edit(&cap.join(f), "device_timestamp_ns", 0.into());
    }
    let e = fails(&run(&cap, &[]));
    assert!(e.contains("frame_000001.json") && e.contains("device_timestamp_ns") && e.contains("--frame-period-us"), "{e}");
    ok(&run(&cap, &["--frame-period-us", "2000"]));

    // A period shorter than one video frame time (100 us here), given or timestamped.
    let e = fails(&run(&cap, &["--frame-period-us", "60"]));
    assert!(e.contains("--frame-period-us") && e.contains("60 us") && e.contains("one video frame time T_f = 100 us"), "{e}");
    let cap = simulate(dir.path(), "close");
    edit(&cap.join("frame_000001.json"), "device_timestamp_ns", 50_000.into());
    let e = fails(&run(&cap, &[]));
    assert!(e.contains("frame_000001.json") && e.contains("device_timestamp_ns") && e.contains("50 us") && e.contains("one video frame time"), "{e}");
    // Timestamps out of order.
    edit(&cap.join("frame_000001.json"), "device_timestamp_ns", 9_000_000.into());
    let e = fails(&run(&cap, &[]));
    assert!(e.contains("frame_000002.json") && e.contains("not after") && e.contains("frame_000001.json"), "{e}");

    // A joint solve over the memory limit, with the figure; streaming still runs.
    let cap = simulate(dir.path(), "memory");
    let e = fails(&run(&cap, &["--memory-limit-gb", "0.0001"]));
    assert!(
        e.contains("3 captures") && e.contains("58 frames of 32 x 40") && e.contains(" MB, above the limit of 0.10 MB") && e.contains("--mode streaming"),
        "{e}"
    );
    ok(&run(&cap, &["--memory-limit-gb", "0.0001", "--mode", "streaming"]));

    // Key frames belong to one capture's solve: refused, not left out unseen.
    let cap = simulate(dir.path(), "keys");
    std::fs::copy(cap.join("frame_000000.tiff"), cap.join("key.tiff")).unwrap();
    let toml = cap.join("capture.toml");
    let text = std::fs::read_to_string(&toml).unwrap();
    std::fs::write(&toml, format!("{text}\n[[keyframes]]\nfile = \"key.tiff\"\nstart_us = 0.0\nexposure_us = 100.0\n")).unwrap();
    let e = fails(&run(&cap, &[]));
    assert!(e.contains("capture.toml") && e.contains("[[keyframes]]") && e.contains("rollcam reconstruct"), "{e}");
}

#[test]
fn a_frame_without_its_sidecar_is_left_out_aloud() {
    let dir = tempfile::tempdir().unwrap();
    let cap = simulate(dir.path(), "orphan");
    // The recorder writes the sidecar last: an image without one was not finished.
    std::fs::remove_file(cap.join("frame_000002.json")).unwrap();
    let out = dir.path().join("rec");
    let o = rollcam(&["reconstruct-sequence", cap.to_str().unwrap(), "--out", out.to_str().unwrap(), "--iters", "2"], dir.path());
    ok(&o);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("frame_000002.tiff") && err.contains("no sidecar"), "{err}");
    let s = json(&out.join("summary.json"));
    let skipped = s["skipped"].as_array().unwrap();
    assert!(skipped.iter().any(|k| k["file"].as_str().unwrap().ends_with("frame_000002.tiff")), "{skipped:?}");
}
