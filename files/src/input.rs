//! The one way an input file is read (here, below both crates, so the capture-folder
//! reader uses it too; `rollcam::io::input` re-exports it): it must be a regular file (a
//! FIFO, a device such as `/dev/zero`, a socket or a folder is refused before it is
//! opened, so nothing blocks), and it is read with a bounded size (a file past the bound
//! is refused, not read into memory).

use std::io::Read;
use std::path::Path;

/// The most bytes of a text input (capture.toml, a JSON record or cache entry).
pub const MAX_TEXT_BYTES: u64 = 64 << 20;

/// What kind of file system object `meta` is, in words, for a refusal.
fn kind(meta: &std::fs::Metadata) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    let t = meta.file_type();
    if t.is_dir() {
        "a folder"
    } else if t.is_fifo() {
        "a FIFO (named pipe)"
    } else if t.is_char_device() || t.is_block_device() {
        "a device"
    } else if t.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    }
}

fn refused(message: String) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidInput, message)
}

/// The bytes of the regular file at `path` (a link to one is followed), at most
/// `max_bytes` of them; anything else is an error that says what the path is.
pub fn read_bounded(path: &Path, max_bytes: u64) -> std::io::Result<Vec<u8>> {
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        return Err(refused(format!("{}: expected a regular file", kind(&meta))));
    }
    let file = std::fs::File::open(path)?;
    // The object opened is the one checked (not one put there since).
    let meta = file.metadata()?;
    if !meta.is_file() {
        return Err(refused(format!("{}: expected a regular file", kind(&meta))));
    }
    if meta.len() > max_bytes {
        return Err(refused(format!("{} bytes, more than the {max_bytes} an input of this kind may have", meta.len())));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(max_bytes + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max_bytes {
        return Err(refused(format!("grew past the {max_bytes} bytes an input of this kind may have while it was read")));
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn devices_fifos_and_folders_are_refused_without_blocking_and_sizes_are_bounded() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("fifo");
        assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
        let e = read_bounded(&fifo, 100).unwrap_err().to_string();
        assert!(e.contains("FIFO") && e.contains("regular file"), "{e}");
        let e = read_bounded(Path::new("/dev/zero"), 100).unwrap_err().to_string();
        assert!(e.contains("a device"), "{e}");
        assert!(read_bounded(dir.path(), 100).unwrap_err().to_string().contains("a folder"));
        let f = dir.path().join("f");
        std::fs::write(&f, [7u8; 101]).unwrap();
        assert!(read_bounded(&f, 100).unwrap_err().to_string().contains("101 bytes"));
        assert_eq!(read_bounded(&f, 101).unwrap(), vec![7u8; 101]);
    }
}
