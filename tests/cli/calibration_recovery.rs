//! Real-bench departures, through the real binary, with the measured DiffuserCam PSF as
//! the optics: a clean capture is the reference; each departure alone (hot pixels,
//! clipping, a fixed-pattern dark, a static background) and all of them together are
//! simulated with the same scene and noise, then reconstructed as a user would:
//! without calibration (the automatic masks), and after `rollcam calibrate` on the
//! simulated dark, PSF and background stacks. The LED time courses and the relative
//! error must come within a stated margin of the clean capture's.

use crate::support::cli;

use cli::{json, ok, rollcam};
use ndarray::{Array4, Axis};
use rollcam::analysis::{correlation, region_time_course};
use std::path::{Path, PathBuf};

const PSF: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data/diffusercam-tutorial/psf_sample.tif");
/// 1200 x 1600 / 5: a 240 x 320 sensor, as the bench issue measured.
const PSF_DOWNSAMPLE: &str = "5";
const ITERS: &str = "150";
/// LED radiance, photo-electrons per microsecond: bright enough that a 12-bit sensor
/// clips the brightest pixels, not so bright that the full well does.
const E_PER_US: &str = "60000";
/// Bright enough that the 12-bit sensor clips a few percent of the pixels.
const CLIP_E_PER_US: &str = "120000";
/// The static background's mean radiance (e-/us per raw pixel).
const BACKGROUND: &str = "2";

/// Absolute slack on the relative error against the clean capture's (see `near_clean`).
const ERROR_SLACK: f64 = 0.05;

/// Simulate into `dir/name` with the shared scene flags and `extra` (which may set its
/// own `--e-per-us`).
fn simulate(dir: &Path, name: &str, extra: &[&str]) -> PathBuf {
    let out = dir.join(name);
    let mut args =
        vec!["simulate", "--psf", PSF, "--psf-downsample", PSF_DOWNSAMPLE, "--leds", "4", "--spacing-px", "24", "--seed", "5", "--out", out.to_str().unwrap()];
    if !extra.contains(&"--e-per-us") {
        args.extend(["--e-per-us", E_PER_US]);
    }
    args.extend_from_slice(extra);
    ok(&rollcam(&args, dir));
    out
}

/// Reconstruct `sim`'s raw (its own PSF unless a calibration brings one); returns the
/// output folder and what the command printed.
fn reconstruct(dir: &Path, sim: &Path, name: &str, extra: &[&str]) -> (PathBuf, String) {
    let out = dir.join(name);
    let (raw, cfg, truth) = (sim.join("raw.tiff"), sim.join("capture.toml"), sim.join("truth.npy"));
    let mut args = vec![
        "reconstruct",
        "--raw",
        raw.to_str().unwrap(),
        "--config",
        cfg.to_str().unwrap(),
        "--truth",
        truth.to_str().unwrap(),
        "--iters",
        ITERS,
        "--out",
        out.to_str().unwrap(),
    ];
    let psf = sim.join("psf.tiff");
    if !extra.contains(&"--calibration") {
        args.extend(["--psf", psf.to_str().unwrap()]);
    }
    args.extend_from_slice(extra);
    let stdout = ok(&rollcam(&args, dir));
    (out, stdout)
}

/// Quality against the truth: the worst LED time-course correlation and the relative
/// error of the whole video.
fn quality(sim: &Path, rec: &Path) -> (f64, f64) {
    let (r, _, e) = quality_seen(sim, rec);
    (r, e)
}

/// [`quality`] with the worst LED correlation over the frames the data see too (those
/// the reconstruction's `support.sources.unseen_frames` leaves out; all when none).
fn quality_seen(sim: &Path, rec: &Path) -> (f64, f64, f64) {
    let unseen = rollcam::analysis::input::unseen_frames(&rec.join("summary.json"));
    let truth: Array4<f32> = rollcam::io::read_npy(sim.join("truth.npy")).unwrap();
    let video: Array4<f32> = rollcam::io::read_npy(rec.join("video.npy")).unwrap();
    assert_eq!(truth.dim(), video.dim());
    // The LEDs: the brightest columns of the truth's mean frame along its brightest row.
    let mean = truth.mean_axis(Axis(0)).unwrap();
    let (_, m, n, _) = truth.dim();
    let (mut best, mut row) = (f32::MIN, 0);
    for i in 0..m {
        let s: f32 = (0..n).map(|j| mean[[i, j, 0]]).sum();
        if s > best {
            (best, row) = (s, i);
        }
    }
    let line: Vec<f32> = (0..n).map(|j| mean[[row, j, 0]]).collect();
    let peak = line.iter().cloned().fold(0.0f32, f32::max);
    let mut leds = Vec::new();
    for j in 1..n - 1 {
        if line[j] > 0.5 * peak && line[j] >= line[j - 1] && line[j] > line[j + 1] {
            leds.push(j);
        }
    }
    assert_eq!(leds.len(), 4, "four LEDs in the truth's row {row}: {line:?}");
    let seen = |k: &usize| !unseen.iter().any(|&[s, e]| (s..e).contains(k));
    let pick = |c: &[f64]| -> Vec<f64> { c.iter().enumerate().filter(|(k, _)| seen(k)).map(|(_, &v)| v).collect() };
    let courses: Vec<(Vec<f64>, Vec<f64>)> =
        leds.iter().map(|&c| (region_time_course(truth.view(), 0, row, c, 1), region_time_course(video.view(), 0, row, c, 1))).collect();
    let worst = courses.iter().map(|(t, v)| correlation(t, v)).fold(f64::INFINITY, f64::min);
    let worst_seen = courses.iter().map(|(t, v)| correlation(&pick(t), &pick(v))).fold(f64::INFINITY, f64::min);
    let diff: f64 = truth.iter().zip(video.iter()).map(|(&t, &v)| (t as f64 - v as f64).powi(2)).sum();
    let norm: f64 = truth.iter().map(|&t| (t as f64).powi(2)).sum();
    (worst, worst_seen, (diff / norm).sqrt())
}

