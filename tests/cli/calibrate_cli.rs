//! `rollcam calibrate` end to end with the real binary, on synthetic shots of a sensor
//! whose truth is known: a dark level with a fixed pattern, Gaussian read noise, planted
//! hot and stuck pixels, a 12-bit ADC; point-source shots of a known PSF (synthetic
//! caustics, and the measured DiffuserCam PSF) with shot noise; background frames.
//! Checks the read noise, the defect map's precision and recall, the PSF's agreement
//! with the truth and its centroid, the folder's files, and the refusals (a non-empty
//! --out, a missing input, a frame of another size).

use crate::support::cli::{fails, ok};
use ndarray::{Array2, Array3, Array4, Axis};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rollcam::io::calibration::load_calibration;
use rollcam::model::sensor::{self, Defect};
use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const DARK_LEVEL: f64 = 100.0;
const FPN_RMS: f64 = 3.0;
const READ_NOISE: f64 = 4.0;
const FULL_SCALE: f64 = 4095.0;

fn rollcam(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rollcam")).args(args).env("RUST_LOG", "warn").output().expect("rollcam runs")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A sensor with a known dark: per-pixel offsets, hot pixels (extra dark signal,
/// possibly clipped) and stuck pixels (a constant whatever the light).
struct Sensor {
    rows: usize,
    cols: usize,
    fpn: Array2<f64>,
    hot: Vec<((usize, usize), f64)>,
    stuck: Vec<((usize, usize), f64)>,
    rng: ChaCha8Rng,
}

impl Sensor {
    /// `hot` hot pixels with extra dark signal in `hot_extra`, `stuck` stuck pixels
    /// reading 92..108, at distinct positions at least 3 pixels apart.
    fn new(rows: usize, cols: usize, hot: usize, hot_extra: (f64, f64), stuck: usize, seed: u64) -> Sensor {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let g = Normal::new(0.0, FPN_RMS).unwrap();
        let fpn = Array2::from_shape_fn((rows, cols), |_| g.sample(&mut rng));
        let mut taken: Vec<(usize, usize)> = Vec::new();
        let mut pick = |rng: &mut ChaCha8Rng| loop {
            let p = (rng.gen_range(2..rows - 2), rng.gen_range(2..cols - 2));
            if taken.iter().all(|q| q.0.abs_diff(p.0) > 2 || q.1.abs_diff(p.1) > 2) {
                taken.push(p);
                return p;
            }
        };
        let hot = (0..hot).map(|_| (pick(&mut rng), rng.gen_range(hot_extra.0..=hot_extra.1))).collect();
        let stuck = (0..stuck).map(|_| (pick(&mut rng), rng.gen_range(92.0..108.0f64).round())).collect();
        Sensor { rows, cols, fpn, hot, stuck, rng }
    }

    /// One frame of `light` (counts above dark, gain 1: Poisson-like noise of the same
    /// variance), read noise, the dark, clipped to 12 bits and rounded.
    fn frame(&mut self, light: Option<&Array2<f64>>) -> Array3<f32> {
        let g = Normal::new(0.0, 1.0).unwrap();
        let mut extra = Array2::<f64>::zeros((self.rows, self.cols));
        for &(p, e) in &self.hot {
            extra[p] = e;
        }
        let mut f = Array3::from_shape_fn((self.rows, self.cols, 1), |(i, j, _)| {
            let l = light.map_or(0.0, |l| l[[i, j]]);
            let v = DARK_LEVEL + self.fpn[[i, j]] + extra[[i, j]] + l + (READ_NOISE * READ_NOISE + l).sqrt() * g.sample(&mut self.rng);
            v.round().clamp(0.0, FULL_SCALE) as f32
        });
        for &(p, v) in &self.stuck {
            f[[p.0, p.1, 0]] = v as f32;
        }
        f
    }

    fn planted(&self) -> HashSet<(usize, usize)> {
        self.hot.iter().chain(&self.stuck).map(|(p, _)| *p).collect()
    }
}

fn write_u16(path: &Path, f: &Array3<f32>) {
    rollcam::io::write_tiff_u16(path, f.view()).unwrap();
}

/// `n` frames as `dir/name_000.tif`...; returns their paths.
fn write_frames(dir: &Path, name: &str, frames: &[Array3<f32>]) -> Vec<PathBuf> {
    std::fs::create_dir_all(dir).unwrap();
    frames
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let p = dir.join(format!("{name}_{i:03}.tif"));
            write_u16(&p, f);
            p
        })
        .collect()
}

