//! The live page: (a) over raw HTTP (status codes, content types, bodies, every
//! traversal form refused), (b) in a real headless Chromium, whose DOM must show the
//! counters the page's script rendered from session.json, the new values after the
//! file changes on disk, and the previews loaded at their true size; (c) the
//! `rollcam serve` command (URL printed, Ctrl-C, port in use named); (d) the limits:
//! links below the folder never followed, idle connections holding no thread and not
//! blocking a prompt request, slow and oversized heads cut off, session.json over the
//! cap refused unread and read once per change.

use crate::support::browser;

use browser::{attribute, chromium, dump_dom, element_text, spawn_page, wait_with_timeout};
use rollcam::lab::live::{LiveServer, ServeOptions, MAX_FILE_BYTES};
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::Path;
use std::process::Command;
use std::time::Duration;

struct Reply {
    status: u16,
    headers: Vec<(String, String)>,
    body: Vec<u8>,
}

impl Reply {
    fn header(&self, name: &str) -> Option<&str> {
        self.headers.iter().find(|(k, _)| k.eq_ignore_ascii_case(name)).map(|(_, v)| v.as_str())
    }
    fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }
}

/// One HTTP/1.0 request with the target sent byte for byte (no client-side normalising).
fn request(addr: SocketAddr, method: &str, target: &str) -> Reply {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
    write!(s, "{method} {target} HTTP/1.0\r\nHost: {addr}\r\nConnection: close\r\n\r\n").unwrap();
    let mut raw = Vec::new();
    s.read_to_end(&mut raw).unwrap();
    let split = raw.windows(4).position(|w| w == b"\r\n\r\n").expect("end of headers");
    let head = String::from_utf8_lossy(&raw[..split]).into_owned();
    let mut lines = head.split("\r\n");
    let status_line = lines.next().unwrap();
    let status = status_line.split_whitespace().nth(1).unwrap().parse().unwrap();
    let headers = lines.filter_map(|l| l.split_once(':')).map(|(k, v)| (k.trim().to_string(), v.trim().to_string())).collect();
    Reply { status, headers, body: raw[split + 4..].to_vec() }
}

fn get(addr: SocketAddr, target: &str) -> Reply {
    request(addr, "GET", target)
}

/// A grey PNG of `w x h` pixels.
fn png(path: &Path, w: u32, h: u32, level: u8) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    image::GrayImage::from_pixel(w, h, image::Luma([level])).save(path).unwrap();
}

/// Atomic write, as the pipeline does.
fn write_session(dir: &Path, json: &serde_json::Value) {
    let tmp = dir.join(".session.json.tmp");
    std::fs::write(&tmp, serde_json::to_vec_pretty(json).unwrap()).unwrap();
    std::fs::rename(&tmp, dir.join("session.json")).unwrap();
}

fn session(captured: u64, reconstructed: u64, state: &str) -> serde_json::Value {
    serde_json::json!({
        "state": state,
        "camera": "replay:/data/bench-7",
        "started_utc": "2026-11-22T10:00:00Z",
        "updated_utc": format!("2026-11-22T10:00:{:02}Z", captured % 60),
        "counters": {"captured": captured, "recorded": captured - 1, "reconstructed": reconstructed, "skipped": 4, "dropped": 0, "failed": 1, "queued": 2},
        "latency_ms": {"last": 812.5, "median": 790.0, "max": 1304.0},
        "frames": [
            {"sequence": captured - 1, "raw": "raw/frame_000040.tiff", "status": "reconstructed", "video": "rec/frame_000040", "latency_ms": 790.0, "error": null},
            {"sequence": captured, "raw": "raw/frame_000041.tiff", "status": "failed", "video": null, "latency_ms": null, "error": "solver: non-finite <objective>"}
        ],
        "errors": ["frame 41: solver: non-finite <objective>"],
        "exposure_us": 660.0
    })
}

fn session_dir() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    write_session(dir.path(), &session(41, 37, "running"));
    png(&dir.path().join("preview/latest_raw.png"), 64, 48, 90);
    png(&dir.path().join("preview/latest_frame.png"), 40, 30, 200);
    dir
}

