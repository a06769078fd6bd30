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
            fix.join("capture.toml").to_str().unwrap(),
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
    assert_eq!(applied.exposure_us, 660.0);
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