fn centroid(p: &Array2<f64>) -> (f64, f64) {
    let s = p.sum();
    let r = p.indexed_iter().map(|((i, _), &v)| i as f64 * v).sum::<f64>() / s;
    let c = p.indexed_iter().map(|((_, j), &v)| j as f64 * v).sum::<f64>() / s;
    (r, c)
}

fn correlation(a: &Array2<f64>, b: &Array2<f64>) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.sum() / n, b.sum() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (&x, &y) in a.iter().zip(b.iter()) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    sab / (saa * sbb).sqrt()
}

/// `img` shifted by whole pixels (down and right positive), zero fill.
fn shift(img: &Array2<f64>, by: [i64; 2]) -> Array2<f64> {
    let (m, n) = img.dim();
    let mut out = Array2::zeros((m, n));
    for ((i, j), &v) in img.indexed_iter() {
        let (a, b) = (i as i64 + by[0], j as i64 + by[1]);
        if a >= 0 && b >= 0 && (a as usize) < m && (b as usize) < n {
            out[[a as usize, b as usize]] = v;
        }
    }
    out
}

/// Precision and recall of a defect map against the planted pixels.
fn precision_recall(map: &Array2<u8>, planted: &HashSet<(usize, usize)>) -> (f64, f64) {
    let found: HashSet<(usize, usize)> = map.indexed_iter().filter(|(_, &c)| c != Defect::Good.code()).map(|(p, _)| p).collect();
    let hit = found.intersection(planted).count() as f64;
    (hit / found.len().max(1) as f64, hit / planted.len() as f64)
}

/// Synthetic caustics: a few thin curved lines and blobs, unit sum.
fn synthetic_psf(rows: usize, cols: usize) -> Array2<f64> {
    let mut p = Array2::<f64>::zeros((rows, cols));
    for ((i, j), v) in p.indexed_iter_mut() {
        let (y, x) = (i as f64, j as f64);
        // Two blobs and three caustic arcs.
        *v += (-((y - 40.0).powi(2) + (x - 60.0).powi(2)) / 30.0).exp();
        *v += 0.6 * (-((y - 80.0).powi(2) + (x - 110.0).powi(2)) / 12.0).exp();
        for (cy, cx, r, w) in [(60.0, 80.0, 35.0, 1.2), (50.0, 100.0, 20.0, 0.8), (75.0, 60.0, 28.0, 1.0)] {
            let d = ((y - cy).powi(2) + (x - cx).powi(2)).sqrt() - r;
            *v += 0.4 * (-d * d / (2.0 * w * w)).exp();
        }
    }
    let s = p.sum();
    p / s
}

fn load_truth_from_measured() -> Array2<f64> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data/diffusercam-tutorial/psf_sample.tif");
    assert!(Path::new(path).exists(), "the measured PSF {path} is missing");
    let img = rollcam::io::read_image(path).unwrap();
    let (m, n, ch) = img.dim();
    let grey: Vec<f32> = img.mean_axis(Axis(2)).unwrap().iter().cloned().collect();
    assert!(ch == 1 || ch == 3, "{ch} channels");
    // To about 240 x 320.
    let d = (m / 240).max(1);
    let (small, r, c) = rollcam::model::resample::box_downsample(&grey, m, n, d);
    let dark = rollcam::model::prepare::estimate_dark(&small);
    let mut p = Array2::from_shape_vec((r, c), small.iter().map(|&v| (v - dark as f32).max(0.0)).collect()).unwrap();
    // The measured image has defects of its own (a lone bright corner pixel): they are
    // not the diffuser's, so the truth is the image without them.
    let noise = sensor::pixel_noise(p.view());
    let own = sensor::find_outliers(p.view(), noise, 0.0, 6.0).mapv(|c| c != 0);
    sensor::repair(&mut p, &own);
    let p = p.mapv(f64::from);
    let s = p.sum();
    assert!(s > 0.0);
    p / s
}