#[test]
fn http_routes_types_and_refusals() {
    let dir = session_dir();
    let server = LiveServer::start(dir.path(), "127.0.0.1:0".parse().unwrap()).unwrap();
    let addr = server.local_addr();
    assert_ne!(addr.port(), 0);
    assert!(addr.ip().is_loopback());
    assert_eq!(server.url(), format!("http://{addr}/"));

    let page = get(addr, "/");
    assert_eq!(page.status, 200);
    assert_eq!(page.header("Content-Type"), Some("text/html; charset=utf-8"));
    assert_eq!(page.header("Cache-Control"), Some("no-store"));
    assert_eq!(page.text(), rollcam::lab::live::PAGE_HTML);
    assert!(page.text().contains("/session.json"));

    let json = get(addr, "/session.json");
    assert_eq!(json.status, 200);
    assert_eq!(json.header("Content-Type"), Some("application/json; charset=utf-8"));
    assert_eq!(json.header("Cache-Control"), Some("no-store"));
    assert_eq!(json.body, std::fs::read(dir.path().join("session.json")).unwrap(), "the file as written");
    // Cache-busting queries reach the same file.
    assert_eq!(get(addr, "/session.json?t=123").body, json.body);

    for (target, file) in [("/preview/latest_raw.png?t=9", "preview/latest_raw.png"), ("/preview/latest_frame.png", "preview/latest_frame.png")] {
        let r = get(addr, target);
        assert_eq!(r.status, 200, "{target}");
        assert_eq!(r.header("Content-Type"), Some("image/png"));
        assert_eq!(r.header("Cache-Control"), Some("no-store"));
        assert_eq!(r.body, std::fs::read(dir.path().join(file)).unwrap(), "{target}");
    }
    // HEAD: headers, no body.
    let head = request(addr, "HEAD", "/session.json");
    assert_eq!(head.status, 200);
    assert!(head.body.is_empty());
    assert_eq!(request(addr, "POST", "/session.json").status, 405);

    // A file beside session.json that must never be served, and one outside the folder.
    std::fs::write(dir.path().join("secret.txt"), "do not serve").unwrap();
    for target in [
        "/../Cargo.toml",
        "/preview/../session.json",
        "/preview/../secret.txt",
        "/secret.txt",
        "/%2e%2e/Cargo.toml",
        "/%2E%2E%2FCargo.toml",
        "/preview/%2e%2e/session.json",
        "/preview/..%2fsession.json",
        "/preview%2f..%2fsecret.txt",
        "/..%5c..%5cCargo.toml",
        "/preview/latest_raw.png/../../secret.txt",
        "//etc/passwd",
        "/preview/",
        "/raw/frame_000040.tiff",
        "/index.html/..",
        "/session.json%00.png",
    ] {
        let r = get(addr, target);
        assert_eq!(r.status, 404, "{target}: {}", r.text());
        assert!(!r.text().contains("do not serve") && !r.text().contains("[package]"), "{target}");
        assert_eq!(r.header("Cache-Control"), Some("no-store"));
    }

    // A preview not written yet is a 404 naming it.
    std::fs::remove_file(dir.path().join("preview/latest_frame.png")).unwrap();
    let r = get(addr, "/preview/latest_frame.png");
    assert_eq!(r.status, 404);
    assert!(r.text().contains("latest_frame.png"), "{}", r.text());

    server.stop();
    assert!(TcpStream::connect_timeout(&addr, Duration::from_secs(5)).is_err() || get_fails(addr), "still answering after stop");
}

/// After stop the port may still accept at the OS level for a moment; no answer may come.
fn get_fails(addr: SocketAddr) -> bool {
    let Ok(mut s) = TcpStream::connect(addr) else { return true };
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let _ = write!(s, "GET / HTTP/1.0\r\n\r\n");
    let mut buf = Vec::new();
    s.read_to_end(&mut buf).map(|n| n == 0).unwrap_or(true)
}

#[test]
fn before_the_session_starts_the_server_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let server = LiveServer::start(&dir.path().join("not-yet"), "127.0.0.1:0".parse().unwrap()).unwrap();
    let r = get(server.local_addr(), "/session.json");
    assert_eq!(r.status, 404);
    assert_eq!(r.header("Content-Type"), Some("application/json; charset=utf-8"));
    let v: serde_json::Value = serde_json::from_slice(&r.body).unwrap();
    assert_eq!(v["state"], "waiting");
    assert!(v["message"].as_str().unwrap().contains("session.json does not exist yet"), "{v}");
    assert_eq!(get(server.local_addr(), "/").status, 200, "the page itself is there");
    // A truncated or foreign file is reported, not passed on.
    std::fs::create_dir(dir.path().join("not-yet")).unwrap();
    std::fs::write(dir.path().join("not-yet/session.json"), "{\"state\": \"runn").unwrap();
    let r = get(server.local_addr(), "/session.json");
    assert_eq!(r.status, 500);
    assert!(r.text().contains("session.json: not valid JSON"), "{}", r.text());
    // A file where the folder should be is refused by name.
    let file = dir.path().join("file");
    std::fs::write(&file, "x").unwrap();
    let e = LiveServer::start(&file, "127.0.0.1:0".parse().unwrap()).err().unwrap().to_string();
    assert!(e.contains("file") && e.contains("not a folder"), "{e}");
}

