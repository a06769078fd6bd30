//! Atomic writes: a reader never sees a half-written file.

use super::error::IoError;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// Write `text` to `path` atomically (see [`write_atomic`]).
pub fn write_text_atomic(path: &Path, text: &str) -> Result<(), IoError> {
    write_atomic(path, |w| {
        use std::io::Write;
        w.write_all(text.as_bytes()).map_err(|source| IoError::Os { path: path.to_path_buf(), action: "write", source })
    })
}

/// Writes a file atomically: `fill` writes into a buffered temporary file created in the
/// destination's directory; on success the file is flushed, fsynced and renamed onto `path`
/// (and the directory fsynced where the platform allows). On any error the temporary file
/// is removed and `path` is left as it was.
pub fn write_atomic<F>(path: &Path, fill: F) -> Result<(), IoError>
where
    F: FnOnce(&mut BufWriter<File>) -> Result<(), IoError>,
{
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path.file_name().ok_or_else(|| IoError::bad_input(path, "the path names no file"))?;
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(name);
    static COUNTER: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    tmp_name.push(format!(".{}-{n}.tmp", std::process::id()));
    let tmp = dir.join(tmp_name);

    let result = (|| {
        let file = File::create(&tmp).map_err(|e| IoError::os(path, "cannot create temporary file", e))?;
        let mut w = BufWriter::new(file);
        fill(&mut w)?;
        w.flush().map_err(|e| IoError::os(path, "cannot write", e))?;
        let file = w.into_inner().map_err(|e| IoError::os(path, "cannot write", e.into_error()))?;
        file.sync_all().map_err(|e| IoError::os(path, "cannot sync", e))?;
        drop(file);
        std::fs::rename(&tmp, path).map_err(|e| IoError::os(path, "cannot rename temporary file", e))?;
        #[cfg(unix)]
        if let Ok(d) = File::open(&dir) {
            let _ = d.sync_all();
        }
        Ok(())
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}