#[test]
fn a_synthetic_bench_is_calibrated_to_its_truth() {
    let dir = tempfile::tempdir().unwrap();
    let (rows, cols) = (120, 160);
    let mut sensor = Sensor::new(rows, cols, 40, (150.0, 1500.0), 25, 3);
    let truth = synthetic_psf(rows, cols);
    let light = &truth * (2500.0 / truth.iter().cloned().fold(0.0, f64::max));
    let background = Array2::from_shape_fn((rows, cols), |(i, j)| 30.0 + 40.0 * (i + j) as f64 / (rows + cols) as f64);

    let darks: Vec<_> = (0..20).map(|_| sensor.frame(None)).collect();
    write_frames(&dir.path().join("darks"), "dark", &darks);
    let shots: Vec<_> = (0..8).map(|_| sensor.frame(Some(&light))).collect();
    let shot_paths = write_frames(&dir.path().join("psf"), "shot", &shots);
    // The background as one multi-page float TIFF.
    let bg: Vec<_> = (0..4).map(|_| sensor.frame(Some(&background))).collect();
    let views: Vec<_> = bg.iter().map(|f| f.view()).collect();
    let bg_stack: Array4<f32> = ndarray::stack(Axis(0), &views).unwrap();
    let bg_path = dir.path().join("background.tiff");
    rollcam::io::write_tiff_stack_f32(&bg_path, bg_stack.view()).unwrap();

    let out = dir.path().join("cal");
    let darks_dir = dir.path().join("darks");
    let mut args: Vec<&str> = vec!["calibrate", "--dark", s(&darks_dir), "--psf-shots"];
    args.extend(shot_paths.iter().map(|p| s(p)));
    args.extend(["--background", s(&bg_path), "--out", s(&out)]);
    let stdout = ok(&rollcam(&args));
    println!("{stdout}");
    assert!(stdout.contains("read noise") && stdout.contains("hot") && stdout.contains("PSF: 8 shots") && stdout.contains("background: 4 frames"), "{stdout}");

    for f in ["calibration.toml", "dark.tiff", "defects.tiff", "psf.tiff", "background.tiff", "report.png"] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let cal = load_calibration(&out).unwrap();
    let rec = &cal.record;
    assert_eq!((rec.rows, rec.cols, rec.channels), (rows, cols, 1));
    assert!(!rec.created_utc.is_empty());

    // Read noise: the truth, with the rounding to counts (1/12 count^2).
    let dark = rec.dark.as_ref().unwrap();
    let read_truth = (READ_NOISE * READ_NOISE + 1.0 / 12.0).sqrt();
    assert!((dark.read_noise - read_truth).abs() < 0.1 * read_truth, "read noise {} vs {read_truth}", dark.read_noise);
    assert!((dark.fixed_pattern_rms - FPN_RMS).abs() < 0.15 * FPN_RMS, "{dark:?}");
    assert!((dark.median_level - DARK_LEVEL).abs() < 1.0, "{dark:?}");
    assert_eq!(dark.frames, 20);
    assert_eq!(dark.files.len(), 1);
    assert!(dark.files[0].ends_with("darks"), "{:?}", dark.files);

    // The defect map: precision and recall on the planted pixels, and the kinds.
    let map = cal.defects.as_ref().unwrap();
    let (precision, recall) = precision_recall(map, &sensor.planted());
    assert!(precision >= 0.95 && recall >= 0.95, "precision {precision}, recall {recall}, {:?}", rec.defects);
    let hot_ok = sensor.hot.iter().filter(|(p, _)| map[*p] == Defect::Hot.code()).count();
    let stuck_ok = sensor.stuck.iter().filter(|(p, _)| map[*p] == Defect::Stuck.code()).count();
    assert!(hot_ok as f64 >= 0.95 * 40.0 && stuck_ok as f64 >= 0.95 * 25.0, "hot {hot_ok}/40, stuck {stuck_ok}/25");

    // The PSF: unit sum, the truth's shape and centroid.
    let p = rec.psf.as_ref().unwrap();
    let psf = cal.psf.as_ref().unwrap().index_axis(Axis(2), 0).mapv(f64::from);
    assert!((psf.sum() - 1.0).abs() < 1e-4, "sum {}", psf.sum());
    let r = correlation(&truth, &psf);
    println!("correlation {r}, centre ({}, {}) vs {:?}, precision/recall {precision} {recall}", p.centre_row, p.centre_col, centroid(&truth));
    assert!(r >= 0.98, "correlation with the true PSF {r}");
    let (tr, tc) = centroid(&truth);
    assert!((p.centre_row - tr).abs() < 0.5 && (p.centre_col - tc).abs() < 0.5, "centre ({}, {}) vs ({tr}, {tc})", p.centre_row, p.centre_col);
    assert_eq!(p.shift, [0, 0]);
    assert!((p.energy_counts - light.sum()).abs() < 0.05 * light.sum(), "energy {} vs {}", p.energy_counts, light.sum());
    assert_eq!(p.files.len(), 8);
    assert!(p.peak_snr > 100.0, "{p:?}");

    // The background as shot, and its level above the dark.
    let b = rec.background.as_ref().unwrap();
    assert!((b.mean_above_dark - background.mean().unwrap()).abs() < 2.0, "{b:?} vs {}", background.mean().unwrap());
    assert_eq!(b.files.len(), 1);
}

