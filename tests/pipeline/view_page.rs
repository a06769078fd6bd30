//! The video viewer of the live page and of `rollcam view DIR`, in a real headless
//! Chromium with no network: the page loads a reconstruction folder and a finished
//! session, plays the video, the slider is moved (by the page's `#seek=N` hook, which
//! dispatches the slider's own `input` event), and a screenshot of the video canvas
//! shows exactly the frame the slider names, compared pixel by pixel with that frame
//! of `video.npy` (grey colour map, fixed display range, nearest-neighbour zoom). Also:
//! the raw capture, the error-against-run-time trace, the per-frame sensitivity with the
//! weak frames, the LED time courses, the folder's kind for each output, and the
//! viewer writing nothing into the folder.

use crate::support::browser;
use crate::support::pipeline_common;

use browser::{attribute, chromium, dump_dom, element_text, http_get as get, marked_box, screenshot, spawn_page, wait_with_timeout};
use ndarray::{s, Array4};
use pipeline_common::{fixture, text};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::time::Duration;

/// `rollcam view DIR` on a free loopback port: the child, its URL and address.
fn spawn_view(dir: &Path) -> (Child, String, SocketAddr) {
    let (child, mut out, url, addr) = spawn_page("view", dir);
    std::thread::spawn(move || std::io::copy(&mut out, &mut std::io::sink()));
    (child, url, addr)
}

fn stop(mut child: Child) {
    Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    let status = wait_with_timeout(&mut child, Duration::from_secs(60)).expect("view did not stop on SIGINT");
    assert!(status.success(), "{status}");
}

/// Every file below `dir` with its length and modification time.
fn snapshot(dir: &Path) -> Vec<(PathBuf, u64, std::time::SystemTime)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let e = e.unwrap();
            let m = e.metadata().unwrap();
            if m.is_dir() {
                stack.push(e.path());
            }
            out.push((e.path(), m.len(), m.modified().unwrap()));
        }
    }
    out.sort();
    out
}

/// The grey level the page shows for `v` over the display range [lo, hi].
fn level(v: f32, lo: f64, hi: f64) -> i32 {
    (255.0 * ((f64::from(v) - lo) / (hi - lo)).clamp(0.0, 1.0)).round() as i32
}

/// For the screenshot's marked video canvas: the largest difference (in grey levels)
/// between the centre of every zoomed video pixel and frame `f` of `video`, for each
/// frame `f`.
fn differences(shot: &image::RgbaImage, video: &Array4<f32>, zoom: u32, lo: f64, hi: f64) -> Vec<i32> {
    let (_, rows, cols, _) = video.dim();
    let (x0, y0, w, h) = marked_box(shot).expect("a magenta-outlined video canvas in the screenshot");
    assert_eq!((w, h), (cols as u32 * zoom, rows as u32 * zoom), "canvas size in the screenshot: {cols} x {rows} pixels at zoom {zoom}");
    (0..video.dim().0)
        .map(|f| {
            let mut worst = 0;
            for r in 0..rows {
                for c in 0..cols {
                    let p = shot.get_pixel(x0 + c as u32 * zoom + zoom / 2, y0 + r as u32 * zoom + zoom / 2).0;
                    assert!(p[0] == p[1] && p[1] == p[2], "grey colour map: {p:?}");
                    worst = worst.max((i32::from(p[0]) - level(video[[f, r, c, 0]], lo, hi)).abs());
                }
            }
            worst
        })
        .collect()
}

/// The fit report's terminal line and a warning, as summary.json carries them.
const FIT_LINE: &str =
    "fit: chi2 1.064 (video) vs 1.224 (still) per pixel over the noise (sensor-model), the still is within 2x the noise: the misfit alone shows no motion";
const FIT_WARNING: &str = "the data hold motion the video does not show";

