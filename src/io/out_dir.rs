//! The one rule for outputs: a command never replaces a file it did not create in this
//! run. An existing output folder is refused unless it is empty or `--force` is given;
//! with `--force` the command writes its own files into it (replacing same-named files
//! of an earlier run) and leaves every other file alone, and an input of the command is
//! never replaced, inside the folder or not. All of it is checked by [`claim`], before
//! any work (a missing folder must be creatable: its nearest existing ancestor a
//! writable folder), so a typo in `--out` costs nothing.
//!
//! Beside the check before the work, [`claim`] registers the inputs with the atomic
//! writer ([`super::write_atomic`]), which refuses to replace any of them: a file name
//! that no list foresaw still cannot overwrite an input.

use std::path::{Path, PathBuf};

/// An output folder a command may write into (see [`claim`]).
#[derive(Clone, Debug)]
pub struct OutputFolder {
    pub path: PathBuf,
    /// It existed and held files (allowed by `--force`).
    pub reused: bool,
}

#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error("{}: exists and is not a folder (expected a new or empty output folder)", path.display())]
    NotAFolder { path: PathBuf },
    #[error(
        "{}: the output folder is not empty (it holds {listing}); choose a new folder, or give --force to write into it (this command's files are replaced, every other file is left alone)",
        path.display()
    )]
    NotEmpty { path: PathBuf, listing: String },
    #[error("{}: is {role} of this command and would be replaced by its output; an input is never overwritten: choose another output folder", path.display())]
    WouldReplaceInput { path: PathBuf, role: String },
    #[error("{}: cannot {action}: {error}", path.display())]
    Os { path: PathBuf, action: &'static str, error: std::io::Error },
}

/// An input of a command: what it is (for messages: "the raw image (--raw)") and where.
pub type Input<'a> = (&'a str, &'a Path);

/// Checks and creates the output folder `out` before any work (see the module doc).
///
/// `writes` names the files (relative to `out`) the command may write, as far as they
/// are known; `inputs` are the files it reads. Refused: `out` exists and is not a
/// folder; `out` holds anything and `force` is false; one of `writes` is one of
/// `inputs` (same file, by device and inode). The inputs are also registered with the
/// atomic writer for the rest of the process.
pub fn claim(out: &Path, force: bool, writes: &[&str], inputs: &[Input]) -> Result<OutputFolder, OutputError> {
    let os = |action, error| OutputError::Os { path: out.to_path_buf(), action, error };
    super::atomic::protect(inputs.iter().map(|(_, p)| *p));
    let reused = match std::fs::symlink_metadata(out) {
        // Missing, or not reachable (a file on the path): creating it says why.
        Err(_) => false,
        Ok(m) => {
            let is_dir = m.is_dir() || (m.file_type().is_symlink() && out.is_dir());
            if !is_dir {
                return Err(OutputError::NotAFolder { path: out.to_path_buf() });
            }
            let mut names: Vec<String> = std::fs::read_dir(out)
                .map_err(|e| os("list the folder", e))?
                .filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect();
            if names.is_empty() {
                false
            } else if !force {
                names.sort();
                let n = names.len();
                let mut listing = names.into_iter().take(4).collect::<Vec<_>>().join(", ");
                if n > 4 {
                    listing.push_str(&format!(" and {} more", n - 4));
                }
                return Err(OutputError::NotEmpty { path: out.to_path_buf(), listing });
            } else {
                true
            }
        }
    };
    for name in writes {
        let target = out.join(name);
        if let Some((role, _)) = inputs.iter().find(|(_, p)| same_file(&target, p)) {
            return Err(OutputError::WouldReplaceInput { path: target, role: role.to_string() });
        }
    }
    if !out.exists() {
        check_creatable(out)?;
    }
    Ok(OutputFolder { path: out.to_path_buf(), reused })
}

/// Whether `out` (missing) can be created: its nearest existing ancestor must be a
/// writable folder. Nothing is created here (the writers create the folder with their
/// first file, so a command that fails before it leaves nothing behind).
fn check_creatable(out: &Path) -> Result<(), OutputError> {
    let fail = |why: String| OutputError::Os { path: out.to_path_buf(), action: "create the folder", error: std::io::Error::other(why) };
    for a in out.ancestors().skip(1) {
        let a = if a.as_os_str().is_empty() { Path::new(".") } else { a };
        match std::fs::metadata(a) {
            Ok(m) if m.is_dir() => {
                #[cfg(unix)]
                {
                    use std::os::unix::ffi::OsStrExt;
                    let c = std::ffi::CString::new(a.as_os_str().as_bytes()).map_err(|_| fail(format!("{} holds a NUL byte", a.display())))?;
                    // SAFETY: a valid NUL-terminated path; access only reads it.
                    if unsafe { libc::access(c.as_ptr(), libc::W_OK | libc::X_OK) } != 0 {
                        return Err(fail(format!("{} is not writable", a.display())));
                    }
                }
                return Ok(());
            }
            Ok(_) => return Err(fail(format!("{} is not a folder", a.display()))),
            // Missing, or below a file (ENOTDIR): look further up.
            Err(e) if e.kind() == std::io::ErrorKind::NotFound || e.raw_os_error() == Some(libc::ENOTDIR) => continue,
            Err(e) => return Err(fail(format!("{}: {e}", a.display()))),
        }
    }
    Ok(())
}

