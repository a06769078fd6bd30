//! `rollcam run` end to end on the recorded fixture sessions (replay camera) and the
//! simulated camera: raw frames recorded byte-identical, videos close to the truth,
//! counters consistent, `--live` skipping and `--resume`, refusals of bad input.

use crate::support::pipeline_common;
use pipeline_common::*;

#[test]
fn replayed_fixtures_are_recorded_byte_identical_and_reconstructed_close_to_truth() {
    let tmp = tempfile::tempdir().unwrap();
    for (name, frames) in [("led-505hz", 3u64), ("moving-disc", 2)] {
        let fix = fixture(name);
        let out = tmp.path().join(name);
        let o = rollcam(
            &["run", "--camera", &format!("replay:{}", fix.display()), "--out", out.to_str().unwrap(), "--iters", "60", "--truth-dir", fix.to_str().unwrap()],
            tmp.path(),
        );
        assert!(o.status.success(), "{}", text(&o));
        let s = session(&out);
        assert_eq!(s["state"], "finished", "{s}");
        assert!(s["stop_reason"].as_str().unwrap().contains(&format!("ended after {frames} frames")), "{}", s["stop_reason"]);
        assert_consistent(&s);
        for n in ["captured", "recorded", "reconstructed"] {
            assert_eq!(counter(&s, n), frames, "{n}: {}", s["counters"]);
        }
        for n in ["skipped", "dropped", "failed", "queued", "unrecorded"] {
            assert_eq!(counter(&s, n), 0, "{n}: {}", s["counters"]);
        }
        assert!(s["latency_ms"]["median"].as_f64().unwrap() > 0.0);
        assert!(s["latency_ms"]["max"].as_f64().unwrap() >= s["latency_ms"]["median"].as_f64().unwrap());
        assert!(s["camera"].as_str().unwrap().starts_with("replay:"));
        for seq in 0..frames {
            let raw = format!("frame_{seq:06}.tiff");
            assert_eq!(std::fs::read(out.join("raw").join(&raw)).unwrap(), std::fs::read(fix.join(&raw)).unwrap(), "{name}: {raw} differs");
            let f = &s["frames"][seq as usize];
            assert_eq!(f["raw"], format!("raw/{raw}"));
            assert_eq!(f["status"], "reconstructed");
            assert_eq!(f["video"], format!("rec/frame_{seq:06}/video.tiff"));
            assert!(out.join(f["video"].as_str().unwrap()).is_file());
            assert!(out.join(format!("rec/frame_{seq:06}/summary.json")).is_file());
            assert!(f["psnr_db"].as_f64().is_some());
            // The video matches its own frame's truth, and better than any other frame's.
            let v = video(&out, seq);
            let own = correlation(&v, &truth(&fix, seq));
            eprintln!("{name} frame {seq}: correlation with its truth {own:.3}, PSNR {}", f["psnr_db"]);
            assert!(own > 0.7, "{name} frame {seq}: correlation {own:.3} with the truth");
            for other in (0..frames).filter(|&o| o != seq) {
                let c = correlation(&v, &truth(&fix, other));
                eprintln!("{name} frame {seq}: correlation with frame {other}'s truth {c:.3}");
                assert!(own > c + 0.2, "{name} frame {seq}: own truth {own:.3}, frame {other}'s {c:.3}");
            }
        }
        // Previews: PNGs of the raw and of the latest video, named in the session.
        for (key, file) in [("raw", "preview/latest_raw.png"), ("frame", "preview/latest_frame.png")] {
            assert_eq!(s["preview"][key], file);
            let bytes = std::fs::read(out.join(file)).unwrap();
            assert_eq!(&bytes[1..4], b"PNG", "{file}");
        }
        // The raw capture folder is itself a valid capture, and the session keeps its inputs.
        let cap = rollcam_hw::record::CaptureReader::open(out.join("raw")).unwrap();
        assert_eq!(cap.len() as u64, frames);
        assert_eq!(cap.session().end.as_ref().unwrap().outcome, "completed");
        assert_eq!(std::fs::read(out.join("psf.tiff")).unwrap(), std::fs::read(fix.join("psf.tiff")).unwrap());
        assert_eq!(
            rollcam::model::capture::CaptureConfig::load(&out.join("capture.toml")).unwrap(),
            rollcam::model::capture::CaptureConfig::load(&fix.join("capture.toml")).unwrap()
        );
    }
}