#[test]
fn port_in_use_is_named() {
    let dir = session_dir();
    let first = LiveServer::start(dir.path(), "127.0.0.1:0".parse().unwrap()).unwrap();
    let e = LiveServer::start(dir.path(), first.local_addr()).err().expect("second bind must fail").to_string();
    assert!(e.contains(&first.local_addr().to_string()) && e.contains("already in use"), "{e}");
    // The command says the same and exits non-zero.
    let out = Command::new(env!("CARGO_BIN_EXE_rollcam")).args(["serve"]).arg(dir.path()).args(["--addr", &first.local_addr().to_string()]).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(&first.local_addr().to_string()) && err.contains("already in use"), "{err}");
}

#[test]
fn serve_command_prints_the_url_and_stops_on_ctrl_c() {
    let dir = session_dir();
    let (mut child, mut out, url, addr) = spawn_page("serve", dir.path());
    assert!(addr.ip().is_loopback() && addr.port() != 0, "{url}");
    let r = get(addr, "/session.json");
    assert_eq!(r.status, 200);
    assert_eq!(r.body, std::fs::read(dir.path().join("session.json")).unwrap());
    // Ctrl-C.
    let st = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(st.success());
    let status = wait_with_timeout(&mut child, Duration::from_secs(60)).expect("serve did not stop on SIGINT");
    assert!(status.success(), "{status}");
    let mut rest = String::new();
    out.read_to_string(&mut rest).unwrap();
    assert!(rest.contains("stopped"), "{rest}");
}

#[test]
fn a_real_browser_renders_the_session() {
    let browser = chromium();
    let dir = session_dir();
    let profile = tempfile::tempdir().unwrap();
    let server = LiveServer::start(dir.path(), "127.0.0.1:0".parse().unwrap()).unwrap();

    let dom = dump_dom(&browser, profile.path(), &server.url());
    // Rendered by the script from session.json: none of these values are in the HTML.
    assert_eq!(element_text(&dom, "state"), Some("running"), "{dom}");
    assert_eq!(element_text(&dom, "counter-captured"), Some("41"), "{dom}");
    assert_eq!(element_text(&dom, "counter-recorded"), Some("40"));
    assert_eq!(element_text(&dom, "counter-reconstructed"), Some("37"));
    assert_eq!(element_text(&dom, "counter-skipped"), Some("4"));
    assert_eq!(element_text(&dom, "counter-failed"), Some("1"));
    assert_eq!(element_text(&dom, "counter-queued"), Some("2"));
    assert_eq!(element_text(&dom, "latency-last"), Some("812.5"));
    assert_eq!(element_text(&dom, "latency-max"), Some("1304"));
    assert_eq!(element_text(&dom, "meta-camera"), Some("replay:/data/bench-7"));
    assert_eq!(element_text(&dom, "other-exposure_us"), Some("660"), "fields beyond the schema are shown");
    assert!(dom.contains("raw/frame_000041.tiff") && dom.contains("data-sequence=\"41\""), "frames table");
    // Text from the file is text, never markup.
    assert!(dom.contains("non-finite &lt;objective&gt;") && !dom.contains("<objective>"), "errors escaped");
    // Both previews loaded, at their true size.
    assert_eq!(attribute(&dom, "img-raw", "data-loaded"), Some("64x48"), "{dom}");
    assert_eq!(attribute(&dom, "img-frame", "data-loaded"), Some("40x30"));

    // The session moves on: a second load shows the new values and the new preview.
    write_session(dir.path(), &session(58, 52, "finished"));
    png(&dir.path().join("preview/latest_frame.png"), 80, 60, 10);
    let dom = dump_dom(&browser, profile.path(), &server.url());
    assert_eq!(element_text(&dom, "state"), Some("finished"), "{dom}");
    assert_eq!(element_text(&dom, "counter-captured"), Some("58"));
    assert_eq!(element_text(&dom, "counter-reconstructed"), Some("52"));
    assert_eq!(attribute(&dom, "img-frame", "data-loaded"), Some("80x60"), "cache-busted preview");

    // Before any session: the page says it waits, with the server's message.
    let empty = tempfile::tempdir().unwrap();
    let waiting = LiveServer::start(empty.path(), "127.0.0.1:0".parse().unwrap()).unwrap();
    let dom = dump_dom(&browser, profile.path(), &waiting.url());
    assert_eq!(element_text(&dom, "state"), Some("waiting"), "{dom}");
    assert!(element_text(&dom, "message").unwrap_or("").contains("does not exist yet"), "{dom}");
    assert_eq!(attribute(&dom, "img-raw", "data-loaded"), Some("missing"));
}

