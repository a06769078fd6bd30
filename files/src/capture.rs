//! The capture folder: crash-safe recording of camera frames, and the reader for
//! recorded captures (the hardware crate records through it as `rollcam_hw::record`; the
//! main crate reads consecutive captures with it).
//!
//! A capture folder holds:
//! * `capture.json`: the session ([`CaptureSession`]): camera, requested and applied
//!   settings, synchronisation info ([`SyncInfo`]), how the capture ended.
//! * `frame_NNNNNN.tiff`: 16-bit greyscale TIFF of frame `NNNNNN` (sequence number).
//!   Absent for dropped frames. Incomplete frames are zero-padded to full size.
//! * `frame_NNNNNN.json`: the frame's [`FrameMeta`] sidecar, written last, so a
//!   sidecar on disk means its TIFF is complete.
//!
//! Every file is written to a temporary name, fsynced, renamed into place, and the
//! folder is fsynced, before [`Recorder::write_frame`] returns: a frame handed to
//! the rest of the program is already safe on disk.

use std::fs::{self, File};
use std::io::{Cursor, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::frame::{host_now_ns, AppliedSettings, CameraInfo, CameraSettings, Frame, FrameMeta, FrameStatus, SensorGeometry};
use crate::input::{read_bounded, MAX_TEXT_BYTES};
use crate::tiff::{self, Samples};

/// Format tag written into `capture.json`.
pub const CAPTURE_FORMAT: &str = "rollcam-capture/1";
/// Session file name inside a capture folder.
pub const SESSION_FILE: &str = "capture.json";
/// The most bytes of a frame TIFF read back (a 16-bit frame of about 46000 x 46000).
pub const MAX_FRAME_BYTES: u64 = 4 << 30;

#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("{path}: {action}: {source}")]
    Io { path: PathBuf, action: &'static str, source: std::io::Error },
    #[error("{path}: invalid JSON ({expected}): {source}")]
    Json { path: PathBuf, expected: &'static str, source: serde_json::Error },
    #[error("{path}: TIFF {action} failed: {message}")]
    Tiff { path: PathBuf, action: &'static str, message: String },
    #[error("{path}: {message}")]
    Format { path: PathBuf, message: String },
    #[error("{path}: already holds a capture ({SESSION_FILE}); refusing to overwrite it")]
    Exists { path: PathBuf },
}

fn io_err(path: &Path, action: &'static str) -> impl FnOnce(std::io::Error) -> RecordError {
    let path = path.to_path_buf();
    move |source| RecordError::Io { path, action, source }
}

/// Which device triggers which, e.g. camera exposure-active → LED pulser input.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TriggerLink {
    /// Device and signal that drives, e.g. `camera:Line1 (ExposureActive)` or `led:trigger_out`.
    pub source: String,
    /// Device and input that is driven, e.g. `led:trigger_in` or `camera:Line0`.
    pub target: String,
    /// Free text: edge, delay, cable.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

/// Synchronisation between the camera and the LED pulser for one capture.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SyncInfo {
    /// LED pulse start relative to the start of the first row's exposure, in µs
    /// (positive: the pulse starts after the first row opens).
    pub led_phase_us: Option<f64>,
    /// Row-to-row delay used to map LED time onto sensor rows, in µs.
    pub line_time_us: Option<f64>,
    /// Trigger wiring, in signal order.
    #[serde(default)]
    pub trigger_chain: Vec<TriggerLink>,
    /// LED controller settings as reported by the LED driver (its own schema).
    pub led: Option<serde_json::Value>,
    pub notes: Option<String>,
}

/// How a capture ended.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaptureEnd {
    pub host_timestamp_ns: u64,
    /// `completed`, or `error`.
    pub outcome: String,
    pub error: Option<String>,
}

/// Content of `capture.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaptureSession {
    pub format: String,
    pub created_host_ns: u64,
    pub camera: CameraInfo,
    pub geometry: Option<SensorGeometry>,
    pub requested: CameraSettings,
    pub applied: Option<AppliedSettings>,
    #[serde(default)]
    pub sync: SyncInfo,
    pub frames_requested: Option<u64>,
    pub frames_recorded: u64,
    pub end: Option<CaptureEnd>,
}

