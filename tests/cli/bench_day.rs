//! A bench day without hand-written timing: stills, captures that describe themselves,
//! files other tools read, and the inputs lensless users have.

use crate::support::cli;

use cli::{json, ok, rollcam};
use std::path::Path;

const TUTORIAL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data/diffusercam-tutorial");

/// The DiffuserCam tutorial's folder, or `None` (with a line saying the test is
/// skipped) where the shared data is not there.
fn tutorial() -> Option<&'static Path> {
    let dir = Path::new(TUTORIAL);
    if dir.join("rawdata_hand_sample.tif").is_file() && dir.join("psf_sample.tif").is_file() {
        Some(dir)
    } else {
        eprintln!("skipped: the DiffuserCam tutorial data is not at {TUTORIAL}");
        None
    }
}

#[test]
fn the_tutorial_hand_is_a_still_with_no_timing() {
    let Some(data) = tutorial() else { return };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("hand");
    let (raw, psf) = (data.join("rawdata_hand_sample.tif"), data.join("psf_sample.tif"));
    let text = ok(&rollcam(
        &[
            "reconstruct",
            "--raw",
            raw.to_str().unwrap(),
            "--psf",
            psf.to_str().unwrap(),
            "--shutter",
            "global",
            "--downsample",
            "4",
            "--out",
            out.to_str().unwrap(),
        ],
        dir.path(),
    ));
    assert!(text.contains("still: one image of 300 x 400"), "{text}");
    assert!(!text.contains("fps"), "{text}");
    let estimated = text.find("estimated solve time: ").expect("an estimate");
    assert!(estimated < text.find("still: one image").unwrap(), "the estimate comes before the solve: {text}");
    let summary = json(&out.join("summary.json"));
    assert_eq!(summary["video_shape"][0].as_u64(), Some(1), "{summary}");
    assert_eq!(summary["still"].as_bool(), Some(true));
    assert_eq!(summary["capture"]["shutter"].as_str(), Some("global"));
    assert!(!imagej_description(&out.join("video.tiff")).contains("finterval"), "a still has no frame interval");
}

/// The ImageJ description of a TIFF's first page, read with the `tiff` crate.
fn imagej_description(path: &Path) -> String {
    let mut dec = tiff::decoder::Decoder::new(std::fs::File::open(path).unwrap()).unwrap();
    dec.get_tag_ascii_string(tiff::tags::Tag::ImageDescription).unwrap()
}

#[test]
fn video_tiff_carries_the_frame_interval_and_the_summary_the_contact_sheet_frames() {
    let dir = tempfile::tempdir().unwrap();
    let sim = cli::simulate_small(dir.path(), "led-array");
    let rec = dir.path().join("rec");
    let summary = cli::reconstruct_sim(&sim, &rec, &["--iters", "3"]);
    let frame_time_us = summary["frame_time_us"].as_f64().unwrap();
    let description = imagej_description(&rec.join("video.tiff"));
    let value = |key: &str| description.lines().find_map(|l| l.strip_prefix(key)).unwrap_or_else(|| panic!("{key} in {description}")).to_string();
    let finterval: f64 = value("finterval=").parse().unwrap();
    assert!((finterval - frame_time_us * 1e-6).abs() <= 1e-12, "finterval {finterval} s, frame time {frame_time_us} us");
    assert_eq!((value("tunit="), value("unit=")), ("sec".to_string(), "pixel".to_string()));
    let frames = summary["video_shape"][0].as_u64().unwrap() as usize;
    let shown: Vec<usize> = summary["contact_sheet_frames"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap() as usize).collect();
    assert_eq!(shown.len(), frames.min(rollcam::io::CONTACT_SHEET_MAX_FRAMES));
    assert_eq!((shown[0], *shown.last().unwrap()), (0, frames - 1));
    assert_eq!(summary["still"].as_bool(), Some(false));
}

