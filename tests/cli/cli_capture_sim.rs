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
