//! The live page of a bench session: a small localhost HTTP server over a session
//! folder (written by `rollcam run`) that serves one self-contained HTML page, the
//! folder's `session.json` and its two previews, and nothing else.
//!
//! Routes (exact matches on the request path, query strings ignored; everything else
//! is 404, so no path can reach another file):
//!
//! - `/`: the page (`live/index.html`, embedded); its script polls `/session.json`
//!   about every 500 ms and refreshes the previews with cache-busting queries;
//! - `/session.json`: the file as written (checked to be JSON); before it exists, a
//!   404 whose JSON body says so (`{"state": "waiting", ...}`);
//! - `/preview/latest_raw.png`, `/preview/latest_frame.png`: the previews, or 404.
//!
//! Every answer carries `Cache-Control: no-store`. The writer renames complete files
//! into place, so a read never sees half a file.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

/// The page, with its script and style inline.
pub const PAGE_HTML: &str = include_str!("live_page/index.html");

/// How many threads answer requests.
const WORKERS: usize = 2;

#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    #[error("cannot serve on {addr}: {reason}")]
    Bind { addr: SocketAddr, reason: String },
    #[error("{path}: not a folder (expected the session folder that holds session.json)")]
    NotAFolder { path: PathBuf },
}

/// What one request gets: status, content type and body.
struct Answer {
    status: u16,
    content_type: &'static str,
    body: Vec<u8>,
}

impl Answer {
    fn new(status: u16, content_type: &'static str, body: impl Into<Vec<u8>>) -> Self {
        Answer { status, content_type, body: body.into() }
    }
    fn json(status: u16, value: serde_json::Value) -> Self {
        Answer::new(status, "application/json; charset=utf-8", value.to_string())
    }
    fn text(status: u16, text: impl Into<String>) -> Self {
        Answer::new(status, "text/plain; charset=utf-8", text.into())
    }
}

/// The answer to `GET path` (the raw request target) over `dir`.
fn answer(dir: &Path, method: &tiny_http::Method, target: &str) -> Answer {
    use tiny_http::Method;
    if !matches!(method, Method::Get | Method::Head) {
        return Answer::text(405, format!("{method} is not served: this page answers GET only\n"));
    }
    let path = target.split(['?', '#']).next().unwrap_or("");
    match path {
        "/" | "/index.html" => Answer::new(200, "text/html; charset=utf-8", PAGE_HTML),
        "/session.json" => session_json(dir),
        "/preview/latest_raw.png" | "/preview/latest_frame.png" => {
            let file = dir.join(&path[1..]);
            match std::fs::read(&file) {
                Ok(bytes) => Answer::new(200, "image/png", bytes),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => Answer::text(404, format!("{}: no preview yet\n", file.display())),
                Err(e) => Answer::text(500, format!("{}: cannot read: {e}\n", file.display())),
            }
        }
        _ => Answer::text(404, "not found: this server answers /, /session.json, /preview/latest_raw.png and /preview/latest_frame.png only\n"),
    }
}

fn session_json(dir: &Path) -> Answer {
    let file = dir.join("session.json");
    match std::fs::read(&file) {
        Ok(bytes) => match serde_json::from_slice::<serde_json::Value>(&bytes) {
            Ok(v) if v.is_object() => Answer::new(200, "application/json; charset=utf-8", bytes),
            Ok(_) => Answer::json(500, serde_json::json!({"state": "unreadable", "message": format!("{}: expected a JSON object", file.display())})),
            Err(e) => Answer::json(500, serde_json::json!({"state": "unreadable", "message": format!("{}: not valid JSON: {e}", file.display())})),
        },
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Answer::json(
            404,
            serde_json::json!({"state": "waiting", "message": format!("{} does not exist yet: no session has started in this folder", file.display())}),
        ),
        Err(e) => Answer::json(500, serde_json::json!({"state": "unreadable", "message": format!("{}: cannot read: {e}", file.display())})),
    }
}

fn respond(dir: &Path, request: tiny_http::Request) {
    let a = answer(dir, request.method(), request.url());
    tracing::debug!(method = %request.method(), url = request.url(), status = a.status, "live page request");
    let header = |k: &str, v: &str| tiny_http::Header::from_bytes(k.as_bytes(), v.as_bytes()).expect("ASCII header");
    let head = matches!(request.method(), tiny_http::Method::Head);
    let len = a.body.len();
    let body = if head { Vec::new() } else { a.body };
    let response = tiny_http::Response::new(
        tiny_http::StatusCode(a.status),
        vec![header("Content-Type", a.content_type), header("Cache-Control", "no-store"), header("X-Content-Type-Options", "nosniff")],
        std::io::Cursor::new(body),
        Some(if head { 0 } else { len }),
        None,
    );
    if let Err(e) = request.respond(response) {
        tracing::debug!("live page: client went away: {e}");
    }
}

