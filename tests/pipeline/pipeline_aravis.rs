//! `rollcam run` with libaravis' fake GenICam camera (rollcam's XML: rolling-shutter
//! features): configured from a capture.toml, frames recorded and reconstructed
//! through the same pipeline as any camera.
#![cfg(feature = "aravis")]

use crate::support::pipeline_common;
use pipeline_common::*;

#[test]
fn aravis_fake_camera_runs_through_the_pipeline() {
    let tmp = tempfile::tempdir().unwrap();
    let fix = fixture("led-505hz");
    let out = tmp.path().join("s");
    // The fake camera scales its ramp by 1 + gain + log10(exposure / 10 ms): all zero at
    // gain 0 below 1 ms (the fixture's 660 us; a raw with no light is refused), the ramp
    // as drawn at 10 ms.
    let config = tmp.path().join("capture.toml");
    let fixture_toml = std::fs::read_to_string(fix.join("capture.toml")).unwrap();
    std::fs::write(&config, fixture_toml.replace("exposure_us = 660.0", "exposure_us = 10000.0")).unwrap();
    let o = rollcam(
        &[
            "run",
            "--camera",
            "aravis:Fake_1",
            "--roi",
            "0,0,64,48",
            "--pixel-format",
            "Mono16",
            "--config",
            config.to_str().unwrap(),
            "--psf",
            fix.join("psf.tiff").to_str().unwrap(),
            "--frames",
            "3",
            "--iters",
            "5",
            "--out",
            out.to_str().unwrap(),
        ],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let s = session(&out);
    assert_consistent(&s);
    assert_eq!(s["state"], "finished");
    assert_eq!(s["camera"], "aravis:Fake_1");
    assert_eq!((counter(&s, "captured"), counter(&s, "recorded"), counter(&s, "reconstructed")), (3, 3, 3), "{}", s["counters"]);
    let cap = rollcam_hw::record::CaptureReader::open(out.join("raw")).unwrap();
    assert_eq!(cap.len(), 3);
    let applied = cap.session().applied.clone().unwrap();
    assert_eq!((applied.roi.width, applied.roi.height), (64, 48));
    assert_eq!(applied.exposure_us, 10_000.0);
    assert!((applied.line_time_us.unwrap() - 220.0).abs() < 0.5, "{applied:?}");
    for i in 0..3 {
        let f = cap.read_frame(i).unwrap();
        assert_eq!(f.pixels.len(), 64 * 48);
        assert!(out.join(format!("rec/frame_{:06}/summary.json", f.meta.sequence)).is_file());
    }
}

#[test]
fn a_missing_camera_is_named_with_what_is_available() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("s");
    let o = rollcam(&["run", "--camera", "aravis:NoSuchCamera", "--psf", "x.tiff", "--out", out.to_str().unwrap()], tmp.path());
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("NoSuchCamera") && err.contains("not found") && (err.contains("available") || err.contains("no cameras found")), "{err}");
    assert!(!out.exists());
}