/// The first of `base`, `base-2`, `base-3`, ... that does not exist or is an empty
/// folder: for a default output folder, so that running a command twice writes a new
/// folder instead of refusing or replacing the first.
pub fn fresh_folder(base: &Path) -> PathBuf {
    let free = |p: &Path| match std::fs::read_dir(p) {
        Ok(mut it) => it.next().is_none(),
        Err(_) => !p.exists(),
    };
    if free(base) {
        return base.to_path_buf();
    }
    let name = base.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "out".into());
    (2..).map(|k| base.with_file_name(format!("{name}-{k}"))).find(|p| free(p)).expect("an unused folder name exists")
}

/// Whether `a` and `b` are the same existing file (device and inode; paths as a
/// fallback where the platform has no inodes).
pub(crate) fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::metadata(a), std::fs::metadata(b)) {
        (Ok(ma), Ok(mb)) => {
            #[cfg(unix)]
            {
                use std::os::unix::fs::MetadataExt;
                ma.dev() == mb.dev() && ma.ino() == mb.ino()
            }
            #[cfg(not(unix))]
            {
                let _ = (ma, mb);
                a.canonicalize().ok() == b.canonicalize().ok()
            }
        }
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn new_and_empty_folders_are_claimed_and_nothing_is_created() {
        let t = tempfile::tempdir().unwrap();
        let new = t.path().join("a/b");
        let f = claim(&new, false, &["video.npy"], &[]).unwrap();
        assert!(!new.exists() && !f.reused, "claiming creates nothing");
        std::fs::create_dir_all(&new).unwrap();
        assert!(!claim(&new, false, &[], &[]).unwrap().reused);
        let e = claim(&t.path().join("notes/x"), false, &[], &[]);
        assert!(e.is_ok());
        std::fs::write(t.path().join("file"), "").unwrap();
        let e = claim(&t.path().join("file/x/y"), false, &[], &[]).unwrap_err().to_string();
        assert!(e.contains("cannot create the folder") && e.contains("is not a folder"), "{e}");
    }

    #[test]
    fn a_folder_with_files_needs_force_and_a_file_is_no_folder() {
        let t = tempfile::tempdir().unwrap();
        std::fs::write(t.path().join("notes.txt"), "mine").unwrap();
        let e = claim(t.path(), false, &[], &[]).unwrap_err().to_string();
        assert!(e.contains("not empty") && e.contains("notes.txt") && e.contains("--force"), "{e}");
        assert!(claim(t.path(), true, &["video.npy"], &[]).unwrap().reused);
        let e = claim(&t.path().join("notes.txt"), true, &[], &[]).unwrap_err();
        assert!(matches!(e, OutputError::NotAFolder { .. }), "{e}");
    }

    #[test]
    fn force_never_replaces_an_input_even_through_another_path() {
        let t = tempfile::tempdir().unwrap();
        let raw = t.path().join("video.tiff");
        std::fs::write(&raw, b"raw bytes").unwrap();
        let other = t.path().join("sub/../video.tiff");
        std::fs::create_dir(t.path().join("sub")).unwrap();
        let e = claim(t.path(), true, &["video.tiff", "video.npy"], &[("the raw image (--raw)", &other)]).unwrap_err();
        assert!(matches!(e, OutputError::WouldReplaceInput { .. }), "{e}");
        assert!(e.to_string().contains("the raw image (--raw)"), "{e}");
        // The atomic writer refuses it too, whatever list the command had.
        let w = crate::io::atomic::write_text_atomic(&raw, "replaced").unwrap_err().to_string();
        assert!(w.contains("input"), "{w}");
        assert_eq!(std::fs::read(&raw).unwrap(), b"raw bytes");
    }

    #[test]
    fn fresh_folder_skips_used_names() {
        let t = tempfile::tempdir().unwrap();
        let base = t.path().join("rollcam-demo");
        assert_eq!(fresh_folder(&base), base);
        std::fs::create_dir_all(&base).unwrap();
        assert_eq!(fresh_folder(&base), base);
        std::fs::write(base.join("x"), "").unwrap();
        assert_eq!(fresh_folder(&base), t.path().join("rollcam-demo-2"));
    }
}
