//! The live page of a bench session: a small HTTP server (loopback by default) over a
//! session folder (written by `rollcam run`) that serves one self-contained HTML page,
//! the folder's `session.json`, its two previews, and (for the page's video viewer) the
//! videos, raw captures, summaries and figures inside it, and nothing else.
//!
//! Routes (exact matches on the request path, query strings ignored; everything else
//! is 404, so no path can reach another file):
//!
//! - `/`: the page (`live/index.html`, embedded); its script polls `/session.json`
//!   about every 500 ms and refreshes the previews with cache-busting queries;
//! - `/session.json`: the file as written (checked to be a JSON object); before it
//!   exists, a 404 whose JSON body says so (`{"state": "waiting", ...}`);
//! - `/preview/latest_raw.png`, `/preview/latest_frame.png`: the previews, or 404;
//! - `/api/...`: the viewer's routes ([`super::viewer`]): the folder's listing, its
//!   videos and raw images in a compact 16-bit form, and its summaries, traces and
//!   figures, each a plain path inside the folder.
//!
//! Only GET and HEAD are answered (405 otherwise). Every answer carries
//! `Cache-Control: no-store` and `Connection: close` (one request per connection). The
//! writer renames complete files into place, so a read never sees half a file.
//!
//! Files: each is opened component by component from the session folder with
//! `openat(O_NOFOLLOW)`, and what was opened is checked with `fstat` (folders for
//! `preview`, a regular file at the end). A symbolic link anywhere below the folder is
//! refused (403), whatever it points to, and since the checks are made on the open file
//! descriptors, swapping a component for a link between a check and the read cannot
//! slip through. The session folder itself is the operator's argument and may be a link.
//! No file larger than [`MAX_FILE_BYTES`] is read, and never more than that many bytes.
//!
//! `session.json` is read once per change: its bytes (and the verdict on them) are
//! cached, keyed by (device, inode, length, mtime) from `fstat`; a request whose key
//! matches is answered from the cache without reading the file.
//!
//! The server ([`LiveServer`]): one thread accepts connections and reads their request
//! heads with `poll` (non-blocking, so an idle connection never holds a worker); a
//! complete head goes through a bounded queue to a fixed pool of workers, which answer
//! with [`respond_cached`] (the pure [`respond`] plus the cache) and close. Limits, all in
//! [`ServeOptions`]: a head must arrive whole within `head_timeout` (else 408 and close)
//! and within [`MAX_HEAD_BYTES`] (else 431); at most `max_pending` connections wait for
//! their head, and when one more arrives the oldest is closed, so idle or slow clients
//! cannot lock a prompt one out; a head that finds the worker queue full gets 503; an
//! answer must be written within `write_timeout`. The thread count is fixed:
//! `workers` + 1, whatever the number of connections.

