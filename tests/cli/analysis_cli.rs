//! `rollcam analyze` end to end on a synthetic video with known timing: a bright spot
//! flashing a 1980 us square wave sampled every 220 us, and a second steady spot.
//! Checks the spectrum peak in Hz, the files, the theory numbers in analysis.json, and
//! the errors for a video without timing and for a region outside the frame.

use ndarray::Array4;
use rollcam::sim::scene::square_wave_mean;
use std::path::Path;
use std::process::Command;

fn rollcam() -> Command {
    Command::new(env!("CARGO_BIN_EXE_rollcam"))
}

/// 120 frames of 40 x 50: spot A at (20, 15) flashes with period 1980 us, spot B at
/// (20, 35) is steady.
fn write_inputs(dir: &Path) {
    let (k, m, n) = (120, 240, 50);
    let mut v = Array4::<f32>::zeros((k, m, n, 1));
    for f in 0..k {
        let on = square_wave_mean(f as f64 * 220.0, (f + 1) as f64 * 220.0, 1980.0, 0.5, 0.0) as f32;
        for dr in 0..3 {
            for dc in 0..3 {
                v[[f, 19 + dr, 14 + dc, 0]] = 10.0 * on;
                v[[f, 19 + dr, 34 + dc, 0]] = 4.0;
            }
        }
    }
    rollcam::io::write_npy(dir.join("video.npy"), v.view()).unwrap();
    // The video's 240 x 50 sensor, dual shutter, line time 220 us, exposure 660 us.
    std::fs::write(dir.join("capture.toml"), "rows = 240\ncols = 50\nline_time_us = 220.0\nexposure_us = 660.0\nshutter = \"dual\"\n").unwrap();
}

#[test]
fn analyze_a_video_with_its_config() {
    let dir = tempfile::tempdir().unwrap();
    write_inputs(dir.path());
    let out = dir.path().join("a");
    let o = rollcam()
        .args(["analyze", "--video"])
        .arg(dir.path().join("video.npy"))
        .arg("--config")
        .arg(dir.path().join("capture.toml"))
        .args(["--waveform-period-us", "1980", "--distance-mm", "12.4", "--pixel-pitch-um", "6.5", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&o.stderr));
    for f in ["xt_max.png", "xt_sum.png", "yt_max.png", "yt_sum.png", "spectrum.svg", "spectrum.png", "timecourse.png", "analysis.json"] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    let a: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("analysis.json")).unwrap()).unwrap();
    // Theory from the timing.
    assert!((a["theory"]["nyquist_hz"].as_f64().unwrap() - 1e6 / 440.0).abs() < 1e-6);
    assert!((a["theory"]["exposure_first_zero_hz"].as_f64().unwrap() - 1e6 / 660.0).abs() < 1e-6);
    // The two spots were found automatically; the flashing one peaks at 505 Hz.
    let regions = a["regions"].as_array().unwrap();
    assert_eq!(regions.len(), 2, "{regions:?}");
    let covers = |r: &serde_json::Value, col: u64| r["region"]["c0"].as_u64().unwrap() <= col && col < r["region"]["c1"].as_u64().unwrap();
    let flashing = regions.iter().find(|r| covers(r, 15)).expect("region on the flashing spot");
    let f = flashing["peak_frequency_hz"].as_f64().unwrap();
    let bin = a["bin_hz"].as_f64().unwrap();
    assert!((bin - 1e6 / (120.0 * 220.0)).abs() < 1e-9);
    assert!((f - 1e6 / 1980.0).abs() <= bin, "{f}");
    assert!(a["verdict"]["peak_within_one_bin"].as_bool().unwrap());
    // The steady spot carries no fundamental; the flashing one nearly a full one.
    let steady = regions.iter().find(|r| covers(r, 35)).expect("region on the steady spot");
    assert!(steady["fundamental_contrast"].as_f64().unwrap() < 0.01);
    assert!(flashing["fundamental_contrast"].as_f64().unwrap() > 0.8);
    // Spots 20 px apart with nothing between: resolved, and the angle from the geometry.
    assert!(a["dips"][0]["resolved"].as_bool().unwrap());
    let deg = a["angular"]["degrees_per_pixel"].as_f64().unwrap();
    assert!((deg - (6.5e-3f64 / 12.4).atan().to_degrees()).abs() < 1e-9);
    // The global-shutter comparison for this sensor: 120 line slots of 220 us at > 1010 fps.
    let g = &a["theory"]["waveform"]["global_shutter"];
    assert_eq!(g["frames"].as_u64(), Some(27));
    assert!(stdout.contains("global shutter"), "{stdout}");
}

#[test]
fn a_video_without_timing_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    write_inputs(dir.path());
    let o = rollcam().args(["analyze", "--video"]).arg(dir.path().join("video.npy")).output().unwrap();
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("video.npy") && e.contains("without timing") && e.contains("--config"), "{e}");
    // A folder without summary.json.
    let o = rollcam().arg("analyze").arg(dir.path()).output().unwrap();
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("summary.json"), "{e}");
}

