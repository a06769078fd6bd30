//! How a session runs: the backlog [`Policy`], the [`Options`] of a session and the
//! [`TestHooks`] that make faults happen on purpose.

use std::path::PathBuf;
use std::time::Duration;

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

/// The longest work queue: frames held in memory ahead of the workers (the backlog
/// beyond it waits on disk, so a longer queue only costs memory).
pub const MAX_QUEUE: usize = 1024;

/// The most reconstruction workers of one session.
pub const MAX_WORKERS: usize = 256;

impl Options {
    /// The one check of a session's options; a bad value names its flag.
    pub fn check(&self) -> anyhow::Result<()> {
        if !(1..=MAX_QUEUE).contains(&self.queue) {
            anyhow::bail!("--queue = {}: expected 1 to {MAX_QUEUE} frames (the backlog beyond the queue waits on disk)", self.queue);
        }
        if !(1..=MAX_WORKERS).contains(&self.workers) {
            anyhow::bail!("--workers = {}: expected 1 to {MAX_WORKERS} workers", self.workers);
        }
        Ok(())
    }

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
