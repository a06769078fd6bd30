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
