//! The acquisition thread: owns the camera and does nothing but pull frames, stamp
//! them and hand them to the writer over an unbounded channel, so it never waits on
//! disk or reconstruction. It stops when asked (`--frames`, Ctrl-C, a recording fault),
//! at the end of a replay, or on a camera fault.

use super::session::State;
use super::shared::Shared;
use crossbeam_channel::Sender;
use rollcam_hw::camera::{Camera, CameraError, Frame, FrameStatus, Trigger};
use std::time::Instant;

pub(super) fn acquire(mut cam: Box<dyn Camera>, tx: Sender<Frame>, shared: &Shared) {
    let span = tracing::info_span!("acquire", camera = %cam.info().spec());
    let _g = span.enter();
    let opts = &shared.opts;
    let (software, need) = match cam.applied_settings() {
        Ok(s) => {
            let (w, h) = s.image_size();
            (s.trigger == Trigger::Software, super::writer::reserve_bytes(opts.min_free_mb, w, h))
        }
        Err(e) => {
            shared.request_stop(State::Failed, format!("camera fault: reading settings: {e}"));
            return;
        }
    };
    if let Err(e) = cam.start() {
        shared.request_stop(State::Failed, format!("camera fault: cannot start acquisition: {e}"));
        return;
    }
    tracing::info!(frames = ?opts.frames, "acquisition started");
    let mut delivered: u64 = 0;
    let mut silent_since: Option<Instant> = None;
    loop {
        if shared.stop_requested() {
            break;
        }
        if let Some(n) = opts.frames {
            if delivered >= n {
                shared.request_stop(State::Finished, format!("{n} frames acquired as asked (--frames {n})"));
                break;
            }
        }
        if software {
            if let Err(e) = cam.software_trigger() {
                shared.request_stop(State::Failed, format!("camera fault: software trigger: {e}"));
                break;
            }
        }
        match cam.next_frame(opts.frame_timeout) {
            Ok(mut frame) => {
                silent_since = None;
                if frame.meta.host_timestamp_ns == 0 {
                    frame.meta.host_timestamp_ns = rollcam_hw::camera::host_now_ns();
                }
                delivered += 1;
                if frame.meta.status == FrameStatus::Dropped {
                    tracing::warn!(sequence = frame.meta.sequence, frame_id = frame.meta.frame_id, "camera dropped a frame");
                } else {
                    shared.captured.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                }
                tracing::debug!(sequence = frame.meta.sequence, "frame acquired");
                if tx.send(frame).is_err() {
                    // The writer has gone: it stopped recording and said why.
                    break;
                }
            }
            Err(CameraError::Timeout { .. }) => {
                let since = *silent_since.get_or_insert_with(Instant::now);
                let silent = since.elapsed() + opts.frame_timeout;
                tracing::warn!(silent_s = silent.as_secs_f64(), "no frame from the camera yet");
                if let Some(limit) = opts.stall_limit {
                    if silent >= limit {
                        shared.request_stop(
                            State::Failed,
                            format!("camera fault: no frame for {:.1} s (stall limit {:.1} s)", silent.as_secs_f64(), limit.as_secs_f64()),
                        );
                        break;
                    }
                }
            }
            Err(CameraError::EndOfStream { frames, .. }) => {
                shared.request_stop(State::Finished, format!("the camera's stream ended after {frames} frames"));
                break;
            }
            Err(e) => {
                // A simulated camera writes its truth into the session: a full disk
                // fails it, and is reported as the disk's fault.
                let why = super::writer::camera_disk_fault(&e.to_string(), &shared.dir, need).unwrap_or_else(|| format!("camera fault: {e}"));
                shared.request_stop(State::Failed, why);
                break;
            }
        }
    }
    if let Err(e) = cam.stop() {
        tracing::warn!("stopping the camera: {e}");
    }
    tracing::info!(delivered, "acquisition stopped");
}