/// A raw with no capture description: one message that names `--config FILE`, every
/// flag missing in its place and `--shutter global` for a still; with one flag given,
/// only the others are named.
#[test]
fn a_missing_capture_description_is_named_in_one_message() {
    let dir = tempfile::tempdir().unwrap();
    let sim = cli::simulate_small(dir.path(), "led-array");
    let (raw, psf) = (sim.join("raw.tiff"), sim.join("psf.tiff"));
    let out = dir.path().join("rec");
    let base = ["reconstruct", "--raw", raw.to_str().unwrap(), "--psf", psf.to_str().unwrap(), "--out", out.to_str().unwrap()];
    let e = cli::fails(&rollcam(&base, dir.path()));
    assert_eq!(e.trim().lines().count(), 1, "one message: {e}");
    for needed in ["--config FILE", "--line-time-us, --exposure-us, --shutter", "--shutter global"] {
        assert!(e.contains(needed), "{needed} in {e}");
    }
    let mut with_line = base.to_vec();
    with_line.extend(["--line-time-us", "220"]);
    let e = cli::fails(&rollcam(&with_line, dir.path()));
    assert!(e.contains("missing: --exposure-us, --shutter)") && !e.contains("--line-time-us,"), "{e}");
    assert!(!out.exists(), "nothing written");
}

/// The number before `what` in `text` (e.g. "1235 saturated pixels").
fn count_before(text: &str, what: &str) -> usize {
    let at = text.find(what).unwrap_or_else(|| panic!("{what} in {text}"));
    text[..at].trim_end().rsplit(|c: char| !c.is_ascii_digit()).next().unwrap().parse().unwrap_or_else(|e| panic!("{what} in {text}: {e}"))
}

/// A saturating simulation writes its full well in counts as capture.toml's
/// saturation level, so `reconstruct` counts the pixels the simulator clipped.
#[test]
fn a_saturating_simulation_shows_its_clipped_pixels_in_the_reconstruction() {
    let dir = tempfile::tempdir().unwrap();
    let sim = dir.path().join("sim");
    let text =
        ok(&rollcam(&["simulate", "--scene", "led-array", "--rows", "64", "--cols", "80", "--e-per-us", "1e5", "--out", sim.to_str().unwrap()], dir.path()));
    let clipped_sim = count_before(&text, "saturated pixels");
    assert!(clipped_sim > 20, "{text}");
    let cfg = rollcam::model::capture::CaptureConfig::load(&sim.join("capture.toml")).unwrap();
    // 0.5 ADU/e- x 30000 e- + 100, less four read-noise deviations (2 e-).
    assert_eq!(cfg.saturation_level, Some(15096.0));
    let summary = cli::reconstruct_sim(&sim, &dir.path().join("rec"), &["--iters", "3"]);
    let clipped_rec = summary["sensor"]["saturated_pixels"].as_u64().unwrap() as usize;
    assert_eq!(summary["sensor"]["saturation_source"].as_str(), Some("capture-toml"), "{}", summary["sensor"]);
    assert!(
        clipped_rec * 10 >= clipped_sim * 9 && clipped_rec <= clipped_sim + clipped_sim / 10,
        "simulated {clipped_sim} clipped, reconstruct sees {clipped_rec}"
    );
}

