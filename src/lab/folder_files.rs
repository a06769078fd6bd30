//! Reading files of one served folder (a session or a result folder) without ever leaving
//! it: every path is opened component by component with `openat(O_NOFOLLOW)` from the
//! descriptor of its parent and checked with `fstat` on what was opened, folders are
//! listed from their open descriptor, and every read is capped. Shared by the live page
//! ([`super::live`]) and the result viewer ([`super::viewer`]).

use std::fs::File;
use std::io::Read;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::os::unix::ffi::OsStrExt;
use std::path::Path;

#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    #[error("does not exist")]
    NotFound,
    #[error("{component} is a symbolic link; the page serves only regular files inside the folder it was started on")]
    Link { component: String },
    #[error("{component} is not a folder")]
    NotAFolder { component: String },
    #[error("{component} is not a regular file")]
    NotRegular { component: String },
    /// A file with several names may be one outside the folder, linked in.
    #[error("{component} has {links} hard links; the page serves only files whose one name is inside the folder")]
    HardLinked { component: String, links: u64 },
    #[error("{0}")]
    Io(std::io::Error),
}

impl OpenError {
    /// The HTTP status that goes with the error: 404, 403 (a link, a FIFO, a folder
    /// where a file was expected) or 500.
    pub fn status(&self) -> u16 {
        match self {
            OpenError::NotFound => 404,
            OpenError::Link { .. } | OpenError::NotRegular { .. } | OpenError::NotAFolder { .. } | OpenError::HardLinked { .. } => 403,
            OpenError::Io(_) => 500,
        }
    }
}

/// At most `cap` bytes of `file`; one more means it grew past the cap.
pub fn read_capped(file: File, cap: u64) -> std::io::Result<Vec<u8>> {
    let mut bytes = Vec::new();
    file.take(cap + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > cap {
        return Err(std::io::Error::other(format!("grew past the cap of {cap} bytes while being read")));
    }
    Ok(bytes)
}

/// Whether `rel` is a path the routes may open: 1 to 8 slash-separated names of ASCII
/// letters, digits, `_`, `-` and `.`, none empty or starting with a dot (so no `.`, `..`
/// or hidden file), 512 bytes at most. Percent escapes are not decoded: `%` is refused.
pub fn valid_rel(rel: &str) -> bool {
    let names: Vec<&str> = rel.split('/').collect();
    rel.len() <= 512
        && names.len() <= 8
        && names.iter().all(|n| !n.is_empty() && !n.starts_with('.') && n.bytes().all(|b| b.is_ascii_alphanumeric() || matches!(b, b'_' | b'-' | b'.')))
}

fn cstring(s: &[u8]) -> Result<std::ffi::CString, OpenError> {
    std::ffi::CString::new(s).map_err(|_| OpenError::Io(std::io::Error::other("a NUL byte in the path")))
}

fn errno_of(fd: libc::c_int) -> Option<std::io::Error> {
    if fd < 0 {
        Some(std::io::Error::last_os_error())
    } else {
        None
    }
}

/// Open `rel` (slash-separated, checked by the caller) below `dir` without following any
/// symbolic link below `dir`: each component is opened with `openat(O_NOFOLLOW)` from the
/// descriptor of its parent and checked with `fstat` on what was opened (folders, then a
/// regular file, or a folder when `want_dir`), so nothing can be swapped in between a
/// check and the read. `O_NONBLOCK` keeps a FIFO from blocking the open. An empty `rel`
/// with `want_dir` is `dir` itself (the operator's argument, which may be a link).
fn open_below(dir: &Path, rel: &str, want_dir: bool) -> Result<(File, std::fs::Metadata), OpenError> {
    let root = cstring(dir.as_os_str().as_bytes())?;
    // SAFETY: a valid NUL-terminated path; the result is checked before use.
    let fd = unsafe { libc::open(root.as_ptr(), libc::O_RDONLY | libc::O_DIRECTORY | libc::O_CLOEXEC) };
    if let Some(e) = errno_of(fd) {
        return Err(if e.kind() == std::io::ErrorKind::NotFound { OpenError::NotFound } else { OpenError::Io(e) });
    }
    // SAFETY: fd was just returned by open and is owned by nobody else.
    let mut current = unsafe { OwnedFd::from_raw_fd(fd) };
    if rel.is_empty() {
        let file = File::from(current);
        let meta = file.metadata().map_err(OpenError::Io)?;
        return if want_dir { Ok((file, meta)) } else { Err(OpenError::NotRegular { component: String::new() }) };
    }
    let names: Vec<&str> = rel.split('/').collect();
    for (i, name) in names.iter().enumerate() {
        let component = names[..=i].join("/");
        let last = i + 1 == names.len();
        let cname = cstring(name.as_bytes())?;
        let flags = libc::O_RDONLY | libc::O_CLOEXEC | libc::O_NOFOLLOW | libc::O_NONBLOCK | libc::O_NOCTTY;
        // SAFETY: current is an open descriptor, cname a valid NUL-terminated name.
        let fd = unsafe { libc::openat(current.as_raw_fd(), cname.as_ptr(), flags) };
        if let Some(e) = errno_of(fd) {
            return Err(match e.raw_os_error() {
                Some(libc::ENOENT) | Some(libc::ENOTDIR) => OpenError::NotFound,
                Some(libc::ELOOP) => OpenError::Link { component },
                _ => OpenError::Io(e),
            });
        }
        // SAFETY: as above.
        current = unsafe { OwnedFd::from_raw_fd(fd) };
        let file = File::from(current);
        let meta = file.metadata().map_err(OpenError::Io)?;
        if last {
            if want_dir && !meta.is_dir() {
                return Err(OpenError::NotAFolder { component });
            }
            if !want_dir && !meta.is_file() {
                return Err(OpenError::NotRegular { component });
            }
            return Ok((file, meta));
        }
        if !meta.is_dir() {
            return Err(OpenError::NotAFolder { component });
        }
        current = OwnedFd::from(file);
    }
    Err(OpenError::NotFound)
}

/// The regular file `rel` below `dir` (see [`open_below`]), with its metadata from `fstat`.
pub fn open_inside(dir: &Path, rel: &str) -> Result<(File, std::fs::Metadata), OpenError> {
    use std::os::unix::fs::MetadataExt;
    let (file, meta) = open_below(dir, rel, false)?;
    if meta.nlink() > 1 {
        return Err(OpenError::HardLinked { component: rel.to_string(), links: meta.nlink() });
    }
    Ok((file, meta))
}

/// What a folder entry is, from `fstatat(AT_SYMLINK_NOFOLLOW)`: a link is a link.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EntryKind {
    File,
    Folder,
    Other,
}