/// Bytes from a connection until the server closes it (or `limit` passes).
fn read_until_closed(s: &mut TcpStream, limit: Duration) -> Vec<u8> {
    s.set_read_timeout(Some(limit)).unwrap();
    let mut raw = Vec::new();
    let _ = s.read_to_end(&mut raw);
    raw
}

#[test]
fn links_below_the_folder_are_never_followed() {
    let dir = session_dir();
    let outside = tempfile::tempdir().unwrap();
    std::fs::write(outside.path().join("secret"), "SECRET-OUTSIDE-THE-FOLDER").unwrap();
    // The previews and session.json as links to a file outside the folder...
    for rel in ["preview/latest_raw.png", "session.json"] {
        std::fs::remove_file(dir.path().join(rel)).unwrap();
        std::os::unix::fs::symlink(outside.path().join("secret"), dir.path().join(rel)).unwrap();
    }
    let server = LiveServer::start(dir.path(), "127.0.0.1:0".parse().unwrap()).unwrap();
    let addr = server.local_addr();
    let r = get(addr, "/preview/latest_raw.png");
    assert_eq!(r.status, 403, "{}", r.text());
    assert!(r.text().contains("preview/latest_raw.png is a symbolic link") && !r.text().contains("SECRET"), "{}", r.text());
    assert_eq!(r.header("Cache-Control"), Some("no-store"));
    let r = get(addr, "/session.json");
    assert_eq!(r.status, 403, "{}", r.text());
    let v: serde_json::Value = serde_json::from_slice(&r.body).unwrap();
    assert!(v["message"].as_str().unwrap().contains("session.json is a symbolic link"), "{v}");
    assert!(!r.text().contains("SECRET"));
    // ... even to a file inside it: only regular files are served.
    std::fs::remove_file(dir.path().join("preview/latest_raw.png")).unwrap();
    std::os::unix::fs::symlink(dir.path().join("preview/latest_frame.png"), dir.path().join("preview/latest_raw.png")).unwrap();
    assert_eq!(get(addr, "/preview/latest_raw.png").status, 403);
    // ... and the preview folder as a link to a folder outside, holding both names.
    png(&outside.path().join("elsewhere/latest_frame.png"), 8, 8, 1);
    std::fs::write(outside.path().join("elsewhere/latest_raw.png"), "SECRET-PNG").unwrap();
    std::fs::remove_dir_all(dir.path().join("preview")).unwrap();
    std::os::unix::fs::symlink(outside.path().join("elsewhere"), dir.path().join("preview")).unwrap();
    for target in ["/preview/latest_raw.png", "/preview/latest_frame.png"] {
        let r = get(addr, target);
        assert_eq!(r.status, 403, "{target}: {}", r.text());
        assert!(r.text().contains("preview is a symbolic link") && !r.text().contains("SECRET") && !r.text().contains("PNG"), "{}", r.text());
    }
    // A preview that is a folder is refused too.
    std::fs::remove_file(dir.path().join("preview")).unwrap();
    std::fs::create_dir_all(dir.path().join("preview/latest_raw.png")).unwrap();
    let r = get(addr, "/preview/latest_raw.png");
    assert_eq!(r.status, 403);
    assert!(r.text().contains("not a regular file"), "{}", r.text());
}

/// Threads of process `pid`.
fn threads(pid: u32) -> usize {
    std::fs::read_dir(format!("/proc/{pid}/task")).unwrap().count()
}

