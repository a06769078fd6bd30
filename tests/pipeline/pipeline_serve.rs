//! `rollcam run --serve`: the live page serves the session while it runs. The URL is
//! printed on stderr and recorded in session.json; `/session.json` and
//! `/preview/latest_raw.png` over HTTP are the files on disk; a headless Chromium
//! renders the session's counters; the server is gone once the session has ended.

use crate::support::browser;
use crate::support::pipeline_common;

use browser::{attribute, chromium, dump_dom, element_text, http_get as get, wait_with_timeout};

use pipeline_common::{fixture, text};
use std::io::{BufRead, BufReader, Read};
use std::net::{SocketAddr, TcpStream};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Poll `cond` every 50 ms for up to `limit`; panics with `what` on timeout.
fn wait_until(what: &str, limit: Duration, mut cond: impl FnMut() -> bool) {
    let t0 = Instant::now();
    while !cond() {
        assert!(t0.elapsed() < limit, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The HTTP body equals the file on disk (the pipeline rewrites the file every half
/// second, so a few tries are allowed for one that changed in between).
fn served_equals_disk(addr: SocketAddr, target: &str, file: &Path) -> Vec<u8> {
    for _ in 0..100 {
        let (status, body) = get(addr, target);
        assert_eq!(status, 200, "{target}: {}", String::from_utf8_lossy(&body));
        if std::fs::read(file).ok().as_deref() == Some(body.as_slice()) {
            return body;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    panic!("{target} never matched {}", file.display());
}

fn interrupt(child: &Child) {
    let st = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(st.success());
}

#[test]
fn the_live_page_serves_the_running_session() {
    let browser = chromium();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("s");
    let fix = fixture("led-505hz");
    // A slow worker keeps the session running while the page is looked at.
    let mut child = Command::new(env!("CARGO_BIN_EXE_rollcam"))
        .args(["run", "--camera", &format!("replay:{}", fix.display()), "--out", out.to_str().unwrap()])
        .args(["--iters", "5", "--worker-delay-ms", "60000", "--serve", "127.0.0.1:0", "--serve-linger-s", "1"])
        .env("ROLLCAM_CACHE_DIR", tmp.path())
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    let stderr = child.stderr.take().unwrap();
    let err_reader = std::thread::spawn(move || {
        let mut all = String::new();
        for line in BufReader::new(stderr).lines() {
            let line = line.unwrap();
            if let Some(url) = line.strip_prefix("live page: ") {
                let _ = tx.send(url.trim().to_string());
            }
            all.push_str(&line);
            all.push('\n');
        }
        all
    });
    let url = match rx.recv_timeout(Duration::from_secs(120)) {
        Ok(url) => url,
        Err(_) => {
            let _ = child.kill();
            panic!("no live page URL on stderr: {}", err_reader.join().unwrap())
        }
    };
    let addr: SocketAddr = url.trim_start_matches("http://").trim_end_matches('/').parse().unwrap_or_else(|e| panic!("{url}: {e}"));
    assert!(addr.ip().is_loopback() && addr.port() != 0, "{url}");

    // All three frames recorded (the replay never waits), the raw preview written.
    let session = |dir: &Path| -> Option<serde_json::Value> { serde_json::from_slice(&std::fs::read(dir.join("session.json")).ok()?).ok() };
    wait_until("three recorded frames and the raw preview", Duration::from_secs(120), || {
        session(&out).is_some_and(|s| s["counters"]["recorded"] == 3 && s["preview"]["raw_sequence"] == 2)
    });
    let body = served_equals_disk(addr, "/session.json", &out.join("session.json"));
    let s: serde_json::Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(s["live_url"], url.as_str());
    assert_eq!(s["state"], "running");
    let png = served_equals_disk(addr, "/preview/latest_raw.png", &out.join("preview/latest_raw.png"));
    let img = image::load_from_memory(&png).expect("a PNG");
    assert_eq!((img.width(), img.height()), (64, 48));

    // A real browser renders the counters from session.json while the session runs.
    let profile = tempfile::tempdir().unwrap();
    let dom = dump_dom(&browser, profile.path(), &url);
    assert_eq!(element_text(&dom, "state"), Some("running"), "{dom}");
    assert_eq!(element_text(&dom, "counter-captured"), Some("3"), "{dom}");
    assert_eq!(element_text(&dom, "counter-recorded"), Some("3"));
    assert_eq!(element_text(&dom, "counter-reconstructed"), Some("0"));
    assert_eq!(attribute(&dom, "img-raw", "data-loaded"), Some("64x48"), "{dom}");

    // Ctrl-C twice: the slow queue is left for --resume; the page lingers 1 s, then stops.
    interrupt(&child);
    std::thread::sleep(Duration::from_millis(500));
    interrupt(&child);
    let status = wait_with_timeout(&mut child, Duration::from_secs(120)).expect("run did not end after Ctrl-C");
    let mut stdout = String::new();
    child.stdout.take().unwrap().read_to_string(&mut stdout).unwrap();
    let err = err_reader.join().unwrap();
    assert!(status.success(), "{status}\n{stdout}\n{err}");
    assert!(err.contains("live page stays up 1 s"), "{err}");
    let s = session(&out).unwrap();
    // The replay ended before the Ctrl-C (finished); the drain was abandoned.
    assert_ne!(s["state"], "running", "{}", text_of(&stdout, &err));
    assert!(s["stop_reason"].as_str().unwrap_or("").contains("abandoned"), "{}", s["stop_reason"]);
    assert_eq!(s["pending"].as_array().unwrap().len(), 3, "{}", s["pending"]);
    assert_eq!(s["live_url"], url.as_str());
    assert!(TcpStream::connect_timeout(&addr, Duration::from_secs(5)).is_err(), "the live page still answers after the session ended");
}

fn text_of(stdout: &str, stderr: &str) -> String {
    format!("stdout:\n{stdout}\nstderr:\n{stderr}")
}

#[test]
fn a_busy_address_is_refused_before_the_session_starts() {
    let tmp = tempfile::tempdir().unwrap();
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = taken.local_addr().unwrap().to_string();
    let out = tmp.path().join("s");
    let fix = fixture("led-505hz");
    let o = pipeline_common::rollcam(
        &["run", "--camera", &format!("replay:{}", fix.display()), "--out", out.to_str().unwrap(), "--iters", "2", "--serve", &addr],
        tmp.path(),
    );
    assert!(!o.status.success(), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains(&addr) && err.contains("already in use"), "{err}");
}
