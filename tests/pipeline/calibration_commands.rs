//! A bench calibration reaches every command that reconstructs: `run` (and its
//! session's own capture.toml, so `--resume` finds it), `reconstruct-sequence`,
//! `compare`, and `[calibration] dir` in a capture.toml; on a recorded fixture session
//! with a calibration folder written here (a per-pixel dark and one defect).

use crate::support::pipeline_common;
use ndarray::{Array2, Array3};
use pipeline_common::*;
use rollcam::io::calibration::write_calibration;
use rollcam::model::sensor::{Calibration, CalibrationRecord, DarkRecord, Defect, DefectRecord};
use std::path::Path;

const DEFECT: (usize, usize) = (20, 30);

/// A calibration for the `led-505hz` fixture (48 x 64): its dark level with a gentle
/// pattern, and one stuck pixel.
fn calibration(dir: &Path) {
    let (m, n) = (48, 64);
    let dark = Array3::from_shape_fn((m, n, 1), |(i, j, _)| 100.0 + 0.01 * ((i + j) % 5) as f32);
    let mut defects = Array2::<u8>::zeros((m, n));
    defects[DEFECT] = Defect::Stuck.code();
    let record = CalibrationRecord {
        rows: m,
        cols: n,
        channels: 1,
        dark: Some(DarkRecord { frames: 1, median_level: 100.0, ..Default::default() }),
        defects: Some(DefectRecord { stuck: 1, total: 1, fraction: 1.0 / (m * n) as f64, ..Default::default() }),
        ..Default::default()
    };
    std::fs::create_dir_all(dir).unwrap();
    write_calibration(dir, &Calibration { record, dark: Some(dark), defects: Some(defects), psf: None, background: None }).unwrap();
}

fn summary(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))).unwrap()
}

