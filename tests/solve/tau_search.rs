//! `--tau-rel auto`: the TV weight chosen by held-out pixels. Through the real binary:
//! on a small bright dense scene (a disc over a textured still scene) the search must
//! start from the noise rule's weight and land closer to the truth than a strong
//! weight, say what it did in
//! summary.json and count its seconds in the run's time; on flashing LEDs (a moving
//! scene) it must not search and leave the default's video bit for bit; and what it
//! cannot honour must be refused, naming the flag.

use crate::support::cli;

use cli::{fails, reconstruct_sim as reconstruct, rollcam, simulate_small as simulate};
use rollcam::solve::tau_search::SEARCH_STEP;

/// The weight relative to max(A^T b) the noise rule gave a run (its summary's
/// `params.tau_choice`).
fn noise_tau_rel(summary: &serde_json::Value) -> f64 {
    let choice = &summary["params"]["tau_choice"];
    assert_eq!(choice["rule"], "noise", "{choice}");
    choice["tau_rel"].as_f64().unwrap()
}

fn rel_error(summary: &serde_json::Value) -> f64 {
    summary["channels"][0]["error"]["rel_error"].as_f64().unwrap_or_else(|| panic!("no rel_error in {summary}"))
}

/// Measured at 64 x 80 (seed 1), with the former default 2e-3 as the start: the search
/// went 2e-3 -> 2.5e-4 and rose at 1.25e-4; relative error 0.202 against 2e-3's 0.250
/// after 200 iterations. The search now starts from the noise rule's weight; a strong
/// weight (2e-3) is the reference it must beat.
#[test]
fn auto_starts_from_the_noise_rule_and_beats_a_strong_weight_on_a_bright_dense_scene() {
    let dir = tempfile::tempdir().unwrap();
    let sim = simulate(dir.path(), "disc-over-texture");
    // The search is of the plain video's weight: the plain video declared (left out,
    // this mostly still scene gets the static + dynamic model, whose noise-rule weight
    // is halved).
    let plain = ["--scene", "static_background=false"];
    let strong = reconstruct(&sim, &dir.path().join("strong"), &[&plain[..], &["--tau-rel", "2e-3"]].concat());
    let default = reconstruct(&sim, &dir.path().join("default"), &plain);
    let auto = reconstruct(&sim, &dir.path().join("auto"), &[&plain[..], &["--tau-rel", "auto"]].concat());
    let (ed, ea) = (rel_error(&strong), rel_error(&auto));
    let s = &auto["tau_search"];
    println!("strong {ed:.4}, auto {ea:.4}: {s}");
    assert!(default.get("tau_search").is_none(), "no search without auto");
    assert_eq!(s["searched"], true, "{s}");
    let chosen = s["tau_rel"].as_f64().unwrap();
    let base = noise_tau_rel(&default);
    assert!(ea < 0.9 * ed, "auto ({ea}) should beat a strong weight ({ed}) by 10%");

    // The candidates: a ladder from the noise rule's weight by the search step, the chosen one the
    // best predictor of the held-out pixels, and the solve's tau that one.
    let cands = s["candidates"].as_array().unwrap();
    assert!(cands.len() >= 3, "{s}");
    assert!((cands[0]["tau_rel"].as_f64().unwrap() / base - 1.0).abs() < 1e-6, "the ladder starts at the noise rule's {base}: {s}");
    // Down the ladder first, up from the start instead when the first step down is
    // worse: every rung is the start times a power of the step.
    for c in cands {
        let rungs = (c["tau_rel"].as_f64().unwrap() / base).ln() / (SEARCH_STEP as f64).ln();
        assert!((rungs - rungs.round()).abs() < 1e-3, "a ladder by {SEARCH_STEP} from {base}: {s}");
    }
    let best = cands.iter().min_by(|a, b| a["held_out_residual"].as_f64().unwrap().total_cmp(&b["held_out_residual"].as_f64().unwrap())).unwrap();
    assert_eq!(best["tau_rel"].as_f64(), Some(chosen));
    let last = cands.last().unwrap()["held_out_residual"].as_f64().unwrap();
    assert!(last > best["held_out_residual"].as_f64().unwrap(), "the search stops where the residual rises: {s}");
    let scale = default["params"]["tau"].as_f64().unwrap() / base;
    let tau = auto["params"]["tau"].as_f64().unwrap();
    assert!((tau / (chosen * scale) - 1.0).abs() < 1e-4, "params.tau {tau} is the chosen tau_rel times max(A^T b) {scale}");
    let held = s["held_out_pixels"].as_u64().unwrap() as f64;
    assert!((held / (64.0 * 80.0) - 0.1).abs() < 0.02, "about a tenth of the pixels held out: {held}");

    // Error against run time: the search's seconds are in the trace and the channel's.
    let secs = s["seconds"].as_f64().unwrap();
    assert!(secs > 0.0);
    assert!(auto["channels"][0]["seconds"].as_f64().unwrap() >= secs);
    let trace = std::fs::read_to_string(dir.path().join("auto/trace.csv")).unwrap();
    let header: Vec<&str> = trace.lines().next().unwrap().split(',').collect();
    let col = header.iter().position(|h| *h == "seconds").expect("a seconds column");
    let first: f64 = trace.lines().nth(1).unwrap().split(',').nth(col).unwrap().parse().unwrap();
    assert!(first >= secs, "the first trace row ({first} s) comes after the search ({secs} s)");
}

