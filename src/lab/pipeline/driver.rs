//! The session's threads: [`run`] starts acquisition, the raw writer and the workers
//! on a camera and ticks (Ctrl-C, `session.json`, previews) until they end;
//! [`resume`] runs the workers alone over what a session left unreconstructed.

use super::folder::{RAW_DIR, REC_DIR};
use super::lock::SessionLock;
use super::options::{Options, Policy};
use super::session::{self, FrameEntry, FrameState, SessionFile, State};
use super::shared::{refill, skip, Shared};
use super::worker::{FrameJob, FrameReconstructor, ReconstructFailure};
use super::{acquire, preview, writer};
use anyhow::{Context, Result};
use crossbeam_channel::{Receiver, Sender};
use rollcam_hw::camera::{Camera, Frame};
use rollcam_hw::record::{CaptureReader, CaptureSession, Recorder};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

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
    opts.check()?;
    let dir = opts.dir.clone();
    let _lock = super::lock::SessionLock::acquire(&dir)?;
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
        let wr =
            std::thread::Builder::new().name("record".into()).spawn_scoped(scope, move || writer::write_frames(rec, frame_rx, wtx, wrx, sh)).expect("spawn");
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
            let name = t.thread().name().unwrap_or("pipeline").to_string();
            if let Err(panic) = t.join() {
                let why = panic.downcast_ref::<String>().cloned().or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string())).unwrap_or_default();
                shared.with_session(|s| s.errors.push(format!("the {name} thread panicked: {why}")));
                shared.request_stop(State::Failed, format!("the {name} thread panicked"));
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
            f.status = FrameState::Reconstructing;
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
                    f.status = FrameState::Reconstructed;
                    f.video = Some(rel(&v.video));
                    f.rec = Some(rel(&job.out));
                    let lat = done_ns.saturating_sub(job.host_timestamp_ns) as f64 / 1e6;
                    f.latency_ms = Some(lat);
                    f.solve_s = Some(v.solve_s);
                    f.psnr_db = v.psnr_db;
                    f.converged = v.converged;
                    f.error = None;
                    f.sequence_frames = v.sequence_frames.clone();
                    tracing::info!(latency_ms = lat, solve_s = v.solve_s, psnr_db = v.psnr_db, converged = v.converged, "frame reconstructed");
                }
                Ok(Err(ReconstructFailure::Interrupted)) => {
                    f.status = FrameState::Recorded;
                    tracing::info!("reconstruction interrupted; the frame stays pending");
                }
                Ok(Err(ReconstructFailure::Error(e))) => {
                    f.status = FrameState::Failed;
                    let msg = format!("{e:#}");
                    tracing::error!("frame {} failed: {msg}", job.sequence);
                    f.error = Some(msg.clone());
                    err = Some(format!("frame {}: {msg}", job.sequence));
                }
                Err(p) => {
                    f.status = FrameState::Failed;
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
            // Frames were left unreconstructed: not finished, whatever stopped it first.
            if s.state == State::Finished {
                s.state = State::Stopped;
            }
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
/// refresh), with the counters re-derived from them. Failed and incomplete frames are
/// left as they are. The caller holds the session's lock, taken before it read the
/// session (a consecutive stream is rebuilt under it).
pub fn resume(
    _lock: &SessionLock,
    dir: &Path,
    reconstructor: Arc<dyn FrameReconstructor>,
    workers: usize,
    refresh: Duration,
    interrupt: Arc<AtomicBool>,
    retry_failed: bool,
) -> Result<SessionFile> {
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
            status: if incomplete { FrameState::Failed } else { FrameState::Recorded },
            video: None,
            rec: None,
            host_timestamp_ns: meta.host_timestamp_ns,
            latency_ms: None,
            solve_s: None,
            psnr_db: None,
            converged: None,
            incomplete,
            error: incomplete.then(|| "incomplete frame (not reconstructed)".to_string()),
            sequence_frames: None,
        });
    }
    session.frames.sort_by_key(|f| f.sequence);
    session.dropped_frames.sort_unstable();
    if retry_failed {
        // Frames whose reconstruction failed get another try; an incomplete frame (the
        // camera delivered part of it) has nothing more to give and stays failed.
        let mut retried = 0;
        for f in session.frames.iter_mut().filter(|f| f.status == FrameState::Failed && !f.incomplete) {
            f.status = FrameState::Recorded;
            f.error = None;
            retried += 1;
        }
        tracing::info!(frames = retried, "retrying failed frames");
    }
    let jobs: Vec<FrameJob> = session
        .frames
        .iter_mut()
        .filter(|f| session::needs_reconstruction(f))
        .map(|f| {
            f.status = FrameState::Recorded;
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
    // The counters from the frames on disk: a process killed between two writes of
    // session.json left them behind its frames (captured 0 with 30 recorded). Every
    // recorded frame was captured; a captured frame not on disk was not recorded.
    let recorded = session.frames.len() as u64;
    let captured = session.counters.captured.max(recorded + session.counters.unrecorded);
    let unrecorded = captured - recorded;
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
        let count = |st: FrameState| s.frames.iter().filter(|f| job_ids.contains(&f.sequence) && f.status == st).count();
        let c = (count(FrameState::Reconstructed), count(FrameState::Failed), count(FrameState::Recorded));
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