#[test]
fn the_measured_diffusercam_psf_is_recovered_and_registered() {
    let dir = tempfile::tempdir().unwrap();
    let truth = load_truth_from_measured();
    let (rows, cols) = truth.dim();
    // Hot pixels clip at the 12-bit full scale: a pile there gives the saturation level.
    let mut sensor = Sensor::new(rows, cols, 30, (FULL_SCALE, FULL_SCALE), 20, 9);
    let light = &truth * (3000.0 / truth.iter().cloned().fold(0.0, f64::max));
    let darks: Vec<_> = (0..16).map(|_| sensor.frame(None)).collect();
    let dark_paths = write_frames(&dir.path().join("darks"), "d", &darks);
    let shots: Vec<_> = (0..6).map(|_| sensor.frame(Some(&light))).collect();
    let shot_paths = write_frames(&dir.path().join("psf"), "p", &shots);

    let out = dir.path().join("cal");
    let mut args: Vec<&str> = vec!["calibrate", "--register", "--out", s(&out), "--dark"];
    args.extend(dark_paths.iter().map(|p| s(p)));
    args.push("--psf-shots");
    args.extend(shot_paths.iter().map(|p| s(p)));
    let stdout = ok(&rollcam(&args));
    println!("{stdout}");
    assert!(stdout.contains("saturation level 4095 counts (detected"), "{stdout}");
    assert!(!stdout.contains("outside the defect map clip"), "clipped hot pixels are defects, not clipped light: {stdout}");

    let cal = load_calibration(&out).unwrap();
    let rec = &cal.record;
    assert_eq!(rec.saturation_level, Some(FULL_SCALE));
    assert!(rec.background.is_none() && cal.background.is_none() && !out.join("background.tiff").exists());
    let dark = rec.dark.as_ref().unwrap();
    let read_truth = (READ_NOISE * READ_NOISE + 1.0 / 12.0).sqrt();
    assert!((dark.read_noise - read_truth).abs() < 0.1 * read_truth, "{dark:?}");
    assert_eq!(dark.files.len(), 16);
    let (precision, recall) = precision_recall(cal.defects.as_ref().unwrap(), &sensor.planted());
    assert!(precision >= 0.95 && recall >= 0.95, "precision {precision}, recall {recall}, {:?}", rec.defects);

    let p = rec.psf.as_ref().unwrap();
    let (tr, tc) = centroid(&truth);
    assert!((p.centre_row - tr).abs() < 0.5 && (p.centre_col - tc).abs() < 0.5, "centre ({}, {}) vs ({tr}, {tc})", p.centre_row, p.centre_col);
    let expected_shift = [((rows / 2) as f64 - p.centre_row).round() as i64, ((cols / 2) as f64 - p.centre_col).round() as i64];
    assert_eq!(p.shift, expected_shift);
    let psf = cal.psf.as_ref().unwrap().index_axis(Axis(2), 0).mapv(f64::from);
    assert!((psf.sum() - 1.0).abs() < 1e-4);
    let moved = shift(&truth, p.shift);
    let r = correlation(&moved, &psf);
    println!("correlation {r}, centre ({}, {}) vs {:?}, precision/recall {precision} {recall}, truth {rows} x {cols}", p.centre_row, p.centre_col, (tr, tc));
    assert!(r >= 0.98, "correlation with the measured PSF {r}");
    let (cr, cc) = centroid(&psf);
    assert!((cr - (rows / 2) as f64).abs() <= 0.6 && (cc - (cols / 2) as f64).abs() <= 0.6, "registered centroid ({cr}, {cc})");
    assert!(out.join("report.png").is_file());
}