#[test]
fn run_and_resume_use_the_calibration() {
    let tmp = tempfile::tempdir().unwrap();
    let calib = tmp.path().join("calib");
    calibration(&calib);
    let fix = fixture("led-505hz");
    let out = tmp.path().join("session");
    let camera = format!("replay:{}", fix.display());
    let o = rollcam(
        &["run", "--camera", &camera, "--out", out.to_str().unwrap(), "--iters", "10", "--frames", "1", "--calibration", calib.to_str().unwrap()],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let s = session(&out);
    assert_eq!(counter(&s, "reconstructed"), 1, "{}", s["errors"]);
    let abs = std::fs::canonicalize(&calib).unwrap().display().to_string();
    assert_eq!(s["config"]["capture"]["calibration"]["dir"], abs, "{}", s["config"]);
    let rec = summary(&out.join("rec/frame_000000/summary.json"));
    assert_eq!(rec["sensor"]["dark_source"], "calibration", "{}", rec["sensor"]);
    assert_eq!(rec["sensor"]["calibration_defects"], 1);
    assert_eq!(rec["inputs"]["calibration"], abs);
    // The session's own capture.toml names the folder: a resumed session finds it.
    let text_toml = std::fs::read_to_string(out.join("capture.toml")).unwrap();
    assert!(text_toml.contains("[calibration]") && text_toml.contains(&abs), "{text_toml}");
    // As if the session had stopped before reconstructing the frame.
    std::fs::remove_dir_all(out.join("rec/frame_000000")).unwrap();
    let mut s = s;
    s["frames"][0]["status"] = "recorded".into();
    for k in ["video", "rec", "solve_s", "psnr_db"] {
        s["frames"][0][k] = serde_json::Value::Null;
    }
    s["counters"]["reconstructed"] = 0.into();
    s["counters"]["recorded"] = 1.into();
    std::fs::write(out.join("session.json"), serde_json::to_string_pretty(&s).unwrap()).unwrap();
    let o = rollcam(&["run", "--resume", out.to_str().unwrap()], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let rec = summary(&out.join("rec/frame_000000/summary.json"));
    assert_eq!(rec["sensor"]["calibration_defects"], 1, "{}", rec["sensor"]);

    // A calibration of another size is refused, naming its file.
    let wrong = tmp.path().join("wrong");
    std::fs::create_dir_all(&wrong).unwrap();
    let record = CalibrationRecord { rows: 8, cols: 8, channels: 1, dark: Some(DarkRecord::default()), ..Default::default() };
    write_calibration(&wrong, &Calibration { record, dark: Some(Array3::from_elem((8, 8, 1), 100.0)), ..Default::default() }).unwrap();
    let out2 = tmp.path().join("session2");
    let o = rollcam(
        &["run", "--camera", &camera, "--out", out2.to_str().unwrap(), "--iters", "5", "--frames", "1", "--calibration", wrong.to_str().unwrap()],
        tmp.path(),
    );
    let t = text(&o);
    assert!(t.contains("dark.tiff") && t.contains("8 x 8"), "{t}");
}

#[test]
fn sequence_compare_and_the_capture_toml_table_use_the_calibration() {
    let tmp = tempfile::tempdir().unwrap();
    let calib = tmp.path().join("calib");
    calibration(&calib);
    let fix = fixture("led-505hz");

    // reconstruct-sequence: every capture gets the calibration's dark and defect.
    let out = tmp.path().join("seq");
    let o = rollcam(
        &["reconstruct-sequence", fix.to_str().unwrap(), "--out", out.to_str().unwrap(), "--iters", "5", "--calibration", calib.to_str().unwrap()],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let s = summary(&out.join("summary.json"));
    let sensor = s["sensor"].as_array().unwrap();
    assert_eq!(sensor.len(), 3);
    for r in sensor {
        assert_eq!(r["dark_source"], "calibration");
        assert_eq!(r["calibration_defects"], 1);
    }
    assert_eq!(s["calibration"], calib.display().to_string());

    // A capture.toml with [calibration] dir (relative to its folder), used by reconstruct
    // and compare without a flag.
    let cfg_text = std::fs::read_to_string(fix.join("capture.toml")).unwrap() + "\n[calibration]\ndir = \"calib\"\n";
    let cfg = tmp.path().join("capture.toml");
    std::fs::write(&cfg, cfg_text).unwrap();
    let (raw, psf) = (fix.join("frame_000000.tiff"), fix.join("psf.tiff"));
    let rec = tmp.path().join("rec");
    let o = rollcam(
        &[
            "reconstruct",
            "--raw",
            raw.to_str().unwrap(),
            "--psf",
            psf.to_str().unwrap(),
            "--config",
            cfg.to_str().unwrap(),
            "--iters",
            "5",
            "--out",
            rec.to_str().unwrap(),
        ],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let r = summary(&rec.join("summary.json"));
    assert_eq!(r["sensor"]["dark_source"], "calibration");
    assert_eq!(r["inputs"]["calibration"], tmp.path().join("calib").display().to_string());
    assert!(text(&o).contains("1 calibration defects"), "{}", text(&o));

    let cmp = tmp.path().join("cmp");
    let o = rollcam(
        &[
            "compare",
            "--raw",
            raw.to_str().unwrap(),
            "--psf",
            psf.to_str().unwrap(),
            "--config",
            cfg.to_str().unwrap(),
            "--solvers",
            "fista,pgd",
            "--iters",
            "5",
            "--out",
            cmp.to_str().unwrap(),
        ],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("1 calibration defects"), "{}", text(&o));

    // A missing calibration folder named in capture.toml is an error naming it.
    std::fs::remove_dir_all(&calib).unwrap();
    let o = rollcam(
        &[
            "reconstruct",
            "--raw",
            raw.to_str().unwrap(),
            "--psf",
            psf.to_str().unwrap(),
            "--config",
            cfg.to_str().unwrap(),
            "--out",
            tmp.path().join("r2").to_str().unwrap(),
        ],
        tmp.path(),
    );
    assert!(!o.status.success());
    assert!(text(&o).contains("calib") && text(&o).contains("calibration folder"), "{}", text(&o));

    // The simulated LED sweep takes a calibration of its sensor (small: 64 x 80).
    let (m, n) = (64, 80);
    let sweep_cal = tmp.path().join("sweep-calib");
    std::fs::create_dir_all(&sweep_cal).unwrap();
    let mut defects = Array2::<u8>::zeros((m, n));
    defects[[10, 10]] = Defect::Hot.code();
    let record = CalibrationRecord {
        rows: m,
        cols: n,
        channels: 1,
        defects: Some(DefectRecord { hot: 1, total: 1, fraction: 1.0 / (m * n) as f64, ..Default::default() }),
        ..Default::default()
    };
    write_calibration(&sweep_cal, &Calibration { record, defects: Some(defects), ..Default::default() }).unwrap();
    let sweep = tmp.path().join("sweep");
    let o = rollcam(
        &[
            "experiment",
            "led-sweep",
            "--size",
            "small",
            "--periods-us",
            "2640",
            "--iters",
            "5",
            "--calibration",
            sweep_cal.to_str().unwrap(),
            "--out",
            sweep.to_str().unwrap(),
        ],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let r = summary(&sweep.join("period-2640us/rec/summary.json"));
    assert_eq!(r["sensor"]["calibration_defects"], 1, "{}", r["sensor"]);
    assert_eq!(r["inputs"]["calibration"], sweep_cal.display().to_string());
}
