//! Running the `rollcam` binary from the command-line tests: a private Lipschitz
//! cache, warnings only on stderr, and the success / failure checks they share.
#![allow(dead_code)]

use std::path::Path;
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
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}
