//! The still start (`--start auto`, the default): the video solve starts from the
//! still image, solved first through the one-convolution still operator and repeated
//! in every frame. Through the real binary, on a small dense scene (a disc over a
//! textured still scene): after the same iterations it must be closer to the truth
//! than the start from zero, say what it did in summary.json, count its seconds in the
//! run's time and trace, and be chosen per run in `compare`.

use crate::support::cli;

use cli::{fails, json, ok, reconstruct_sim, rollcam, simulate_small};
use std::path::Path;

fn simulate(dir: &Path) -> std::path::PathBuf {
    simulate_small(dir, "disc-over-texture")
}

/// 30 iterations of `reconstruct` with `extra`.
fn reconstruct(sim: &Path, out: &Path, extra: &[&str]) -> serde_json::Value {
    // The weight these figures were measured at, and exactly 30 iterations.
    let mut args = vec!["--iters", "30", "--tau-rel", "2e-3", "--obj-tol", "0"];
    args.extend_from_slice(extra);
    reconstruct_sim(sim, out, &args)
}

fn rel_error(summary: &serde_json::Value) -> f64 {
    summary["channels"][0]["error"]["rel_error"].as_f64().unwrap_or_else(|| panic!("no rel_error in {summary}"))
}

#[test]
fn still_start_beats_zero_start_and_reports_itself() {
    let dir = tempfile::tempdir().unwrap();
    let sim = simulate(dir.path());
    let zero = reconstruct(&sim, &dir.path().join("zero"), &["--start", "zero"]);
    let still = reconstruct(&sim, &dir.path().join("still"), &[]);
    let (ez, es) = (rel_error(&zero), rel_error(&still));
    println!("30 iterations: relative error {ez:.4} from zero, {es:.4} from the still image");
    assert!(es < 0.8 * ez, "the still start ({es}) should be well below the zero start ({ez}) after 30 iterations");

    // The report: absent for a zero start; the still solve's figures otherwise.
    assert!(zero["channels"][0].get("start").is_none(), "{}", zero["channels"][0]);
    let start = &still["channels"][0]["start"];
    let (iters, secs) = (start["iterations"].as_u64().unwrap(), start["seconds"].as_f64().unwrap());
    assert_eq!(iters, rollcam::solve::start::STILL_ITERS as u64);
    assert_eq!(start["used"], true, "{start}");
    let residual = start["residual_rel"].as_f64().unwrap();
    assert!(secs > 0.0 && start["lipschitz"].as_f64().unwrap() > 0.0 && residual > 0.0 && residual < rollcam::solve::start::STILL_RESIDUAL_MAX, "{start}");
    // Its seconds are in the run's and in every trace row.
    let total = still["channels"][0]["seconds"].as_f64().unwrap();
    assert!(total >= secs, "run {total} s, start {secs} s");
    let trace = std::fs::read_to_string(dir.path().join("still/trace.csv")).unwrap();
    let header: Vec<&str> = trace.lines().find(|l| !l.starts_with('#')).unwrap().split(',').collect();
    let col = header.iter().position(|h| *h == "seconds").expect("a seconds column");
    let first: f64 = trace.lines().filter(|l| !l.starts_with('#')).nth(1).unwrap().split(',').nth(col).unwrap().parse().unwrap();
    assert!(first >= secs, "first trace row at {first} s, before the start's {secs} s");
}

#[test]
fn a_start_that_is_not_known_is_refused_and_compare_runs_each_start() {
    let dir = tempfile::tempdir().unwrap();
    let sim = simulate(dir.path());
    let (raw, psf, cfg, truth) = (sim.join("raw.tiff"), sim.join("psf.tiff"), sim.join("capture.toml"), sim.join("truth.npy"));
    let (raw, psf, cfg, truth) = (raw.to_str().unwrap(), psf.to_str().unwrap(), cfg.to_str().unwrap(), truth.to_str().unwrap());
    let out = dir.path().join("bad");
    let e = fails(&rollcam(&["reconstruct", "--raw", raw, "--psf", psf, "--config", cfg, "--start", "cold", "--out", out.to_str().unwrap()], dir.path()));
    assert!(e.contains("--start") && e.contains("auto, still or zero"), "{e}");
    assert!(!out.exists(), "a refused run must not create its folder");
    // Consecutive captures start each window from the result so far: `still` is refused
    // there before anything is read.
    let seq = dir.path().join("seq");
    let e = fails(&rollcam(&["reconstruct-sequence", sim.to_str().unwrap(), "--start", "still", "--out", seq.to_str().unwrap()], dir.path()));
    assert!(e.contains("--start = still") && e.contains("consecutive captures"), "{e}");
    assert!(!seq.exists());

    let cmp = dir.path().join("cmp");
    let e = fails(&rollcam(
        &["compare", "--raw", raw, "--psf", psf, "--config", cfg, "--solvers", "fista-restart:start=warm", "--out", cmp.to_str().unwrap()],
        dir.path(),
    ));
    assert!(e.contains("start") && e.contains("auto, still or zero"), "{e}");
    ok(&rollcam(
        &[
            "compare",
            "--raw",
            raw,
            "--psf",
            psf,
            "--config",
            cfg,
            "--truth",
            truth,
            "--iters",
            "20",
            "--solvers",
            "fista-restart:start=zero,fista-restart",
            "--out",
            cmp.to_str().unwrap(),
        ],
        dir.path(),
    ));
    let s = json(&cmp.join("summary.json"));
    let runs = s["solvers"].as_array().unwrap();
    assert!(runs[0]["start"].is_null(), "{}", runs[0]);
    assert_eq!(runs[1]["start"]["iterations"].as_u64(), Some(rollcam::solve::start::STILL_ITERS as u64));
    let psnr = |r: &serde_json::Value| r["final_psnr_db"].as_f64().unwrap();
    assert!(psnr(&runs[1]) > psnr(&runs[0]), "still {} dB against zero {} dB", psnr(&runs[1]), psnr(&runs[0]));
}

/// Flashing LEDs: the still image leaves most of the raw unexplained, so `auto` stops
/// the still solve at its check and starts from zero. The video is then the zero
/// start's, bit for bit; `--start still` takes the still image anyway.
#[test]
fn auto_starts_a_flashing_scene_from_zero() {
    let dir = tempfile::tempdir().unwrap();
    let sim = simulate_small(dir.path(), "led-array");
    let auto = reconstruct(&sim, &dir.path().join("auto"), &[]);
    let zero = reconstruct(&sim, &dir.path().join("zero"), &["--start", "zero"]);
    let still = reconstruct(&sim, &dir.path().join("still"), &["--start", "still"]);
    let start = &auto["channels"][0]["start"];
    assert_eq!(start["used"], false, "{start}");
    assert_eq!(start["iterations"].as_u64(), Some(rollcam::solve::start::STILL_CHECK_ITERS as u64));
    assert!(start["residual_rel"].as_f64().unwrap() > rollcam::solve::start::STILL_RESIDUAL_MAX, "{start}");
    let video = |name: &str| -> ndarray::Array4<f32> { rollcam::io::read_npy(dir.path().join(name).join("video.npy")).unwrap() };
    assert_eq!(video("auto"), video("zero"), "a start not taken leaves the zero start's video");
    assert_eq!(still["channels"][0]["start"]["used"], true);
    assert_ne!(video("still"), video("zero"));
    assert!(rel_error(&zero).is_finite());
}