/// Flashing LEDs: the still image leaves most of the raw unexplained, the held-out
/// pixels cannot see what moves, so the noise rule's weight stands and the video is
/// the default's, bit for bit.
#[test]
fn auto_keeps_the_given_tau_on_a_moving_scene() {
    let dir = tempfile::tempdir().unwrap();
    let sim = simulate(dir.path(), "led-array");
    let auto = reconstruct(&sim, &dir.path().join("auto"), &["--tau-rel", "auto"]);
    let default = reconstruct(&sim, &dir.path().join("default"), &[]);
    let s = &auto["tau_search"];
    assert_eq!(s["searched"], false, "{s}");
    assert!(s["candidates"].as_array().unwrap().is_empty());
    assert!((s["tau_rel"].as_f64().unwrap() / noise_tau_rel(&default) - 1.0).abs() < 1e-6, "{s}");
    assert_eq!(auto["params"]["tau_choice"], default["params"]["tau_choice"], "the rule stands, and says so");
    assert!(s["reason"].as_str().unwrap().contains("unexplained"), "{s}");
    assert!(s["still_residual_rel"].as_f64().unwrap() > rollcam::solve::start::STILL_RESIDUAL_MAX);
    assert_eq!(auto["params"]["tau"], default["params"]["tau"]);
    let video = |name: &str| -> ndarray::Array4<f32> { rollcam::io::read_npy(dir.path().join(name).join("video.npy")).unwrap() };
    assert_eq!(video("auto"), video("default"));
}

#[test]
fn what_auto_cannot_honour_is_refused_naming_the_flag() {
    let dir = tempfile::tempdir().unwrap();
    let sim = simulate(dir.path(), "disc-over-texture");
    let (raw, psf, cfg) = (sim.join("raw.tiff"), sim.join("psf.tiff"), sim.join("capture.toml"));
    let base = ["reconstruct", "--raw", raw.to_str().unwrap(), "--psf", psf.to_str().unwrap(), "--config", cfg.to_str().unwrap()];
    let out = dir.path().join("r");
    let with = |extra: &[&str]| -> Vec<String> {
        let mut v: Vec<String> = base.iter().map(|s| s.to_string()).collect();
        v.extend(extra.iter().map(|s| s.to_string()));
        v.extend(["--out".to_string(), out.display().to_string()]);
        v
    };
    let run = |args: Vec<String>| fails(&rollcam(&args.iter().map(|s| s.as_str()).collect::<Vec<_>>(), dir.path()));
    let e = run(with(&["--tau", "0.1", "--tau-rel", "auto"]));
    assert!(e.contains("--tau = 0.1") && e.contains("auto"), "{e}");
    let e = run(with(&["--tau-rel", "sometimes"]));
    assert!(e.contains("sometimes") && e.contains("noise or auto"), "{e}");
    assert!(!out.exists(), "a refused run writes nothing");
    let seq = dir.path().join("seq");
    let e = fails(&rollcam(&["reconstruct-sequence", sim.to_str().unwrap(), "--tau-rel", "auto", "--out", seq.to_str().unwrap()], dir.path()));
    assert!(e.contains("--tau-rel = auto") && e.contains("consecutive captures"), "{e}");
}

/// The solve's stop flag (Ctrl-C) ends the search before a choice: the noise rule's
/// tau_rel stands and the report says so. Without it, the library's search on the same
/// capture chooses as the command line does.
#[test]
fn a_stopped_search_keeps_the_given_tau() {
    use rollcam::model::capture::CaptureOverrides;
    use rollcam::model::prepare::{prepare, SensorInput};
    use rollcam::solve::problem::{Problem, SolveSettings, ValidSettings};
    use std::sync::atomic::AtomicBool;
    let dir = tempfile::tempdir().unwrap();
    let sim = simulate(dir.path(), "disc-over-texture");
    let raw = rollcam::io::read_image(sim.join("raw.tiff")).unwrap();
    let psf = rollcam::io::read_image(sim.join("psf.tiff")).unwrap();
    let cfg = rollcam::io::capture_file::resolve_capture(Some(&sim.join("capture.toml")), &CaptureOverrides::default(), (64, 80)).unwrap();
    let prepared = prepare(raw.view(), "raw", psf.view(), "psf", &cfg, &SensorInput::default()).unwrap();
    let problem = Problem::new(&prepared, &cfg, cfg.fov).unwrap();
    let settings = SolveSettings { tau: rollcam::solve::tau::Tau::Auto(None), ..SolveSettings::default() }.validate().unwrap();
    let cache = rollcam::io::cache::LipschitzCache::disabled();
    let stopped = rollcam::solve::tau_search::search(&settings, &problem, &cache, &AtomicBool::new(true));
    assert!(stopped.reason.contains("stopped"), "{}", stopped.reason);
    let base = ValidSettings::default().resolve(&problem, cfg.fov).tau_choice.tau_rel().unwrap();
    assert_eq!(stopped.tau_rel, base);
    assert!(stopped.candidates.is_empty());
    let run = rollcam::solve::tau_search::search(&settings, &problem, &cache, &AtomicBool::new(false));
    assert!(run.searched && run.candidates.len() >= 2 && run.candidates[0].tau_rel == base, "{run:?}");
    let best = run.candidates.iter().min_by(|a, b| a.held_out_residual.total_cmp(&b.held_out_residual)).unwrap();
    assert_eq!(best.tau_rel, run.tau_rel);
}
