//! `--solver` and `--tv-prox` reach every solve: a bench session's frames (`run`, also
//! after `--resume`) and a sequence's windows (`reconstruct-sequence`) record the solver
//! and TV map that were asked for, and bad solver settings are refused naming the flag
//! before any work.

use crate::support::cli::json;
use crate::support::pipeline_common;
use pipeline_common::*;
use std::path::Path;

#[test]
fn a_session_reconstructs_every_frame_with_the_solver_asked_for() {
    let tmp = tempfile::tempdir().unwrap();
    let fix = fixture("led-505hz");
    let out = tmp.path().join("s");
    let o = run_replay(&fix, &out, &["--frames", "2", "--iters", "4", "--solver", "pgd", "--tv-prox", "dual3"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let s = session(&out);
    assert_eq!(s["config"]["solver"]["solver"], "pgd", "{}", s["config"]["solver"]);
    assert_eq!(s["config"]["solver"]["tv_prox"], "dual3");
    assert_eq!(counter(&s, "reconstructed"), 2);
    for seq in 0..2 {
        let summary = json(&out.join(format!("rec/frame_{seq:06}/summary.json")));
        assert_eq!(summary["params"]["solver"], "pgd");
        assert_eq!(summary["channels"][0]["solver"], "pgd");
        assert_eq!(summary["channels"][0]["tv_prox"], "dual3");
        assert_eq!(summary["channels"][0]["iterations"], 4);
    }

    // The default stays FISTA with restart and the automatic TV map.
    let out = tmp.path().join("d");
    let o = run_replay(&fix, &out, &["--frames", "1", "--iters", "2"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let summary = json(&out.join("rec/frame_000000/summary.json"));
    assert_eq!(summary["channels"][0]["solver"], "fista-restart");
    assert_eq!(summary["params"]["tv_prox"], "auto");
}

#[test]
fn a_resumed_session_keeps_its_solver() {
    let tmp = tempfile::tempdir().unwrap();
    let fix = fixture("led-505hz");
    let out = tmp.path().join("s");
    // Frames queue behind a slow worker; the session is stopped by its frame limit
    // with some of them not reconstructed in live mode, and --resume finishes them.
    let o =
        run_replay(&fix, &out, &["--iters", "3", "--live", "--queue", "1", "--worker-delay-ms", "2000", "--solver", "mfista", "--tv-prox", "haar"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let before = counter(&session(&out), "reconstructed");
    let o = rollcam(&["run", "--resume", out.to_str().unwrap()], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let s = session(&out);
    let after = counter(&s, "reconstructed");
    assert!(after > before, "resume reconstructed nothing ({before} -> {after})");
    for f in s["frames"].as_array().unwrap() {
        let seq = f["sequence"].as_u64().unwrap();
        let summary = json(&out.join(format!("rec/frame_{seq:06}/summary.json")));
        assert_eq!(summary["channels"][0]["solver"], "mfista", "frame {seq}");
        assert_eq!(summary["channels"][0]["tv_prox"], "haar", "frame {seq}");
    }
}

/// Three 32 x 40 dual-shutter captures 2000 us apart.
fn simulate(dir: &Path) -> std::path::PathBuf {
    let cap = dir.join("cap");
    let o = rollcam(
        &[
            "simulate",
            "--out",
            cap.to_str().unwrap(),
            "--rows",
            "32",
            "--cols",
            "40",
            "--line-time-us",
            "100",
            "--exposure-us",
            "300",
            "--captures",
            "3",
            "--frame-period-us",
            "2000",
            "--leds",
            "2",
            "--period-us",
            "1300,900",
            "--no-noise",
        ],
        dir,
    );
    assert!(o.status.success(), "{}", text(&o));
    cap
}

#[test]
fn a_sequence_solves_every_window_with_the_solver_asked_for() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = simulate(tmp.path());
    let c = cap.to_str().unwrap();
    for (mode, solver, prox, windows) in [("streaming", "mfista", "haar", 3), ("joint", "admm", "auto", 1), ("separate", "pgd", "dual2", 3)] {
        let rec = tmp.path().join(format!("rec-{mode}"));
        let o = rollcam(
            &["reconstruct-sequence", c, "--out", rec.to_str().unwrap(), "--mode", mode, "--iters", "3", "--solver", solver, "--tv-prox", prox],
            tmp.path(),
        );
        assert!(o.status.success(), "{}", text(&o));
        let s = json(&rec.join("summary.json"));
        assert_eq!(s["params"]["solver"], solver, "{mode}");
        assert_eq!(s["params"]["tv_prox"], prox, "{mode}");
        let solves = s["solves"].as_array().unwrap();
        assert_eq!(solves.len(), windows, "{mode}");
        for w in solves {
            assert_eq!(w["solver"], solver, "{mode}");
            assert_eq!(w["iterations"], 3, "{mode}");
            let expected = if solver == "admm" { "exact shrinkage (admm)" } else { prox };
            assert_eq!(w["tv_prox"], expected, "{mode}");
        }
    }
    // Without flags: FISTA with restart, as before.
    let rec = tmp.path().join("rec-default");
    let o = rollcam(&["reconstruct-sequence", c, "--out", rec.to_str().unwrap(), "--iters", "2"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let s = json(&rec.join("summary.json"));
    assert!(s["solves"].as_array().unwrap().iter().all(|w| w["solver"] == "fista-restart"), "{}", s["solves"]);
}

#[test]
fn bad_solver_settings_are_refused_naming_the_flag() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = simulate(tmp.path());
    for (flag, value) in [("--rel-tol", "nan"), ("--time-budget-s", "-1"), ("--tau-rel", "inf"), ("--alpha", "-2"), ("--iters", "0")] {
        let out = tmp.path().join("never");
        let given = format!("{flag}={value}");
        let o = rollcam(&["reconstruct-sequence", cap.to_str().unwrap(), "--out", out.to_str().unwrap(), &given], tmp.path());
        assert!(!o.status.success(), "{flag} {value} accepted: {}", text(&o));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(flag), "{flag}: {err}");
        assert!(!out.exists(), "{flag}: an output folder was made");
        let raw = cap.join("frame_000000.tiff");
        let o = rollcam(
            &[
                "reconstruct",
                "--raw",
                raw.to_str().unwrap(),
                "--psf",
                cap.join("psf.tiff").to_str().unwrap(),
                "--config",
                cap.join("capture.toml").to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
                &given,
            ],
            tmp.path(),
        );
        assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains(flag), "reconstruct {flag} {value}: {}", text(&o));
    }
}