/// `--scene stack` takes its brightness in photo-electrons per microsecond: the
/// stack's brightest value collects `--stack-e-per-us`, and the truth (counts per
/// frame interval) scales with it.
#[test]
fn a_stack_scene_takes_its_brightness_in_photoelectrons_per_microsecond() {
    let dir = tempfile::tempdir().unwrap();
    let mut image = ndarray::Array4::<f32>::zeros((1, 32, 40, 1));
    for ((_, r, c, _), v) in image.indexed_iter_mut() {
        *v = ((r * 40 + c) % 7) as f32 / 6.0;
    }
    let stack = dir.path().join("stack.npy");
    rollcam::io::write_npy(&stack, image.view()).unwrap();
    let truth_max = |extra: &[&str], name: &str| -> f32 {
        let out = dir.path().join(name);
        let mut args = vec![
            "simulate",
            "--scene",
            "stack",
            "--stack",
            stack.to_str().unwrap(),
            "--rows",
            "32",
            "--cols",
            "40",
            "--no-noise",
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend(extra);
        ok(&rollcam(&args, dir.path()));
        rollcam::io::read_stack(out.join("truth.npy")).unwrap().fold(0.0f32, |m, &v| m.max(v))
    };
    let plain = truth_max(&[], "plain");
    let scaled = truth_max(&["--stack-e-per-us", "100"], "scaled");
    assert!(plain > 0.0 && (scaled / plain - 100.0).abs() < 0.5, "a 0-1 stack at 100 e-/us: truth peak {scaled} against {plain} as given");
    let e = cli::fails(&rollcam(&["simulate", "--scene", "led-array", "--stack-e-per-us", "100", "--out", dir.path().join("x").to_str().unwrap()], dir.path()));
    assert!(e.contains("--stack-e-per-us") && e.contains("--scene stack"), "{e}");
}

/// The estimate before a solve counts the iterations the stop rule usually runs, not
/// the cap: on a simulated dense capture (which converges well before the cap) the
/// iterations the estimate counts are within 3x of those the solve ran, summary.json's
/// `estimated_seconds` is that count's share of the cap's, and the terminal gives the
/// range up to the cap. (Iterations, not seconds: a timed comparison would fail on a
/// loaded machine, where the estimate's three timed applications run slower or faster
/// than the solve's.)
#[test]
fn the_estimate_follows_the_stop_rule_on_a_dense_capture() {
    let dir = tempfile::tempdir().unwrap();
    let sim = dir.path().join("dense");
    ok(&rollcam(
        &["simulate", "--scene", "disc-over-texture", "--rows", "64", "--cols", "80", "--downsample", "2", "--out", sim.to_str().unwrap()],
        dir.path(),
    ));
    let out = dir.path().join("rec");
    let (raw, psf, cfg) = (sim.join("raw.tiff"), sim.join("psf.tiff"), sim.join("capture.toml"));
    let text = ok(&rollcam(
        &["reconstruct", "--raw", raw.to_str().unwrap(), "--psf", psf.to_str().unwrap(), "--config", cfg.to_str().unwrap(), "--out", out.to_str().unwrap()],
        dir.path(),
    ));
    assert!(text.contains("estimated solve time: about") && text.contains("at most the cap of 600"), "{text}");
    let summary = json(&out.join("summary.json"));
    let (seconds, estimated) = (summary["seconds"].as_f64().unwrap(), summary["estimated_seconds"].as_f64().expect("estimated_seconds"));
    let iterations = summary["channels"][0]["iterations"].as_u64().unwrap();
    assert!(iterations < 600, "the dense capture converges before the cap: {iterations}");
    let usual: u64 = text
        .split("usually about ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no usual iteration count in {text}"));
    assert!(usual <= 3 * iterations && iterations <= 3 * usual, "estimated for {usual} iterations, ran {iterations}");
    let per = text.split(" s per iteration").next().and_then(|t| t.rsplit(' ').next()).and_then(|n| n.parse::<f64>().ok()).expect("seconds per iteration");
    // The terminal rounds the seconds per iteration to 4 decimals.
    assert!((estimated - per * usual as f64).abs() <= 5e-5 * usual as f64 + 1e-9, "estimated {estimated} s = {usual} x {per} s (took {seconds:.2} s)");
    // trace.svg's legend names the solver that ran.
    let svg = std::fs::read_to_string(out.join("trace.svg")).unwrap();
    assert!(svg.contains("fista-restart") && !svg.contains(">FISTA<"), "the legend names fista-restart");
}
