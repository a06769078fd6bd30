//! The live page's request handling (`rollcam::lab::live::respond`): any bytes a client
//! sends get a well-formed HTTP answer, and nothing outside the session folder is ever
//! served (the folder's preview is a symbolic link to a file outside it).
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::PathBuf;
use std::sync::OnceLock;

const SECRET: &[u8] = b"SECRET-OUTSIDE-THE-SESSION-FOLDER";

/// A session folder with session.json, a preview that links outside, and a file there.
fn session_dir() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let root = std::env::temp_dir().join(format!("rollcam-fuzz-live-{}", std::process::id()));
        let dir = root.join("session");
        std::fs::create_dir_all(dir.join("preview")).unwrap();
        std::fs::write(root.join("secret.txt"), SECRET).unwrap();
        std::fs::write(dir.join("session.json"), br#"{"state": "running", "frames": []}"#).unwrap();
        let link = dir.join("preview/latest_raw.png");
        if !link.exists() {
            std::os::unix::fs::symlink(root.join("secret.txt"), &link).unwrap();
        }
        std::fs::write(dir.join("preview/latest_frame.png"), b"\x89PNG\r\n\x1a\n").unwrap();
        dir
    })
}

fuzz_target!(|data: &[u8]| {
    let answer = rollcam::lab::live::respond(session_dir(), data);
    assert!(answer.starts_with(b"HTTP/1.1 "), "not an HTTP answer: {:?}", String::from_utf8_lossy(&answer[..answer.len().min(64)]));
    assert!(!answer.windows(SECRET.len()).any(|w| w == SECRET), "a file outside the session folder was served");
});