use super::folder_files::{open_inside, read_capped, OpenError};
use super::viewer;
use std::io::{Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::os::fd::AsRawFd;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The page, with its script and style inline.
pub const PAGE_HTML: &str = include_str!("live_page/index.html");

/// The largest file (session.json or a preview) the page serves: 16 MiB. The page
/// fetches session.json twice a second, so a bigger file would cost each viewer over
/// 32 MB/s and a browser-side parse that cannot keep up; the previews are small PNGs.
/// It also bounds the server's memory: the cache holds one session.json and each
/// worker at most one answer.
pub const MAX_FILE_BYTES: u64 = 16 << 20;

/// The largest request head (request line and headers) accepted; a longer one gets 431.
pub const MAX_HEAD_BYTES: usize = 8 << 10;

/// Limits of the live-page server; [`Default`] is what `rollcam serve` and `rollcam run
/// --serve` use.
#[derive(Clone, Debug)]
pub struct ServeOptions {
    /// Threads that answer complete requests.
    pub workers: usize,
    /// Complete requests waiting for a worker; one more gets 503.
    pub queue: usize,
    /// Connections held while their request head arrives; when one more is accepted,
    /// the oldest of them is closed.
    pub max_pending: usize,
    /// Time from accepting a connection to the end of its request head; then 408 and close.
    pub head_timeout: Duration,
    /// Time to write one answer; then the connection is closed.
    pub write_timeout: Duration,
}

impl Default for ServeOptions {
    fn default() -> Self {
        ServeOptions { workers: 4, queue: 32, max_pending: 256, head_timeout: Duration::from_secs(5), write_timeout: Duration::from_secs(10) }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    #[error("cannot serve on {addr}: {reason}")]
    Bind { addr: SocketAddr, reason: String },
    #[error("{path}: not a folder (expected the session folder that holds session.json)")]
    NotAFolder { path: PathBuf },
}

// ---------------------------------------------------------------------------------------
// Answers
// ---------------------------------------------------------------------------------------

/// What one request gets: status, content type and body (shared, so a cached
/// session.json is not copied per request).
#[derive(Clone)]
struct Answer {
    status: u16,
    content_type: &'static str,
    body: Arc<[u8]>,
}

impl Answer {
    fn new(status: u16, content_type: &'static str, body: impl Into<Arc<[u8]>>) -> Self {
        Answer { status, content_type, body: body.into() }
    }
    fn json(status: u16, value: serde_json::Value) -> Self {
        Answer::new(status, "application/json; charset=utf-8", value.to_string().into_bytes())
    }
    fn text(status: u16, text: impl Into<String>) -> Self {
        Answer::new(status, "text/plain; charset=utf-8", text.into().into_bytes())
    }
}

fn reason(status: u16) -> &'static str {
    match status {
        200 => "OK",
        400 => "Bad Request",
        403 => "Forbidden",
        404 => "Not Found",
        405 => "Method Not Allowed",
        408 => "Request Timeout",
        413 => "Content Too Large",
        421 => "Misdirected Request",
        422 => "Unprocessable Content",
        431 => "Request Header Fields Too Large",
        500 => "Internal Server Error",
        503 => "Service Unavailable",
        505 => "HTTP Version Not Supported",
        _ => "Unknown",
    }
}

/// The full HTTP/1.1 response: status line, headers, and the body unless `head_only`.
fn encode(a: &Answer, head_only: bool) -> Vec<u8> {
    let mut out = format!(
        "HTTP/1.1 {} {}\r\nContent-Type: {}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nX-Content-Type-Options: nosniff\r\n{}Connection: close\r\n\r\n",
        a.status,
        reason(a.status),
        a.content_type,
        a.body.len(),
        if a.status == 405 { "Allow: GET, HEAD\r\n" } else { "" },
    )
    .into_bytes();
    if !head_only {
        out.extend_from_slice(&a.body);
    }
    out
}

/// Where the request head ends (just past its empty line), accepting CRLF or bare LF.
fn head_end(buf: &[u8]) -> Option<usize> {
    let mut i = 0;
    while let Some(p) = buf[i..].iter().position(|&b| b == b'\n') {
        let nl = i + p;
        match buf.get(nl + 1..) {
            Some([b'\n', ..]) => return Some(nl + 2),
            Some([b'\r', b'\n', ..]) => return Some(nl + 3),
            _ => i = nl + 1,
        }
    }
    None
}

/// The answer to the raw bytes of one request (its head and anything after it) over the
/// session folder `dir`: the complete HTTP response, ready to write. Never panics; reads
/// session.json afresh (the server uses [`respond_cached`] with its cache).
pub fn respond(dir: &Path, request: &[u8]) -> Vec<u8> {
    respond_cached(dir, &SessionCache::new(), request)
}

/// [`respond`], answering `/session.json` through `cache`.
pub fn respond_cached(dir: &Path, cache: &SessionCache, request: &[u8]) -> Vec<u8> {
    let (answer, head_only) = parse_and_answer(dir, cache, request);
    encode(&answer, head_only)
}

fn parse_and_answer(dir: &Path, cache: &SessionCache, request: &[u8]) -> (Answer, bool) {
    let end = match head_end(request) {
        Some(end) if end <= MAX_HEAD_BYTES => end,
        Some(_) => return (head_too_large(), false),
        None if request.len() > MAX_HEAD_BYTES => return (head_too_large(), false),
        None => return (Answer::text(400, "incomplete request: the head must end with an empty line\n"), false),
    };
    let Ok(head) = std::str::from_utf8(&request[..end]) else {
        return (Answer::text(400, "the request head is not UTF-8\n"), false);
    };
    let line = head.lines().next().unwrap_or("");
    let parts: Vec<&str> = line.split(' ').collect();
    let [method, target, version] = parts[..] else {
        return (Answer::text(400, "malformed request line: expected METHOD TARGET HTTP/1.x\n"), false);
    };
    if !version.starts_with("HTTP/1.") {
        let status = if version.starts_with("HTTP/") { 505 } else { 400 };
        return (Answer::text(status, "this server speaks HTTP/1.0 and HTTP/1.1 only\n"), false);
    }
    let head_only = method == "HEAD";
    if method != "GET" && !head_only {
        let shown: String = method.chars().take(32).collect();
        return (Answer::text(405, format!("{shown:?} is not served: this page answers GET and HEAD only\n")), false);
    }
    let hosts: Vec<&str> =
        head.lines().skip(1).filter_map(|l| l.split_once(':').filter(|(k, _)| k.trim().eq_ignore_ascii_case("host")).map(|(_, v)| v.trim())).collect();
    if hosts.len() > 1 {
        return (Answer::text(400, "more than one Host header: expected exactly one\n"), false);
    }
    // An absolute-form target (`http://host/path`) names its host too: it must be one
    // the page answers, whatever the Host header says.
    let target_host = target.strip_prefix("http://").or_else(|| target.strip_prefix("https://")).map(|rest| rest.split(['/', '?', '#']).next().unwrap_or(""));
    if hosts.iter().copied().chain(target_host).any(|h| !host_allowed(h)) {
        // The foreign name is not echoed: a refusal carries nothing the request chose.
        return (Answer::text(421, "this Host is not served: ask for localhost or the address the page listens on\n"), false);
    }
    (answer(dir, cache, target), head_only)
}

/// A Host header the page answers: `localhost` or an IP address (the one it listens
/// on), with or without a port. A name that resolves to it (a DNS-rebinding page's own
/// domain) is refused, so another site's script cannot read the folder.
fn host_allowed(host: &str) -> bool {
    let name = match host.strip_prefix('[') {
        Some(rest) => rest.split(']').next().unwrap_or(""),
        None => match host.rsplit_once(':') {
            Some((name, port)) if port.bytes().all(|b| b.is_ascii_digit()) => name,
            _ => host,
        },
    };
    name.eq_ignore_ascii_case("localhost") || name.parse::<std::net::IpAddr>().is_ok()
}

fn head_too_large() -> Answer {
    Answer::text(431, format!("request head over {MAX_HEAD_BYTES} bytes\n"))
}

/// The answer to GET `target` (the raw request target) over `dir`.
fn answer(dir: &Path, cache: &SessionCache, target: &str) -> Answer {
    // Absolute form (`http://host/path`): the path part.
    let target = match target.strip_prefix("http://").or_else(|| target.strip_prefix("https://")) {
        Some(rest) => rest.find('/').map_or("/", |i| &rest[i..]),
        None => target,
    };
    let path = target.split(['?', '#']).next().unwrap_or("");
    match path {
        "/" | "/index.html" => Answer::new(200, "text/html; charset=utf-8", PAGE_HTML.as_bytes()),
        "/session.json" => session_json(dir, cache),
        "/preview/latest_raw.png" | "/preview/latest_frame.png" => preview(dir, &path[1..]),
        _ => match viewer::answer(dir, path) {
            Some(a) => Answer::new(a.status, a.content_type, a.body),
            None => Answer::text(
                404,
                "not found: this server answers /, /session.json, /preview/latest_raw.png, /preview/latest_frame.png and the viewer's /api/ paths only\n",
            ),
        },
    }
}

fn preview(dir: &Path, rel: &str) -> Answer {
    let shown = dir.join(rel);
    let shown = shown.display();
    match open_inside(dir, rel) {
        Ok((_, meta)) if meta.len() > MAX_FILE_BYTES => Answer::text(500, format!("{shown}: {} bytes, over the cap of {MAX_FILE_BYTES} bytes\n", meta.len())),
        Ok((file, _)) => match read_capped(file, MAX_FILE_BYTES) {
            Ok(bytes) => Answer::new(200, "image/png", bytes),
            Err(e) => Answer::text(500, format!("{shown}: cannot read: {e}\n")),
        },
        Err(OpenError::NotFound) => Answer::text(404, format!("{shown}: no preview yet\n")),
        Err(e @ (OpenError::Link { .. } | OpenError::NotRegular { .. } | OpenError::NotAFolder { .. } | OpenError::HardLinked { .. })) => {
            Answer::text(403, format!("{shown}: refused: {e}\n"))
        }
        Err(OpenError::Io(e)) => Answer::text(500, format!("{shown}: cannot open: {e}\n")),
    }
}

// ---------------------------------------------------------------------------------------
// session.json, read once per change
// ---------------------------------------------------------------------------------------

/// What identifies one version of session.json without reading it.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
struct FileKey {
    dev: u64,
    ino: u64,
    len: u64,
    mtime: i64,
    mtime_ns: i64,
}

impl FileKey {
    fn of(m: &std::fs::Metadata) -> FileKey {
        FileKey { dev: m.dev(), ino: m.ino(), len: m.len(), mtime: m.mtime(), mtime_ns: m.mtime_nsec() }
    }
}

/// The last answer for session.json, keyed by (device, inode, length, mtime): a request
/// whose `fstat` matches is answered without reading the file. Shared by the workers; the
/// file is read under the lock, so one change is read once however many ask at once.
#[derive(Default)]
pub struct SessionCache {
    last: Mutex<Option<(FileKey, Answer)>>,
    reads: AtomicU64,
}

impl SessionCache {
    pub fn new() -> SessionCache {
        SessionCache::default()
    }

    /// How many times session.json has been read (its bytes, not its metadata).
    pub fn reads(&self) -> u64 {
        self.reads.load(Ordering::SeqCst)
    }
}

fn session_json(dir: &Path, cache: &SessionCache) -> Answer {
    let path = dir.join("session.json");
    let shown = path.display();
    let unreadable = |status: u16, state: &str, message: String| Answer::json(status, serde_json::json!({"state": state, "message": message}));
    let (file, meta) = match open_inside(dir, "session.json") {
        Ok(opened) => opened,
        Err(OpenError::NotFound) => {
            return unreadable(404, "waiting", format!("{shown} does not exist yet: no session has started in this folder"));
        }
        Err(e @ (OpenError::Link { .. } | OpenError::NotRegular { .. } | OpenError::NotAFolder { .. } | OpenError::HardLinked { .. })) => {
            return unreadable(403, "unreadable", format!("{shown}: refused: {e}"));
        }
        Err(OpenError::Io(e)) => return unreadable(500, "unreadable", format!("{shown}: cannot open: {e}")),
    };
    let key = FileKey::of(&meta);
    let mut last = cache.last.lock().unwrap_or_else(PoisonError::into_inner);
    if let Some((k, a)) = last.as_ref() {
        if *k == key {
            return a.clone();
        }
    }
    let a = if meta.len() > MAX_FILE_BYTES {
        unreadable(500, "unreadable", format!("{shown}: {} bytes, over the live page's cap of {MAX_FILE_BYTES} bytes (16 MiB); not read", meta.len()))
    } else {
        cache.reads.fetch_add(1, Ordering::SeqCst);
        match read_capped(file, MAX_FILE_BYTES) {
            Ok(bytes) => match check_object(&bytes) {
                Ok(()) => Answer::new(200, "application/json; charset=utf-8", bytes),
                Err(why) => unreadable(500, "unreadable", format!("{shown}: {why}")),
            },
            Err(e) => unreadable(500, "unreadable", format!("{shown}: cannot read: {e}")),
        }
    };
    *last = Some((key, a.clone()));
    a
}

/// Valid JSON whose top level is an object, checked without building it.
fn check_object(bytes: &[u8]) -> Result<(), String> {
    serde_json::from_slice::<serde::de::IgnoredAny>(bytes).map_err(|e| format!("not valid JSON: {e}"))?;
    match bytes.iter().find(|b| !b.is_ascii_whitespace()) {
        Some(b'{') => Ok(()),
        _ => Err("expected a JSON object".into()),
    }
}

// ---------------------------------------------------------------------------------------
// The server
// ---------------------------------------------------------------------------------------

/// A running live-page server; stops on [`LiveServer::stop`] or drop.
pub struct LiveServer {
    stop: Arc<AtomicBool>,
    acceptor: Option<JoinHandle<()>>,
    workers: Vec<JoinHandle<()>>,
    cache: Arc<SessionCache>,
    addr: SocketAddr,
    dir: PathBuf,
}

/// A connection whose request head is still arriving.
struct Pending {
    stream: TcpStream,
    head: Vec<u8>,
    deadline: Instant,
}

/// A complete request head, for a worker.
struct Job {
    stream: TcpStream,
    request: Vec<u8>,
}

impl LiveServer {
    /// Serve `session_dir` on `addr` (port 0 picks a free port) with the default
    /// [`ServeOptions`]. The folder may not exist yet (the page then says it is
    /// waiting), but must not be a file.
    pub fn start(session_dir: &Path, addr: SocketAddr) -> Result<LiveServer, LiveError> {
        LiveServer::start_with(session_dir, addr, ServeOptions::default())
    }

    /// [`LiveServer::start`] with explicit limits.
    pub fn start_with(session_dir: &Path, addr: SocketAddr, options: ServeOptions) -> Result<LiveServer, LiveError> {
        if session_dir.exists() && !session_dir.is_dir() {
            return Err(LiveError::NotAFolder { path: session_dir.to_path_buf() });
        }
        let listener = TcpListener::bind(addr).map_err(|e| LiveError::Bind { addr, reason: bind_reason(&e) })?;
        let local = listener.local_addr().map_err(|e| LiveError::Bind { addr, reason: e.to_string() })?;
        listener.set_nonblocking(true).map_err(|e| LiveError::Bind { addr, reason: e.to_string() })?;
        let options = ServeOptions { workers: options.workers.max(1), queue: options.queue.max(1), max_pending: options.max_pending.max(1), ..options };
        let stop = Arc::new(AtomicBool::new(false));
        let cache = Arc::new(SessionCache::new());
        let (tx, rx) = crossbeam_channel::bounded::<Job>(options.queue);
        let workers = (0..options.workers)
            .map(|i| {
                let (rx, dir, cache, write_timeout) = (rx.clone(), session_dir.to_path_buf(), cache.clone(), options.write_timeout);
                std::thread::Builder::new()
                    .name(format!("live-page-{i}"))
                    .spawn(move || {
                        for job in rx {
                            serve_one(&dir, &cache, job, write_timeout);
                        }
                    })
                    .expect("spawn a live-page worker")
            })
            .collect();
        let acceptor = {
            let stop = stop.clone();
            std::thread::Builder::new()
                .name("live-page-accept".into())
                .spawn(move || accept_loop(listener, tx, &options, &stop))
                .expect("spawn the live-page acceptor")
        };
        tracing::info!(addr = %local, dir = %session_dir.display(), "live page serving");
        Ok(LiveServer { stop, acceptor: Some(acceptor), workers, cache, addr: local, dir: session_dir.to_path_buf() })
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

    /// How many times this server has read session.json's bytes (once per change).
    pub fn session_json_reads(&self) -> u64 {
        self.cache.reads()
    }

    /// Stop answering and close the listening socket.
    pub fn stop(self) {
        drop(self)
    }
}

impl Drop for LiveServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        // The acceptor drops the listener, the pending connections and the queue's
        // sender; the workers then finish what they hold and end.
        if let Some(a) = self.acceptor.take() {
            let _ = a.join();
        }
        for w in self.workers.drain(..) {
            let _ = w.join();
        }
    }
}

