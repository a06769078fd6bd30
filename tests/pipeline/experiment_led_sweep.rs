//! The LED sweep at a small size (64 x 80, 40 iterations): the simulated outcome the
//! paper reports. Spectral peaks at the LED frequency for the long periods, temporal
//! contrast collapsing at 660 us (= T_e), all four LEDs resolved spatially; the report
//! files exist and agree with the returned numbers.

use rollcam::analysis::led_sweep::{quiet_hooks, run_sweep, SweepOptions, SweepSize};
use std::sync::atomic::AtomicBool;

#[test]
fn small_sweep_reproduces_the_paper_outcome() {
    let dir = tempfile::tempdir().unwrap();
    let opts = SweepOptions { periods_us: vec![2640.0, 1980.0, 660.0], size: SweepSize::Small, iters: 40, ..SweepOptions::default() };
    let stop = AtomicBool::new(false);
    let report = run_sweep(&opts, dir.path(), "test", &quiet_hooks(&stop), &|_| {}).unwrap();
    assert_eq!(report.rows.len(), 3);
    for r in &report.rows {
        println!(
            "{:.0} us: peak {:?} Hz (expected {:.1}, bin {:.0}), contrast {:.2} (truth {:.2?}, theory {:.2}), spatial {:.2}, {}/{} pairs",
            r.period_us,
            r.measured_peak_hz,
            r.expected_frequency_hz,
            r.bin_hz,
            r.temporal_contrast,
            r.truth_temporal_contrast,
            r.expected_temporal_contrast,
            r.spatial_contrast,
            r.pairs_resolved,
            r.pairs
        );
        // Four LEDs resolved at every period.
        assert_eq!((r.pairs_resolved, r.pairs), (3, 3), "period {}", r.period_us);
    }
    let (p2640, p1980, p660) = (&report.rows[0], &report.rows[1], &report.rows[2]);
    for r in [p2640, p1980] {
        let f = r.measured_peak_hz.expect("a spectral peak");
        assert!((f - r.expected_frequency_hz).abs() <= r.bin_hz, "period {}: peak {f} Hz vs {} Hz (bin {})", r.period_us, r.expected_frequency_hz, r.bin_hz);
        assert!(r.peak_within_one_bin);
    }
    // At 660 us the exposure integrates whole periods: contrast collapses, no peak there.
    assert!(p660.expected_temporal_contrast < 1e-9);
    assert!(p660.temporal_contrast < 0.25 * p2640.temporal_contrast, "{} vs {}", p660.temporal_contrast, p2640.temporal_contrast);
    assert!(!p660.peak_within_one_bin);
    // The truth keeps its contrast at 660 us: the loss is the measurement's, not the scene's.
    assert!(p660.truth_temporal_contrast.expect("simulated truth") > 0.5, "{:?}", p660.truth_temporal_contrast);
    // Report files.
    for f in ["report.md", "report.json", "figure.png", "period-660us/analysis/analysis.json", "period-2640us/rec/video.npy"] {
        assert!(dir.path().join(f).exists(), "{f} missing");
    }
    let md = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    assert!(md.contains("| 2640 |") && md.contains("| 660 |"), "{md}");
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.path().join("report.json")).unwrap()).unwrap();
    assert_eq!(json["rows"].as_array().unwrap().len(), 3);
    assert_eq!(json["rows"][2]["period_us"].as_f64(), Some(660.0));
    // The figure holds one row per period.
    let fig = image::open(dir.path().join("figure.png")).unwrap();
    assert!(fig.height() >= 3 * 300, "{}", fig.height());
}

#[test]
fn bad_periods_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let stop = AtomicBool::new(false);
    let opts = SweepOptions { periods_us: vec![2640.0, -1.0], size: SweepSize::Small, iters: 2, ..SweepOptions::default() };
    let e = run_sweep(&opts, dir.path(), "test", &quiet_hooks(&stop), &|_| {}).unwrap_err().to_string();
    assert!(e.contains("--periods-us") && e.contains("-1"), "{e}");
    // A period of 1e308 us is refused by its range before any folder is named after it.
    let opts = SweepOptions { periods_us: vec![1e308], size: SweepSize::Small, iters: 2, ..SweepOptions::default() };
    let e = run_sweep(&opts, &dir.path().join("huge"), "test", &quiet_hooks(&stop), &|_| {}).unwrap_err().to_string();
    assert!(e.contains("--periods-us") && e.contains("1e7 us") && !e.contains("too long"), "{e}");
    assert!(!dir.path().join("huge").exists());
}

/// A bench capture in which the reconstruction shows no bright spot (uniform light) and
/// no LED pixel was given: the sweep says to give `--led-pixel` rather than only that
/// the video has no spot.
#[test]
fn a_capture_without_bright_spots_asks_for_the_led_pixels() {
    use rollcam::analysis::led_sweep::{analyse_period, Acquired, LINE_TIME_US};
    use rollcam::model::capture::CaptureConfig;
    use rollcam::model::shutter::ShutterMode;
    let dir = tempfile::tempdir().unwrap();
    let (rows, cols) = (32, 40);
    let mut cfg = CaptureConfig::new(rows, cols, LINE_TIME_US, 3.0 * LINE_TIME_US, ShutterMode::Dual);
    cfg.dark_level = Some(0.0);
    let mut psf = ndarray::Array3::<f32>::zeros((rows, cols, 1));
    psf[[rows / 2, cols / 2, 0]] = 1000.0;
    let acq = Acquired {
        raw: ndarray::Array3::from_elem((rows, cols, 1), 1000.0),
        raw_name: "flat.tiff".into(),
        psf,
        psf_name: "point.tiff".into(),
        psf_clean: true,
        cfg,
        config_name: "capture.toml".into(),
        truth: None,
        centres: None,
        leds: 4,
        duty: 0.5,
        led_readback: None,
        capture: None,
    };
    let opts = SweepOptions { size: SweepSize::Small, iters: 5, ..SweepOptions::default() };
    let stop = AtomicBool::new(false);
    let e = analyse_period(&opts, 2640.0, acq, dir.path(), &quiet_hooks(&stop), std::time::Instant::now()).unwrap_err().to_string();
    assert!(e.contains("no bright spot") && e.contains("--led-pixel ROW,COL"), "{e}");
}