/// A reconstruction folder whose frames are told apart at a glance: frame k of 12 is a
/// 10 x 14 pattern of 20 grey steps shifted by 7k, plus what `reconstruct` writes
/// beside it (summary with timing and sensitivity, trace, LEDs) and a raw capture
/// inside the folder that the summary names by a longer path.
fn reconstruction_folder(dir: &Path) -> Array4<f32> {
    let video = Array4::from_shape_fn((12, 10, 14, 1), |(f, r, c, _)| 50.0 * ((r * 14 + c + 7 * f) % 20) as f32);
    rollcam::io::write_npy(dir.join("video.npy"), video.view()).unwrap();
    let relative: Vec<f64> = (0..12).map(|k| if k == 0 || k == 11 { 0.3 } else { 0.6 + 0.03 * k as f64 }).collect();
    let summary = serde_json::json!({
        "inputs": {"raw": "/somewhere/else/cap/raw.png"},
        "video_shape": [12, 10, 14],
        "frame_time_us": 220.0,
        "frame_sensitivity": {"relative": relative, "weak_below": 0.5, "weak_frames": [[0, 1], [11, 12]]},
        "config": {"a_long_value": "x".repeat(3000)},
        "fit": {"chi2_video": 1.06, "chi2_still": 1.22, "line": FIT_LINE, "warnings": [FIT_WARNING]},
    });
    std::fs::write(dir.join("summary.json"), serde_json::to_vec_pretty(&summary).unwrap()).unwrap();
    let mut trace = String::from("channel,iteration,seconds,objective,data_term,tv_term,rel_change,psnr_db,rel_error\n");
    for i in 1..=30 {
        trace += &format!("0,{i},{:.3},{},1,1,0.1,{},0.5\n", 0.01 * f64::from(i), 1e6 / f64::from(i), 20.0 + f64::from(i).ln());
    }
    std::fs::write(dir.join("trace.csv"), trace).unwrap();
    let leds = serde_json::json!([{"led": 0, "period_us": 2640.0, "row": 3, "col": 4}, {"led": 1, "period_us": 1980.0, "row": 6, "col": 9}]);
    std::fs::write(dir.join("leds.json"), leds.to_string()).unwrap();
    std::fs::create_dir(dir.join("cap")).unwrap();
    image::GrayImage::from_fn(28, 20, |x, y| image::Luma([(x * 9 + y) as u8])).save(dir.join("cap/raw.png")).unwrap();
    video
}

#[test]
fn view_plays_a_reconstruction_folder_and_shows_the_frame_the_slider_names() {
    let browser = chromium();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("rec");
    std::fs::create_dir(&dir).unwrap();
    let video = reconstruction_folder(&dir);
    let before = snapshot(&dir);
    let (child, url, addr) = spawn_view(&dir);
    assert!(addr.ip().is_loopback(), "{url}");

    // The listing and the compact video over HTTP.
    let (status, body) = get(addr, "/api/folder.json");
    assert_eq!(status, 200);
    let listing: serde_json::Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(listing["kind"], "reconstruction", "{listing}");
    assert_eq!(listing["videos"][0]["video"], "video.npy", "{listing}");
    let (status, body) = get(addr, "/api/video/video.npy");
    assert_eq!(status, 200);
    assert_eq!(&body[..4], b"RCQ1");
    assert!(body.len() < 12 * 10 * 14 * 4, "16-bit levels, not float32: {} bytes", body.len());
    for bad in ["/api/video/../rec/video.npy", "/api/file/cap/../summary.json", "/api/image/summary.json", "/api/file/video.npy"] {
        assert_eq!(get(addr, bad).0, 404, "{bad}");
    }

    // Play, then move the slider to frame 7; grey, fixed range 0..1000, zoom 8.
    let (zoom, lo, hi, target) = (8u32, 0.0, 1000.0, 7usize);
    let page = format!("{url}#cmap=grey&lo={lo}&hi={hi}&zoom={zoom}&fps=30&seek={target}&mark=1");
    let profile = tempfile::tempdir().unwrap();
    let dom = dump_dom(&browser, profile.path(), &page);
    assert_eq!(element_text(&dom, "mode"), Some("view"), "{dom}");
    assert_eq!(element_text(&dom, "state"), Some("reconstruction"));
    assert_eq!(element_text(&dom, "frame-number"), Some("7"), "{dom}");
    assert_eq!(element_text(&dom, "frame-count"), Some("12"));
    assert_eq!(element_text(&dom, "frame-time"), Some("1540"), "7 frames of 220 us");
    assert_eq!(attribute(&dom, "video-canvas", "data-frame"), Some("7"));
    let played: usize = attribute(&dom, "video-canvas", "data-played").unwrap().parse().unwrap();
    assert!(played >= 3, "the video played {played} frames before the slider moved");
    assert_eq!(attribute(&dom, "video-canvas", "data-shape"), Some("12x10x14x1"));
    assert_eq!(attribute(&dom, "raw-canvas", "data-loaded"), Some("28x20"), "raw found inside the folder from the summary's path");
    assert_eq!(attribute(&dom, "raw-canvas", "data-rel"), Some("cap/raw.png"));
    assert_eq!(attribute(&dom, "trace-canvas", "data-points"), Some("30"), "{dom}");
    assert_eq!(attribute(&dom, "sens-canvas", "data-frames"), Some("12"));
    assert_eq!(attribute(&dom, "sens-canvas", "data-weak"), Some("0,11"), "weak frames marked");
    assert_eq!(attribute(&dom, "tc-canvas", "data-series"), Some("2"), "one time course per LED");
    assert_eq!(element_text(&dom, "fit-line"), Some(FIT_LINE), "the fit report's line, as the terminal prints it");
    assert_eq!(attribute(&dom, "fit-warnings", "data-count"), Some("1"));
    assert!(dom.contains(&format!("warning: {FIT_WARNING}")), "{dom}");
    assert!(dom.contains("<details id=\"details\">") && dom.contains(&"x".repeat(3000)), "raw JSON behind the details toggle");

    let shot = screenshot(&browser, profile.path(), &page, 1400, 1100);
    let diff = differences(&shot, &video, zoom, lo, hi);
    assert!(diff[target] <= 1, "frame {target} on screen differs by {} levels: {diff:?}", diff[target]);
    for (f, d) in diff.iter().enumerate() {
        assert!(f == target || *d >= 40, "frame {f} would look the same ({d} levels): {diff:?}");
    }

    // Another frame and another range: what the screen shows follows.
    let page = format!("{url}#cmap=grey&lo=200&hi=700&zoom=4&frame=3&mark=1");
    let shot = screenshot(&browser, profile.path(), &page, 1400, 1100);
    let diff = differences(&shot, &video, 4, 200.0, 700.0);
    assert!(diff[3] <= 1, "{diff:?}");
    assert!(diff.iter().enumerate().all(|(f, d)| f == 3 || *d > 1), "{diff:?}");

    stop(child);
    assert_eq!(snapshot(&dir), before, "the viewer wrote into the folder");
    // Everything the page needs is inline: no script, style or image from elsewhere.
    let page_html = rollcam::lab::live::PAGE_HTML;
    assert!(!page_html.contains("<script src") && !page_html.contains("<link") && !page_html.contains("http://") && !page_html.contains("https://"));
}

