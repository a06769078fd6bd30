//! The viewer's routes over a served folder (a bench session or any result folder:
//! `reconstruct`, `compare`, `reconstruct-sequence`, `experiment led-sweep`), under
//! `/api/`, answered by the live page's server ([`super::live`]) for its page:
//!
//! - `/api/folder.json`: what the folder holds: its `kind` (`session`, `reconstruction`,
//!   `compare`, `sequence`, `led-sweep` or `folder`), the videos found below it
//!   (`video.npy`, `truth.npy`, and a compare's `videos/LABEL.npy`; a session's come
//!   from its session.json instead), and the figures and documents at its
//!   top;
//! - `/api/video/REL.npy`: a video in the compact 16-bit form of
//!   [`crate::io::encode_levels_u16`] (`application/octet-stream`), which the page decodes;
//! - `/api/image/REL.{tif,tiff,png}`: one image (a raw capture) in the same form;
//! - `/api/file/REL.{json,csv,png,md,toml}`: the file as it is.
//!
//! `REL` is a path below the folder checked by [`valid_rel`] (plain names, no dot
//! files, no `..`, no percent escapes) and opened by [`open_inside`]: no symbolic link
//! below the folder is followed. Nothing is written. Limits: files over
//! [`MAX_FILE_BYTES`](super::live::MAX_FILE_BYTES) (videos: [`MAX_VIDEO_BYTES`]) are
//! refused unread; one video or image is decoded at a time in the process (a request
//! that finds the decoder busy gets 503 and the page retries); the listing looks at
//! [`MAX_LISTED_ENTRIES`] entries at most, [`MAX_DEPTH`] folders deep.

use super::folder_files::{list_inside, open_inside, read_capped, valid_rel, EntryKind, OpenError};
use crate::io::{decode_image_bytes, decode_stack_bytes, encode_levels_u16, ByteBudget};
use std::path::Path;
use std::sync::Mutex;

/// The largest video file (`.npy`) or raw image decoded for the page: 64 MiB (the
/// answer is half that: 16-bit levels instead of float32).
pub const MAX_VIDEO_BYTES: u64 = 64 << 20;

/// The most folder entries `/api/folder.json` looks at.
pub const MAX_LISTED_ENTRIES: usize = 4096;

/// How deep below the folder the listing looks for videos (a sweep's
/// `period-660us/rec/video.npy` is at depth 2).
pub const MAX_DEPTH: usize = 3;

/// The largest file served as it is by `/api/file/`: the live page's cap.
const MAX_PLAIN_BYTES: u64 = 16 << 20;

/// One decode at a time in the process.
static DECODER: Mutex<()> = Mutex::new(());

/// What one `/api/` request gets.
pub struct ViewAnswer {
    pub status: u16,
    pub content_type: &'static str,
    pub body: Vec<u8>,
}

impl ViewAnswer {
    fn text(status: u16, text: impl Into<String>) -> ViewAnswer {
        ViewAnswer { status, content_type: "text/plain; charset=utf-8", body: text.into().into_bytes() }
    }
}

/// The answer to the path `path` (query removed) over `dir`, or `None` when `path` is
/// not under `/api/`.
pub fn answer(dir: &Path, path: &str) -> Option<ViewAnswer> {
    let rest = path.strip_prefix("/api/")?;
    if rest == "folder.json" {
        return Some(folder_json(dir));
    }
    let (route, rel) = rest.split_once('/').unwrap_or((rest, ""));
    let ext = rel.rsplit_once('.').map(|(_, e)| e.to_ascii_lowercase()).unwrap_or_default();
    let allowed: &[&str] = match route {
        "video" => &["npy"],
        "image" => &["tif", "tiff", "png"],
        "file" => &["json", "csv", "png", "md", "toml"],
        _ => return Some(not_found()),
    };
    if !valid_rel(rel) || !allowed.contains(&ext.as_str()) {
        return Some(not_found());
    }
    Some(match route {
        "file" => plain(dir, rel, &ext),
        _ => decoded(dir, rel, route == "video"),
    })
}

fn not_found() -> ViewAnswer {
    ViewAnswer::text(
        404,
        "not found: the viewer answers /api/folder.json, /api/video/PATH.npy, /api/image/PATH.(tif|tiff|png) and /api/file/PATH.(json|csv|png|md|toml) for plain paths inside the folder\n",
    )
}

fn open_capped(dir: &Path, rel: &str, cap: u64) -> Result<Vec<u8>, ViewAnswer> {
    let shown = dir.join(rel);
    let shown = shown.display();
    match open_inside(dir, rel) {
        Ok((_, meta)) if meta.len() > cap => {
            Err(ViewAnswer::text(413, format!("{shown}: {} bytes, over the viewer's cap of {cap} bytes; not read\n", meta.len())))
        }
        Ok((file, _)) => read_capped(file, cap).map_err(|e| ViewAnswer::text(500, format!("{shown}: cannot read: {e}\n"))),
        Err(e @ OpenError::NotFound) => Err(ViewAnswer::text(404, format!("{shown}: {e}\n"))),
        Err(e) => Err(ViewAnswer::text(e.status(), format!("{shown}: refused: {e}\n"))),
    }
}