#[test]
fn refusals_name_what_is_wrong_and_touch_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let mut sensor = Sensor::new(16, 20, 0, (0.0, 0.0), 0, 1);
    let darks: Vec<_> = (0..4).map(|_| sensor.frame(None)).collect();
    let darks_dir = dir.path().join("darks");
    write_frames(&darks_dir, "d", &darks);

    // A non-empty --out: refused by name, its content unchanged.
    let out = dir.path().join("used");
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("calibration.toml"), "keep me").unwrap();
    let e = fails(&rollcam(&["calibrate", "--dark", s(&darks_dir), "--out", s(&out)]));
    assert!(e.contains(s(&out)) && e.contains("not empty"), "{e}");
    assert_eq!(std::fs::read_to_string(out.join("calibration.toml")).unwrap(), "keep me");
    assert_eq!(std::fs::read_dir(&out).unwrap().count(), 1);

    // A missing input is named.
    let missing = dir.path().join("no-such-darks");
    let fresh = dir.path().join("fresh");
    let e = fails(&rollcam(&["calibrate", "--dark", s(&missing), "--out", s(&fresh)]));
    assert!(e.contains(s(&missing)), "{e}");
    assert!(!fresh.exists(), "nothing is created on a refusal");

    // Neither darks nor PSF shots.
    let e = fails(&rollcam(&["calibrate", "--background", s(&darks_dir), "--out", s(&fresh)]));
    assert!(e.contains("--dark") && e.contains("--psf-shots"), "{e}");

    // A frame of another size is named by its file.
    let odd = dir.path().join("odd.tif");
    write_u16(&odd, &Array3::from_elem((16, 21, 1), 100.0));
    let e = fails(&rollcam(&["calibrate", "--dark", s(&darks_dir), s(&odd), "--out", s(&fresh)]));
    assert!(e.contains("odd.tif") && e.contains("16 x 21") && e.contains("16 x 20"), "{e}");

    // A bad saturation level names its flag.
    let e = fails(&rollcam(&["calibrate", "--dark", s(&darks_dir), "--saturation-level", "0", "--out", s(&fresh)]));
    assert!(e.contains("--saturation-level"), "{e}");

    // Every PSF shot clipped at 65535 (a flat PSF was accepted): refused, naming the shots.
    let clipped_dir = dir.path().join("clipped");
    write_frames(&clipped_dir, "p", &vec![Array3::from_elem((16, 20, 1), 65535.0); 3]);
    let e = fails(&rollcam(&["calibrate", "--dark", s(&darks_dir), "--psf-shots", s(&clipped_dir), "--out", s(&fresh)]));
    assert!(e.contains("PSF shots") && e.contains("65535 counts at every pixel of every shot"), "{e}");
    assert!(!fresh.exists(), "nothing is created on a refusal");

    // And a good run into a fresh folder works.
    let stdout = ok(&rollcam(&["calibrate", "--dark", s(&darks_dir), "--out", s(&fresh)]));
    assert!(stdout.contains("dark: 4 frames"), "{stdout}");
    assert!(fresh.join("calibration.toml").is_file() && fresh.join("report.png").is_file() && !fresh.join("psf.tiff").exists());
}
