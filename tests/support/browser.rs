//! Headless Chromium for the live-page tests: find it (no silent skip), dump the DOM
//! of a page after its script has run, take a screenshot of it, read elements of the
//! dump. Also what those tests share beside the browser: a `rollcam serve` / `view`
//! child on a free port, and a plain HTTP GET. The browser resolves no host name (only 127.0.0.1 is reachable), so a page
//! that needed the network would show it.
#![allow(dead_code)]

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::time::{Duration, Instant};

/// `rollcam COMMAND DIR` (`serve` or `view`) on a free loopback port: the child, its
/// stdout after the first line, the URL that line gives, and its address.
pub fn spawn_page(command: &str, dir: &Path) -> (Child, BufReader<ChildStdout>, String, SocketAddr) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_rollcam"))
        .arg(command)
        .arg(dir)
        .args(["--addr", "127.0.0.1:0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut out = BufReader::new(child.stdout.take().unwrap());
    let mut line = String::new();
    out.read_line(&mut line).unwrap();
    let url = line.split_whitespace().find(|w| w.starts_with("http://")).unwrap_or_else(|| panic!("no URL in {line:?}")).to_string();
    let addr: SocketAddr = url.trim_start_matches("http://").trim_end_matches('/').parse().unwrap();
    (child, out, url, addr)
}

/// GET over HTTP/1.0: (status, body).
pub fn http_get(addr: SocketAddr, target: &str) -> (u16, Vec<u8>) {
    let mut s = TcpStream::connect(addr).unwrap_or_else(|e| panic!("connect {addr}: {e}"));
    s.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
    write!(s, "GET {target} HTTP/1.0\r\nHost: {addr}\r\nConnection: close\r\n\r\n").unwrap();
    let mut raw = Vec::new();
    s.read_to_end(&mut raw).unwrap();
    let split = raw.windows(4).position(|w| w == b"\r\n\r\n").expect("end of headers");
    let status = String::from_utf8_lossy(&raw[..split]).split_whitespace().nth(1).unwrap().parse().unwrap();
    (status, raw[split + 4..].to_vec())
}

pub fn wait_with_timeout(child: &mut Child, limit: Duration) -> Option<std::process::ExitStatus> {
    let t0 = Instant::now();
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return Some(s);
        }
        if t0.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            return None;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

pub fn chromium() -> PathBuf {
    let path = std::env::var_os("ROLLCAM_CHROMIUM").map(PathBuf::from).unwrap_or_else(|| PathBuf::from("/usr/bin/chromium"));
    assert!(
        path.exists(),
        "{}: no Chromium for the live-page browser test; run scripts/test.sh (it installs the Debian package chromium) or set ROLLCAM_CHROMIUM",
        path.display()
    );
    path
}

/// The DOM of `url` after the page's script has run for a few (virtual) seconds.
pub fn dump_dom(browser: &Path, profile: &Path, url: &str) -> String {
    let mut child = Command::new(browser)
        .args(["--headless", "--no-sandbox", "--disable-gpu", "--disable-extensions", "--no-first-run", "--virtual-time-budget=5000", OFFLINE])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(["--dump-dom", url])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("{}: cannot start: {e}", browser.display()));
    let mut stdout = child.stdout.take().unwrap();
    let mut stderr = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        stdout.read_to_string(&mut s).unwrap();
        s
    });
    let err_reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr.read_to_string(&mut s);
        s
    });
    let status = wait_with_timeout(&mut child, Duration::from_secs(180));
    let dom = reader.join().unwrap();
    let err = err_reader.join().unwrap();
    let status = status.unwrap_or_else(|| panic!("{}: no DOM within 180 s; stderr: {err}", browser.display()));
    assert!(status.success() && !dom.is_empty(), "{}: {status}; stderr: {err}", browser.display());
    dom
}

/// Every host name fails to resolve; 127.0.0.1 (the server under test) stays reachable.
const OFFLINE: &str = "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1";

/// A screenshot of `url` (a `width` x `height` window at one device pixel per CSS pixel,
/// sRGB) after the page's script has run for a few (virtual) seconds.
pub fn screenshot(browser: &Path, profile: &Path, url: &str, width: u32, height: u32) -> image::RgbaImage {
    let shot = profile.join("screenshot.png");
    let _ = std::fs::remove_file(&shot);
    let mut child = Command::new(browser)
        .args(["--headless", "--no-sandbox", "--disable-gpu", "--disable-extensions", "--no-first-run", "--virtual-time-budget=5000", OFFLINE])
        .args(["--hide-scrollbars", "--force-device-scale-factor=1", "--force-color-profile=srgb"])
        .arg(format!("--window-size={width},{height}"))
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg(format!("--screenshot={}", shot.display()))
        .arg(url)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("{}: cannot start: {e}", browser.display()));
    let mut stderr = child.stderr.take().unwrap();
    let err_reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr.read_to_string(&mut s);
        s
    });
    let status = wait_with_timeout(&mut child, Duration::from_secs(180));
    let err = err_reader.join().unwrap();
    let status = status.unwrap_or_else(|| panic!("{}: no screenshot within 180 s; stderr: {err}", browser.display()));
    assert!(status.success() && shot.exists(), "{}: {status}; stderr: {err}", browser.display());
    image::open(&shot).unwrap_or_else(|e| panic!("{}: {e}", shot.display())).to_rgba8()
}

/// The inside of the box drawn by a 3 px outline of pure magenta (#ff00ff), which the page
/// draws around its video canvases when asked (`#mark=1`): (x, y, width, height) of the
/// first such box from the top left.
pub fn marked_box(shot: &image::RgbaImage) -> Option<(u32, u32, u32, u32)> {
    let magenta = |x: u32, y: u32| x < shot.width() && y < shot.height() && shot.get_pixel(x, y).0[..3] == [255, 0, 255];
    let (x0, y0) = (0..shot.height()).flat_map(|y| (0..shot.width()).map(move |x| (x, y))).find(|&(x, y)| magenta(x, y))?;
    let mut x1 = x0;
    while magenta(x1 + 1, y0) {
        x1 += 1;
    }
    let mut y1 = y0;
    while magenta(x0, y1 + 1) {
        y1 += 1;
    }
    (x1 >= x0 + 6 && y1 >= y0 + 6).then(|| (x0 + 3, y0 + 3, x1 - x0 - 5, y1 - y0 - 5))
}

/// The text of the element with `id` in the dumped DOM (the element holds text only).
pub fn element_text<'a>(dom: &'a str, id: &str) -> Option<&'a str> {
    let at = dom.find(&format!("id=\"{id}\""))?;
    let open_end = at + dom[at..].find('>')? + 1;
    let close = open_end + dom[open_end..].find('<')?;
    Some(&dom[open_end..close])
}

pub fn attribute<'a>(dom: &'a str, id: &str, attr: &str) -> Option<&'a str> {
    let at = dom.find(&format!("id=\"{id}\""))?;
    let tag_end = at + dom[at..].find('>')?;
    let tag = &dom[at..tag_end];
    let a = tag.find(&format!("{attr}=\""))? + attr.len() + 2;
    Some(&tag[a..a + tag[a..].find('"')?])
}