/// `rollcam capture` writes the capture description of what the camera applied, and
/// `reconstruct` takes it with no timing flag.
#[test]
fn a_capture_describes_itself_and_reconstructs_without_timing_flags() {
    let tmp = tempfile::tempdir().unwrap();
    let fix = fixture("led-505hz");
    let cap = tmp.path().join("cap");
    let o = rollcam(
        &["capture", "--camera", "aravis:Fake_1", "--roi", "0,0,64,48", "--pixel-format", "Mono8", "--frames", "2", "--out", cap.to_str().unwrap()],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let cfg = rollcam::model::capture::CaptureConfig::load(&cap.join("capture.toml")).unwrap();
    let applied = rollcam_hw::record::CaptureReader::open(&cap).unwrap().session().applied.clone().unwrap();
    assert_eq!((cfg.rows, cfg.cols, cfg.saturation_level), (48, 64, Some(255.0)));
    assert_eq!((cfg.exposure_us, Some(cfg.line_time_us)), (applied.exposure_us, applied.line_time_us));
    assert_eq!(rollcam::lab::hardware::camera_shutter(cfg.shutter), applied.shutter);
    let camera = cfg.camera.as_ref().expect("[camera] provenance");
    assert_eq!((camera["pixel_format"].as_str(), camera["bit_depth"].as_integer()), (Some("Mono8"), Some(8)));
    let rec = tmp.path().join("rec");
    let o = rollcam(
        &[
            "reconstruct",
            "--raw",
            cap.join("frame_000000.tiff").to_str().unwrap(),
            "--psf",
            fix.join("psf.tiff").to_str().unwrap(),
            "--config",
            cap.join("capture.toml").to_str().unwrap(),
            "--iters",
            "3",
            "--out",
            rec.to_str().unwrap(),
        ],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let summary: serde_json::Value = serde_json::from_slice(&std::fs::read(rec.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["capture"]["exposure_us"].as_f64(), Some(applied.exposure_us));
}

/// `rollcam run` without a capture.toml takes the timing the camera reports.
#[test]
fn run_takes_its_timing_from_the_camera() {
    let tmp = tempfile::tempdir().unwrap();
    let fix = fixture("led-505hz");
    let out = tmp.path().join("s");
    let o = rollcam(
        &[
            "run",
            "--camera",
            "aravis:Fake_1",
            "--roi",
            "0,0,64,48",
            "--psf",
            fix.join("psf.tiff").to_str().unwrap(),
            "--frames",
            "1",
            "--iters",
            "3",
            "--out",
            out.to_str().unwrap(),
        ],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let s = session(&out);
    assert_eq!(s["state"], "finished");
    assert_eq!(counter(&s, "reconstructed"), 1, "{}", s["counters"]);
    let applied = rollcam_hw::record::CaptureReader::open(out.join("raw")).unwrap().session().applied.clone().unwrap();
    let cfg = rollcam::model::capture::CaptureConfig::load(&out.join("capture.toml")).unwrap();
    assert_eq!((cfg.exposure_us, Some(cfg.line_time_us)), (applied.exposure_us, applied.line_time_us));
}

/// Calibration shots with `rollcam capture --kind`: each folder is what `calibrate`
/// reads, the PSF shots come with their check.
#[test]
fn calibration_shots_are_captured_in_the_layout_calibrate_reads() {
    let tmp = tempfile::tempdir().unwrap();
    let cam = ["--camera", "aravis:Fake_1", "--roi", "0,0,64,48", "--pixel-format", "Mono8"];
    for kind in ["dark", "psf"] {
        let out = tmp.path().join(kind);
        let mut args = vec!["capture", "--kind", kind, "--frames", "4", "--out", out.to_str().unwrap()];
        args.extend(cam);
        let o = rollcam(&args, tmp.path());
        assert!(o.status.success(), "{}", text(&o));
        let stdout = String::from_utf8_lossy(&o.stdout);
        let flag = if kind == "dark" { "--dark" } else { "--psf-shots" };
        assert!(stdout.contains(&format!("rollcam calibrate {flag} {}", out.display())), "{stdout}");
        let cfg = rollcam::model::capture::CaptureConfig::load(&out.join("capture.toml")).unwrap();
        assert_eq!(cfg.camera.as_ref().unwrap()["shot"].as_str(), Some(kind));
        if kind == "psf" {
            assert!(stdout.contains("psf shot (4 frames): peak") && stdout.contains("of 255 counts"), "{stdout}");
            let check: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("psf-check.json")).unwrap()).unwrap();
            assert_eq!(check["frames"], 4);
            assert!(check["spread_px"].as_f64().unwrap() > 0.0, "{check}");
        }
    }
    let stack = rollcam::io::read_stack(tmp.path().join("dark")).unwrap();
    assert_eq!(stack.dim(), (4, 48, 64, 1), "the folder reads as its four frames");
}

/// A 16-bit PSF (a point source at up to 60000 counts over a pedestal of 300) for a
/// 64 x 48 frame.
fn psf_16_bit(path: &std::path::Path) {
    let mut psf = ndarray::Array3::<f32>::from_elem((48, 64, 1), 300.0);
    for (r, c, peak) in [(20usize, 30usize, 60000.0f32), (25, 36, 40000.0), (18, 40, 30000.0), (30, 28, 50000.0)] {
        for dr in 0..5 {
            for dc in 0..5 {
                let v = peak * 0.5f32.powi((dr as i32 - 2).abs() + (dc as i32 - 2).abs());
                let p = &mut psf[(r + dr - 2, c + dc - 2, 0)];
                *p = p.max(v);
            }
        }
    }
    rollcam::io::write_tiff_u16(path, psf.view()).unwrap();
}

/// An 8-bit camera (saturation level 255, from its bit depth) with a 16-bit PSF: the
/// PSF is judged by its own file's full scale and dark level, and the session writes
/// its videos; a PSF with no light is refused once per frame, its message not repeated.
#[test]
fn an_8_bit_camera_reconstructs_with_a_16_bit_psf() {
    let tmp = tempfile::tempdir().unwrap();
    let psf = tmp.path().join("psf16.tiff");
    psf_16_bit(&psf);
    let cam =
        ["--camera", "aravis:Fake_1", "--roi", "0,0,64,48", "--pixel-format", "Mono8", "--exposure-us", "10000", "--line-time-us", "220", "--shutter", "dual"];
    let out = tmp.path().join("s");
    let mut args: Vec<&str> = vec!["run"];
    args.extend(cam);
    args.extend(["--psf", psf.to_str().unwrap(), "--frames", "2", "--iters", "5", "--out", out.to_str().unwrap()]);
    let o = rollcam(&args, tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let s = session(&out);
    assert_eq!(counter(&s, "reconstructed"), 2, "{}", s["counters"]);
    assert!(out.join("rec/frame_000000/video.tiff").is_file());

    let flat = tmp.path().join("flat16.tiff");
    // No light above its own dark: 5000 counts everywhere but one pixel below.
    let mut no_light = ndarray::Array3::<f32>::from_elem((48, 64, 1), 5000.0);
    no_light[[0, 0, 0]] = 4000.0;
    rollcam::io::write_tiff_u16(&flat, no_light.view()).unwrap();
    let out = tmp.path().join("s2");
    let mut args: Vec<&str> = vec!["run"];
    args.extend(cam);
    args.extend(["--psf", flat.to_str().unwrap(), "--frames", "1", "--iters", "5", "--out", out.to_str().unwrap()]);
    let o = rollcam(&args, tmp.path());
    assert!(!o.status.success());
    let err = text(&o);
    let lines: Vec<&str> = err.lines().filter(|l| l.contains("is all zero after subtracting")).collect();
    assert!(!lines.is_empty(), "{err}");
    for l in lines {
        assert_eq!(l.matches("is all zero after subtracting").count(), 1, "printed once: {l}");
    }
}

/// `capture --keyframe-camera`: a second fake camera (aravis' GigE Vision fake at
/// 127.0.0.1, which honours software triggers) fires with every frame of the
/// in-library fake (which free-runs); its frames are recorded with their device timestamps beside the
/// raw ones and each raw frame's [[keyframes]] tables written, commanded times by
/// default, measured with --keyframe-clock shared (both fakes stamp with the host's
/// real-time clock).
#[test]
fn a_key_camera_over_gige_fake_records_key_frames_with_their_timestamps() {
    let _gv = rollcam_hw::camera::aravis::start_gv_fake_camera("127.0.0.1", "RCAMKEY").expect("GigE fake camera");
    let tmp = tempfile::tempdir().unwrap();
    for clock in ["commanded", "shared"] {
        let cap = tmp.path().join(clock);
        let o = rollcam(
            &[
                "capture",
                "--camera",
                "aravis:Fake_1",
                "--roi",
                "0,0,64,48",
                "--pixel-format",
                "Mono8",
                "--frames",
                "2",
                "--keyframe-camera",
                "aravis:127.0.0.1",
                "--keyframes",
                "first",
                "--keyframe-exposure-us",
                "2000",
                "--keyframe-clock",
                clock,
                "--out",
                cap.to_str().unwrap(),
            ],
            tmp.path(),
        );
        assert!(o.status.success(), "{}", text(&o));
        let out = String::from_utf8_lossy(&o.stdout);
        assert!(out.contains("key frames: 1 per raw frame from aravis:127.0.0.1 at 0 us, exposure 2000 us"), "{out}");
        for seq in 0..2u64 {
            let table = rollcam::model::capture::CaptureConfig::load(&cap.join(format!("frame_{seq:06}.toml"))).unwrap();
            let key: rollcam_hw::camera::FrameMeta = serde_json::from_slice(&std::fs::read(cap.join(format!("keyframe_{seq:06}_00.json"))).unwrap()).unwrap();
            let raw: rollcam_hw::camera::FrameMeta = serde_json::from_slice(&std::fs::read(cap.join(format!("frame_{seq:06}.json"))).unwrap()).unwrap();
            assert!(key.device_timestamp_ns > 0 && key.camera.contains("RCAMKEY"), "{key:?}");
            assert_eq!(key.settings.exposure_us, 2000.0);
            let image = rollcam::io::read_image(cap.join(format!("keyframe_{seq:06}_00.tiff"))).unwrap();
            assert_eq!(image.dim(), (key.height as usize, key.width as usize, 1));
            let sync = &table.sync.as_ref().unwrap()["keyframe_camera"];
            assert_eq!(sync["clock"].as_str(), Some(clock));
            assert_eq!(sync["device_timestamps_ns"][0].as_integer(), Some(key.device_timestamp_ns as i64));
            let measured_us = (key.device_timestamp_ns as f64 - raw.device_timestamp_ns as f64) / 1e3;
            eprintln!("{clock} raw {seq}: key - raw device timestamps {measured_us} us, tables {:?}", table.keyframes);
            let video_us = table.timing().weights().unwrap().frames() as f64 * table.timing().frame_time_us();
            match clock {
                "commanded" => assert_eq!(table.keyframes[0].start_us, 0.0),
                // Measured: kept with its measured start when its window overlaps the
                // raw frame's video, else recorded but left out of the tables (the
                // in-library fake free-runs: its frames need not meet the key frames).
                _ if measured_us < video_us && measured_us + 2000.0 > 0.0 => assert!((table.keyframes[0].start_us - measured_us).abs() < 1e-3),
                _ => assert!(table.keyframes.is_empty(), "{:?} outside 0 .. {video_us} us", table.keyframes),
            }
        }
        let top = rollcam::model::capture::CaptureConfig::load(&cap.join("capture.toml")).unwrap();
        assert_eq!(top.keyframes, rollcam::model::capture::CaptureConfig::load(&cap.join("frame_000000.toml")).unwrap().keyframes);
    }
    // `run` fires it with every frame of the live pipeline, which reconstructs each frame
    // with its own key frames.
    let fix = fixture("led-505hz");
    let config = tmp.path().join("capture.toml");
    let fixture_toml = std::fs::read_to_string(fix.join("capture.toml")).unwrap();
    std::fs::write(&config, fixture_toml.replace("exposure_us = 660.0", "exposure_us = 10000.0")).unwrap();
    let out = tmp.path().join("s");
    let (config, psf) = (config.to_str().unwrap(), fix.join("psf.tiff"));
    let o = rollcam(
        &[
            "run",
            "--camera",
            "aravis:Fake_1",
            "--roi",
            "0,0,64,48",
            "--pixel-format",
            "Mono16",
            "--config",
            config,
            "--psf",
            psf.to_str().unwrap(),
            "--frames",
            "2",
            "--iters",
            "3",
            "--keyframe-camera",
            "aravis:127.0.0.1",
            // The fake's ramp holds light from about 1 ms of exposure on (as the raw's).
            "--keyframe-exposure-us",
            "10000",
            "--out",
            out.to_str().unwrap(),
        ],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let s = session(&out);
    assert_eq!((counter(&s, "recorded"), counter(&s, "reconstructed")), (2, 2), "{}", s["counters"]);
    for seq in 0..2u64 {
        let table = rollcam::model::capture::CaptureConfig::load(&out.join(format!("raw/frame_{seq:06}.toml"))).unwrap();
        assert_eq!(table.keyframes.len(), 1);
        assert!(out.join(format!("raw/keyframe_{seq:06}_00.json")).is_file());
        let summary: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join(format!("rec/frame_{seq:06}/summary.json"))).unwrap()).unwrap();
        let fits = summary["channels"][0]["keyframes"].as_array().unwrap_or_else(|| panic!("{summary}"));
        assert!(fits[0]["file"].as_str().unwrap().ends_with(&format!("keyframe_{seq:06}_00.tiff")), "{}", fits[0]);
    }
}