impl CaptureSession {
    pub fn new(camera: CameraInfo) -> Self {
        CaptureSession {
            format: CAPTURE_FORMAT.to_string(),
            created_host_ns: host_now_ns(),
            camera,
            geometry: None,
            requested: CameraSettings::default(),
            applied: None,
            sync: SyncInfo::default(),
            frames_requested: None,
            frames_recorded: 0,
            end: None,
        }
    }
}

/// Write `bytes` to `dir/name` atomically: a fresh temporary file
/// ([`crate::temp::create_temp`]: no planted link redirects it), fsync, rename, fsync
/// folder. A failure (a full disk) names `dir/name`, the file asked for, and removes the
/// temporary file.
pub fn write_atomic(dir: &Path, name: &str, bytes: &[u8]) -> Result<PathBuf, RecordError> {
    let dest = dir.join(name);
    let (tmp, mut f) = crate::temp::create_temp(dir, name.as_ref()).map_err(io_err(&dest, "create (as a temporary file)"))?;
    let written = (|| {
        f.write_all(bytes).map_err(io_err(&dest, "write"))?;
        f.sync_all().map_err(io_err(&dest, "fsync"))?;
        fs::rename(&tmp, &dest).map_err(io_err(&dest, "rename into place"))
    })();
    if let Err(e) = written {
        let _ = fs::remove_file(&tmp);
        return Err(e);
    }
    sync_dir(dir)?;
    Ok(dest)
}

fn sync_dir(dir: &Path) -> Result<(), RecordError> {
    File::open(dir).and_then(|d| d.sync_all()).map_err(io_err(dir, "fsync folder"))
}

/// Encode 16-bit greyscale samples as a TIFF.
pub fn encode_tiff16(width: u32, height: u32, pixels: &[u16], path_for_errors: &Path) -> Result<Vec<u8>, RecordError> {
    let mut buf = Cursor::new(Vec::new());
    tiff::write_u16(&mut buf, width, height, 1, pixels).map_err(|e| RecordError::Tiff {
        path: path_for_errors.to_path_buf(),
        action: "encoding",
        message: e.to_string(),
    })?;
    Ok(buf.into_inner())
}

/// Decode a 16-bit greyscale TIFF into (width, height, samples).
pub fn decode_tiff16(path: &Path) -> Result<(u32, u32, Vec<u16>), RecordError> {
    let bytes = read_bounded(path, MAX_FRAME_BYTES).map_err(io_err(path, "read frame"))?;
    let (w, h, samples) =
        tiff::decode_first_page(&bytes).map_err(|e| RecordError::Tiff { path: path.to_path_buf(), action: "decoding", message: e.to_string() })?;
    match samples {
        Samples::U16(v) => Ok((w, h, v)),
        other => Err(RecordError::Format { path: path.to_path_buf(), message: format!("expected 16-bit greyscale samples, found {}", other.kind()) }),
    }
}

fn frame_stem(sequence: u64) -> String {
    format!("frame_{sequence:06}")
}

/// Writes frames of one capture to a folder.
#[derive(Debug)]
pub struct Recorder {
    dir: PathBuf,
    session: CaptureSession,
}