/// The entries of the folder `rel` below `dir` (empty: `dir` itself), opened as
/// [`open_inside`] opens files, listed from its descriptor: at most `max_entries` (then
/// the flag is true), hidden names left out, sorted by name.
pub fn list_inside(dir: &Path, rel: &str, max_entries: usize) -> Result<(Vec<(String, EntryKind)>, bool), OpenError> {
    let (folder, _) = open_below(dir, rel, true)?;
    let fd = OwnedFd::from(folder);
    // SAFETY: fd is an open folder descriptor that fdopendir takes over (closedir closes it).
    let stream = unsafe { libc::fdopendir(fd.as_raw_fd()) };
    if stream.is_null() {
        return Err(OpenError::Io(std::io::Error::last_os_error()));
    }
    let raw = fd.as_raw_fd();
    std::mem::forget(fd);
    let mut out = Vec::new();
    let mut truncated = false;
    loop {
        // SAFETY: stream is a valid DIR*; readdir returns null at the end or on error.
        let entry = unsafe { libc::readdir(stream) };
        if entry.is_null() {
            break;
        }
        // SAFETY: d_name is a NUL-terminated array inside the entry readdir returned.
        let name = unsafe { std::ffi::CStr::from_ptr((*entry).d_name.as_ptr()) };
        let bytes = name.to_bytes();
        if bytes.first() == Some(&b'.') {
            continue;
        }
        let Ok(text) = std::str::from_utf8(bytes) else { continue };
        if out.len() >= max_entries {
            truncated = true;
            break;
        }
        // SAFETY: a zeroed stat is a valid out-parameter.
        let mut st: libc::stat = unsafe { std::mem::zeroed() };
        // SAFETY: raw is the stream's descriptor, name a valid C string, st a valid stat.
        let rc = unsafe { libc::fstatat(raw, name.as_ptr(), &mut st, libc::AT_SYMLINK_NOFOLLOW) };
        let kind = if rc != 0 {
            EntryKind::Other
        } else {
            match st.st_mode & libc::S_IFMT {
                libc::S_IFREG => EntryKind::File,
                libc::S_IFDIR => EntryKind::Folder,
                _ => EntryKind::Other,
            }
        };
        out.push((text.to_string(), kind));
    }
    // SAFETY: stream came from fdopendir and is closed once.
    unsafe { libc::closedir(stream) };
    out.sort_by(|a, b| a.0.cmp(&b.0));
    Ok((out, truncated))
}
