//! Atomic writes: a reader never sees a half-written file.

use super::error::IoError;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// The inputs of this process's command, which no write may replace (registered by
/// [`super::out_dir::claim`]): device, inode and canonical path. The path guards
/// against an inode the file system reuses for a new file after an input is deleted
/// (a long-lived process, the test harness); the inode against the same file named
/// through another path.
static PROTECTED: Mutex<Vec<(u64, u64, PathBuf)>> = Mutex::new(Vec::new());

/// The (device, inode) and canonical path of an existing file.
fn file_id(path: &Path) -> Option<(u64, u64, PathBuf)> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        let m = std::fs::metadata(path).ok()?;
        Some((m.dev(), m.ino(), path.canonicalize().ok()?))
    }
    #[cfg(not(unix))]
    {
        let _ = path;
        None
    }
}

/// Registers files no atomic write of this process may replace.
pub(crate) fn protect<'a>(paths: impl IntoIterator<Item = &'a Path>) {
    let ids: Vec<_> = paths.into_iter().filter_map(file_id).collect();
    PROTECTED.lock().unwrap_or_else(|e| e.into_inner()).extend(ids);
}

fn is_protected(path: &Path) -> bool {
    let protected = PROTECTED.lock().unwrap_or_else(|e| e.into_inner());
    !protected.is_empty() && file_id(path).is_some_and(|id| protected.contains(&id))
}

/// Write `text` to `path` atomically (see [`write_atomic`]).
pub fn write_text_atomic(path: &Path, text: &str) -> Result<(), IoError> {
    write_atomic(path, |w| {
        use std::io::Write;
        w.write_all(text.as_bytes()).map_err(|source| IoError::Os { path: path.to_path_buf(), action: "write", source })
    })
}

/// Writes a file atomically: `fill` writes into a buffered temporary file created anew in
/// the destination's directory (`rollcam_files::temp::create_temp`: a planted link is
/// never followed); on success the file is flushed, fsynced and renamed onto `path`
/// (and the directory fsynced where the platform allows). On any error the temporary file
/// is removed and `path` is left as it was. A file registered as an input of this
/// command (see [`super::out_dir`]) is never replaced.
pub fn write_atomic<F>(path: &Path, fill: F) -> Result<(), IoError>
where
    F: FnOnce(&mut BufWriter<File>) -> Result<(), IoError>,
{
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path.file_name().ok_or_else(|| IoError::bad_input(path, "the path names no file"))?;
    if is_protected(path) {
        return Err(IoError::bad_input(path, "it is an input of this command, and an input is never overwritten; choose another output folder"));
    }
    let (tmp, file) = rollcam_files::temp::create_temp(&dir, name).map_err(|e| IoError::os(path, "cannot create temporary file", e))?;

    let result = (|| {
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