/// How often the acceptor looks at the stop flag when nothing happens.
const TICK: Duration = Duration::from_millis(100);

/// Accept connections and read their heads without blocking (poll), hand complete heads
/// to the workers, close connections past their head deadline (408) and, when
/// `max_pending` are waiting, the oldest one.
fn accept_loop(listener: TcpListener, tx: crossbeam_channel::Sender<Job>, o: &ServeOptions, stop: &AtomicBool) {
    let mut pending: Vec<Pending> = Vec::new();
    while !stop.load(Ordering::SeqCst) {
        let now = Instant::now();
        pending.retain_mut(|p| {
            let alive = p.deadline > now;
            if !alive {
                reject(&mut p.stream, 408, format!("no complete request head within {} ms\n", o.head_timeout.as_millis()));
            }
            alive
        });
        let wait = pending.iter().map(|p| p.deadline - now).min().unwrap_or(TICK).min(TICK);
        let mut fds: Vec<libc::pollfd> = std::iter::once(listener.as_raw_fd())
            .chain(pending.iter().map(|p| p.stream.as_raw_fd()))
            .map(|fd| libc::pollfd { fd, events: libc::POLLIN, revents: 0 })
            .collect();
        let ms = wait.as_micros().div_ceil(1000).max(1) as libc::c_int;
        // SAFETY: fds is a valid array of fds.len() pollfd structures.
        let n = unsafe { libc::poll(fds.as_mut_ptr(), fds.len() as libc::nfds_t, ms) };
        if n < 0 {
            let e = std::io::Error::last_os_error();
            if e.kind() != std::io::ErrorKind::Interrupted {
                tracing::debug!("live page: poll: {e}");
                std::thread::sleep(Duration::from_millis(10));
            }
            continue;
        }
        if n == 0 {
            continue;
        }
        // Heads first: read what arrived.
        let ready: Vec<bool> = fds[1..].iter().map(|f| f.revents != 0).collect();
        for (p, ready) in std::mem::take(&mut pending).into_iter().zip(ready) {
            if !ready {
                pending.push(p);
                continue;
            }
            match read_head(p) {
                HeadState::Waiting(p) => pending.push(p),
                HeadState::Complete(job) => dispatch(&tx, job),
                HeadState::Gone => {}
            }
        }
        // Then new connections.
        if fds[0].revents != 0 {
            loop {
                match listener.accept() {
                    Ok((stream, _)) => {
                        if stream.set_nonblocking(true).is_err() {
                            continue;
                        }
                        if pending.len() >= o.max_pending {
                            let mut oldest = pending.remove(0);
                            reject(&mut oldest.stream, 503, "too many connections waiting; closed to admit a newer one\n");
                        }
                        pending.push(Pending { stream, head: Vec::new(), deadline: Instant::now() + o.head_timeout });
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => break,
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                    Err(e) => {
                        // Out of descriptors, most likely: close the oldest waiting
                        // connection to free one, and do not spin on the listener.
                        tracing::debug!("live page: accept: {e}");
                        if !pending.is_empty() {
                            let mut oldest = pending.remove(0);
                            reject(&mut oldest.stream, 503, "the live page is out of connections; closed to admit a newer one\n");
                        }
                        std::thread::sleep(Duration::from_millis(10));
                        break;
                    }
                }
            }
        }
    }
}

enum HeadState {
    Waiting(Pending),
    Complete(Job),
    Gone,
}

/// Read what is there of a head; complete at its empty line or past [`MAX_HEAD_BYTES`]
/// (the worker then answers 431).
fn read_head(mut p: Pending) -> HeadState {
    let mut buf = [0u8; 4096];
    loop {
        match p.stream.read(&mut buf) {
            Ok(0) => return HeadState::Gone,
            Ok(n) => {
                let from = p.head.len().saturating_sub(3);
                p.head.extend_from_slice(&buf[..n]);
                if head_end(&p.head[from..]).is_some() || p.head.len() > MAX_HEAD_BYTES {
                    return HeadState::Complete(Job { stream: p.stream, request: p.head });
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return HeadState::Waiting(p),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(_) => return HeadState::Gone,
        }
    }
}

fn dispatch(tx: &crossbeam_channel::Sender<Job>, job: Job) {
    match tx.try_send(job) {
        Ok(()) => {}
        Err(crossbeam_channel::TrySendError::Full(mut job)) => reject(&mut job.stream, 503, "the live page is busy; try again\n"),
        Err(crossbeam_channel::TrySendError::Disconnected(_)) => {}
    }
}

/// Best-effort short answer on a non-blocking socket, then close.
fn reject(stream: &mut TcpStream, status: u16, text: impl Into<String>) {
    let _ = stream.write(&encode(&Answer::text(status, text), false));
    let _ = stream.shutdown(Shutdown::Both);
}

/// A worker's part: answer one complete request and close.
fn serve_one(dir: &Path, cache: &SessionCache, job: Job, write_timeout: Duration) {
    let Job { mut stream, request } = job;
    let response = respond_cached(dir, cache, &request);
    tracing::debug!(request = %String::from_utf8_lossy(&request[..request.len().min(120)]).lines().next().unwrap_or(""), bytes = response.len(), "live page request");
    if stream.set_nonblocking(false).is_err() {
        return;
    }
    if let Err(e) = write_by(&mut stream, &response, Instant::now() + write_timeout) {
        tracing::debug!("live page: client went away: {e}");
        return;
    }
    // Close gently: end our side, then drop what the client may still send (briefly),
    // so unread input does not turn the close into a reset that loses the answer.
    let _ = stream.shutdown(Shutdown::Write);
    let until = Instant::now() + Duration::from_millis(200);
    let mut sink = [0u8; 4096];
    let mut drained = 0usize;
    while drained < 64 << 10 {
        let left = until.saturating_duration_since(Instant::now());
        if left.is_zero() || stream.set_read_timeout(Some(left)).is_err() {
            break;
        }
        match stream.read(&mut sink) {
            Ok(0) | Err(_) => break,
            Ok(n) => drained += n,
        }
    }
}

/// Write all of `bytes` before `deadline` (a whole-answer limit, not per call).
fn write_by(stream: &mut TcpStream, mut bytes: &[u8], deadline: Instant) -> std::io::Result<()> {
    while !bytes.is_empty() {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(std::io::Error::new(std::io::ErrorKind::TimedOut, "write timeout"));
        }
        stream.set_write_timeout(Some(left))?;
        match stream.write(bytes) {
            Ok(0) => return Err(std::io::ErrorKind::WriteZero.into()),
            Ok(n) => bytes = &bytes[n..],
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

fn bind_reason(e: &std::io::Error) -> String {
    match e.kind() {
        std::io::ErrorKind::AddrInUse => format!("the address is already in use ({e}); stop the other server or choose another port with --addr"),
        std::io::ErrorKind::AddrNotAvailable => format!("no such local address ({e})"),
        std::io::ErrorKind::PermissionDenied => format!("permission denied ({e}); ports below 1024 need privileges"),
        _ => e.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::ffi::OsStrExt;

    fn status(response: &[u8]) -> u16 {
        let line = response.split(|&b| b == b'\r').next().unwrap();
        std::str::from_utf8(line).unwrap().split(' ').nth(1).unwrap().parse().unwrap()
    }

    fn body(response: &[u8]) -> &[u8] {
        &response[head_end(response).unwrap()..]
    }

    fn get(dir: &Path, target: &str) -> Vec<u8> {
        respond(dir, format!("GET {target} HTTP/1.1\r\nHost: localhost\r\n\r\n").as_bytes())
    }

    #[test]
    fn another_sites_host_and_a_hard_linked_file_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("session.json"), br#"{"state":"running"}"#).unwrap();
        let with_host = |host: &str| respond(dir.path(), format!("GET /session.json HTTP/1.1\r\nHost: {host}\r\n\r\n").as_bytes());
        // A DNS-rebinding page's own name was answered with the folder's files.
        for bad in ["attacker.example", "attacker.example:8080", "localhost.attacker.example"] {
            let r = with_host(bad);
            assert_eq!(status(&r), 421, "{bad}");
            assert!(!String::from_utf8_lossy(&r).contains("running"), "{bad}");
            assert!(!String::from_utf8_lossy(&r).contains("attacker"), "the refusal echoes the name: {bad}");
        }
        for good in ["localhost", "LOCALHOST:8080", "127.0.0.1:8080", "[::1]:8080", "192.168.1.20"] {
            assert_eq!(status(&with_host(good)), 200, "{good}");
        }
        assert_eq!(status(&respond(dir.path(), b"GET /session.json HTTP/1.0\r\n\r\n")), 200, "HTTP/1.0 without a Host");
        // A hard link in the folder to a file outside it was served.
        let outside = tempfile::tempdir().unwrap();
        std::fs::write(outside.path().join("secret"), b"secret").unwrap();
        std::fs::create_dir(dir.path().join("preview")).unwrap();
        std::fs::hard_link(outside.path().join("secret"), dir.path().join("preview/latest_raw.png")).unwrap();
        let r = get(dir.path(), "/preview/latest_raw.png");
        assert_eq!(status(&r), 403);
        assert!(String::from_utf8_lossy(&r).contains("hard links") && !String::from_utf8_lossy(&r).contains("secret\n"));
    }

    #[test]
    fn only_the_known_routes_answer() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("preview")).unwrap();
        std::fs::write(dir.path().join("preview/latest_raw.png"), b"png").unwrap();
        std::fs::write(dir.path().join("session.json"), br#"{"state":"running"}"#).unwrap();
        assert_eq!(status(&get(dir.path(), "/")), 200);
        assert_eq!(body(&get(dir.path(), "/session.json?t=5")), br#"{"state":"running"}"#);
        assert_eq!(body(&get(dir.path(), "http://127.0.0.1:8080/session.json")), br#"{"state":"running"}"#, "absolute form");
        assert!(String::from_utf8_lossy(&get(dir.path(), "/preview/latest_raw.png")).contains("Content-Type: image/png\r\n"));
        assert_eq!(status(&get(dir.path(), "/preview/latest_frame.png")), 404);
        for bad in [
            "/preview/../session.json",
            "/preview",
            "/preview/",
            "//session.json",
            "/session.json/",
            "/%2e%2e/x",
            "/preview/latest_raw.png/..",
            "*",
            "http://localhost/y",
        ] {
            assert_eq!(status(&get(dir.path(), bad)), 404, "{bad}");
        }
        assert_eq!(body(&get(dir.path(), "http://127.0.0.1")), PAGE_HTML.as_bytes(), "absolute form without a path");
        let post = respond(dir.path(), b"POST /session.json HTTP/1.1\r\n\r\n");
        assert_eq!(status(&post), 405);
        assert!(String::from_utf8_lossy(&post).contains("Allow: GET, HEAD\r\n"));
        let head = respond(dir.path(), b"HEAD /session.json HTTP/1.0\r\n\r\n");
        assert_eq!(status(&head), 200);
        assert!(body(&head).is_empty() && String::from_utf8_lossy(&head).contains("Content-Length: 19\r\n"));
    }

    #[test]
    fn bad_session_json_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let r = get(dir.path(), "/session.json");
        assert_eq!(status(&r), 404);
        assert!(String::from_utf8_lossy(&r).contains("does not exist yet"));
        std::fs::write(dir.path().join("session.json"), b"{\"state\": ").unwrap();
        let r = get(dir.path(), "/session.json");
        assert_eq!(status(&r), 500);
        assert!(String::from_utf8_lossy(&r).contains("not valid JSON"));
        std::fs::write(dir.path().join("session.json"), b" [1, 2]").unwrap();
        assert!(String::from_utf8_lossy(&get(dir.path(), "/session.json")).contains("expected a JSON object"));
    }

    #[test]
    fn malformed_requests_get_an_answer_not_a_panic() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("session.json"), b"{}").unwrap();
        let huge = format!("GET / HTTP/1.1\r\nX: {}\r\n\r\n", "a".repeat(MAX_HEAD_BYTES));
        let cases: Vec<(Vec<u8>, u16)> = vec![
            (b"".to_vec(), 400),
            (b"GET / HTTP/1.1\r\n".to_vec(), 400),
            (b"GET /".to_vec(), 400),
            (b"\r\n\r\n".to_vec(), 400),
            (b"\n\n".to_vec(), 400),
            (b"GET / HTTP/1.1\n\n".to_vec(), 200),
            (b"GET\r\n\r\n".to_vec(), 400),
            (b"GET  / HTTP/1.1\r\n\r\n".to_vec(), 400),
            (b"GET / HTTP/2\r\n\r\n".to_vec(), 505),
            (b"GET / FOO\r\n\r\n".to_vec(), 400),
            (b"GET /\xff\xfe HTTP/1.1\r\n\r\n".to_vec(), 400),
            (b"\x00\x01\x02\r\n\r\n".to_vec(), 400),
            (huge.clone().into_bytes(), 431),
            (huge.as_bytes()[..MAX_HEAD_BYTES + 1].to_vec(), 431),
            (b"GET /../../../etc/passwd HTTP/1.1\r\n\r\n".to_vec(), 404),
            (b"GET /session.json\0 HTTP/1.1\r\n\r\n".to_vec(), 404),
            (b"DELETE / HTTP/1.1\r\n\r\n".to_vec(), 405),
            (b"GET http://localhost/../session.json HTTP/1.1\r\n\r\n".to_vec(), 404),
        ];
        for (req, want) in cases {
            let r = respond(dir.path(), &req);
            assert_eq!(status(&r), want, "{:?}", String::from_utf8_lossy(&req[..req.len().min(60)]));
            assert!(head_end(&r).is_some());
        }
        // Pseudo-random garbage, and every prefix of a valid request.
        const ALPHABET: &[u8] = b"GET /session.json HTTP/1.1\r\n\n\xff\0 %?#:";
        let mut x: u64 = 0x9e3779b97f4a7c15;
        for len in 0..2000 {
            let bytes: Vec<u8> = (0..len % 300)
                .map(|_| {
                    x ^= x << 13;
                    x ^= x >> 7;
                    x ^= x << 17;
                    ALPHABET[(x % ALPHABET.len() as u64) as usize]
                })
                .collect();
            let r = respond(dir.path(), &bytes);
            assert!(head_end(&r).is_some());
        }
        let ok = b"GET /preview/latest_raw.png?t=1 HTTP/1.1\r\nHost: 127.0.0.1:8080\r\n\r\n";
        for n in 0..ok.len() {
            assert!(head_end(&respond(dir.path(), &ok[..n])).is_some());
        }
    }

    #[test]
    fn links_below_the_folder_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let outside = tempfile::tempdir().unwrap();
        std::fs::write(outside.path().join("secret"), b"SECRET-CONTENT").unwrap();
        std::fs::create_dir(dir.path().join("preview")).unwrap();
        std::os::unix::fs::symlink(outside.path().join("secret"), dir.path().join("preview/latest_raw.png")).unwrap();
        std::os::unix::fs::symlink(outside.path().join("secret"), dir.path().join("session.json")).unwrap();
        for target in ["/preview/latest_raw.png", "/session.json"] {
            let r = String::from_utf8_lossy(&get(dir.path(), target)).into_owned();
            assert!(r.starts_with("HTTP/1.1 403 ") && r.contains("symbolic link") && !r.contains("SECRET"), "{r}");
        }
        // A FIFO does not block the open and is refused.
        let fifo = std::ffi::CString::new(dir.path().join("preview/latest_frame.png").as_os_str().as_bytes()).unwrap();
        assert_eq!(unsafe { libc::mkfifo(fifo.as_ptr(), 0o600) }, 0);
        let r = String::from_utf8_lossy(&get(dir.path(), "/preview/latest_frame.png")).into_owned();
        assert!(r.starts_with("HTTP/1.1 403 ") && r.contains("not a regular file"), "{r}");
    }
}
