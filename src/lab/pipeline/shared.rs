//! The state the pipeline's threads share ([`Shared`]: session file, stop cause,
//! backlog, latest frames, counters) and the two moves on it that the writer and the
//! workers both make: [`refill`] the work queue from the backlog, [`skip`] a frame.

use super::options::Options;
use super::session::{FrameState, SessionFile, State};
use super::worker::FrameJob;
use crossbeam_channel::{Sender, TrySendError};
use rollcam_hw::camera::Frame;
use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Mutex;

/// State shared by the pipeline's threads.
pub(crate) struct Shared {
    pub(crate) dir: PathBuf,
    pub(crate) opts: Options,
    pub(crate) session: Mutex<SessionFile>,
    /// Why the session stops (the first cause wins).
    pub(crate) stop: Mutex<Option<(State, String)>>,
    /// Raised by a second Ctrl-C: workers stop taking frames and interrupt their solve.
    pub(crate) abandon: AtomicBool,
    pub(crate) writer_done: AtomicBool,
    pub(crate) backlog: Mutex<VecDeque<FrameJob>>,
    pub(crate) latest_raw: Mutex<Option<Frame>>,
    pub(crate) latest_video: Mutex<Option<(u64, ndarray::Array3<f32>)>>,
    pub(crate) captured: AtomicU64,
    pub(crate) unrecorded: AtomicU64,
}

impl Shared {
    pub(crate) fn new(opts: Options, session: SessionFile) -> Self {
        Shared {
            dir: opts.dir.clone(),
            opts,
            session: Mutex::new(session),
            stop: Mutex::new(None),
            abandon: AtomicBool::new(false),
            writer_done: AtomicBool::new(false),
            backlog: Mutex::new(VecDeque::new()),
            latest_raw: Mutex::new(None),
            latest_video: Mutex::new(None),
            captured: AtomicU64::new(0),
            unrecorded: AtomicU64::new(0),
        }
    }

    pub(crate) fn request_stop(&self, state: State, reason: String) {
        let mut s = self.stop.lock().unwrap();
        match s.as_mut() {
            None => {
                tracing::info!(reason = %reason, "stopping acquisition");
                *s = Some((state, reason));
            }
            // A fault after a normal stop (the disk filling while the last frames are
            // written) still fails the session; both reasons are kept.
            Some((old_state, old_reason)) if state == State::Failed && *old_state != State::Failed => {
                *old_reason = format!("{reason} (after: {old_reason})");
                *old_state = State::Failed;
            }
            Some(_) => {}
        }
    }

    pub(crate) fn stop_requested(&self) -> bool {
        self.stop.lock().unwrap().is_some()
    }

    pub(crate) fn with_session<T>(&self, f: impl FnOnce(&mut SessionFile) -> T) -> T {
        f(&mut self.session.lock().unwrap())
    }

    pub(crate) fn snapshot(&self) -> SessionFile {
        let mut s = self.session.lock().unwrap().clone();
        s.counters.captured = self.captured.load(Ordering::SeqCst);
        s.counters.unrecorded = self.unrecorded.load(Ordering::SeqCst);
        s.refresh();
        s
    }
}

/// Move backlog ids into the work queue while it has room (order kept).
pub(crate) fn refill(backlog: &mut VecDeque<FrameJob>, tx: &Sender<FrameJob>) {
    while let Some(job) = backlog.pop_front() {
        match tx.try_send(job) {
            Ok(()) => {}
            Err(TrySendError::Full(job)) | Err(TrySendError::Disconnected(job)) => {
                backlog.push_front(job);
                break;
            }
        }
    }
}

/// `--live`: mark a queued frame skipped in favour of a newer one.
pub(crate) fn skip(shared: &Shared, old: &FrameJob, newer: u64) {
    tracing::info!(sequence = old.sequence, newer, "live: skipping an older frame");
    shared.with_session(|s| {
        if let Some(f) = s.frame_mut(old.sequence) {
            f.status = FrameState::Skipped;
        }
    });
}