fn plain(dir: &Path, rel: &str, ext: &str) -> ViewAnswer {
    match open_capped(dir, rel, MAX_PLAIN_BYTES) {
        Ok(body) => {
            let content_type = match ext {
                "png" => "image/png",
                "json" => "application/json; charset=utf-8",
                _ => "text/plain; charset=utf-8",
            };
            ViewAnswer { status: 200, content_type, body }
        }
        Err(a) => a,
    }
}

fn decoded(dir: &Path, rel: &str, video: bool) -> ViewAnswer {
    let Ok(_one) = DECODER.try_lock() else {
        return ViewAnswer::text(503, "the viewer is decoding another video; try again\n");
    };
    let bytes = match open_capped(dir, rel, MAX_VIDEO_BYTES) {
        Ok(b) => b,
        Err(a) => return a,
    };
    let name = dir.join(rel);
    let budget = ByteBudget::system();
    let data =
        if video { decode_stack_bytes(&name, &bytes, &budget) } else { decode_image_bytes(&name, &bytes, &budget).map(|i| i.insert_axis(ndarray::Axis(0))) };
    match data {
        Ok(v) => ViewAnswer { status: 200, content_type: "application/octet-stream", body: encode_levels_u16(v.view()) },
        Err(e) => ViewAnswer::text(422, format!("{e}\n")),
    }
}

/// The folder's kind, from the names at its top.
fn kind(top: &[(String, EntryKind)]) -> &'static str {
    let has = |n: &str| top.iter().any(|(name, k)| name == n && *k == EntryKind::File);
    let has_dir = |n: &str| top.iter().any(|(name, k)| name == n && *k == EntryKind::Folder);
    // A session's folder holds rec/ and preview/ from its start, before session.json.
    if has("session.json") || (has_dir("rec") && has_dir("preview")) {
        "session"
    } else if has("report.json") && has("figure.png") {
        "led-sweep"
    } else if has("traces.csv") {
        "compare"
    } else if has("coverage.csv") {
        "sequence"
    } else if has("video.npy") {
        "reconstruction"
    } else {
        "folder"
    }
}

/// `/api/folder.json`.
fn folder_json(dir: &Path) -> ViewAnswer {
    let json = |status: u16, v: serde_json::Value| ViewAnswer { status, content_type: "application/json; charset=utf-8", body: v.to_string().into_bytes() };
    match listing(dir) {
        Ok(v) => json(200, v),
        Err(e) => json(e.status(), serde_json::json!({"message": format!("{}: {e}", dir.display())})),
    }
}

