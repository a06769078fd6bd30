//! The advisory lock of a session folder: `session.lock` holds the owner's pid and its
//! start time (the kernel's, field 22 of `/proc/PID/stat`, so a recycled pid is not
//! taken for the owner). `rollcam run` and `--resume` take it before touching the
//! session; a second one is refused while the owner lives, and a lock left by a process
//! that died is taken over. The lock is removed when its guard is dropped.

use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

/// The lock file's name in a session folder.
pub const LOCK_FILE: &str = "session.lock";

/// A held session lock; dropping it removes the file.
#[derive(Debug)]
pub struct SessionLock {
    path: PathBuf,
}

/// The start time of process `pid` in clock ticks since boot, if it lives.
fn start_time(pid: u32) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name (field 2) may hold spaces and parentheses: fields after its ')'.
    let rest = &stat[stat.rfind(')')? + 1..];
    rest.split_whitespace().nth(19)?.parse().ok()
}

impl SessionLock {
    /// Take the lock of the session folder `dir`, or say who holds it.
    pub fn acquire(dir: &Path) -> Result<SessionLock> {
        let path = dir.join(LOCK_FILE);
        let me = std::process::id();
        let text = format!("{me} {}\n", start_time(me).unwrap_or(0));
        for _ in 0..2 {
            match std::fs::OpenOptions::new().write(true).create_new(true).open(&path) {
                Ok(mut f) => {
                    use std::io::Write;
                    f.write_all(text.as_bytes()).with_context(|| format!("{}: cannot write the session lock", path.display()))?;
                    return Ok(SessionLock { path });
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                    let held = crate::io::input::read_text(&path).unwrap_or_default();
                    let mut parts = held.split_whitespace().map(|v| v.parse::<u64>().ok());
                    if let (Some(Some(pid)), Some(Some(start))) = (parts.next(), parts.next()) {
                        if let Ok(pid) = u32::try_from(pid) {
                            if start_time(pid).is_some_and(|s| s == start || start == 0) {
                                bail!(
                                    "{}: the session is in use by process {pid} (its {LOCK_FILE}); wait for it to end, or stop it, before running or resuming this session",
                                    dir.display()
                                );
                            }
                        }
                    }
                    // Left by a process that has ended (or unreadable): taken over.
                    tracing::warn!(path = %path.display(), held = %held.trim(), "a stale session lock is taken over");
                    std::fs::remove_file(&path).with_context(|| format!("{}: cannot remove the stale session lock", path.display()))?;
                }
                Err(e) => return Err(e).with_context(|| format!("{}: cannot create the session lock", path.display())),
            }
        }
        bail!("{}: another process took the session lock while a stale one was replaced", path.display())
    }
}

impl Drop for SessionLock {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_live_owner_refuses_a_second_and_a_dead_one_is_taken_over() {
        let dir = tempfile::tempdir().unwrap();
        let lock = SessionLock::acquire(dir.path()).unwrap();
        let e = SessionLock::acquire(dir.path()).unwrap_err().to_string();
        assert!(e.contains("in use by process") && e.contains(&std::process::id().to_string()), "{e}");
        drop(lock);
        assert!(!dir.path().join(LOCK_FILE).exists());
        // A pid that lives with another start time (a recycled pid), or none at all.
        std::fs::write(dir.path().join(LOCK_FILE), format!("{} 1\n", std::process::id())).unwrap();
        let lock = SessionLock::acquire(dir.path()).unwrap();
        drop(lock);
        std::fs::write(dir.path().join(LOCK_FILE), "4294967294 5\n").unwrap();
        assert!(SessionLock::acquire(dir.path()).is_ok());
    }
}