impl Recorder {
    /// Create (or reuse an empty) capture folder and write its `capture.json`.
    pub fn create(dir: impl AsRef<Path>, session: CaptureSession) -> Result<Self, RecordError> {
        let dir = dir.as_ref().to_path_buf();
        fs::create_dir_all(&dir).map_err(io_err(&dir, "create folder"))?;
        if dir.join(SESSION_FILE).exists() {
            return Err(RecordError::Exists { path: dir });
        }
        let rec = Recorder { dir, session };
        rec.write_session()?;
        Ok(rec)
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn session(&self) -> &CaptureSession {
        &self.session
    }

    fn write_session(&self) -> Result<(), RecordError> {
        let path = self.dir.join(SESSION_FILE);
        let bytes = serde_json::to_vec_pretty(&self.session).map_err(|source| RecordError::Json { path: path.clone(), expected: "capture session", source })?;
        write_atomic(&self.dir, SESSION_FILE, &bytes)?;
        Ok(())
    }

    /// Write one frame (TIFF then sidecar), durably. Returns the sidecar path.
    pub fn write_frame(&mut self, frame: &Frame) -> Result<PathBuf, RecordError> {
        let stem = frame_stem(frame.meta.sequence);
        let meta = &frame.meta;
        if meta.status != FrameStatus::Dropped {
            let n = meta.width as usize * meta.height as usize;
            let tiff_name = format!("{stem}.tiff");
            let path = self.dir.join(&tiff_name);
            if frame.pixels.len() > n || frame.pixels.len() as u64 != meta.valid_pixels {
                return Err(RecordError::Format {
                    path,
                    message: format!(
                        "frame {} has {} samples, metadata says {} valid of {}x{}",
                        meta.sequence,
                        frame.pixels.len(),
                        meta.valid_pixels,
                        meta.width,
                        meta.height
                    ),
                });
            }
            let bytes = if frame.pixels.len() == n {
                encode_tiff16(meta.width, meta.height, &frame.pixels, &path)?
            } else {
                let mut padded = frame.pixels.clone();
                padded.resize(n, 0);
                encode_tiff16(meta.width, meta.height, &padded, &path)?
            };
            write_atomic(&self.dir, &tiff_name, &bytes)?;
        }
        let json_name = format!("{stem}.json");
        let path = self.dir.join(&json_name);
        let bytes = serde_json::to_vec_pretty(meta).map_err(|source| RecordError::Json { path: path.clone(), expected: "frame metadata", source })?;
        let written = write_atomic(&self.dir, &json_name, &bytes)?;
        self.session.frames_recorded += 1;
        if self.session.applied.is_none() {
            self.session.applied = Some(meta.settings.clone());
        }
        Ok(written)
    }

    /// Record how the capture ended and rewrite `capture.json`.
    pub fn finish(mut self, error: Option<String>) -> Result<CaptureSession, RecordError> {
        self.session.end =
            Some(CaptureEnd { host_timestamp_ns: host_now_ns(), outcome: if error.is_some() { "error".into() } else { "completed".into() }, error });
        self.write_session()?;
        Ok(self.session)
    }
}

/// Reads a capture folder written by [`Recorder`].
#[derive(Debug, Clone)]
pub struct CaptureReader {
    dir: PathBuf,
    session: CaptureSession,
    frames: Vec<FrameMeta>,
    /// `frame_NNNNNN.tiff` files without their sidecar (an unfinished frame).
    orphans: Vec<PathBuf>,
}

impl CaptureReader {
    pub fn open(dir: impl AsRef<Path>) -> Result<Self, RecordError> {
        let dir = dir.as_ref().to_path_buf();
        let session_path = dir.join(SESSION_FILE);
        let text = read_bounded(&session_path, MAX_TEXT_BYTES).map_err(io_err(&session_path, "read capture session"))?;
        let session: CaptureSession =
            serde_json::from_slice(&text).map_err(|source| RecordError::Json { path: session_path.clone(), expected: "capture session", source })?;
        if session.format != CAPTURE_FORMAT {
            return Err(RecordError::Format { path: session_path, message: format!("format '{}', expected '{CAPTURE_FORMAT}'", session.format) });
        }
        let mut frames = Vec::new();
        let mut images = Vec::new();
        for entry in fs::read_dir(&dir).map_err(io_err(&dir, "list folder"))? {
            let entry = entry.map_err(io_err(&dir, "list folder"))?;
            let name = entry.file_name().to_string_lossy().into_owned();
            if name.ends_with(".tmp") {
                tracing::warn!(file = %entry.path().display(), "ignoring unfinished temporary file");
                continue;
            }
            if name.starts_with("frame_") && name.ends_with(".tiff") {
                images.push(entry.path());
            }
            if !(name.starts_with("frame_") && name.ends_with(".json")) {
                continue;
            }
            let path = entry.path();
            let bytes = read_bounded(&path, MAX_TEXT_BYTES).map_err(io_err(&path, "read frame metadata"))?;
            let meta: FrameMeta =
                serde_json::from_slice(&bytes).map_err(|source| RecordError::Json { path: path.clone(), expected: "frame metadata", source })?;
            frames.push(meta);
        }
        frames.sort_by_key(|m| m.sequence);
        let mut orphans: Vec<PathBuf> = images.into_iter().filter(|p| !p.with_extension("json").exists()).collect();
        orphans.sort();
        Ok(CaptureReader { dir, session, frames, orphans })
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn session(&self) -> &CaptureSession {
        &self.session
    }

    /// Number of frames (sidecars) on disk.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// Frame images without a sidecar: the recorder writes the sidecar last, so these
    /// frames were not finished; they are not in [`metas`](Self::metas).
    pub fn orphans(&self) -> &[PathBuf] {
        &self.orphans
    }

    /// Metadata of all frames, in sequence order.
    pub fn metas(&self) -> &[FrameMeta] {
        &self.frames
    }

    /// Read frame `index` (position in [`CaptureReader::metas`]).
    pub fn read_frame(&self, index: usize) -> Result<Frame, RecordError> {
        let meta = self.frames.get(index).cloned().ok_or_else(|| RecordError::Format {
            path: self.dir.clone(),
            message: format!("frame index {index} out of range, capture holds {} frames", self.frames.len()),
        })?;
        if meta.status == FrameStatus::Dropped {
            return Ok(Frame { meta, pixels: Vec::new() });
        }
        let path = self.dir.join(format!("{}.tiff", frame_stem(meta.sequence)));
        let (w, h, mut pixels) = decode_tiff16(&path)?;
        if (w, h) != (meta.width, meta.height) {
            return Err(RecordError::Format { path, message: format!("image is {w}x{h}, sidecar says {}x{}", meta.width, meta.height) });
        }
        if meta.valid_pixels as usize > pixels.len() {
            return Err(RecordError::Format { path, message: format!("sidecar says {} valid samples, image holds {}", meta.valid_pixels, pixels.len()) });
        }
        pixels.truncate(meta.valid_pixels as usize);
        Ok(Frame { meta, pixels })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_write_names_the_file_asked_for_and_a_planted_link_is_not_written_through() {
        let dir = tempfile::tempdir().unwrap();
        // A folder that is not there: the error names the file asked for.
        let missing = dir.path().join("missing");
        let e = write_atomic(&missing, SESSION_FILE, b"{}").unwrap_err().to_string();
        assert!(e.contains(&missing.join(SESSION_FILE).display().to_string()) && !e.contains(".capture.json."), "{e}");
        // A link planted under the old fixed temporary name leads nowhere: the write
        // goes to a fresh name, the file outside keeps its bytes, the link is left.
        let outside = tempfile::tempdir().unwrap();
        let target = outside.path().join("precious");
        std::fs::write(&target, b"precious").unwrap();
        std::os::unix::fs::symlink(&target, dir.path().join(".capture.json.tmp")).unwrap();
        write_atomic(dir.path(), SESSION_FILE, b"{}").unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"precious");
        assert!(!std::fs::symlink_metadata(dir.path().join(SESSION_FILE)).unwrap().file_type().is_symlink());
        std::fs::remove_file(dir.path().join(".capture.json.tmp")).unwrap();
        std::fs::remove_file(dir.path().join(SESSION_FILE)).unwrap();
        // A write that works leaves the file and no temporary one.
        write_atomic(dir.path(), SESSION_FILE, b"{}").unwrap();
        assert_eq!(std::fs::read(dir.path().join(SESSION_FILE)).unwrap(), b"{}");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }
}