fn sensor(rec: &Path) -> serde_json::Value {
    json(&rec.join("summary.json"))["sensor"].clone()
}

#[test]
fn departures_alone_and_together_come_back_to_the_clean_capture() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let clean = simulate(dir, "clean", &[]);
    let (rec, _) = reconstruct(dir, &clean, "rec-clean", &[]);
    let (r_clean, r_clean_seen, e_clean) = quality_seen(&clean, &rec);
    assert!(r_clean > 0.6, "the clean capture's LEDs: r = {r_clean}");
    assert_eq!(sensor(&rec)["masked_pixels"], 0, "a clean capture uses every pixel");
    eprintln!("clean: r = {r_clean:.3} ({r_clean_seen:.3} over the frames the data see), relative error {e_clean:.3}");
    // Each departure may cost a little of what the clean capture holds: the error within
    // a share `de` of the clean one's plus ERROR_SLACK (the clean error fell from 0.78 to
    // 0.14 with the sources' own shape fit, and a share of it alone became a bound
    // tighter than two captures' noise; measured: clipping +0.014, background +0.026).
    let near_clean = |what: &str, r: f64, e: f64, dr: f64, de: f64| {
        assert!(
            r >= r_clean - dr && e <= e_clean * (1.0 + de) + ERROR_SLACK,
            "{what}: r = {r:.4} (clean {r_clean:.4}), relative error {e:.4} (clean {e_clean:.4})"
        );
    };

    // Hot pixels alone (16-bit, no fixed pattern, no stuck pixels, the same noise):
    // found as outliers without any calibration.
    let hot = simulate(dir, "hot", &["--sensor-defects", "--bit-depth", "16", "--dark-fpn-rms-adu", "0", "--stuck-fraction", "0", "--hot-fraction", "0.002"]);
    let (rec, out) = reconstruct(dir, &hot, "rec-hot", &[]);
    let (r, e) = quality(&hot, &rec);
    let s = sensor(&rec);
    let planted = json(&hot.join("sensor_truth.json"))["hot"].as_array().unwrap().len() as f64;
    let found = s["outliers_hot"].as_f64().unwrap() + s["saturated_pixels"].as_f64().unwrap();
    eprintln!("hot pixels: r = {r:.3}, relative error {e:.3}, {found} of {planted} found\n{out}");
    assert!(found >= 0.95 * planted && found <= 1.05 * planted, "{found} outliers for {planted} hot pixels: {s}");
    near_clean("hot pixels", r, e, 0.01, 0.01);

    // Clipping alone: a 12-bit sensor; the pile at 4095 is found without a declared
    // level, against the same raw with clipping ignored (a level above every value).
    let clip =
        simulate(dir, "clip", &["--sensor-defects", "--dark-fpn-rms-adu", "0", "--hot-fraction", "0", "--stuck-fraction", "0", "--e-per-us", CLIP_E_PER_US]);
    let (rec, out) = reconstruct(dir, &clip, "rec-clip", &[]);
    let (r, e) = quality(&clip, &rec);
    let s = sensor(&rec);
    eprintln!("clipping: r = {r:.3}, relative error {e:.3}\n{out}");
    assert_eq!(s["saturation_level"], 4095.0, "{s}");
    assert_eq!(s["saturation_source"], "pile-at-maximum", "{s}");
    assert!(s["saturated_fraction"].as_f64().unwrap() > 1e-3, "{s}");
    assert!(out.contains("left out of the data term"), "{out}");
    let (rec, _) = reconstruct(dir, &clip, "rec-clip-ignored", &["--saturation-level", "1e9"]);
    let (r_ignored, e_ignored) = quality(&clip, &rec);
    eprintln!("clipping ignored: r = {r_ignored:.3}, relative error {e_ignored:.3}");
    assert_eq!(sensor(&rec)["saturated_pixels"], 0);
    assert!(
        r >= r_ignored - 0.005 && e <= e_ignored,
        "one-sided clipped pixels do no worse than clipping ignored: r {r} vs {r_ignored}, error {e} vs {e_ignored}"
    );
    near_clean("clipping", r, e, 0.05, 0.1);

    // A static background alone (ideal sensor): one background frame as shot,
    // subtracted with --background, against none.
    let bg = simulate(dir, "bg", &["--background-scene", "--background-level", BACKGROUND, "--calibration-shots", "1"]);
    let (rec, _) = reconstruct(dir, &bg, "rec-bg-ignored", &[]);
    let (r_kept, e_kept) = quality(&bg, &rec);
    let frame = bg.join("calibration-shots/background/background_000.tiff");
    let (rec, out) = reconstruct(dir, &bg, "rec-bg", &["--background", frame.to_str().unwrap()]);
    let (r, e) = quality(&bg, &rec);
    eprintln!("background: kept r = {r_kept:.3}, error {e_kept:.3}; subtracted r = {r:.3}, error {e:.3}\n{out}");
    assert_eq!(sensor(&rec)["dark_source"], "background");
    assert_eq!(json(&rec.join("summary.json"))["inputs"]["background"], frame.display().to_string());
    // The LEDs are a sparse scene: both runs start on the support the still image
    // shows (the kept background's probe then drops it), so the LEDs' time courses
    // match (measured 0.68661 vs 0.68669); the video's error shows the background.
    assert!(r >= r_kept - 0.005 && e < e_kept, "subtracting the background helps: r {r} vs {r_kept}, error {e} vs {e_kept}");
    near_clean("background subtracted", r, e, 0.05, 0.1);

    // Everything at once: fixed-pattern dark, hot and stuck pixels, 12-bit clipping, a
    // static background; calibrated from the simulated stacks.
    let bench = simulate(dir, "bench", &["--sensor-defects", "--background-scene", "--background-level", BACKGROUND, "--calibration-shots", "12"]);
    let (rec, out) = reconstruct(dir, &bench, "rec-bench-uncalibrated", &[]);
    let (r_raw, e_raw) = quality(&bench, &rec);
    eprintln!("bench, no calibration: r = {r_raw:.3}, relative error {e_raw:.3}\n{out}");
    let calib = dir.join("calib");
    let shots = bench.join("calibration-shots");
    let (d, p, b) = (shots.join("dark"), shots.join("psf"), shots.join("background"));
    let printed = ok(&rollcam(
        &[
            "calibrate",
            "--dark",
            d.to_str().unwrap(),
            "--psf-shots",
            p.to_str().unwrap(),
            "--background",
            b.to_str().unwrap(),
            "--out",
            calib.to_str().unwrap(),
        ],
        dir,
    ));
    eprintln!("{printed}");
    let (rec, out) = reconstruct(dir, &bench, "rec-bench", &["--calibration", calib.to_str().unwrap()]);
    let (r, r_seen, e) = quality_seen(&bench, &rec);
    let s = sensor(&rec);
    let summary = json(&rec.join("summary.json"));
    eprintln!("bench, calibrated: r = {r:.3} ({r_seen:.3} over the frames the data see), relative error {e:.3}\n{out}");
    assert_eq!(s["dark_source"], "background", "{s}");
    assert!(s["calibration_defects"].as_u64().unwrap() > 0, "{s}");
    assert_eq!(summary["inputs"]["calibration"], calib.display().to_string());
    assert_eq!(summary["inputs"]["psf"], calib.join("psf.tiff").display().to_string());
    assert!(r > r_raw && e < e_raw, "calibration helps: r {r} vs {r_raw}, error {e} vs {e_raw}");
    // Both captures' LEDs are fitted as sources, and in the first 16 frames the rows
    // that expose them barely see the LEDs (`unseen_frames`). Over the frames the data
    // see the bench comes back to the clean capture (measured 0.9999 and 0.9999). Over
    // every frame it trails (0.921 against 0.996; least squares alone in the unseen
    // frames left it at 0.692) and its error is 0.255 against 0.137 (stop 57: 0.816 and
    // 0.777): the shapes' own fit improved the clean capture far more than the bench
    // (docs/limits.md; not yet explained).
    assert!(
        r >= 0.9 && r_seen >= r_clean_seen - 0.05 && e <= e_clean * 2.0,
        "calibrated bench: r = {r_seen:.4} over the frames the data see (clean {r_clean_seen:.4}; over every frame {r:.4} and {r_clean:.4}), relative error {e:.4} (clean {e_clean:.4})"
    );
}