#[test]
fn a_region_outside_the_frame_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    write_inputs(dir.path());
    let o = rollcam()
        .args(["analyze", "--video"])
        .arg(dir.path().join("video.npy"))
        .arg("--config")
        .arg(dir.path().join("capture.toml"))
        .args(["--region", "10,20,5,10", "--region", "230,245,0,10"])
        .output()
        .unwrap();
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("region 1") && e.contains("230,245,0,10") && e.contains("240 rows"), "{e}");
}

/// `--truth` on a reconstruction folder: each spot's time course against the truth's,
/// over every frame and, when `summary.json` reports frames where a source's brightness
/// is not in the data (`support.sources.unseen_frames`), over the rest.
#[test]
fn time_courses_against_the_truth_leave_out_the_frames_the_data_do_not_see() {
    let dir = tempfile::tempdir().unwrap();
    write_inputs(dir.path());
    let truth = rollcam::io::read_npy(dir.path().join("video.npy")).unwrap();
    rollcam::io::write_npy(dir.path().join("truth.npy"), truth.view()).unwrap();
    // The reconstruction: the truth, but the flashing spot wrong in frames 0-3.
    let rec = dir.path().join("rec");
    std::fs::create_dir(&rec).unwrap();
    let mut v = truth.clone();
    for f in 0..4 {
        for (dr, dc) in (0..3).flat_map(|r| (0..3).map(move |c| (r, c))) {
            v[[f, 19 + dr, 14 + dc, 0]] = if f % 2 == 0 { 40.0 } else { 0.0 };
        }
    }
    rollcam::io::write_npy(rec.join("video.npy"), v.view()).unwrap();
    let summary = |kept: bool| {
        format!(
            r#"{{"frame_time_us": 220.0, "capture": {{"rows": 240, "cols": 50, "line_time_us": 220.0, "exposure_us": 660.0, "shutter": "dual"}},
               "channels": [{{"support": {{"sources": {{"kept": {kept}, "unseen_frames": [[0, 4]]}}}}}}]}}"#
        )
    };
    let courses = |kept: bool| {
        std::fs::write(rec.join("summary.json"), summary(kept)).unwrap();
        let out = dir.path().join(format!("a-{kept}"));
        let o = rollcam().arg("analyze").arg(&rec).arg("--truth").arg(dir.path().join("truth.npy")).arg("--out").arg(&out).output().unwrap();
        let stdout = String::from_utf8_lossy(&o.stdout).to_string();
        assert!(o.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&o.stderr));
        let t: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("track.json")).unwrap()).unwrap();
        (t["courses"].as_array().unwrap().clone(), stdout)
    };
    let (with, stdout) = courses(true);
    assert_eq!(with.len(), 2, "{with:?}\n{stdout}");
    // The spots are named by their brightest pixel: the flashing one lies left of column 25.
    let left = |c: &&serde_json::Value| {
        c["name"].as_str().unwrap().split(", ").nth(1).and_then(|v| v.trim_end_matches(')').parse::<u32>().ok()).is_some_and(|col| col < 25)
    };
    let flashing = with.iter().find(left).unwrap_or_else(|| panic!("the flashing spot in {with:?}"));
    let (all, seen) = (flashing["correlation"].as_f64().unwrap(), flashing["correlation_seen"].as_f64().unwrap());
    assert!(all < 0.99 && seen > 0.999_999, "over every frame {all}, over the seen ones {seen}");
    assert_eq!(flashing["seen_frames"].as_u64(), Some(116));
    assert_eq!(flashing["truth_constant"].as_bool(), Some(false));
    assert!(stdout.contains("over the 116 the data see (frames 0-3 (4 of 120) left out"), "{stdout}");
    // The steady spot: the truth is the same in every frame, so no correlation is given
    // (a constant has none), and the terminal says why instead of printing a 0.
    let steady = with.iter().find(|c| !left(c)).unwrap_or_else(|| panic!("the steady spot in {with:?}"));
    assert_eq!(steady["truth_constant"].as_bool(), Some(true), "{steady:?}");
    assert!(steady["correlation"].is_null() && steady["correlation_seen"].is_null(), "{steady:?}");
    let name = steady["name"].as_str().unwrap();
    assert!(stdout.contains(&format!("{name}: the truth is the same in every frame there")), "{stdout}");
    assert!(!stdout.contains(&format!("{name}: time course against the truth's")), "{stdout}");
    // Sources not kept: the video is not theirs, and no frame is left out.
    let (without, stdout) = courses(false);
    let flashing = without.iter().find(left).unwrap();
    assert!(flashing["correlation_seen"].is_null() && (flashing["correlation"].as_f64().unwrap() - all).abs() < 1e-12);
    assert!(!stdout.contains("the data see"), "{stdout}");
}