#[test]
fn a_finished_session_plays_any_recorded_frame() {
    let browser = chromium();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("s");
    let fix = fixture("led-505hz");
    let o = pipeline_common::run_replay(&fix, &out, &["--iters", "20"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let server = rollcam::lab::live::LiveServer::start(&out, "127.0.0.1:0".parse().unwrap()).unwrap();

    // Frame 1 of the session (not the latest, 2): the frame of its video that differs
    // most from its neighbours, shown over the video's own range.
    let rel = "rec/frame_000001/video.npy";
    let video = rollcam::io::read_npy(out.join(rel)).unwrap();
    let (frames, rows, cols, _) = video.dim();
    let lo = video.iter().cloned().fold(f32::INFINITY, f32::min) as f64;
    let hi = video.iter().cloned().fold(f32::NEG_INFINITY, f32::max) as f64;
    let step = |a: usize, b: usize| {
        video
            .slice(s![a, .., .., 0])
            .iter()
            .zip(video.slice(s![b, .., .., 0]).iter())
            .map(|(x, y)| (level(*x, lo, hi) - level(*y, lo, hi)).abs())
            .max()
            .unwrap()
    };
    let target = (2..frames - 2).max_by_key(|&f| step(f, f - 1).min(step(f, f + 1))).unwrap();
    let zoom = 6;
    let page = format!("{}#video={rel}&cmap=grey&lo={lo}&hi={hi}&zoom={zoom}&fps=30&seek={target}&mark=1", server.url());
    let profile = tempfile::tempdir().unwrap();
    let dom = dump_dom(&browser, profile.path(), &page);
    assert_eq!(element_text(&dom, "state"), Some("finished"), "{dom}");
    assert_eq!(element_text(&dom, "counter-reconstructed"), Some("3"));
    assert_eq!(attribute(&dom, "video-canvas", "data-video"), Some(rel), "{dom}");
    assert_eq!(element_text(&dom, "frame-number"), Some(target.to_string().as_str()), "{dom}");
    assert_eq!(element_text(&dom, "frame-count"), Some(frames.to_string().as_str()));
    assert!(attribute(&dom, "video-canvas", "data-played").unwrap().parse::<usize>().unwrap() >= 3);
    assert_eq!(attribute(&dom, "video-canvas", "data-shape"), Some(format!("{frames}x{rows}x{cols}x1").as_str()));
    assert_eq!(attribute(&dom, "raw-canvas", "data-rel"), Some("raw/frame_000001.tiff"), "the frame's own raw capture");
    assert_eq!(attribute(&dom, "raw-canvas", "data-loaded"), Some("64x48"));
    assert_eq!(attribute(&dom, "trace-canvas", "data-points"), Some("20"), "{dom}");
    let sens: usize = attribute(&dom, "sens-canvas", "data-frames").unwrap().parse().unwrap();
    assert_eq!(sens, frames);
    // History: every reconstructed frame can be chosen.
    for seq in 0..3 {
        assert!(dom.contains(&format!("value=\"rec/frame_{seq:06}/video.npy\"")), "frame {seq} in the history: {dom}");
    }

    let shot = screenshot(&browser, profile.path(), &page, 1400, 1100);
    let diff = differences(&shot, &video, zoom, lo, hi);
    assert!(diff[target] <= 1, "frame {target} on screen differs by {} levels: {diff:?}", diff[target]);
    let others = diff.iter().enumerate().filter(|&(f, _)| f != target).map(|(_, d)| *d).min().unwrap();
    assert!(others >= 3, "another frame looks the same as frame {target}: {diff:?}");
}

#[test]
fn every_result_folder_has_its_kind() {
    let tmp = tempfile::tempdir().unwrap();
    let kinds = [
        ("cmp", &["summary.json", "traces.csv", "psnr_vs_time.png"][..], "compare"),
        ("seq", &["summary.json", "coverage.csv", "video.npy"][..], "sequence"),
        ("sweep", &["report.json", "figure.png"][..], "led-sweep"),
        ("s", &["session.json"][..], "session"),
    ];
    for (name, files, kind) in kinds {
        let d = tmp.path().join(name);
        std::fs::create_dir(&d).unwrap();
        for f in files {
            std::fs::write(d.join(f), b"{}").unwrap();
        }
        let v = rollcam::lab::viewer::listing(&d).unwrap();
        assert_eq!(v["kind"], kind, "{name}: {v}");
    }
    // A session folder just created, before its session.json.
    let d = tmp.path().join("new-session");
    for sub in ["rec", "preview"] {
        std::fs::create_dir_all(d.join(sub)).unwrap();
    }
    std::fs::write(d.join("capture.toml"), "").unwrap();
    assert_eq!(rollcam::lab::viewer::listing(&d).unwrap()["kind"], "session");
    let v = rollcam::lab::viewer::listing(&tmp.path().join("cmp")).unwrap();
    assert_eq!(v["figures"], serde_json::json!(["psnr_vs_time.png"]));
    // `rollcam compare` writes each run's video under videos/: they are listed, to be
    // played side by side.
    let runs = tmp.path().join("cmp/videos");
    std::fs::create_dir(&runs).unwrap();
    for label in ["fista", "admm_cg_2"] {
        rollcam::io::write_npy(runs.join(format!("{label}.npy")), Array4::from_elem((3, 4, 5, 1), 1.0f32).view()).unwrap();
    }
    let v = rollcam::lab::viewer::listing(&tmp.path().join("cmp")).unwrap();
    assert_eq!(v["kind"], "compare");
    let listed = v["videos"].to_string();
    assert!(listed.contains("videos/fista.npy") && listed.contains("videos/admm_cg_2.npy"), "{v}");
    // A file or a missing folder is refused by the command, by name.
    let o = Command::new(env!("CARGO_BIN_EXE_rollcam")).arg("view").arg(tmp.path().join("cmp/summary.json")).output().unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("not a folder"), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn links_below_the_folder_are_not_followed_by_the_viewer() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("rec");
    let outside = tmp.path().join("outside");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::create_dir_all(&outside).unwrap();
    let video = Array4::from_elem((2, 3, 4, 1), 1.0f32);
    rollcam::io::write_npy(outside.join("video.npy"), video.view()).unwrap();
    std::fs::write(outside.join("summary.json"), "{\"SECRET\": 1}").unwrap();
    std::os::unix::fs::symlink(outside.join("video.npy"), dir.join("video.npy")).unwrap();
    std::os::unix::fs::symlink(&outside, dir.join("sub")).unwrap();
    let server = rollcam::lab::live::LiveServer::start(&dir, "127.0.0.1:0".parse().unwrap()).unwrap();
    let addr = server.local_addr();
    let (status, body) = get(addr, "/api/video/video.npy");
    assert_eq!(status, 403, "{}", String::from_utf8_lossy(&body));
    let (status, body) = get(addr, "/api/file/sub/summary.json");
    assert_eq!(status, 403);
    assert!(!String::from_utf8_lossy(&body).contains("SECRET"));
    let (_, body) = get(addr, "/api/folder.json");
    let v: serde_json::Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(v["videos"], serde_json::json!([]), "a linked video or folder is not listed: {v}");
}

/// The page's colour map: `stops` spread evenly over levels 0..=255, linear between them.
fn colour_map(stops: &[[f64; 3]], level: i32) -> [i32; 3] {
    let x = f64::from(level) / 255.0 * (stops.len() - 1) as f64;
    let k = (x.floor() as usize).min(stops.len() - 2);
    let f = x - k as f64;
    let mut rgb = [0; 3];
    for c in 0..3 {
        rgb[c] = (stops[k][c] * (1.0 - f) + stops[k + 1][c] * f).round() as i32;
    }
    rgb
}

#[test]
fn colour_maps_and_the_auto_range_follow_the_settings() {
    let browser = chromium();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("rec");
    std::fs::create_dir(&dir).unwrap();
    let video = reconstruction_folder(&dir);
    let (child, url, _) = spawn_view(&dir);
    let (zoom, frame, pct) = (8u32, 5usize, 90.0);
    let page = format!("{url}#cmap=viridis&pct={pct}&zoom={zoom}&frame={frame}&mark=1");
    let profile = tempfile::tempdir().unwrap();
    let dom = dump_dom(&browser, profile.path(), &page);
    assert_eq!(attribute(&dom, "video-canvas", "data-frame"), Some("5"), "{dom}");
    // Auto range: the 10th and 90th percentiles of the video's values (one sample per
    // value at this size), to within one 16-bit step of the page's levels.
    let range: Vec<f64> = attribute(&dom, "video-canvas", "data-range").unwrap().split(',').map(|v| v.parse().unwrap()).collect();
    let mut sorted: Vec<f64> = video.iter().map(|&v| f64::from(v)).collect();
    sorted.sort_by(f64::total_cmp);
    let at = |p: f64| sorted[(p / 100.0 * (sorted.len() - 1) as f64).round() as usize];
    let step = (sorted[sorted.len() - 1] - sorted[0]) / 65535.0;
    let (lo, hi) = (at(100.0 - pct), at(pct));
    assert!((range[0] - lo).abs() <= 2.0 * step && (range[1] - hi).abs() <= 2.0 * step, "page range {range:?}, percentiles {lo} .. {hi}");
    assert!(hi - lo < sorted[sorted.len() - 1] - sorted[0], "the 90% range is narrower than the full one");

    // Viridis: every video pixel's colour is the map's at its level (within one level,
    // the page's 16-bit values round where the test's floats do not).
    let viridis = [[68.0, 1.0, 84.0], [59.0, 82.0, 139.0], [33.0, 145.0, 140.0], [94.0, 201.0, 98.0], [253.0, 231.0, 37.0]];
    let shot = screenshot(&browser, profile.path(), &page, 1400, 1100);
    let (x0, y0, w, h) = marked_box(&shot).expect("the marked video canvas");
    let (_, rows, cols, _) = video.dim();
    assert_eq!((w, h), (cols as u32 * zoom, rows as u32 * zoom));
    let mut clipped = [0usize; 2];
    for r in 0..rows {
        for c in 0..cols {
            let p = shot.get_pixel(x0 + c as u32 * zoom + zoom / 2, y0 + r as u32 * zoom + zoom / 2).0;
            let got = [i32::from(p[0]), i32::from(p[1]), i32::from(p[2])];
            let l = level(video[[frame, r, c, 0]], range[0], range[1]);
            clipped[0] += usize::from(l == 0);
            clipped[1] += usize::from(l == 255);
            let near = (l - 1..=l + 1).filter(|x| (0..=255).contains(x)).any(|x| {
                let want = colour_map(&viridis, x);
                (0..3).all(|i| (got[i] - want[i]).abs() <= 1)
            });
            assert!(near, "pixel ({r}, {c}) of frame {frame}: {got:?}, the viridis colour of level {l} is {:?}", colour_map(&viridis, l));
        }
    }
    // The range clips: some pixels at each end of the map.
    assert!(clipped[0] > 0 && clipped[1] > 0, "{clipped:?}");
    stop(child);
}
