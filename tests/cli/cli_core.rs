//! End to end through the command line: demo, simulate -> reconstruct, and bad input.

use crate::support::cli;

use cli::{fails, json, ok, rollcam};

#[test]
fn demo_resolves_every_led_square_wave() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    let text = ok(&rollcam(&["demo", "--out", out.to_str().unwrap(), "--iters", "120"], dir.path()));
    // The headline leads with the relative error after the best scale and puts the PSNR
    // beside an all-zero video's and the truth's temporal mean's.
    assert!(text.contains("against the truth: relative error"), "{text}");
    assert!(text.contains("an all-zero video:") && text.contains("the truth's temporal mean:"), "{text}");
    for f in [
        "sim/raw.tiff",
        "sim/psf.tiff",
        "sim/truth.npy",
        "sim/capture.toml",
        "rec/video.tiff",
        "rec/video.npy",
        "rec/contact.png",
        "rec/video.gif",
        "rec/trace.csv",
        "rec/trace.png",
        "rec/summary.json",
        "rec/leds.json",
    ] {
        assert!(out.join(f).is_file(), "missing {f}");
    }
    let summary = json(&out.join("rec/summary.json"));
    let psnr = summary["psnr_db"].as_f64().unwrap();
    assert!(psnr > 30.0, "PSNR {psnr}");
    assert!(summary["seconds"].as_f64().unwrap() > 0.0);
    // The cap or the convergence test ended the solve, and the summary says which.
    let iterations = summary["channels"][0]["iterations"].as_u64().unwrap();
    assert!(iterations <= 120);
    assert_eq!(summary["converged"].as_bool().unwrap(), iterations < 120, "{text}");
    let zero_db = summary["channels"][0]["baseline"]["zero_psnr_db"].as_f64().unwrap();
    assert!(zero_db < psnr, "an all-zero video scores {zero_db} dB against {psnr}");
    let scaled = summary["rel_error_scaled"].as_f64().unwrap();
    assert!(scaled > 0.0 && scaled <= summary["rel_error"].as_f64().unwrap() + 1e-12);
    // The motion error beside it: flashing LEDs move, and after 120 iterations the
    // video holds some of it (measured 0.937; a still scores 1); one channel, so the
    // headline is that channel's.
    let motion = summary["motion_error"].as_f64().unwrap_or_else(|| panic!("no motion_error in {summary}"));
    assert!(motion > 0.0 && motion < 1.0, "motion error {motion}");
    assert_eq!(summary["channels"][0]["motion_error"].as_f64(), Some(motion));
    assert!(text.contains("motion error") && text.contains("(a still scores 1)"), "{text}");
    // The trace has it at every iteration, its last row the summary's.
    let csv = std::fs::read_to_string(out.join("rec/trace.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let col = header.iter().position(|h| *h == "motion_error").expect("a motion_error column");
    let per_iteration: Vec<f64> = csv.lines().skip(1).map(|l| l.split(',').nth(col).unwrap().parse().unwrap()).collect();
    assert_eq!(per_iteration.len(), iterations as usize);
    assert!((per_iteration.last().unwrap() - motion).abs() < 1e-5, "{per_iteration:?} against {motion}");
    assert!(per_iteration[0] > *per_iteration.last().unwrap(), "the motion forms over the run: {} -> {motion}", per_iteration[0]);
    let leds = json(&out.join("rec/leds.json"));
    let leds = leds.as_array().unwrap();
    assert_eq!(leds.len(), 4);
    for l in leds {
        let r = l["correlation"].as_f64().unwrap();
        assert!(r > 0.5, "LED {} (period {} us) correlates at {r}", l["led"], l["period_us"]);
    }
    // The trace has one row per iteration and PSNR improves over the run.
    let csv = std::fs::read_to_string(out.join("rec/trace.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv.lines().skip(1).map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 120);
    let first: f64 = rows[0][7].parse().unwrap();
    let last: f64 = rows[119][7].parse().unwrap();
    // Solved on the LEDs' support first (a sparse scene), the first iterate is already
    // dark where the truth is: the run still gains, and ends well above an all-zero video.
    assert!(last > first && last > zero_db + 5.0, "PSNR {first} -> {last} (all-zero video {zero_db})");
    // The support and its probe are reported, kept or not (after 120 iterations the
    // probe's ratio lies near its threshold).
    let support = &summary["channels"][0]["support"];
    assert!(support["probe_misfit_ratio"].as_f64().is_some_and(|r| r > 0.0) && support["pixels"].as_u64().unwrap() > 0, "{summary}");
    assert!(text.contains("where the still image shows it") || text.contains("the still image's support"), "{text}");
}

#[test]
fn simulate_then_reconstruct_with_flags_overriding_the_config() {
    let dir = tempfile::tempdir().unwrap();
    let sim = dir.path().join("sim");
    let s = sim.to_str().unwrap();
    ok(&rollcam(&["simulate", "--scene", "moving-disc", "--rows", "48", "--cols", "64", "--out", s], dir.path()));
    let cfg = std::fs::read_to_string(sim.join("capture.toml")).unwrap();
    assert!(cfg.contains("shutter = \"dual\"") && cfg.contains("[scene]") && cfg.contains("dark_level"), "{cfg}");
    let rec = dir.path().join("rec");
    let text = ok(&rollcam(
        &[
            "reconstruct",
            "--raw",
            &format!("{s}/raw.tiff"),
            "--psf",
            &format!("{s}/psf.tiff"),
            "--config",
            &format!("{s}/capture.toml"),
            "--truth",
            &format!("{s}/truth.npy"),
            "--out",
            rec.to_str().unwrap(),
            "--iters",
            "30",
            "--obj-tol",
            "0",
            "--alpha",
            "2",
        ],
        dir.path(),
    ));
    // With the convergence test off the cap ends the solve, and the terminal and the
    // summary say so.
    assert!(text.contains("30 iterations"), "{text}");
    assert!(text.contains("NOT converged: the iteration cap ended it after 30 iterations"), "{text}");
    let summary = json(&rec.join("summary.json"));
    assert_eq!(summary["converged"].as_bool(), Some(false));
    assert_eq!(summary["channels"][0]["converged"].as_bool(), Some(false));
    assert_eq!(summary["params"]["alpha"].as_f64().unwrap(), 2.0);
    let shape: Vec<u64> = summary["video_shape"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap()).collect();
    // Dual shutter, 48 rows, N_l = 3: K = 24 + 2.
    assert_eq!(shape, vec![26, 48, 64, 1]);
    // Frames 0 and 25 are seen by one row of each half (the partial exposures at the
    // ends): under half the sensitivity of a fully exposed frame, and said so.
    let sens = &summary["frame_sensitivity"];
    let rel: Vec<f64> = sens["relative"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert_eq!(rel.len(), 26);
    assert!((rel.iter().cloned().fold(0.0, f64::max) - 1.0).abs() < 1e-12, "{rel:?}");
    assert!(rel[0] < 0.5 && rel[25] < 0.5 && rel[12] > 0.5, "{rel:?}");
    let weak = sens["weak_frames"].as_array().unwrap();
    assert_eq!(weak.first().unwrap()[0], 0);
    assert_eq!(weak.last().unwrap()[1], 26);
    assert!(text.contains("weakly constrained: frames 0"), "{text}");
    let video = rollcam::io::read_npy(rec.join("video.npy")).unwrap();
    assert_eq!(video.dim(), (26, 48, 64, 1));
    assert!(video.iter().all(|v| v.is_finite() && *v >= 0.0));

    // Downsampling by 2 from the command line: grid 24 x 32, frames of 2 line times.
    let rec2 = dir.path().join("rec2");
    ok(&rollcam(
        &[
            "reconstruct",
            "--raw",
            &format!("{s}/raw.tiff"),
            "--psf",
            &format!("{s}/psf.tiff"),
            "--config",
            &format!("{s}/capture.toml"),
            "--out",
            rec2.to_str().unwrap(),
            "--iters",
            "5",
            "--downsample",
            "2",
        ],
        dir.path(),
    ));
    let summary = json(&rec2.join("summary.json"));
    assert_eq!(summary["video_shape"][1].as_u64().unwrap(), 24);
    assert_eq!(summary["video_shape"][2].as_u64().unwrap(), 32);
    assert!((summary["frame_time_us"].as_f64().unwrap() - 440.0).abs() < 1e-9);
}

#[test]
fn bad_input_gets_a_clear_error_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let sim = dir.path().join("sim");
    let s = sim.to_str().unwrap().to_string();
    ok(&rollcam(&["simulate", "--rows", "32", "--cols", "40", "--spacing-px", "6", "--out", &s], dir.path()));
    let rec = dir.path().join("rec");
    let r = rec.to_str().unwrap().to_string();
    let raw = format!("{s}/raw.tiff");
    let psf = format!("{s}/psf.tiff");
    let cfg = format!("{s}/capture.toml");
    let run = |extra: &[&str]| -> String {
        let mut args = vec!["reconstruct", "--out", r.as_str(), "--iters", "3"];
        args.extend_from_slice(extra);
        fails(&rollcam(&args, dir.path()))
    };

    // Missing file.
    let e = run(&["--raw", "nope.tiff", "--psf", &psf, "--config", &cfg]);
    assert!(e.contains("nope.tiff"), "{e}");
    // Truncated raw.
    let bytes = std::fs::read(&raw).unwrap();
    let cut = dir.path().join("cut.tiff");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let e = run(&["--raw", cut.to_str().unwrap(), "--psf", &psf, "--config", &cfg]);
    assert!(e.contains("cut.tiff") && e.contains("truncated"), "{e}");
    // PSF of another size.
    let small = dir.path().join("small.tiff");
    rollcam::io::write_tiff_f32(&small, ndarray::Array3::<f32>::ones((30, 40, 1)).view()).unwrap();
    let e = run(&["--raw", &raw, "--psf", small.to_str().unwrap(), "--config", &cfg]);
    assert!(e.contains("small.tiff") && e.contains("30 x 40"), "{e}");
    // NaN in the PSF.
    let mut p = rollcam::io::read_image(&psf).unwrap();
    p[[3, 4, 0]] = f32::NAN;
    let nan = dir.path().join("nan.tiff");
    rollcam::io::write_tiff_f32(&nan, p.view()).unwrap();
    let e = run(&["--raw", &raw, "--psf", nan.to_str().unwrap(), "--config", &cfg]);
    assert!(e.contains("nan.tiff") && e.contains("NaN"), "{e}");
    // A flat PSF (the same value everywhere: no point source), refused as calibrate does.
    let flat = dir.path().join("flat.tiff");
    rollcam::io::write_tiff_f32(&flat, ndarray::Array3::<f32>::from_elem((32, 40, 1), 100.0).view()).unwrap();
    let e = run(&["--raw", &raw, "--psf", flat.to_str().unwrap(), "--config", &cfg]);
    assert!(e.contains("flat.tiff") && e.contains("100 counts at every pixel") && e.contains("expected a point-source image"), "{e}");
    // Channel mismatch.
    let rgb = dir.path().join("rgb.tiff");
    rollcam::io::write_tiff_f32(&rgb, ndarray::Array3::<f32>::from_elem((32, 40, 3), 100.0).view()).unwrap();
    let e = run(&["--raw", &raw, "--psf", rgb.to_str().unwrap(), "--config", &cfg]);
    assert!(e.contains("rgb.tiff") && e.contains("channels"), "{e}");
    // Exposure shorter than a line time.
    let e = run(&["--raw", &raw, "--psf", &psf, "--config", &cfg, "--exposure-us", "100"]);
    assert!(e.contains("--exposure-us = 100") && e.contains("line time"), "{e}");
    // Negative tau.
    let e = run(&["--raw", &raw, "--psf", &psf, "--config", &cfg, "--tau=-1"]);
    assert!(e.contains("--tau"), "{e}");
    // Timing missing without a config.
    let e = run(&["--raw", &raw, "--psf", &psf]);
    assert!(e.contains("--line-time-us"), "{e}");
    // A config with a typo.
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, std::fs::read_to_string(&cfg).unwrap().replace("exposure_us", "exposure_ms")).unwrap();
    let e = run(&["--raw", &raw, "--psf", &psf, "--config", bad.to_str().unwrap()]);
    assert!(e.contains("bad.toml") && e.contains("exposure_ms"), "{e}");
    // A truth of the wrong shape.
    let e = run(&["--raw", &raw, "--psf", &psf, "--config", &cfg, "--truth", &raw]);
    assert!(e.contains("raw.tiff") && e.contains("shape"), "{e}");

    // Nothing was written by any failed run.
    assert!(!rec.join("summary.json").exists());
    assert!(!rec.exists() || std::fs::read_dir(&rec).unwrap().next().is_none());
}

#[test]
fn colour_channels_are_solved_independently_and_full_fov_grows_the_grid() {
    let dir = tempfile::tempdir().unwrap();
    let sim = dir.path().join("sim");
    let s = sim.to_str().unwrap().to_string();
    ok(&rollcam(&["simulate", "--rows", "24", "--cols", "32", "--spacing-px", "5", "--out", &s], dir.path()));
    // RGB: channel c = dark + scale_c * (grey - dark), each with the same PSF.
    let raw = rollcam::io::read_image(sim.join("raw.tiff")).unwrap();
    let psf = rollcam::io::read_image(sim.join("psf.tiff")).unwrap();
    let scales = [1.0f32, 0.5, 2.0];
    let mut rgb = ndarray::Array3::<f32>::zeros((24, 32, 3));
    let mut psf3 = ndarray::Array3::<f32>::zeros((24, 32, 3));
    for c in 0..3 {
        for r in 0..24 {
            for q in 0..32 {
                rgb[[r, q, c]] = 100.0 + scales[c] * (raw[[r, q, 0]] - 100.0);
                psf3[[r, q, c]] = psf[[r, q, 0]];
            }
        }
    }
    let raw_rgb = dir.path().join("raw_rgb.tiff");
    let psf_rgb = dir.path().join("psf_rgb.tiff");
    rollcam::io::write_tiff_f32(&raw_rgb, rgb.view()).unwrap();
    rollcam::io::write_tiff_f32(&psf_rgb, psf3.view()).unwrap();
    let rec = dir.path().join("rec");
    // tau = 0: the solve is positively homogeneous, so channel results scale exactly.
    ok(&rollcam(
        &[
            "reconstruct",
            "--raw",
            raw_rgb.to_str().unwrap(),
            "--psf",
            psf_rgb.to_str().unwrap(),
            "--config",
            &format!("{s}/capture.toml"),
            "--out",
            rec.to_str().unwrap(),
            "--iters",
            "15",
            "--tau=0",
        ],
        dir.path(),
    ));
    let v = rollcam::io::read_npy(rec.join("video.npy")).unwrap();
    assert_eq!(v.dim().3, 3);
    let sum = |c: usize| -> f64 { v.index_axis(ndarray::Axis(3), c).iter().map(|&x| x as f64).sum() };
    let (s0, s1, s2) = (sum(0), sum(1), sum(2));
    assert!(s0 > 0.0);
    assert!((s1 / s0 - 0.5).abs() < 1e-3 && (s2 / s0 - 2.0).abs() < 1e-3, "{s0} {s1} {s2}");
    let summary = json(&rec.join("summary.json"));
    assert_eq!(summary["channels"].as_array().unwrap().len(), 3);

    // --fov full: the video covers (2M-1) x (2N-1).
    let full = dir.path().join("full");
    ok(&rollcam(
        &[
            "reconstruct",
            "--raw",
            &format!("{s}/raw.tiff"),
            "--psf",
            &format!("{s}/psf.tiff"),
            "--config",
            &format!("{s}/capture.toml"),
            "--truth",
            &format!("{s}/truth.npy"),
            "--out",
            full.to_str().unwrap(),
            "--iters",
            "5",
            "--fov",
            "full",
        ],
        dir.path(),
    ));
    let summary = json(&full.join("summary.json"));
    assert_eq!(summary["video_shape"][1].as_u64().unwrap(), 47);
    assert_eq!(summary["video_shape"][2].as_u64().unwrap(), 63);
    assert!(summary["psnr_db"].as_f64().unwrap().is_finite());
}

/// `--device cuda` through the command line: a solver or a TV map the device has no
/// step for is refused naming the flag, before any input is read; consecutive captures
/// are refused naming the device. The plain solve either runs on the device (its
/// video matches the CPU's) or, where no device can run (no `cuda` feature, no driver,
/// no GPU), is refused saying what is missing.
#[test]
fn the_device_flag_is_checked_once_and_names_what_is_missing() {
    let dir = tempfile::tempdir().unwrap();
    let sim = cli::simulate_small(dir.path(), "led-array");
    let (raw, psf, cfg) = (sim.join("raw.tiff"), sim.join("psf.tiff"), sim.join("capture.toml"));
    let (raw, psf, cfg) = (raw.to_str().unwrap(), psf.to_str().unwrap(), cfg.to_str().unwrap());
    let out = dir.path().join("rec");
    let base = ["reconstruct", "--raw", raw, "--psf", psf, "--config", cfg, "--out", out.to_str().unwrap(), "--iters", "30"];
    let with = |extra: &[&str]| {
        let mut a = base.to_vec();
        a.extend_from_slice(extra);
        rollcam(&a, dir.path())
    };
    let e = fails(&with(&["--device", "cuda", "--solver", "mfista"]));
    assert!(e.contains("--device = cuda: expected cpu unless the solver is fista, fista-restart or admm-split"), "{e}");
    let e = fails(&with(&["--device", "cuda", "--tv-prox", "dual10"]));
    assert!(e.contains("--tv-prox = dual10: expected haar or auto with --device cuda"), "{e}");
    let e = fails(&with(&["--device", "tpu"]));
    assert!(e.contains("unknown device 'tpu': expected cpu or cuda"), "{e}");
    assert!(!out.exists(), "refused before anything is written");
    match rollcam::solve::optimize::Device::Cuda.check() {
        Err(why) => {
            let e = fails(&with(&["--device", "cuda"]));
            assert!(e.contains(&why) && why.starts_with("--device cuda: "), "{e}");
            assert!(!out.exists());
        }
        Ok(()) => {
            let gpu = json(&{
                ok(&with(&["--device", "cuda"]));
                out.join("summary.json")
            });
            let cpu_out = dir.path().join("rec-cpu");
            let mut a = base.to_vec();
            a[8] = cpu_out.to_str().unwrap();
            ok(&rollcam(&a, dir.path()));
            let cpu = json(&cpu_out.join("summary.json"));
            assert_eq!(gpu["channels"][0]["iterations"], cpu["channels"][0]["iterations"]);
        }
    }
}

#[test]
fn a_reader_that_closes_the_pipe_early_ends_the_command_without_a_panic() {
    use std::process::{Command, Stdio};
    // The read end is closed before the command prints its first line (simulate
    // prints after its work; `devices` is not used: in an all-features build something
    // its camera back-ends start sets SIGPIPE to ignored again).
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("sim");
    let mut child = Command::new(env!("CARGO_BIN_EXE_rollcam"))
        .args(["simulate", "--out", out_dir.to_str().unwrap()])
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("rollcam runs");
    drop(child.stdout.take());
    let out = child.wait_with_output().expect("rollcam ends");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked") && !stderr.contains("Broken pipe"), "{stderr}");
    assert_ne!(out.status.code(), Some(101), "a panic's exit code: {stderr}");
}
