//! Running the `rollcam` binary from the command-line tests: a private Lipschitz
//! cache, warnings only on stderr, and the success / failure checks they share.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn rollcam(args: &[&str], cache: &Path) -> Output {
    rollcam_env(args, cache, &[])
}

/// [`rollcam`] with further environment variables.
pub fn rollcam_env(args: &[&str], cache: &Path, env: &[(&str, &str)]) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_rollcam"));
    c.args(args).env("ROLLCAM_CACHE_DIR", cache).env("RUST_LOG", "warn");
    for (k, v) in env {
        c.env(k, v);
    }
    c.output().expect("rollcam runs")
}

/// Stdout of a run that must succeed.
pub fn ok(o: &Output) -> String {
    let out = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(o.status.success(), "failed: {}\n{}", out, String::from_utf8_lossy(&o.stderr));
    out
}

/// Stderr of a run that must fail.
pub fn fails(o: &Output) -> String {
    assert!(!o.status.success(), "expected a failure, got success: {}", String::from_utf8_lossy(&o.stdout));
    String::from_utf8_lossy(&o.stderr).into_owned()
}

pub fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))).unwrap()
}

/// A 64 x 80 capture of `scene` (`rollcam simulate --scene`) simulated into `dir/scene`.
pub fn simulate_small(dir: &Path, scene: &str) -> PathBuf {
    let out = dir.join(scene);
    ok(&rollcam(&["simulate", "--scene", scene, "--rows", "64", "--cols", "80", "--out", out.to_str().unwrap()], dir));
    out
}

/// `reconstruct` of a simulated folder (raw.tiff, psf.tiff, capture.toml, truth.npy)
/// into `out` with `extra` flags, which must succeed; its summary.json.
pub fn reconstruct_sim(sim: &Path, out: &Path, extra: &[&str]) -> serde_json::Value {
    let (raw, psf, cfg, truth) = (sim.join("raw.tiff"), sim.join("psf.tiff"), sim.join("capture.toml"), sim.join("truth.npy"));
    let mut args = vec![
        "reconstruct",
        "--raw",
        raw.to_str().unwrap(),
        "--psf",
        psf.to_str().unwrap(),
        "--config",
        cfg.to_str().unwrap(),
        "--truth",
        truth.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    ok(&rollcam(&args, sim.parent().unwrap()));
    json(&out.join("summary.json"))
}