#[test]
fn live_mode_skips_older_frames_and_resume_reconstructs_them() {
    let tmp = tempfile::tempdir().unwrap();
    let fix = fixture("led-505hz");
    let out = tmp.path().join("s");
    let o = run_replay(&fix, &out, &["--iters", "20", "--live", "--queue", "1", "--worker-delay-ms", "3000"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let s = session(&out);
    assert_consistent(&s);
    assert_eq!(s["config"]["policy"], "live");
    assert_eq!(counter(&s, "recorded"), 3);
    assert!(counter(&s, "skipped") >= 1, "{}", s["counters"]);
    assert_eq!(counter(&s, "reconstructed") + counter(&s, "skipped"), 3, "{}", s["counters"]);
    // The newest frame is always reconstructed.
    assert_eq!(s["frames"][2]["status"], "reconstructed");
    let skipped: Vec<u64> = statuses(&s).into_iter().filter(|(_, st)| st == "skipped").map(|(q, _)| q).collect();
    assert_eq!(s["pending"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap()).collect::<Vec<_>>(), skipped);
    assert!(String::from_utf8_lossy(&o.stdout).contains("--resume"), "{}", text(&o));
    // Every skipped raw is on disk.
    assert_eq!(tiff_count(&out.join("raw")), 3);

    // A later resume reconstructs them.
    let o = rollcam(&["run", "--resume", out.to_str().unwrap()], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let s = session(&out);
    assert_consistent(&s);
    assert_eq!(s["state"], "finished");
    assert_eq!(counter(&s, "reconstructed"), 3, "{}", s["counters"]);
    assert_eq!(counter(&s, "skipped"), 0);
    assert!(s["pending"].as_array().unwrap().is_empty());
    assert_eq!(s["resumes"].as_array().unwrap().len(), 1);
    for q in skipped {
        assert!(out.join(format!("rec/frame_{q:06}/summary.json")).is_file());
    }

    // With a longer queue the worker still takes the newest frame and skips the rest.
    let out = tmp.path().join("q3");
    let o = run_replay(&fix, &out, &["--iters", "20", "--live", "--queue", "3", "--worker-delay-ms", "3000"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let s = session(&out);
    assert_consistent(&s);
    assert!(counter(&s, "skipped") >= 1, "{}", s["counters"]);
    assert_eq!(s["frames"][2]["status"], "reconstructed");
}

#[test]
fn resume_finds_recorded_frames_the_session_file_never_listed() {
    let tmp = tempfile::tempdir().unwrap();
    let fix = fixture("moving-disc");
    let out = tmp.path().join("s");
    let o = run_replay(&fix, &out, &["--iters", "10", "--frames", "2"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    // The recording carries its truth videos: without --truth-dir they are still used.
    for f in session(&out)["frames"].as_array().unwrap() {
        assert!(f["psnr_db"].as_f64().is_some_and(|p| p > 10.0), "frame without a PSNR against the recorded truth: {f}");
    }
    // As if the process had died right after recording frame 1: the session file
    // still says running and does not list it, its video is absent.
    let mut s = session(&out);
    s["frames"].as_array_mut().unwrap().truncate(1);
    s["state"] = "running".into();
    std::fs::write(out.join("session.json"), serde_json::to_vec(&s).unwrap()).unwrap();
    std::fs::remove_dir_all(out.join("rec/frame_000001")).unwrap();
    let o = rollcam(&["run", "--resume", out.to_str().unwrap()], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let s = session(&out);
    assert_consistent(&s);
    assert_eq!(counter(&s, "recorded"), 2);
    assert_eq!(counter(&s, "reconstructed"), 2);
    assert!(out.join("rec/frame_000001/summary.json").is_file());
    assert!(s["resumes"][0].as_str().unwrap().contains("1 found on disk unlisted"), "{}", s["resumes"]);
}

#[test]
fn a_used_output_folder_is_refused_unless_resuming() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("s");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("notes.txt"), "keep me").unwrap();
    let fix = fixture("led-505hz");
    let o = run_replay(&fix, &out, &[], tmp.path());
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("not empty") && err.contains("--resume") && err.contains(out.to_str().unwrap()), "{err}");
    assert_eq!(std::fs::read_to_string(out.join("notes.txt")).unwrap(), "keep me");
    assert!(!out.join("session.json").exists() && !out.join("raw").exists());
    // --resume of a folder that holds no session says so.
    let o = rollcam(&["run", "--resume", out.to_str().unwrap()], tmp.path());
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("session.json"), "{}", text(&o));
}

#[test]
fn contradictory_or_invalid_timing_is_refused_before_acquisition() {
    let tmp = tempfile::tempdir().unwrap();
    let fix = fixture("led-505hz");
    let base = std::fs::read_to_string(fix.join("capture.toml")).unwrap();
    let cases = [
        ("exposure.toml", base.replace("exposure_us = 660.0", "exposure_us = 880.0"), "exposure_us"),
        ("line.toml", base.replace("line_time_us = 220.0", "line_time_us = 200.0"), "line_time_us"),
        ("short.toml", base.replace("exposure_us = 660.0", "exposure_us = 100.0"), "exposure_us"),
        ("size.toml", base.replace("rows = 48", "rows = 40"), "rows"),
        ("typo.toml", format!("{base}\nexposure = 3\n"), "exposure"),
    ];
    for (file, content, field) in cases {
        let cfg = tmp.path().join(file);
        std::fs::write(&cfg, content).unwrap();
        let out = tmp.path().join(format!("out-{file}"));
        let o =
            rollcam(&["run", "--camera", &format!("replay:{}", fix.display()), "--config", cfg.to_str().unwrap(), "--out", out.to_str().unwrap()], tmp.path());
        assert!(!o.status.success(), "{file}: {}", text(&o));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(field) && err.contains(file), "{file}: {err}");
        assert!(!out.exists(), "{file}: the session folder was created");
    }
    // A camera that does not exist: the error names it.
    let out = tmp.path().join("nocam");
    let o = rollcam(&["run", "--camera", "replay:/no/such/capture", "--out", out.to_str().unwrap()], tmp.path());
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("/no/such/capture") && err.contains("not found"), "{err}");
    assert!(!out.exists());
    let o = rollcam(&["run", "--camera", "usb3:cam0", "--out", out.to_str().unwrap()], tmp.path());
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("unknown backend"), "{}", text(&o));
}

#[test]
fn simulated_camera_rehearsal_records_and_reconstructs_with_truth() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("s");
    let o = rollcam(
        &[
            "run",
            "--camera",
            "sim",
            "--sim-scene",
            "led-array",
            "--sim-size",
            "48x64",
            "--downsample",
            "2",
            "--frames",
            "2",
            "--iters",
            "40",
            "--out",
            out.to_str().unwrap(),
        ],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let s = session(&out);
    assert_consistent(&s);
    assert_eq!(s["state"], "finished");
    assert_eq!(s["camera"], "sim:led-array");
    assert_eq!(counter(&s, "reconstructed"), 2);
    for seq in 0..2 {
        let v = video(&out, seq);
        let t = truth(&out.join("sim"), seq);
        let c = correlation(&v, &t);
        assert!(c > 0.6, "frame {seq}: correlation {c:.3}");
        assert!(s["frames"][seq as usize]["psnr_db"].as_f64().is_some());
    }
    // The same seed gives the fixture generator's frames: byte-identical raws.
    let fix = fixture("led-505hz");
    let out2 = tmp.path().join("s2");
    let o = rollcam(
        &[
            "run",
            "--camera",
            "sim",
            "--sim-scene",
            "led-array",
            "--sim-period-us",
            "1980",
            "--sim-size",
            "48x64",
            "--downsample",
            "2",
            "--seed",
            "7",
            "--frames",
            "1",
            "--iters",
            "1",
            "--out",
            out2.to_str().unwrap(),
        ],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(std::fs::read(out2.join("raw/frame_000000.tiff")).unwrap(), std::fs::read(fix.join("frame_000000.tiff")).unwrap());
    assert_eq!(std::fs::read(out2.join("sim/truth_000000.npy")).unwrap(), std::fs::read(fix.join("truth_000000.npy")).unwrap());
}

/// A long rehearsal keeps its content: the moving disc bounces off the edges instead
/// of leaving the field after two frames; and the old `--scene` is refused with a pointer.
#[test]
fn the_moving_disc_rehearsal_has_the_disc_in_every_frame() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("s");
    let args = |scene_flag: &'static str| {
        vec!["run", "--camera", "sim", scene_flag, "moving-disc", "--sim-size", "48x64", "--frames", "8", "--iters", "1", "--outputs", "minimal"]
    };
    let mut old = args("--scene");
    old.extend(["--out", out.to_str().unwrap()]);
    let o = rollcam(&old, tmp.path());
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("--sim-scene moving-disc"), "{}", text(&o));
    assert!(!out.exists());
    let mut new = args("--sim-scene");
    new.extend(["--out", out.to_str().unwrap()]);
    let o = rollcam(&new, tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    for seq in 0..8 {
        let t = truth(&out.join("sim"), seq);
        let peak = t.iter().cloned().fold(0.0f32, f32::max);
        let mean = t.iter().sum::<f32>() / t.len() as f32;
        assert!(peak > 4.0 * mean && peak > 0.0, "frame {seq}: no disc (peak {peak}, mean {mean})");
    }
}