/// A running live-page server; stops on [`LiveServer::stop`] or drop.
pub struct LiveServer {
    server: Arc<tiny_http::Server>,
    stop: Arc<AtomicBool>,
    workers: Vec<JoinHandle<()>>,
    addr: SocketAddr,
    dir: PathBuf,
}

impl LiveServer {
    /// Serve `session_dir` on `addr` (port 0 picks a free port). The folder may not
    /// exist yet (the page then says it is waiting), but must not be a file.
    pub fn start(session_dir: &Path, addr: SocketAddr) -> Result<LiveServer, LiveError> {
        if session_dir.exists() && !session_dir.is_dir() {
            return Err(LiveError::NotAFolder { path: session_dir.to_path_buf() });
        }
        let server = tiny_http::Server::http(addr).map_err(|e| LiveError::Bind { addr, reason: bind_reason(&*e) })?;
        let local = server.server_addr().to_ip().ok_or_else(|| LiveError::Bind { addr, reason: "not an IP listener".into() })?;
        let server = Arc::new(server);
        let stop = Arc::new(AtomicBool::new(false));
        let workers = (0..WORKERS)
            .map(|i| {
                let (server, stop, dir) = (server.clone(), stop.clone(), session_dir.to_path_buf());
                std::thread::Builder::new()
                    .name(format!("live-page-{i}"))
                    .spawn(move || {
                        while !stop.load(Ordering::SeqCst) {
                            match server.recv_timeout(Duration::from_millis(200)) {
                                Ok(Some(rq)) => respond(&dir, rq),
                                Ok(None) => {}
                                Err(e) => tracing::debug!("live page: {e}"),
                            }
                        }
                    })
                    .expect("spawn a live-page thread")
            })
            .collect();
        tracing::info!(addr = %local, dir = %session_dir.display(), "live page serving");
        Ok(LiveServer { server, stop, workers, addr: local, dir: session_dir.to_path_buf() })
    }

    /// The address actually bound (the chosen port when started on port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// `http://ADDR/`.
    pub fn url(&self) -> String {
        format!("http://{}/", self.addr)
    }

    /// The session folder served.
    pub fn session_dir(&self) -> &Path {
        &self.dir
    }

    /// Stop answering and close the listening socket.
    pub fn stop(self) {
        drop(self)
    }
}

impl Drop for LiveServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        for _ in 0..self.workers.len() {
            self.server.unblock();
        }
        for w in self.workers.drain(..) {
            let _ = w.join();
        }
    }
}

fn bind_reason(e: &(dyn std::error::Error + 'static)) -> String {
    match e.downcast_ref::<std::io::Error>().map(|io| io.kind()) {
        Some(std::io::ErrorKind::AddrInUse) => format!("the address is already in use ({e}); stop the other server or choose another port with --addr"),
        Some(std::io::ErrorKind::AddrNotAvailable) => format!("no such local address ({e})"),
        Some(std::io::ErrorKind::PermissionDenied) => format!("permission denied ({e}); ports below 1024 need privileges"),
        _ => e.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tiny_http::Method;

    #[test]
    fn only_the_four_routes_answer() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("preview")).unwrap();
        std::fs::write(dir.path().join("preview/latest_raw.png"), b"png").unwrap();
        std::fs::write(dir.path().join("session.json"), br#"{"state":"running"}"#).unwrap();
        assert_eq!(answer(dir.path(), &Method::Get, "/").status, 200);
        assert_eq!(answer(dir.path(), &Method::Get, "/session.json?t=5").body, br#"{"state":"running"}"#);
        assert_eq!(answer(dir.path(), &Method::Get, "/preview/latest_raw.png").content_type, "image/png");
        assert_eq!(answer(dir.path(), &Method::Get, "/preview/latest_frame.png").status, 404);
        for bad in ["/preview/../session.json", "/preview", "/preview/", "//session.json", "/session.json/", "/%2e%2e/x", "/preview/latest_raw.png/.."] {
            assert_eq!(answer(dir.path(), &Method::Get, bad).status, 404, "{bad}");
        }
        assert_eq!(answer(dir.path(), &Method::Post, "/session.json").status, 405);
    }

    #[test]
    fn bad_session_json_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let a = answer(dir.path(), &Method::Get, "/session.json");
        assert_eq!(a.status, 404);
        assert!(String::from_utf8_lossy(&a.body).contains("does not exist yet"));
        std::fs::write(dir.path().join("session.json"), b"{\"state\": ").unwrap();
        let a = answer(dir.path(), &Method::Get, "/session.json");
        assert_eq!(a.status, 500);
        assert!(String::from_utf8_lossy(&a.body).contains("not valid JSON"));
    }
}
