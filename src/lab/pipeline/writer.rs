//! The writer thread: records every raw frame (TIFF + JSON sidecar, fsynced and
//! renamed into place by [`Recorder`]) before anything else sees it, then hands the
//! frame's id to the reconstruction workers. It checks the free space before each
//! frame and keeps `--min-free-mb` free; when the disk is full (or a write fails) it
//! stops recording cleanly, asks acquisition to stop and says why.

use super::options::Policy;
use super::session::{FrameEntry, FrameState, State};
use super::shared::{refill, skip, Shared};
use super::worker::FrameJob;
use crossbeam_channel::{Receiver, Sender, TrySendError};
use rollcam_hw::camera::{Frame, FrameStatus as CamStatus};
use rollcam_hw::record::{RecordError, Recorder};
use std::path::Path;
use std::sync::atomic::Ordering;

/// Bytes free for an unprivileged writer on the file system holding `dir`.
pub fn free_bytes(dir: &Path) -> std::io::Result<u64> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(dir.as_os_str().as_bytes()).map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e))?;
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: `c` is a valid NUL-terminated path and `st` a valid out-pointer.
    let rc = unsafe { libc::statvfs(c.as_ptr(), &mut st) };
    if rc != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(st.f_bavail as u64 * st.f_frsize as u64)
}

/// Whether a recording error means the disk (or quota) is full.
pub fn is_disk_full(e: &RecordError) -> bool {
    match e {
        RecordError::Io { source, .. } => matches!(source.raw_os_error(), Some(libc::ENOSPC) | Some(libc::EDQUOT)),
        _ => false,
    }
}

/// The free bytes a frame needs: the reserve (`--min-free-mb`) and the frame, a TIFF of
/// 2 bytes per sample plus headers.
pub(super) fn reserve_bytes(min_free_mb: u64, width: u32, height: u32) -> u64 {
    min_free_mb.saturating_mul(1_000_000).saturating_add(width as u64 * height as u64 * 2 + 64 * 1024)
}

/// A camera's failure as a disk error when the disk is to blame: the error carries the
/// system's message for a full disk or quota (a simulated camera writing its truth
/// into the session), or the session folder's file system has less than `need` bytes
/// free. The message names the folder; `None`: a camera fault.
pub fn camera_disk_fault(error: &str, dir: &Path, need: u64) -> Option<String> {
    let says_full = [libc::ENOSPC, libc::EDQUOT].iter().any(|&code| error.contains(&std::io::Error::from_raw_os_error(code).to_string()));
    let free = free_bytes(dir).ok();
    if !says_full && !free.is_some_and(|f| f < need) {
        return None;
    }
    let free = free.map(|f| format!(" ({} MB free)", f / 1_000_000)).unwrap_or_default();
    Some(format!("disk full: the file system of {}{free} cannot take the session's files ({error}); recording stopped", dir.display()))
}

