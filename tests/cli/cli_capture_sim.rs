//! The simulated camera end to end: `capture --camera sim:led-array` records frames
//! rendered by the physical simulator, plus the PSF and timing needed to reconstruct
//! them; a recorded frame then reconstructs to the flashing LEDs.

use std::process::Command;

#[test]
fn simulated_camera_capture_reconstructs() {
    let dir = tempfile::tempdir().unwrap();
    let cap = dir.path().join("cap");
    let bin = env!("CARGO_BIN_EXE_rollcam");
    let o = Command::new(bin)
        .args(["capture", "--camera", "sim:led-array", "--frames", "2", "--out", cap.to_str().unwrap()])
        .env("ROLLCAM_CACHE_DIR", dir.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in ["capture.json", "capture.toml", "psf.tiff", "frame_000000.tiff", "frame_000001.tiff", "frame_000001.json"] {
        assert!(cap.join(f).is_file(), "missing {f}");
    }
    let cfg = rollcam::model::capture::CaptureConfig::load(&cap.join("capture.toml")).unwrap();
    assert_eq!((cfg.rows, cfg.cols, cfg.shutter), (128, 160, rollcam::model::shutter::ShutterMode::Dual));
    // Two frames of a time-varying scene differ; both hold light above the dark level.
    let a = rollcam::io::read_image(cap.join("frame_000000.tiff")).unwrap();
    let b = rollcam::io::read_image(cap.join("frame_000001.tiff")).unwrap();
    assert_ne!(a, b);
    assert!(a.iter().cloned().fold(0.0f32, f32::max) > 200.0);

    let rec = dir.path().join("rec");
    let o = Command::new(bin)
        .args(["reconstruct", "--raw", cap.join("frame_000000.tiff").to_str().unwrap(), "--psf", cap.join("psf.tiff").to_str().unwrap()])
        .args(["--config", cap.join("capture.toml").to_str().unwrap(), "--out", rec.to_str().unwrap(), "--iters", "40"])
        .env("ROLLCAM_CACHE_DIR", dir.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = rollcam::io::read_npy(rec.join("video.npy")).unwrap();
    // The four LEDs sit on the middle row: the brightest pixel of the time-summed
    // video lies within a few pixels of it.
    let (k, m, n, _) = v.dim();
    let mut best = (0.0f32, 0, 0);
    for r in 0..m {
        for c in 0..n {
            let s: f32 = (0..k).map(|f| v[[f, r, c, 0]]).sum();
            if s > best.0 {
                best = (s, r, c);
            }
        }
    }
    assert!((best.1 as i64 - 64).abs() <= 2, "brightest pixel at row {} col {}", best.1, best.2);
}

/// `capture --keyframe-camera sim`: the simulated key camera fires with every raw frame;
/// its frames lie beside the raw ones with each frame's [[keyframes]] tables, the
/// folder's capture.toml carries frame 0's, and reconstruct takes them.
#[test]
fn simulated_key_camera_records_key_frames_that_reconstruct_uses() {
    let dir = tempfile::tempdir().unwrap();
    let cap = dir.path().join("cap");
    let bin = env!("CARGO_BIN_EXE_rollcam");
    let o = Command::new(bin)
        .args(["capture", "--camera", "sim:moving-disc", "--keyframe-camera", "sim:key", "--keyframes", "first,14000,1000", "--keyframe-exposure-us", "440"])
        .args(["--frames", "2", "--out", cap.to_str().unwrap()])
        .env("ROLLCAM_CACHE_DIR", dir.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(stdout.contains("key frames: 3 per raw frame from sim:key at 0, 14000, 1000 us, exposure 440 us"), "{stdout}");
    let load = |f: &str| rollcam::model::capture::CaptureConfig::load(&cap.join(f)).unwrap();
    let (top, f0, f1) = (load("capture.toml"), load("frame_000000.toml"), load("frame_000001.toml"));
    assert_eq!(top.keyframes, f0.keyframes);
    let starts: Vec<f64> = f1.keyframes.iter().map(|k| k.start_us).collect();
    assert_eq!(starts, vec![0.0, 14000.0, 1000.0]);
    assert!(f1.keyframes.iter().all(|k| k.exposure_us == 440.0 && k.file.starts_with("keyframe_000001_")));
    assert_eq!(top.sync.as_ref().unwrap()["keyframe_camera"]["clock"].as_str(), Some("shared"));
    // Each raw frame's key frames show its own moment: the disc moved between them.
    let k0 = rollcam::io::read_image(cap.join("keyframe_000000_00.tiff")).unwrap();
    let k1 = rollcam::io::read_image(cap.join("keyframe_000001_00.tiff")).unwrap();
    assert_eq!(k0.dim(), (128, 160, 1));
    assert_ne!(k0, k1);
    let last = rollcam::io::read_image(cap.join("keyframe_000000_01.tiff")).unwrap();
    assert_ne!(k0, last);
    // The recorder's reader still sees two raw frames and nothing else.
    let reader = rollcam_hw::record::CaptureReader::open(&cap).unwrap();
    assert_eq!(reader.len(), 2);
    // capture.json's trigger chain names the key camera and its times.
    let link = reader.session().sync.trigger_chain.last().cloned().expect("the key camera's link");
    assert_eq!(link.target, "sim:key (software)");
    assert!(link.note.as_deref().unwrap_or_default().contains("first, 14000, 1000"), "{link:?}");

    let rec = dir.path().join("rec");
    let o = Command::new(bin)
        .args(["reconstruct", "--raw", cap.join("frame_000001.tiff").to_str().unwrap(), "--psf", cap.join("psf.tiff").to_str().unwrap()])
        .args(["--config", cap.join("frame_000001.toml").to_str().unwrap(), "--out", rec.to_str().unwrap(), "--iters", "3"])
        .env("ROLLCAM_CACHE_DIR", dir.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(stdout.contains("key frames: 3, gain"), "{stdout}");
    // Frame 1 with capture.toml (frame 0's key frames, another moment) is refused.
    let o = Command::new(bin)
        .args(["reconstruct", "--raw", cap.join("frame_000001.tiff").to_str().unwrap(), "--psf", cap.join("psf.tiff").to_str().unwrap()])
        .args(["--config", cap.join("capture.toml").to_str().unwrap(), "--out", dir.path().join("rec2").to_str().unwrap(), "--iters", "3"])
        .env("ROLLCAM_CACHE_DIR", dir.path())
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && e.contains("are not those of --raw") && e.contains("give --config"), "{e}");
}

/// Bad key-camera requests are refused by name before anything is recorded.
#[test]
fn key_camera_requests_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cap");
    let bin = env!("CARGO_BIN_EXE_rollcam");
    let refuse = |extra: &[&str]| {
        let o = Command::new(bin).args(["capture", "--camera", "sim:led-array", "--out", out.to_str().unwrap()]).args(extra).output().unwrap();
        assert!(!o.status.success());
        assert!(!out.join("capture.json").exists());
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    let e = refuse(&["--keyframe-camera", "bogus"]);
    assert!(e.contains("--keyframe-camera bogus: camera spec 'bogus'"), "{e}");
    let e = refuse(&["--keyframe-camera", "sim:led-array"]);
    assert!(e.contains("the same device as --camera"), "{e}");
    let e = refuse(&["--keyframe-camera", "sim:key", "--keyframes", "first,20000"]);
    assert!(e.contains("--keyframes = 20000: expected a key frame inside the video's 0 .. 14520 us"), "{e}");
    let e = refuse(&["--keyframe-camera", "sim:key", "--keyframe-exposure-us=-3"]);
    assert!(e.contains("--keyframe-exposure-us = -3"), "{e}");
    let e = refuse(&["--keyframe-camera", "sim:key", "--keyframe-trigger", "hardware:Line0"]);
    assert!(e.contains("no input lines"), "{e}");
    let e = refuse(&["--keyframe-camera", "sim:key", "--keyframe-clock", "wall"]);
    assert!(e.contains("--keyframe-clock 'wall'"), "{e}");
    let o = Command::new(bin).args(["capture", "--camera", "replay:/nowhere", "--keyframe-camera", "sim", "--out", out.to_str().unwrap()]).output().unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("the simulated key camera sees the simulated main camera's scene"), "{e}");
}
