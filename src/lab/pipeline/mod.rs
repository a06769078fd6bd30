//! The live bench pipeline behind `rollcam run`: every frame the camera delivers is
//! recorded raw, then reconstructed as fast as the machine allows.
//!
//! ```text
//!  camera ──► acquisition ──(unbounded)──► writer ──(bounded work queue)──► workers ──► rec/frame_N/
//!             (acquire.rs)                 raw/ first                      (worker.rs)
//!                                          backlog of ids on disk ─┘
//!  ticker (this thread): session.json + preview/*.png, Ctrl-C
//! ```
//!
//! * Acquisition never waits: frames go to the writer over an unbounded channel.
//! * The writer records each raw frame durably (TIFF + sidecar) before anything else
//!   sees it, then queues its id. When the bounded work queue (`queue`) is full,
//!   `catch-up` keeps the id in an in-memory backlog (the frame itself is on disk) and
//!   the workers take it later, in order; `live` skips the oldest queued frame instead,
//!   so the workers always work on recent frames.
//! * Workers call one [`worker::FrameReconstructor`] per frame, inside
//!   `catch_unwind`: a panic fails that frame only.
//! * Stopping (`frames`, Ctrl-C, a camera fault, a full disk): acquisition stops, the
//!   writer records what it already has, the workers drain the queue. A second Ctrl-C
//!   abandons the drain: what is left stays listed in `session.json` (`pending`) and
//!   [`resume`] reconstructs it later.

pub mod acquire;
pub mod consecutive;
pub mod preview;
pub mod session;
pub mod simbench;
pub mod worker;
pub mod writer;

use anyhow::{bail, Context, Result};
use crossbeam_channel::{Receiver, Sender, TrySendError};
use rollcam_hw::camera::{Camera, Frame};
use rollcam_hw::record::{CaptureReader, CaptureSession, Recorder};
use session::{FrameEntry, FrameStatus, SessionFile, State};
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use worker::{FrameJob, FrameReconstructor, ReconstructFailure};

/// Raw capture folder inside a session folder.
pub const RAW_DIR: &str = "raw";
/// Reconstructions inside a session folder (`rec/frame_NNNNNN/`).
pub const REC_DIR: &str = "rec";
/// The session's capture description and PSF.
pub const CAPTURE_TOML: &str = "capture.toml";
pub const PSF_TIFF: &str = "psf.tiff";

/// What to do when the workers fall behind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Policy {
    /// Every frame is reconstructed, in order; the backlog waits on disk.
    CatchUp,
    /// The newest frame first; older queued frames are skipped (left for `--resume`).
    Live,
}

impl Policy {
    pub fn name(self) -> &'static str {
        match self {
            Policy::CatchUp => "catch-up",
            Policy::Live => "live",
        }
    }
}

/// Test hooks (hidden flags of `rollcam run`): make faults happen on purpose.
#[derive(Clone, Debug, Default)]
pub struct TestHooks {
    /// Each worker sleeps this long before each frame (a slow worker).
    pub worker_delay: Duration,
    /// The worker panics on this frame (sequence number).
    pub panic_on_frame: Option<u64>,
    /// The writer fails with ENOSPC on this frame (sequence number).
    pub fail_write_at: Option<u64>,
}

/// How a session runs.
#[derive(Clone, Debug)]
pub struct Options {
    /// The session folder.
    pub dir: PathBuf,
    /// Stop after this many frames from the camera (dropped ones included).
    pub frames: Option<u64>,
    pub policy: Policy,
    /// Work-queue length (frames handed to workers ahead of time).
    pub queue: usize,
    pub workers: usize,
    /// How long one wait for a frame lasts before a warning.
    pub frame_timeout: Duration,
    /// Give up when the camera stays silent this long (None: wait until stopped).
    pub stall_limit: Option<Duration>,
    /// Free space to keep on the session's disk, MB (10^6 bytes).
    pub min_free_mb: u64,
    /// Period of the session.json and preview refresh.
    pub refresh: Duration,
    pub test: TestHooks,
}

impl Options {
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Options {
            dir: dir.into(),
            frames: None,
            policy: Policy::CatchUp,
            queue: 2,
            workers: 1,
            frame_timeout: Duration::from_secs(5),
            stall_limit: None,
            min_free_mb: 200,
            refresh: Duration::from_millis(500),
            test: TestHooks::default(),
        }
    }
}

