//! `rollcam compare` end to end: several solvers and parameter sets on one simulated
//! capture, one figure, the tables and the files, and refused run specifications.

use crate::support::cli;

use cli::{fails, json, ok, rollcam};
use std::path::Path;

fn simulate(dir: &Path) -> std::path::PathBuf {
    let sim = dir.join("sim");
    ok(&rollcam(&["simulate", "--scene", "led-array", "--rows", "32", "--cols", "40", "--out", sim.to_str().unwrap()], dir));
    sim
}

fn compare_args<'a>(sim: &'a str, out: &'a str, solvers: &'a str) -> Vec<String> {
    [
        "compare",
        "--raw",
        &format!("{sim}/raw.tiff"),
        "--psf",
        &format!("{sim}/psf.tiff"),
        "--config",
        &format!("{sim}/capture.toml"),
        "--truth",
        &format!("{sim}/truth.npy"),
        "--out",
        out,
        "--iters",
        "40",
        "--solvers",
        solvers,
    ]
    .iter()
    .map(|s| s.to_string())
    .collect()
}

#[test]
fn solvers_and_parameter_sets_share_one_plot_and_one_table() {
    let dir = tempfile::tempdir().unwrap();
    let sim = simulate(dir.path());
    let out = dir.path().join("cmp");
    let runs = "fista,fista-restart,fista-restart:tv_prox=dual8,admm:cg=2,admm:cg=6:mu=0.01,pgd";
    let args = compare_args(sim.to_str().unwrap(), out.to_str().unwrap(), runs);
    let text = ok(&rollcam(&args.iter().map(|s| s.as_str()).collect::<Vec<_>>(), dir.path()));

    for f in ["psnr_vs_time.png", "psnr_vs_time.svg", "objective_vs_time.png", "objective_vs_time.svg", "traces.csv", "summary.md", "summary.json"] {
        assert!(out.join(f).is_file(), "missing {f}");
    }
    let labels: Vec<&str> = runs.split(',').collect();
    // Every run is a named curve of the figures.
    let svg = std::fs::read_to_string(out.join("psnr_vs_time.svg")).unwrap();
    for l in &labels {
        assert!(svg.contains(l), "{l} is not in the PSNR figure's legend");
    }
    let s = json(&out.join("summary.json"));
    // The weight is the default rule's, said once for every run, as reconstruct says it.
    let choice = &s["tau_choice"];
    assert_eq!(choice["rule"], "noise", "{choice}");
    let tau = s["tau"].as_f64().unwrap();
    let rule = rollcam::solve::tau::NOISE_TAU_PER_SIGMA as f64 * choice["sigma"].as_f64().unwrap() / (choice["frames"].as_f64().unwrap()).sqrt();
    assert!(choice["bounded"] == true || (tau / rule - 1.0).abs() < 1e-4, "tau {tau} against 0.02 sigma / sqrt(frames) = {rule}: {choice}");
    assert!(text.contains("from the raw's noise"), "{text}");
    let solvers = s["solvers"].as_array().unwrap();
    assert_eq!(solvers.iter().map(|v| v["solver"].as_str().unwrap()).collect::<Vec<_>>(), labels);
    let tv: Vec<&str> = solvers.iter().map(|v| v["tv_prox"].as_str().unwrap()).collect();
    assert_eq!(tv, ["haar", "haar", "dual8", "exact shrinkage", "exact shrinkage", "haar"]);
    for v in solvers {
        let name = v["solver"].as_str().unwrap();
        assert_eq!(v["iterations"].as_u64().unwrap(), 40, "{name}");
        let psnr = v["final_psnr_db"].as_f64().unwrap();
        assert!(psnr.is_finite() && psnr > 15.0, "{name}: final PSNR {psnr}");
        // Time-to-error rows exist for each tolerance of the best run's error, and for
        // the objective.
        assert_eq!(v["time_to_error_s"].as_array().unwrap().len(), 2, "{name}");
        let (fin, low) = (v["final_rel_error_scaled"].as_f64().unwrap(), v["best_rel_error_scaled"].as_f64().unwrap());
        assert!(low > 0.0 && low <= fin, "{name}: lowest error {low}, final {fin}");
        assert_eq!(v["time_to_objective_s"].as_array().unwrap().len(), 2, "{name}");
    }
    // The settings change the runs: ADMM with 6 CG steps and other penalties does not
    // retrace ADMM with 2, nor the exact TV map the Haar map.
    let obj = |i: usize| solvers[i]["objective"].as_f64().unwrap();
    assert!((obj(3) - obj(4)).abs() > 1e-6 * obj(3).abs(), "admm cg=2 and cg=6 gave the same objective {}", obj(3));
    assert!((obj(1) - obj(2)).abs() > 1e-6 * obj(1).abs(), "Haar and dual8 gave the same objective {}", obj(1));
    // At least one run reaches within 1e-2 of the best objective any reached: the best
    // run itself, at its last iteration at the latest.
    assert!(solvers.iter().any(|v| v["time_to_objective_s"][0][1].is_number()));
    // Likewise within 1% of the best error; and a run whose lowest error is over 10%
    // above the best never reaches the 10% target.
    assert!(solvers.iter().any(|v| v["time_to_error_s"][1][1].is_number()));
    let best = solvers.iter().map(|v| v["best_rel_error_scaled"].as_f64().unwrap()).fold(f64::INFINITY, f64::min);
    for v in solvers.iter().filter(|v| v["best_rel_error_scaled"].as_f64().unwrap() > 1.1 * best) {
        assert!(v["time_to_error_s"][0][1].is_null(), "{}", v["solver"]);
    }
    // One trace block per run, in the order given.
    let csv = std::fs::read_to_string(out.join("traces.csv")).unwrap();
    assert!(csv.lines().next().unwrap().ends_with(runs), "{}", csv.lines().next().unwrap());
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    for l in &labels {
        assert!(md.contains(&format!("| {l} |")), "{l} has no row in summary.md");
        assert!(text.contains(&format!("{l}: 40 iterations")), "{text}");
    }
    // Each run's video, for `rollcam view`: the truth's shape, and as close to the truth
    // as its own PSNR says (the runs' last iterates; ADMM with 2 and 6 CG steps differ).
    let truth = rollcam::io::read_stack(sim.join("truth.npy")).unwrap();
    let peak = truth.iter().cloned().fold(0.0f32, f32::max) as f64;
    let mut seen = Vec::new();
    for (v, l) in solvers.iter().zip(&labels) {
        let name: String = l.chars().map(|c| if c.is_ascii_alphanumeric() || "-_.".contains(c) { c } else { '_' }).collect();
        let video = rollcam::io::read_stack(out.join("videos").join(format!("{name}.npy"))).unwrap_or_else(|e| panic!("{l}: {e}"));
        assert_eq!(video.dim(), truth.dim(), "{l}");
        let mse = video.iter().zip(truth.iter()).map(|(&a, &b)| ((a - b) as f64).powi(2)).sum::<f64>() / video.len() as f64;
        let psnr = 10.0 * (peak * peak / mse).log10();
        let reported = v["final_psnr_db"].as_f64().unwrap();
        assert!((psnr - reported).abs() < 0.05, "{l}: the video's PSNR {psnr:.3} dB, the summary's {reported:.3} dB");
        seen.push(video);
    }
    assert!(seen[3] != seen[4], "admm cg=2 and cg=6 wrote the same video");
    // Their frame interval (the simulation's 220 us line time, no binning).
    assert_eq!(s["frame_time_us"].as_f64(), Some(220.0));
    assert_eq!(s["videos"], "videos");
}

#[test]
fn run_specifications_are_checked_before_solving() {
    let dir = tempfile::tempdir().unwrap();
    let sim = simulate(dir.path());
    let cases = [
        ("fista:cg=3", "cg is ADMM's setting"),
        ("admm:tv_prox=dual5", "tv_prox is for the gradient methods"),
        ("fista:step=2", "unknown setting 'step'"),
        ("admm:cg=0", "cg = '0'"),
        ("pgd:tv_prox=box", "tv_prox = 'box'"),
        ("fista:tv_prox", "not KEY=VALUE"),
        ("sgd", "unknown solver 'sgd'"),
        ("pgd,fista,pgd", "'pgd' is given twice"),
    ];
    for (i, (runs, what)) in cases.iter().enumerate() {
        let out = dir.path().join(format!("cmp{i}"));
        let args = compare_args(sim.to_str().unwrap(), out.to_str().unwrap(), runs);
        let err = fails(&rollcam(&args.iter().map(|s| s.as_str()).collect::<Vec<_>>(), dir.path()));
        assert!(err.contains(what), "{runs}: {err}");
        assert!(!out.exists(), "{runs}: created the output folder");
    }
}
