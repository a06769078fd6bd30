//! Temporary files for atomic writes: a fresh name beside the destination, created only
//! if nothing holds it, so a link planted under any name cannot redirect the write.

use std::ffi::OsStr;
use std::fs::{File, OpenOptions};
use std::io;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Create a new temporary file in `dir` for a write of `name`: `.NAME.PID-T-N.tmp`
/// (process id, clock, counter), the first such name that nothing holds
/// ([`create_first_free`]).
pub fn create_temp(dir: &Path, name: &OsStr) -> io::Result<(PathBuf, File)> {
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    let clock = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.subsec_nanos());
    create_first_free((0..64).map(|_| {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let mut tmp_name = std::ffi::OsString::from(".");
        tmp_name.push(name);
        tmp_name.push(format!(".{}-{clock:08x}-{n}.tmp", std::process::id()));
        dir.join(tmp_name)
    }))
}

/// The first of `candidates` created anew (`O_CREAT | O_EXCL`: a link or a file under
/// the name is neither followed nor opened, and the next name is tried).
fn create_first_free(candidates: impl IntoIterator<Item = PathBuf>) -> io::Result<(PathBuf, File)> {
    let mut last = None;
    for tmp in candidates {
        match OpenOptions::new().write(true).create_new(true).open(&tmp) {
            Ok(f) => return Ok((tmp, f)),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => last = Some(e),
            Err(e) => return Err(e),
        }
    }
    Err(last.unwrap_or_else(|| io::Error::other("no free temporary name")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_planted_link_under_a_temporary_name_is_passed_over_not_followed() {
        let dir = tempfile::tempdir().unwrap();
        let outside = dir.path().join("outside.txt");
        std::fs::write(&outside, b"keep").unwrap();
        let planted = dir.path().join(".x.planted.tmp");
        std::os::unix::fs::symlink(&outside, &planted).unwrap();
        let free = dir.path().join(".x.free.tmp");
        let (tmp, mut f) = create_first_free([planted.clone(), free.clone()]).unwrap();
        assert_eq!(tmp, free);
        std::io::Write::write_all(&mut f, b"new").unwrap();
        assert_eq!(std::fs::read(&outside).unwrap(), b"keep");
        assert!(std::fs::symlink_metadata(&planted).unwrap().file_type().is_symlink(), "the planted link is not ours to remove");
        // Every name taken: an error, nothing written through.
        assert!(create_first_free([planted]).is_err());
        assert_eq!(std::fs::read(&outside).unwrap(), b"keep");
        // Two calls never share a name.
        let (a, _) = create_temp(dir.path(), OsStr::new("x")).unwrap();
        let (b, _) = create_temp(dir.path(), OsStr::new("x")).unwrap();
        assert_ne!(a, b);
    }
}
