//! Helpers shared by the pipeline tests: run the CLI, read the session, compare videos.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/captures").join(name)
}

/// `rollcam run ARGS` with a private Lipschitz cache; the output.
pub fn rollcam(args: &[&str], cache: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rollcam")).args(args).env("ROLLCAM_CACHE_DIR", cache).env("RUST_LOG", "info").output().expect("run rollcam")
}

/// `rollcam run --camera replay:FIXTURE --out OUT EXTRA...` with a private Lipschitz cache.
pub fn run_replay(fixture: &Path, out: &Path, extra: &[&str], cache: &Path) -> Output {
    let camera = format!("replay:{}", fixture.display());
    let out = out.to_str().expect("a UTF-8 test folder");
    rollcam(&[&["run", "--camera", &camera, "--out", out][..], extra].concat(), cache)
}

pub fn text(o: &Output) -> String {
    format!("status {:?}\nstdout:\n{}\nstderr:\n{}", o.status, String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

pub fn session(dir: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(dir.join("session.json")).expect("session.json")).expect("session.json parses")
}

pub fn counter(s: &serde_json::Value, name: &str) -> u64 {
    s["counters"][name].as_u64().unwrap_or_else(|| panic!("counter {name} in {}", s["counters"]))
}

pub fn statuses(s: &serde_json::Value) -> Vec<(u64, String)> {
    s["frames"].as_array().unwrap().iter().map(|f| (f["sequence"].as_u64().unwrap(), f["status"].as_str().unwrap().to_string())).collect()
}

/// The end-of-session invariants: every captured frame is recorded or counted
/// unrecorded; every recorded frame is reconstructed, skipped, failed or queued.
pub fn assert_consistent(s: &serde_json::Value) {
    let c = |n| counter(s, n);
    assert_eq!(c("captured"), c("recorded") + c("unrecorded"), "{}", s["counters"]);
    assert_eq!(c("recorded"), c("reconstructed") + c("skipped") + c("failed") + c("queued"), "{}", s["counters"]);
    assert_eq!(c("reconstructing"), 0);
    assert_eq!(s["frames"].as_array().unwrap().len() as u64, c("recorded"));
    assert_eq!(s["pending"].as_array().unwrap().len() as u64, c("queued") + c("skipped"));
    assert_ne!(s["state"], "running");
}

/// Pearson correlation of two equally long sequences (f64 sums).
pub fn correlation(a: &[f32], b: &[f32]) -> f64 {
    assert_eq!(a.len(), b.len());
    let n = a.len() as f64;
    let ma = a.iter().map(|&v| v as f64).sum::<f64>() / n;
    let mb = b.iter().map(|&v| v as f64).sum::<f64>() / n;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (&x, &y) in a.iter().zip(b) {
        let (dx, dy) = (x as f64 - ma, y as f64 - mb);
        sab += dx * dy;
        saa += dx * dx;
        sbb += dy * dy;
    }
    sab / (saa * sbb).sqrt()
}

/// The reconstructed video of frame `seq` in a session folder.
pub fn video(dir: &Path, seq: u64) -> Vec<f32> {
    rollcam::io::read_npy(dir.join(format!("rec/frame_{seq:06}/video.npy"))).expect("video.npy").iter().cloned().collect()
}

pub fn truth(fixture: &Path, seq: u64) -> Vec<f32> {
    rollcam::io::read_npy(fixture.join(format!("truth_{seq:06}.npy"))).expect("truth").iter().cloned().collect()
}

pub fn tiff_count(dir: &Path) -> usize {
    std::fs::read_dir(dir).unwrap().filter(|e| e.as_ref().unwrap().file_name().to_string_lossy().ends_with(".tiff")).count()
}