#[test]
fn idle_connections_hold_no_thread_and_do_not_block_a_request() {
    let dir = session_dir();
    let (mut child, _out, _url, addr) = spawn_page("serve", dir.path());
    let pid = child.id();
    // 300 connections (more than the 256 the server holds while heads arrive): some
    // silent, some with half a head.
    let idle: Vec<TcpStream> = (0..300)
        .map(|i| {
            let mut s = TcpStream::connect(addr).unwrap();
            if i % 2 == 0 {
                s.write_all(b"GET /session.json HTTP/1.1\r\nHost: x\r\n").unwrap();
            }
            s
        })
        .collect();
    std::thread::sleep(Duration::from_millis(300));
    let during = threads(pid);
    // Four workers, the acceptor, main and the Ctrl-C handler, whatever the connections.
    assert!(during <= 4 + 3, "{during} threads with 300 idle connections");
    let t0 = std::time::Instant::now();
    let r = get(addr, "/session.json");
    let took = t0.elapsed();
    assert_eq!(r.status, 200);
    assert_eq!(r.body, std::fs::read(dir.path().join("session.json")).unwrap());
    assert!(took < Duration::from_secs(2), "a request among 300 idle connections took {took:?}");
    assert!(threads(pid) <= 4 + 3);
    drop(idle);
    Command::new("kill").args(["-INT", &pid.to_string()]).status().unwrap();
    assert!(wait_with_timeout(&mut child, Duration::from_secs(60)).expect("serve did not stop").success());
}

fn quick_options() -> ServeOptions {
    ServeOptions { head_timeout: Duration::from_millis(300), ..ServeOptions::default() }
}