/// State shared by the pipeline's threads.
pub(crate) struct Shared {
    pub(crate) dir: PathBuf,
    pub(crate) opts: Options,
    session: Mutex<SessionFile>,
    /// Why the session stops (the first cause wins).
    stop: Mutex<Option<(State, String)>>,
    /// Raised by a second Ctrl-C: workers stop taking frames and interrupt their solve.
    abandon: AtomicBool,
    pub(crate) writer_done: AtomicBool,
    pub(crate) backlog: Mutex<VecDeque<FrameJob>>,
    pub(crate) latest_raw: Mutex<Option<Frame>>,
    latest_video: Mutex<Option<(u64, ndarray::Array3<f32>)>>,
    pub(crate) captured: AtomicU64,
    pub(crate) unrecorded: AtomicU64,
}

impl Shared {
    fn new(opts: Options, session: SessionFile) -> Self {
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

    fn snapshot(&self) -> SessionFile {
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

/// Refuse a session folder that exists and is not empty (`--resume` continues one).
pub fn check_new_folder(dir: &Path) -> Result<()> {
    if dir.exists() {
        if !dir.is_dir() {
            bail!("{}: exists and is not a folder", dir.display());
        }
        let mut entries = std::fs::read_dir(dir).with_context(|| format!("{}: cannot list the folder", dir.display()))?;
        if entries.next().is_some() {
            bail!(
                "{}: the output folder is not empty; choose a new folder, or continue that session with `rollcam run --resume {}`",
                dir.display(),
                dir.display()
            );
        }
    }
    Ok(())
}

/// Where the session's PSF comes from.
pub enum PsfInput<'a> {
    /// A calibration image on disk, copied byte for byte.
    File(&'a Path),
    /// An image in memory (the simulated bench's), written as 16-bit TIFF.
    Image(&'a ndarray::Array3<f32>),
}

/// Create a new session folder (refusing one that is not empty) and write the capture
/// description and the PSF into it. Returns the PSF's path in the folder.
pub fn create_folder(dir: &Path, cfg: &crate::model::capture::CaptureConfig, psf: PsfInput) -> Result<PathBuf> {
    check_new_folder(dir)?;
    for sub in ["", REC_DIR, preview::PREVIEW_DIR] {
        let d = dir.join(sub);
        std::fs::create_dir_all(&d).with_context(|| format!("{}: cannot create the folder", d.display()))?;
    }
    match psf {
        PsfInput::File(p) => {
            let bytes = std::fs::read(p).with_context(|| format!("{}: cannot read the PSF", p.display()))?;
            rollcam_hw::record::write_atomic(dir, PSF_TIFF, &bytes)?;
        }
        PsfInput::Image(img) => crate::io::write_tiff_u16(dir.join(PSF_TIFF), img.view())?,
    }
    rollcam_hw::record::write_atomic(dir, CAPTURE_TOML, cfg.to_toml().as_bytes())?;
    Ok(dir.join(PSF_TIFF))
}

/// Run a session on an open, configured camera until it stops; returns the final
/// session file (also written to `session.json`). `raw` describes the raw capture
/// (`raw/capture.json`). `interrupt` is the Ctrl-C flag: the pipeline clears it each
/// time it sees it raised, so a second press is seen as such.
pub fn run(
    camera: Box<dyn Camera>,
    raw: CaptureSession,
    session: SessionFile,
    reconstructor: Arc<dyn FrameReconstructor>,
    opts: Options,
    interrupt: Arc<AtomicBool>,
) -> Result<SessionFile> {
    if opts.workers == 0 || opts.queue == 0 {
        bail!("--workers and --queue must be at least 1 (got {} and {})", opts.workers, opts.queue);
    }
    let dir = opts.dir.clone();
    let rec = Recorder::create(dir.join(RAW_DIR), raw)?;
    let shared = Shared::new(opts, session);
    shared.snapshot().write(&dir)?;
    let (frame_tx, frame_rx) = crossbeam_channel::unbounded::<Frame>();
    let (work_tx, work_rx) = crossbeam_channel::bounded::<FrameJob>(shared.opts.queue);
    let span = tracing::info_span!("session", dir = %dir.display());
    let _g = span.enter();
    tracing::info!(policy = shared.opts.policy.name(), queue = shared.opts.queue, workers = shared.opts.workers, "session started");
    std::thread::scope(|scope| {
        let sh = &shared;
        let acq = std::thread::Builder::new().name("acquire".into()).spawn_scoped(scope, move || acquire::acquire(camera, frame_tx, sh)).expect("spawn");
        let (wtx, wrx) = (work_tx.clone(), work_rx.clone());
        let wr = std::thread::Builder::new()
            .name("record".into())
            .spawn_scoped(scope, move || writer::write_frames(rec, frame_rx, wtx, wrx, sh))
            .expect("spawn");
        let workers: Vec<_> = (0..shared.opts.workers)
            .map(|i| {
                let (tx, rx, r) = (work_tx.clone(), work_rx.clone(), reconstructor.clone());
                std::thread::Builder::new().name(format!("worker-{i}")).spawn_scoped(scope, move || work(i, rx, tx, r.as_ref(), sh)).expect("spawn")
            })
            .collect();
        drop((work_tx, work_rx));
        let mut threads = vec![acq, wr];
        threads.extend(workers);
        ticker(sh, &interrupt, || threads.iter().all(|t| t.is_finished()));
        for t in threads {
            if t.join().is_err() {
                shared.with_session(|s| s.errors.push("a pipeline thread panicked".into()));
            }
        }
    });
    finish(&shared)
}

/// The ticker: Ctrl-C, session.json and previews, until `done()`.
fn ticker(shared: &Shared, interrupt: &AtomicBool, done: impl Fn() -> bool) {
    let mut presses = 0;
    let mut last_write = Instant::now();
    loop {
        let finished = done();
        if interrupt.swap(false, Ordering::SeqCst) {
            presses += 1;
            if presses == 1 {
                shared.request_stop(State::Stopped, "interrupted (Ctrl-C)".into());
                let queued = shared.snapshot().counters.queued;
                eprintln!("stopping: acquisition stopped, reconstructing the {queued} queued frames (Ctrl-C again to leave them for `rollcam run --resume`)");
            } else if !shared.abandon.swap(true, Ordering::SeqCst) {
                eprintln!("abandoning the queue: unreconstructed frames stay recorded; `rollcam run --resume {}` finishes them", shared.dir.display());
                shared.with_session(|s| s.errors.push("drain abandoned by a second Ctrl-C".into()));
            }
        }
        if finished {
            break;
        }
        if last_write.elapsed() >= shared.opts.refresh {
            write_previews(shared);
            if let Err(e) = shared.snapshot().write(&shared.dir) {
                tracing::warn!("writing the session file: {e}");
            }
            last_write = Instant::now();
        }
        std::thread::sleep(Duration::from_millis(50).min(shared.opts.refresh));
    }
}

fn write_previews(shared: &Shared) {
    let raw = shared.latest_raw.lock().unwrap().take();
    if let Some(frame) = raw {
        let img = preview::raw_image(frame.meta.width, frame.meta.height, &frame.pixels);
        match preview::write_preview(&shared.dir.join(preview::LATEST_RAW), &img) {
            Ok(()) => shared.with_session(|s| {
                s.preview.raw = Some(preview::LATEST_RAW.into());
                s.preview.raw_sequence = Some(frame.meta.sequence);
            }),
            Err(e) => tracing::warn!("raw preview: {e}"),
        }
    }
    let video = shared.latest_video.lock().unwrap().take();
    if let Some((seq, img)) = video {
        match preview::write_preview(&shared.dir.join(preview::LATEST_FRAME), &img) {
            Ok(()) => shared.with_session(|s| {
                s.preview.frame = Some(preview::LATEST_FRAME.into());
                s.preview.frame_sequence = Some(seq);
            }),
            Err(e) => tracing::warn!("frame preview: {e}"),
        }
    }
}

/// A reconstruction worker: frames from the work queue (refilled from the backlog)
/// until the writer is done and nothing is left, or the drain is abandoned.
fn work(index: usize, rx: Receiver<FrameJob>, tx: Sender<FrameJob>, rec: &dyn FrameReconstructor, shared: &Shared) {
    let span = tracing::info_span!("worker", index);
    let _g = span.enter();
    loop {
        if shared.abandon.load(Ordering::SeqCst) {
            break;
        }
        match rx.recv_timeout(Duration::from_millis(100)) {
            Ok(mut job) => {
                if shared.opts.policy == Policy::Live {
                    // The newest queued frame; the older ones are skipped.
                    while let Ok(newer) = rx.try_recv() {
                        skip(shared, &job, newer.sequence);
                        job = newer;
                    }
                }
                reconstruct_one(&job, rec, shared);
                refill(&mut shared.backlog.lock().unwrap(), &tx);
            }
            Err(_) => {
                let mut backlog = shared.backlog.lock().unwrap();
                refill(&mut backlog, &tx);
                if shared.writer_done.load(Ordering::SeqCst) && backlog.is_empty() && rx.is_empty() {
                    break;
                }
            }
        }
    }
}

/// `--live`: mark a queued frame skipped in favour of a newer one.
pub(crate) fn skip(shared: &Shared, old: &FrameJob, newer: u64) {
    tracing::info!(sequence = old.sequence, newer, "live: skipping an older frame");
    shared.with_session(|s| {
        if let Some(f) = s.frame_mut(old.sequence) {
            f.status = FrameStatus::Skipped;
        }
    });
}

fn panic_message(p: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = p.downcast_ref::<&str>() {
        s.to_string()
    } else if let Some(s) = p.downcast_ref::<String>() {
        s.clone()
    } else {
        "(no message)".into()
    }
}

/// One frame, isolated: errors and panics fail this frame only.
fn reconstruct_one(job: &FrameJob, rec: &dyn FrameReconstructor, shared: &Shared) {
    let span = tracing::info_span!("frame", sequence = job.sequence);
    let _g = span.enter();
    shared.with_session(|s| {
        if let Some(f) = s.frame_mut(job.sequence) {
            f.status = FrameStatus::Reconstructing;
        }
    });
    let hooks = &shared.opts.test;
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let until = Instant::now() + hooks.worker_delay;
        while Instant::now() < until && !shared.abandon.load(Ordering::SeqCst) {
            std::thread::sleep(Duration::from_millis(10).min(until.saturating_duration_since(Instant::now())));
        }
        if shared.abandon.load(Ordering::SeqCst) {
            return Err(ReconstructFailure::Interrupted);
        }
        if hooks.panic_on_frame == Some(job.sequence) {
            panic!("test hook: deliberate panic on frame {}", job.sequence);
        }
        rec.reconstruct(job, &shared.abandon)
    }));
    let done_ns = rollcam_hw::camera::host_now_ns();
    shared.with_session(|s| {
        let rel = |p: &Path| p.strip_prefix(&shared.dir).unwrap_or(p).display().to_string();
        let mut err = None;
        if let Some(f) = s.frame_mut(job.sequence) {
            match &result {
                Ok(Ok(v)) => {
                    f.status = FrameStatus::Reconstructed;
                    f.video = Some(rel(&v.video));
                    f.rec = Some(rel(&job.out));
                    let lat = done_ns.saturating_sub(job.host_timestamp_ns) as f64 / 1e6;
                    f.latency_ms = Some(lat);
                    f.solve_s = Some(v.solve_s);
                    f.psnr_db = v.psnr_db;
                    f.error = None;
                    f.sequence_frames = v.sequence_frames.clone();
                    tracing::info!(latency_ms = lat, solve_s = v.solve_s, psnr_db = v.psnr_db, "frame reconstructed");
                }
                Ok(Err(ReconstructFailure::Interrupted)) => {
                    f.status = FrameStatus::Recorded;
                    tracing::info!("reconstruction interrupted; the frame stays pending");
                }
                Ok(Err(ReconstructFailure::Error(e))) => {
                    f.status = FrameStatus::Failed;
                    let msg = format!("{e:#}");
                    tracing::error!("frame {} failed: {msg}", job.sequence);
                    f.error = Some(msg.clone());
                    err = Some(format!("frame {}: {msg}", job.sequence));
                }
                Err(p) => {
                    f.status = FrameStatus::Failed;
                    let msg = format!("worker panicked: {}", panic_message(p.as_ref()));
                    tracing::error!("frame {}: {msg}", job.sequence);
                    f.error = Some(msg.clone());
                    err = Some(format!("frame {}: {msg}", job.sequence));
                }
            }
        }
        if let Some(e) = err {
            s.errors.push(e);
        }
        if let Ok(Ok(Some(st))) = result.as_ref().map(|r| r.as_ref().map(|v| v.sequence.as_ref())) {
            s.sequence = Some(st.clone());
        }
        if let Ok(Ok(_)) = &result {
            s.latency_ms.last = s.frame_mut(job.sequence).and_then(|f| f.latency_ms);
        }
    });
    if let Ok(Ok(v)) = result {
        *shared.latest_video.lock().unwrap() = Some((job.sequence, v.preview));
    }
}

/// Final state, session.json, previews; the summary is returned.
fn finish(shared: &Shared) -> Result<SessionFile> {
    write_previews(shared);
    let (state, reason) = shared.stop.lock().unwrap().clone().unwrap_or((State::Finished, "finished".into()));
    shared.with_session(|s| {
        s.state = state;
        let mut reason = reason;
        if shared.abandon.load(Ordering::SeqCst) {
            reason.push_str("; the drain was abandoned (second Ctrl-C)");
        }
        s.stop_reason = Some(reason);
        s.finished_utc = Some(session::utc_now());
    });
    let s = shared.snapshot();
    s.write(&shared.dir)?;
    tracing::info!(state = ?s.state, counters = ?s.counters, "session ended");
    Ok(s)
}

/// `rollcam run --resume DIR`: reconstruct every recorded frame of a session that has
/// no finished video (queued, interrupted, skipped), including raw frames on disk
/// that the session file never listed (a crash between recording and the next
/// refresh). Failed and incomplete frames are left as they are.
pub fn resume(dir: &Path, reconstructor: Arc<dyn FrameReconstructor>, workers: usize, refresh: Duration, interrupt: Arc<AtomicBool>) -> Result<SessionFile> {
    let mut session = SessionFile::load(dir)?;
    if session.state == State::Running {
        tracing::warn!("{}: the session is marked running; its process ended without finishing it", dir.display());
        session.errors.push("the session was left running (the previous process ended abnormally); resumed".into());
    }
    // Frames recorded but never listed.
    let raw_dir = dir.join(RAW_DIR);
    let reader = CaptureReader::open(&raw_dir).with_context(|| format!("{}: cannot read the raw frames", raw_dir.display()))?;
    let mut added = 0;
    for meta in reader.metas() {
        let known = session.frames.iter().any(|f| f.sequence == meta.sequence) || session.dropped_frames.contains(&meta.sequence);
        if known {
            continue;
        }
        added += 1;
        if meta.status == rollcam_hw::camera::FrameStatus::Dropped {
            session.dropped_frames.push(meta.sequence);
            continue;
        }
        let incomplete = meta.status == rollcam_hw::camera::FrameStatus::Incomplete;
        session.frames.push(FrameEntry {
            sequence: meta.sequence,
            frame_id: meta.frame_id,
            raw: format!("{RAW_DIR}/frame_{:06}.tiff", meta.sequence),
            status: if incomplete { FrameStatus::Failed } else { FrameStatus::Recorded },
            video: None,
            rec: None,
            host_timestamp_ns: meta.host_timestamp_ns,
            latency_ms: None,
            solve_s: None,
            psnr_db: None,
            incomplete,
            error: incomplete.then(|| "incomplete frame (not reconstructed)".to_string()),
            sequence_frames: None,
        });
    }
    session.frames.sort_by_key(|f| f.sequence);
    session.dropped_frames.sort_unstable();
    let jobs: Vec<FrameJob> = session
        .frames
        .iter_mut()
        .filter(|f| session::needs_reconstruction(f))
        .map(|f| {
            f.status = FrameStatus::Recorded;
            FrameJob {
                sequence: f.sequence,
                raw: dir.join(&f.raw),
                host_timestamp_ns: f.host_timestamp_ns,
                out: dir.join(format!("{REC_DIR}/frame_{:06}", f.sequence)),
            }
        })
        .collect();
    let todo = jobs.len();
    tracing::info!(frames = todo, unlisted = added, "resuming");
    let previous = (session.state, session.stop_reason.clone());
    session.state = State::Running;
    let mut opts = Options::new(dir);
    opts.workers = workers.max(1);
    opts.refresh = refresh;
    let job_ids: Vec<u64> = jobs.iter().map(|j| j.sequence).collect();
    let (captured, unrecorded) = (session.counters.captured, session.counters.unrecorded);
    let shared = Shared::new(opts, session);
    shared.captured.store(captured, Ordering::SeqCst);
    shared.unrecorded.store(unrecorded, Ordering::SeqCst);
    shared.backlog.lock().unwrap().extend(jobs);
    shared.writer_done.store(true, Ordering::SeqCst);
    let (work_tx, work_rx) = crossbeam_channel::bounded::<FrameJob>(shared.opts.workers.max(2));
    shared.snapshot().write(dir)?;
    std::thread::scope(|scope| {
        let sh = &shared;
        let workers: Vec<_> = (0..sh.opts.workers)
            .map(|i| {
                let (tx, rx, r) = (work_tx.clone(), work_rx.clone(), reconstructor.clone());
                scope.spawn(move || work(i, rx, tx, r.as_ref(), sh))
            })
            .collect();
        drop((work_tx, work_rx));
        ticker(sh, &interrupt, || workers.iter().all(|t| t.is_finished()));
        for t in workers {
            let _ = t.join();
        }
    });
    write_previews(&shared);
    let abandoned = shared.abandon.load(Ordering::SeqCst);
    shared.with_session(|s| {
        let count = |st: FrameStatus| s.frames.iter().filter(|f| job_ids.contains(&f.sequence) && f.status == st).count();
        let c = (count(FrameStatus::Reconstructed), count(FrameStatus::Failed), count(FrameStatus::Recorded));
        s.state = if abandoned { State::Stopped } else { State::Finished };
        s.stop_reason = previous.1.clone().or(Some("finished".into()));
        s.resumes.push(format!(
            "{}: {todo} frames to reconstruct ({added} found on disk unlisted): {} reconstructed, {} failed, {} left{}",
            session::utc_now(),
            c.0,
            c.1,
            c.2,
            if abandoned { " (interrupted)" } else { "" }
        ));
        s.finished_utc = Some(session::utc_now());
    });
    let s = shared.snapshot();
    s.write(dir)?;
    Ok(s)
}

/// The camera's shutter mode for a capture description's (None: the camera has no
/// such mode, e.g. centre-out dual).
pub fn camera_shutter(mode: crate::model::shutter::ShutterMode) -> Option<rollcam_hw::camera::ShutterMode> {
    use crate::model::shutter::ShutterMode as S;
    use rollcam_hw::camera::ShutterMode as C;
    match mode {
        S::Global => Some(C::Global),
        S::Rolling => Some(C::Rolling),
        S::Dual => Some(C::Dual),
        S::DualCenterOut => None,
    }
}

/// Refuse a capture description that contradicts what the camera applied: exposure,
/// line time, shutter mode (within 0.1%) and the image size. `origin` names the
/// configuration (file or command line) in the message.
pub fn check_timing(cfg: &crate::model::capture::CaptureConfig, applied: &rollcam_hw::camera::AppliedSettings, origin: &str) -> Result<()> {
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-3 * a.abs().max(b.abs());
    if !close(applied.exposure_us, cfg.exposure_us) {
        bail!("{origin}: exposure_us = {} contradicts the camera, which applied an exposure of {} us", cfg.exposure_us, applied.exposure_us);
    }
    match applied.line_time_us {
        Some(l) if !close(l, cfg.line_time_us) => {
            bail!("{origin}: line_time_us = {} contradicts the camera, which applied a line time of {l} us", cfg.line_time_us)
        }
        Some(_) => {}
        None => tracing::warn!("the camera does not report its line time; trusting line_time_us = {} from {origin}", cfg.line_time_us),
    }
    if let Some(s) = applied.shutter {
        if camera_shutter(cfg.shutter) != Some(s) {
            bail!("{origin}: shutter = {} contradicts the camera, whose shutter mode is {s}", cfg.shutter.name());
        }
    }
    let (w, h) = applied.image_size();
    if (h as usize, w as usize) != (cfg.rows, cfg.cols) {
        bail!(
            "{origin}: rows = {}, cols = {} contradict the camera, which delivers {h} x {w} images (rows x cols; set --roi to match)",
            cfg.rows,
            cfg.cols
        );
    }
    Ok(())
}