pub(super) fn write_frames(mut rec: Recorder, rx: Receiver<Frame>, work_tx: Sender<FrameJob>, work_rx: Receiver<FrameJob>, shared: &Shared) {
    let span = tracing::info_span!("record");
    let _g = span.enter();
    let opts = &shared.opts;
    let raw_dir = rec.dir().to_path_buf();
    let mut recording = true;
    let mut fault: Option<String> = None;
    for frame in rx.iter() {
        let seq = frame.meta.sequence;
        let dropped = frame.meta.status == CamStatus::Dropped;
        if !recording {
            if !dropped {
                shared.unrecorded.fetch_add(1, Ordering::SeqCst);
            }
            continue;
        }
        let need = reserve_bytes(opts.min_free_mb, frame.meta.width, frame.meta.height);
        let check = match free_bytes(&raw_dir) {
            Ok(free) if free < need => Err(format!(
                "disk full: {} MB free on the file system of {}, below the reserve of {} MB (--min-free-mb) plus one frame; recording stopped",
                free / 1_000_000,
                raw_dir.display(),
                opts.min_free_mb
            )),
            Ok(_) => Ok(()),
            Err(e) => {
                tracing::warn!("cannot read the free space of {}: {e}", raw_dir.display());
                Ok(())
            }
        };
        let result = check.and_then(|()| {
            let r = if opts.test.fail_write_at == Some(seq) {
                Err(RecordError::Io {
                    path: raw_dir.join(format!("frame_{seq:06}.tiff")),
                    action: "write",
                    source: std::io::Error::from_raw_os_error(libc::ENOSPC),
                })
            } else {
                rec.write_frame(&frame)
            };
            r.map_err(|e| if is_disk_full(&e) { format!("disk full: {e}; recording stopped") } else { format!("recording failed: {e}; recording stopped") })
        });
        if let Err(msg) = result {
            tracing::error!("{msg}");
            eprintln!("error: {msg}");
            shared.request_stop(State::Failed, msg.clone());
            shared.with_session(|s| s.errors.push(format!("frame {seq}: {msg}")));
            if !dropped {
                shared.unrecorded.fetch_add(1, Ordering::SeqCst);
            }
            fault = Some(msg);
            recording = false;
            continue;
        }
        if dropped {
            shared.with_session(|s| s.dropped_frames.push(seq));
            continue;
        }
        let incomplete = frame.meta.status == CamStatus::Incomplete;
        let raw_rel = format!("raw/frame_{seq:06}.tiff");
        let job = FrameJob {
            sequence: seq,
            raw: shared.dir.join(&raw_rel),
            host_timestamp_ns: frame.meta.host_timestamp_ns,
            out: shared.dir.join(format!("rec/frame_{seq:06}")),
        };
        shared.with_session(|s| {
            s.frames.push(FrameEntry {
                sequence: seq,
                frame_id: frame.meta.frame_id,
                raw: raw_rel,
                status: if incomplete { FrameState::Failed } else { FrameState::Recorded },
                video: None,
                rec: None,
                host_timestamp_ns: frame.meta.host_timestamp_ns,
                latency_ms: None,
                solve_s: None,
                psnr_db: None,
                converged: None,
                incomplete,
                error: incomplete.then(|| {
                    format!(
                        "incomplete frame: {} of {} samples arrived (recorded zero-padded, not reconstructed)",
                        frame.meta.valid_pixels,
                        frame.meta.width as u64 * frame.meta.height as u64
                    )
                }),
                sequence_frames: None,
            })
        });
        tracing::debug!(sequence = seq, incomplete, "frame recorded");
        *shared.latest_raw.lock().unwrap() = Some(frame);
        if !incomplete {
            match opts.policy {
                Policy::CatchUp => {
                    let mut backlog = shared.backlog.lock().unwrap();
                    backlog.push_back(job);
                    refill(&mut backlog, &work_tx);
                }
                Policy::Live => dispatch_live(job, &work_tx, &work_rx, shared),
            }
        }
    }
    let end = rec.finish(fault);
    if let Err(e) = end {
        tracing::warn!("finishing the raw capture file: {e}");
    }
    shared.writer_done.store(true, Ordering::SeqCst);
}

/// `--live`: the newest frame always gets a place in the work queue; when it is full,
/// the oldest queued frame is skipped (it stays recorded; `--resume` reconstructs it).
/// Workers, in turn, take the newest queued frame and skip the older ones.
fn dispatch_live(mut job: FrameJob, tx: &Sender<FrameJob>, rx: &Receiver<FrameJob>, shared: &Shared) {
    loop {
        match tx.try_send(job) {
            Ok(()) => return,
            Err(TrySendError::Full(j)) => {
                job = j;
                if let Ok(old) = rx.try_recv() {
                    skip(shared, &old, job.sequence);
                }
            }
            Err(TrySendError::Disconnected(_)) => return,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn free_space_is_read_and_disk_full_is_recognised() {
        let dir = tempfile::tempdir().unwrap();
        assert!(free_bytes(dir.path()).unwrap() > 0);
        assert!(free_bytes(&dir.path().join("missing")).is_err());
        let full = RecordError::Io { path: "x".into(), action: "write", source: std::io::Error::from_raw_os_error(libc::ENOSPC) };
        assert!(is_disk_full(&full));
        let other = RecordError::Io { path: "x".into(), action: "write", source: std::io::Error::from_raw_os_error(libc::EIO) };
        assert!(!is_disk_full(&other));
    }

    #[test]
    fn a_camera_failing_on_a_full_disk_is_a_disk_error_naming_the_folder() {
        let dir = tempfile::tempdir().unwrap();
        // The simulated camera's truth write on a full disk (was: "camera fault: ...").
        let full = format!("camera sim: frame 3: {}: {}", dir.path().join("sim/truth_000003.npy").display(), std::io::Error::from_raw_os_error(libc::ENOSPC));
        let m = camera_disk_fault(&full, dir.path(), 1).unwrap();
        assert!(m.starts_with("disk full: the file system of ") && m.contains(&dir.path().display().to_string()) && m.contains("MB free"), "{m}");
        let quota = std::io::Error::from_raw_os_error(libc::EDQUOT).to_string();
        assert!(camera_disk_fault(&quota, dir.path(), 1).is_some());
        // A camera's own fault with room on the disk stays a camera fault ...
        assert_eq!(camera_disk_fault("frame timeout: the link is down", dir.path(), 1), None);
        // ... and is the disk's when the session's file system has less than a frame.
        assert!(camera_disk_fault("frame timeout: the link is down", dir.path(), u64::MAX).unwrap().contains("disk full"));
    }
}
