//! `rollcam simulate` on a simulated bench, through the real binary: a 12-bit sensor
//! with fixed-pattern dark, hot and stuck pixels, a static background, and the
//! calibration shots taken with that sensor.

use crate::support::cli;

use cli::{fails, json, ok, rollcam};
use ndarray::Array3;
use std::collections::HashSet;
use std::path::Path;

const ROWS: usize = 96;
const COLS: usize = 128;
const SHOTS: usize = 4;
const DARK: f64 = 100.0;
const FULL: f32 = 4095.0;

fn image(path: &Path) -> Array3<f32> {
    let img = rollcam::io::read_image(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(img.dim(), (ROWS, COLS, 1), "{}", path.display());
    img
}

fn positions(list: &serde_json::Value) -> Vec<(usize, usize)> {
    list.as_array().unwrap().iter().map(|p| (p["row"].as_u64().unwrap() as usize, p["col"].as_u64().unwrap() as usize)).collect()
}

#[test]
fn bench_capture_with_calibration_shots() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sim");
    let o = out.to_str().unwrap();
    let flags = format!(
        "simulate --rows {ROWS} --cols {COLS} --spacing-px 10 --e-per-us 8000 --sensor-defects --bit-depth 12 --hot-fraction 0.002 \
         --background-scene --calibration-shots {SHOTS}"
    );
    let args: Vec<&str> = flags.split_whitespace().chain(["--out", o]).collect();
    let stdout = ok(&rollcam(&args, dir.path()));
    assert!(stdout.contains("12-bit") && stdout.contains("calibration shots"), "{stdout}");

    // The shots: SHOTS of each kind, numbered from 000, the sensor's size.
    for kind in ["dark", "psf", "background"] {
        let folder = out.join("calibration-shots").join(kind);
        let mut names: Vec<String> = std::fs::read_dir(&folder).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
        names.sort();
        let expect: Vec<String> = (0..SHOTS).map(|k| format!("{kind}_{k:03}.tiff")).collect();
        assert_eq!(names, expect, "{}", folder.display());
    }
    let shots = |kind: &str| -> Vec<Array3<f32>> { (0..SHOTS).map(|k| image(&out.join(format!("calibration-shots/{kind}/{kind}_{k:03}.tiff")))).collect() };
    let (darks, psfs, backgrounds) = (shots("dark"), shots("psf"), shots("background"));

    // The sensor's truth: the asked fractions of hot and stuck pixels.
    let truth = json(&out.join("sensor_truth.json"));
    let hot = positions(&truth["hot"]);
    let stuck = positions(&truth["stuck"]);
    assert_eq!(hot.len(), (0.002 * (ROWS * COLS) as f64).round() as usize);
    assert_eq!(stuck.len(), (0.0001 * (ROWS * COLS) as f64).round() as usize);
    assert_eq!(truth["full_scale_adu"].as_f64(), Some(FULL as f64));
    let defective: HashSet<(usize, usize)> = hot.iter().chain(&stuck).cloned().collect();
    let good = |i: usize, j: usize| !defective.contains(&(i, j));

    // The raw: 12 bits, clipped at 4095 exactly (LEDs bright enough that their caustics
    // clip, not only the hot pixels).
    let raw = image(&out.join("raw.tiff"));
    assert!(raw.iter().all(|&v| v <= FULL));
    let clipped_good = raw.indexed_iter().filter(|((i, j, _), &v)| v == FULL && good(*i, *j)).count();
    assert!(clipped_good > 0, "no good pixel of the raw clips at {FULL}");

    // Darks: the per-pixel mean over the shots is the dark level plus the fixed pattern
    // at good pixels (read noise 1 ADU / sqrt(SHOTS) left); hot pixels near full scale;
    // stuck pixels constant.
    let fpn = image(&out.join(truth["dark_fpn_file"].as_str().unwrap()));
    let mut resid = Vec::new();
    let mut fpn_good = Vec::new();
    for ((i, j, _), &f) in fpn.indexed_iter() {
        let mean = darks.iter().map(|d| d[[i, j, 0]] as f64).sum::<f64>() / SHOTS as f64;
        if good(i, j) {
            resid.push(mean - DARK - f as f64);
            fpn_good.push(f as f64);
        } else if hot.contains(&(i, j)) {
            assert!(mean >= DARK + 0.85 * (FULL as f64 - DARK), "hot ({i}, {j}) reads {mean} in the dark");
        }
    }
    let nr = resid.len() as f64;
    let m = resid.iter().sum::<f64>() / nr;
    let sd = (resid.iter().map(|v| (v - m).powi(2)).sum::<f64>() / nr).sqrt();
    let fpn_rms = (fpn_good.iter().map(|v| v * v).sum::<f64>() / nr).sqrt();
    assert!(m.abs() < 0.1, "mean dark - fpn - dark level: {m}");
    assert!(sd < 0.7, "per-pixel dark mean departs from the fixed pattern by {sd} ADU rms");
    assert!((fpn_rms / 3.0 - 1.0).abs() < 0.1, "fixed pattern rms {fpn_rms}");
    for s in truth["stuck"].as_array().unwrap() {
        let (i, j, v) = (s["row"].as_u64().unwrap() as usize, s["col"].as_u64().unwrap() as usize, s["value_adu"].as_f64().unwrap());
        for f in darks.iter().chain(&psfs).chain(&backgrounds).chain(std::iter::once(&raw)) {
            assert_eq!(f[[i, j, 0]] as f64, v, "stuck ({i}, {j})");
        }
    }

    // PSF shots peak at 60-80% of full scale (good pixels); background frames above the
    // dark on average.
    for p in &psfs {
        let peak = p.indexed_iter().filter(|((i, j, _), _)| good(*i, *j)).map(|(_, &v)| v).fold(0.0f32, f32::max);
        assert!((0.6 * FULL..=0.8 * FULL).contains(&peak), "PSF shot peak {peak}");
    }
    let mean = |f: &Array3<f32>| f.indexed_iter().filter(|((i, j, _), _)| good(*i, *j)).map(|(_, &v)| v as f64).sum::<f64>() / nr;
    let dark_mean = mean(&darks[0]);
    for b in &backgrounds {
        assert!(mean(b) > dark_mean + 20.0, "background frame mean {} vs dark {dark_mean}", mean(b));
    }

    // capture.toml: a real user's description (dark level as today, no saturation level,
    // no defects); the bench is provenance in [simulation].
    let text = std::fs::read_to_string(out.join("capture.toml")).unwrap();
    let cfg: toml::Table = toml::from_str(&text).unwrap();
    assert_eq!(cfg["dark_level"].as_float(), Some(DARK));
    assert!(!cfg.contains_key("saturation_level"), "{text}");
    let sim = cfg["simulation"].as_table().unwrap();
    assert_eq!(sim["sensor"]["bit_depth"].as_integer(), Some(12));
    assert_eq!(sim["sensor"]["truth_file"].as_str(), Some("sensor_truth.json"));
    assert_eq!(sim["background"]["in_truth"].as_bool(), Some(false));
    assert_eq!(sim["calibration_shots"]["dark_frames"].as_integer(), Some(SHOTS as i64));
    // The ideal psf.tiff is still there, as today.
    assert!(out.join("psf.tiff").is_file() && out.join("truth.npy").is_file());
}