/// What `/api/folder.json` says of `dir`: `kind`, `name`, `videos` (each with `name`,
/// `folder`, `video` and the `files` beside it), `figures` and `documents` at the top,
/// and `truncated` when the listing stopped at its limits.
pub fn listing(dir: &Path) -> Result<serde_json::Value, OpenError> {
    let (top, _) = list_inside(dir, "", MAX_LISTED_ENTRIES)?;
    let kind = kind(&top);
    let ends = |n: &str, exts: &[&str]| exts.iter().any(|e| n.ends_with(e));
    let figures: Vec<&str> = top.iter().filter(|(n, k)| *k == EntryKind::File && ends(n, &[".png"]) && valid_rel(n)).map(|(n, _)| n.as_str()).collect();
    let documents: Vec<&str> =
        top.iter().filter(|(n, k)| *k == EntryKind::File && ends(n, &[".json", ".md", ".csv", ".toml"]) && valid_rel(n)).map(|(n, _)| n.as_str()).collect();
    // Videos: breadth first, a session's rec/ and raw/ left to its session.json.
    let mut videos = Vec::new();
    let mut budget = MAX_LISTED_ENTRIES;
    let mut truncated = false;
    let mut queue: std::collections::VecDeque<(String, usize)> = std::collections::VecDeque::from([(String::new(), 0)]);
    while let Some((rel, depth)) = queue.pop_front() {
        let entries = if rel.is_empty() {
            top.clone()
        } else {
            match list_inside(dir, &rel, budget) {
                Ok((e, cut)) => {
                    truncated |= cut;
                    e
                }
                Err(_) => continue,
            }
        };
        budget = budget.saturating_sub(entries.len());
        let files: Vec<&str> = entries.iter().filter(|(_, k)| *k == EntryKind::File).map(|(n, _)| n.as_str()).collect();
        for npy in ["video.npy", "truth.npy"] {
            if files.contains(&npy) {
                let path = if rel.is_empty() { npy.to_string() } else { format!("{rel}/{npy}") };
                let name = match (rel.as_str(), npy) {
                    ("", "video.npy") => ".".to_string(),
                    (r, "video.npy") => r.to_string(),
                    ("", _) => "truth".to_string(),
                    (r, _) => format!("{r} (truth)"),
                };
                videos.push(serde_json::json!({"name": name, "folder": rel, "video": path, "files": files}));
            }
        }
        // A compare's runs: videos/LABEL.npy, each named by its label.
        if rel.rsplit('/').next() == Some(crate::analysis::compare::VIDEOS_DIR) {
            let parent = rel.rsplit_once('/').map(|(p, _)| format!("{p}/")).unwrap_or_default();
            for f in files.iter().filter(|f| f.ends_with(".npy")) {
                let label = &f[..f.len() - 4];
                videos.push(serde_json::json!({"name": format!("{parent}{label}"), "folder": rel, "video": format!("{rel}/{f}"), "files": files}));
            }
        }
        if depth >= MAX_DEPTH || (kind == "session" && rel.is_empty()) {
            continue;
        }
        for (name, k) in &entries {
            if *k == EntryKind::Folder && budget > 0 {
                let child = if rel.is_empty() { name.clone() } else { format!("{rel}/{name}") };
                if valid_rel(&child) {
                    queue.push_back((child, depth + 1));
                }
            }
        }
        if budget == 0 && !queue.is_empty() {
            truncated = true;
            break;
        }
    }
    let name = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| dir.display().to_string());
    Ok(serde_json::json!({"kind": kind, "name": name, "videos": videos, "figures": figures, "documents": documents, "truncated": truncated}))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn npy(path: &Path, frames: usize) {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        let v = ndarray::Array4::from_shape_fn((frames, 2, 3, 1), |(f, r, c, _)| (f * 100 + r * 10 + c) as f32);
        crate::io::write_npy(path, v.view()).unwrap();
    }

    #[test]
    fn routes_refuse_everything_but_plain_paths_of_known_kinds() {
        let dir = tempfile::tempdir().unwrap();
        npy(&dir.path().join("rec/video.npy"), 4);
        std::fs::write(dir.path().join("rec/summary.json"), b"{}").unwrap();
        std::fs::write(dir.path().join("secret.txt"), b"no").unwrap();
        let status = |p: &str| answer(dir.path(), p).map(|a| a.status);
        assert_eq!(status("/session.json"), None, "not an /api/ path");
        assert_eq!(status("/api/file/rec/summary.json"), Some(200));
        let v = answer(dir.path(), "/api/video/rec/video.npy").unwrap();
        assert_eq!((v.status, &v.body[..4]), (200, &b"RCQ1"[..]));
        // One decode at a time: while another holds the decoder, 503.
        {
            let _busy = DECODER.lock().unwrap();
            assert_eq!(status("/api/video/rec/video.npy"), Some(503));
        }
        // Over the cap: refused unread (a sparse file, nothing on disk).
        std::fs::File::create(dir.path().join("rec/big.npy")).unwrap().set_len(MAX_VIDEO_BYTES + 1).unwrap();
        let big = answer(dir.path(), "/api/video/rec/big.npy").unwrap();
        assert_eq!(big.status, 413);
        assert!(String::from_utf8_lossy(&big.body).contains(&MAX_VIDEO_BYTES.to_string()));
        // Not a video: named, not a panic.
        std::fs::write(dir.path().join("rec/bad.npy"), b"\x93NUMPY garbage").unwrap();
        assert_eq!(status("/api/video/rec/bad.npy"), Some(422));
        for bad in [
            "/api/file/secret.txt",
            "/api/file/../secret.txt",
            "/api/file/rec/../rec/summary.json",
            "/api/file/rec//summary.json",
            "/api/file/.hidden.json",
            "/api/file/rec%2fsummary.json",
            "/api/video/rec/summary.json",
            "/api/image/rec/video.npy",
            "/api/file/",
            "/api/other/rec/summary.json",
            "/api/file/missing.json",
        ] {
            assert_eq!(status(bad), Some(404), "{bad}");
        }
    }

    #[test]
    fn the_listing_finds_videos_and_the_kind() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("report.json"), b"{}").unwrap();
        std::fs::write(dir.path().join("figure.png"), b"png").unwrap();
        npy(&dir.path().join("period-660us/rec/video.npy"), 2);
        npy(&dir.path().join("period-1320us/rec/video.npy"), 2);
        npy(&dir.path().join("a/b/c/d/video.npy"), 2);
        let a = answer(dir.path(), "/api/folder.json").unwrap();
        let v: serde_json::Value = serde_json::from_slice(&a.body).unwrap();
        assert_eq!(v["kind"], "led-sweep");
        let names: Vec<&str> = v["videos"].as_array().unwrap().iter().map(|x| x["video"].as_str().unwrap()).collect();
        assert_eq!(names, ["period-1320us/rec/video.npy", "period-660us/rec/video.npy"], "depth 4 is beyond the listing");
        assert_eq!(v["figures"], serde_json::json!(["figure.png"]));
    }
}