#[test]
fn slow_and_oversized_heads_are_cut_off() {
    let dir = session_dir();
    let server = LiveServer::start_with(dir.path(), "127.0.0.1:0".parse().unwrap(), quick_options()).unwrap();
    let addr = server.local_addr();
    // Silent: 408, then closed, soon after the head timeout.
    let t0 = std::time::Instant::now();
    let mut silent = TcpStream::connect(addr).unwrap();
    let raw = read_until_closed(&mut silent, Duration::from_secs(10));
    let took = t0.elapsed();
    assert!(raw.starts_with(b"HTTP/1.1 408 "), "{}", String::from_utf8_lossy(&raw));
    assert!(took >= Duration::from_millis(250) && took < Duration::from_secs(3), "closed after {took:?}");
    // A byte every 50 ms: the timeout is for the whole head, not for each read.
    let mut slow = TcpStream::connect(addr).unwrap();
    let t0 = std::time::Instant::now();
    let mut cut = false;
    for b in b"GET /session.json HTTP/1.1\r\nHost: a-very-slow-client.example\r\n\r\n" {
        if slow.write_all(&[*b]).is_err() {
            cut = true;
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let raw = read_until_closed(&mut slow, Duration::from_secs(10));
    assert!(cut || raw.starts_with(b"HTTP/1.1 408 "), "{}", String::from_utf8_lossy(&raw));
    assert!(t0.elapsed() < Duration::from_secs(5));
    // A head over 8 KiB: 431.
    let mut big = TcpStream::connect(addr).unwrap();
    let _ = write!(big, "GET / HTTP/1.1\r\nX-Big: {}\r\n\r\n", "b".repeat(9000));
    let raw = read_until_closed(&mut big, Duration::from_secs(10));
    assert!(raw.starts_with(b"HTTP/1.1 431 "), "{}", String::from_utf8_lossy(&raw[..raw.len().min(200)]));
    // The server still answers.
    assert_eq!(get(addr, "/session.json").status, 200);
}

#[test]
fn when_full_the_oldest_waiting_connection_makes_room() {
    let dir = session_dir();
    let options = ServeOptions { max_pending: 4, head_timeout: Duration::from_secs(30), ..ServeOptions::default() };
    let server = LiveServer::start_with(dir.path(), "127.0.0.1:0".parse().unwrap(), options).unwrap();
    let addr = server.local_addr();
    let mut idle: Vec<TcpStream> = Vec::new();
    for _ in 0..10 {
        idle.push(TcpStream::connect(addr).unwrap());
        std::thread::sleep(Duration::from_millis(20));
    }
    // The head timeout is 30 s, yet a prompt request is answered at once.
    let t0 = std::time::Instant::now();
    assert_eq!(get(addr, "/session.json").status, 200);
    assert!(t0.elapsed() < Duration::from_secs(2));
    // The oldest idle connections were closed with a 503.
    let raw = read_until_closed(&mut idle[0], Duration::from_secs(5));
    assert!(raw.starts_with(b"HTTP/1.1 503 "), "{}", String::from_utf8_lossy(&raw));
}

#[test]
fn session_json_over_the_cap_is_refused_unread() {
    let dir = session_dir();
    let server = LiveServer::start(dir.path(), "127.0.0.1:0".parse().unwrap()).unwrap();
    // Sparse: 256 MiB on paper, nothing on disk.
    let f = std::fs::File::create(dir.path().join("session.json")).unwrap();
    f.set_len(256 << 20).unwrap();
    drop(f);
    let r = get(server.local_addr(), "/session.json");
    assert_eq!(r.status, 500);
    assert!(r.body.len() < 1024, "{} bytes", r.body.len());
    let v: serde_json::Value = serde_json::from_slice(&r.body).unwrap();
    let msg = v["message"].as_str().unwrap();
    assert!(msg.contains(&(256u64 << 20).to_string()) && msg.contains(&MAX_FILE_BYTES.to_string()) && msg.contains("cap"), "{msg}");
    assert_eq!(server.session_json_reads(), 0, "a file over the cap is never read");
    // One byte over the cap, the same; at the cap, it is read (and here, not JSON).
    let f = std::fs::OpenOptions::new().write(true).open(dir.path().join("session.json")).unwrap();
    f.set_len(MAX_FILE_BYTES + 1).unwrap();
    assert!(get(server.local_addr(), "/session.json").text().contains("over the live page's cap"));
    f.set_len(MAX_FILE_BYTES).unwrap();
    drop(f);
    assert!(get(server.local_addr(), "/session.json").text().contains("not valid JSON"));
    assert_eq!(server.session_json_reads(), 1);
}

#[test]
fn session_json_is_read_once_per_change() {
    let dir = session_dir();
    let server = LiveServer::start(dir.path(), "127.0.0.1:0".parse().unwrap()).unwrap();
    let addr = server.local_addr();
    let first = std::fs::read(dir.path().join("session.json")).unwrap();
    // Eight clients polling at once.
    std::thread::scope(|s| {
        for _ in 0..8 {
            s.spawn(|| {
                for _ in 0..10 {
                    assert_eq!(get(addr, "/session.json").body, first);
                }
            });
        }
    });
    assert_eq!(server.session_json_reads(), 1, "80 requests, one file version");
    write_session(dir.path(), &session(58, 52, "finished"));
    let second = std::fs::read(dir.path().join("session.json")).unwrap();
    for _ in 0..10 {
        assert_eq!(get(addr, "/session.json").body, second);
    }
    assert_eq!(server.session_json_reads(), 2, "one read for the new version");
}

/// The page answered 200 to `GET http://evil.example/session.json` with `Host:
/// 127.0.0.1`, and to two Host headers of which the first was local.
#[test]
fn a_foreign_absolute_target_and_a_doubled_host_are_refused() {
    let dir = session_dir();
    let status = |request: &str| {
        let r = rollcam::lab::live::respond(dir.path(), request.as_bytes());
        let text = String::from_utf8_lossy(&r).into_owned();
        let code: u16 = text.split(' ').nth(1).unwrap().parse().unwrap();
        assert!(!text.contains("evil"), "the refusal echoes the name: {text}");
        (code, text)
    };
    for (request, expected) in [
        ("GET http://evil.example/session.json HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n", 421),
        ("GET http://evil.example:8080/ HTTP/1.1\r\nHost: localhost\r\n\r\n", 421),
        ("GET https://evil.example HTTP/1.1\r\nHost: localhost\r\n\r\n", 421),
        ("GET http://evil.example/session.json HTTP/1.0\r\n\r\n", 421),
        ("GET /session.json HTTP/1.1\r\nHost: 127.0.0.1\r\nHost: evil.example\r\n\r\n", 400),
        ("GET /session.json HTTP/1.1\r\nHost: localhost\r\nhost: localhost\r\n\r\n", 400),
    ] {
        let (code, text) = status(request);
        assert_eq!(code, expected, "{request:?}: {text}");
        assert!(!text.contains("\"state\""), "{request:?}: the session was served");
    }
    let (code, text) = status("GET /session.json HTTP/1.1\r\nHost: localhost\r\nHost: localhost\r\n\r\n");
    assert!(text.contains("more than one Host header"), "{code}: {text}");
    // The page's own absolute targets are still answered.
    for request in ["GET http://127.0.0.1:8080/session.json HTTP/1.1\r\nHost: 127.0.0.1:8080\r\n\r\n", "GET http://localhost/session.json HTTP/1.0\r\n\r\n"] {
        assert_eq!(status(request).0, 200, "{request:?}");
    }
}