#[test]
fn the_psf_beside_the_config_is_used_and_its_absence_is_named() {
    // A recording without its calibration, and a bench folder (bench.toml + psf.tiff)
    // as a user keeps it: `run --config bench/bench.toml` finds the PSF beside it.
    let tmp = tempfile::tempdir().unwrap();
    let fix = fixture("led-505hz");
    let rec = tmp.path().join("recording");
    std::fs::create_dir_all(&rec).unwrap();
    for e in std::fs::read_dir(&fix).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_str().unwrap().to_string();
        if name.starts_with("frame_") || name == "capture.json" {
            std::fs::copy(&p, rec.join(&name)).unwrap();
        }
    }
    let bench = tmp.path().join("bench");
    std::fs::create_dir_all(&bench).unwrap();
    std::fs::copy(fix.join("capture.toml"), bench.join("bench.toml")).unwrap();
    let camera = format!("replay:{}", rec.display());
    let cfg = bench.join("bench.toml");

    let out = tmp.path().join("without");
    let o = rollcam(&["run", "--camera", &camera, "--config", cfg.to_str().unwrap(), "--out", out.to_str().unwrap()], tmp.path());
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("no PSF") && err.contains("--psf") && err.contains("beside the --config"), "{err}");
    assert!(!out.exists());

    std::fs::copy(fix.join("psf.tiff"), bench.join("psf.tiff")).unwrap();
    let out = tmp.path().join("with");
    let o = rollcam(&["run", "--camera", &camera, "--config", cfg.to_str().unwrap(), "--out", out.to_str().unwrap(), "--iters", "10"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(std::fs::read(out.join("psf.tiff")).unwrap(), std::fs::read(fix.join("psf.tiff")).unwrap());
    assert_eq!(counter(&session(&out), "reconstructed"), 3);
}