#[test]
fn bench_flags_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    let o = dir.path().join("sim");
    let o = o.to_str().unwrap();
    let small = ["simulate", "--rows", "24", "--cols", "32", "--spacing-px", "5", "--out", o];
    let with = |extra: &[&str]| -> String { fails(&rollcam(&[&small[..], extra].concat(), dir.path())) };
    // An override alone does not turn the bench sensor on.
    let e = with(&["--bit-depth", "12"]);
    assert!(e.contains("--sensor-defects"), "{e}");
    let e = with(&["--sensor-defects", "--hot-fraction", "2"]);
    assert!(e.contains("--hot-fraction = 2") && e.contains("expected"), "{e}");
    let e = with(&["--sensor-defects", "--bit-depth", "20"]);
    assert!(e.contains("--bit-depth = 20") && e.contains("16"), "{e}");
    let e = with(&["--sensor-defects", "--captures", "2"]);
    assert!(e.contains("--captures 1"), "{e}");
    let e = with(&["--background-scene", "--background-level=-1"]);
    assert!(e.contains("--background-level"), "{e}");
    // Without shots and background, only the sensor's files are added.
    ok(&rollcam(&[&small[..], &["--sensor-defects"]].concat(), dir.path()));
    let out = Path::new(o);
    assert!(out.join("sensor_truth.json").is_file() && out.join("sensor_fpn.tiff").is_file());
    assert!(!out.join("calibration-shots").exists());
}
