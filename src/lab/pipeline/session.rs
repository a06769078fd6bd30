//! The session file `session.json`: what a live session (or a finished one) has done,
//! frame by frame, with counters and latencies. The pipeline keeps one [`SessionFile`]
//! behind a mutex; every thread updates it, and the ticker writes it atomically (temp
//! file + rename) at least once a second and at the end. Readers (the live page,
//! `run --resume`) only ever see a complete file.

use crate::solve::problem::ValidSettings;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Format tag written into `session.json`.
pub const SESSION_FORMAT: &str = "rollcam-session/1";
/// Session file name inside a session folder.
pub const SESSION_FILE: &str = "session.json";

/// Where a session stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum State {
    /// Acquiring and/or reconstructing.
    Running,
    /// Ended as asked: `--frames` reached, the replay ran out, or a resume completed.
    Finished,
    /// Ended by the user (Ctrl-C).
    Stopped,
    /// Ended by a fault: camera disconnected, disk full, a recording error.
    Failed,
}

/// What happened to one recorded frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FrameState {
    /// On disk, waiting for a worker (in the work queue or the on-disk backlog).
    Recorded,
    /// A worker is solving it.
    Reconstructing,
    /// Its video folder is complete (`summary.json` written).
    Reconstructed,
    /// Passed over by `--live` for a newer frame, or left when a drain was abandoned;
    /// `run --resume` reconstructs it.
    Skipped,
    /// Its reconstruction failed (error, panic, or an incomplete raw frame).
    Failed,
}

/// Frame counters. At the end of a session `captured = recorded + unrecorded` and
/// `recorded = reconstructed + skipped + failed + queued` (no frame is reconstructing
/// once the workers have stopped).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Counters {
    /// Frames delivered by the camera with pixel data (complete or incomplete).
    pub captured: u64,
    /// Captured frames whose raw TIFF and sidecar are on disk.
    pub recorded: u64,
    /// Recorded frames whose video folder is complete.
    pub reconstructed: u64,
    /// Recorded frames passed over (`--live`, or an abandoned drain).
    pub skipped: u64,
    /// Frames the camera announced but never delivered (gaps in its frame counter).
    pub dropped: u64,
    /// Recorded frames whose reconstruction failed.
    pub failed: u64,
    /// Recorded frames waiting for a worker (work queue + on-disk backlog).
    pub queued: u64,
    /// Frames being solved right now.
    #[serde(default)]
    pub reconstructing: u64,
    /// Captured frames that could not be recorded (disk full, write error).
    #[serde(default)]
    pub unrecorded: u64,
    /// Recorded frames that arrived incomplete (truncated buffer; counted in `failed`).
    #[serde(default)]
    pub incomplete: u64,
}

/// Latency from a frame's timestamp (host arrival) to its `summary.json`, milliseconds.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Latency {
    pub last: Option<f64>,
    pub median: Option<f64>,
    pub max: Option<f64>,
    /// From the first row's exposure start to the last row's exposure end of one frame
    /// (the capture's timing): the time a frame takes before it can arrive.
    #[serde(default)]
    pub capture_span: Option<f64>,
    /// `median` and `max` plus `capture_span`: from the start of the frame's exposure to
    /// its finished video. A lower bound: the transfer from camera to host is not known.
    #[serde(default)]
    pub from_exposure_start_median: Option<f64>,
    #[serde(default)]
    pub from_exposure_start_max: Option<f64>,
}

/// One recorded frame in `session.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameEntry {
    /// Position in the acquisition (0, 1, 2, ...; dropped frames keep their number).
    pub sequence: u64,
    /// Device frame counter.
    pub frame_id: u64,
    /// Raw TIFF, relative to the session folder (`raw/frame_NNNNNN.tiff`).
    pub raw: String,
    pub status: FrameState,
    /// Reconstructed video (float32 TIFF stack), relative to the session folder.
    pub video: Option<String>,
    /// The frame's reconstruction folder (`rec/frame_NNNNNN`), once complete.
    #[serde(default)]
    pub rec: Option<String>,
    /// Host arrival time, ns since the Unix epoch.
    pub host_timestamp_ns: u64,
    /// Exposure (arrival) to finished video, milliseconds.
    pub latency_ms: Option<f64>,
    /// Solver wall time, seconds.
    #[serde(default)]
    pub solve_s: Option<f64>,
    /// PSNR against the truth, when a truth was given.
    #[serde(default)]
    pub psnr_db: Option<f64>,
    /// Whether the frame's solve converged (false: its iteration cap or time budget
    /// ended it first; absent: not reconstructed, or by a sequence).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub converged: Option<bool>,
    /// Whether the camera delivered only part of the frame.
    #[serde(default)]
    pub incomplete: bool,
    pub error: Option<String>,
    /// `--consecutive`: where this capture lies in the continuous video.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sequence_frames: Option<CapturePlacement>,
}

/// `--consecutive`: one capture's place in the continuous video.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CapturePlacement {
    /// Global video frames the capture covers, `[first, end)`.
    pub frames: [usize; 2],
    /// Index of the capture in the sequence (dropped and incomplete frames have none).
    pub capture: usize,
    /// First-row exposure start relative to the first capture, microseconds.
    pub start_us: f64,
    /// Frames between the previous capture's end and this one's start that no capture
    /// covers (gap frames, only the temporal TV constrains them).
    pub gap_frames_before: Vec<usize>,
}

/// `--consecutive`: how the stream is reconstructed (kept for `--resume`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ConsecutiveSettings {
    /// Frames of the result so far each window re-solves.
    pub overlap_frames: Option<usize>,
    /// Captures placed by sequence number times this period (None: device timestamps).
    pub frame_period_us: Option<f64>,
    /// Each window starts from the result so far.
    pub warm_start: bool,
}

/// `--consecutive`: the continuous video so far (`sequence/`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SequenceStatus {
    /// The folder, relative to the session folder.
    pub dir: String,
    pub captures: usize,
    /// Video frames so far, and how many of them are final.
    pub frames: usize,
    pub final_frames: usize,
    pub frame_time_us: f64,
    /// Frames no capture covers.
    pub gap_frames: Vec<usize>,
    /// TV weight used for every window (fixed by the first capture unless `--tau`).
    pub tau: f32,
}

/// How the session was set up.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SessionConfig {
    /// The capture description every frame is reconstructed with (also `capture.toml`).
    pub capture: crate::model::capture::CaptureConfig,
    /// The PSF inside the session folder, and where it came from.
    pub psf: String,
    pub psf_source: String,
    /// `catch-up` (every frame, in order) or `live` (newest first, older ones skipped).
    pub policy: String,
    /// Work-queue length; frames beyond it wait in the on-disk backlog.
    pub queue: usize,
    pub workers: usize,
    pub frames_requested: Option<u64>,
    pub min_free_mb: u64,
    pub solver: ValidSettings,
    /// Per-frame truth videos (`truth_NNNNNN.npy`) for PSNR in the summaries.
    #[serde(default)]
    pub truth_dir: Option<String>,
    /// Files each frame's folder gets (`full`, `video`, `minimal`).
    #[serde(default)]
    pub outputs: crate::io::output::OutputSet,
    /// Set when the frames are reconstructed as one continuous video.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub consecutive: Option<ConsecutiveSettings>,
    /// A background frame as shot, subtracted from every raw in place of the dark (the
    /// calibration folder is `capture.calibration`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub background: Option<String>,
    /// The PSF is a calibration's, already dark-subtracted.
    #[serde(default)]
    pub psf_dark_subtracted: bool,
}

/// Latest previews.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Previews {
    /// `preview/latest_raw.png`: the latest recorded raw frame, 8-bit, display-scaled.
    pub raw: Option<String>,
    pub raw_sequence: Option<u64>,
    /// `preview/latest_frame.png`: the temporal maximum projection of the latest video.
    pub frame: Option<String>,
    pub frame_sequence: Option<u64>,
    /// What `frame` shows.
    pub frame_kind: String,
}

/// Content of `session.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SessionFile {
    pub format: String,
    pub state: State,
    /// `backend:id` of the camera.
    pub camera: String,
    pub started_utc: String,
    pub updated_utc: String,
    pub finished_utc: Option<String>,
    /// Why the session ended (or stopped acquiring).
    pub stop_reason: Option<String>,
    pub counters: Counters,
    pub latency_ms: Latency,
    pub frames: Vec<FrameEntry>,
    /// Sequence numbers of frames the camera dropped (no raw data exists).
    #[serde(default)]
    pub dropped_frames: Vec<u64>,
    /// Recorded frames not yet reconstructed: what `run --resume` will do.
    #[serde(default)]
    pub pending: Vec<u64>,
    pub errors: Vec<String>,
    pub config: SessionConfig,
    /// LED controller settings as programmed (the driver's sync summary).
    #[serde(default)]
    pub led: Option<serde_json::Value>,
    #[serde(default)]
    pub preview: Previews,
    /// Resumes of this session, in order.
    #[serde(default)]
    pub resumes: Vec<String>,
    /// The live page's address while `--serve` serves this session.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub live_url: Option<String>,
    /// `--consecutive`: the continuous video so far.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sequence: Option<SequenceStatus>,
}

impl SessionFile {
    pub fn new(camera: String, config: SessionConfig) -> Self {
        let now = utc_now();
        SessionFile {
            format: SESSION_FORMAT.into(),
            state: State::Running,
            camera,
            started_utc: now.clone(),
            updated_utc: now,
            finished_utc: None,
            stop_reason: None,
            counters: Counters::default(),
            latency_ms: Latency::default(),
            frames: Vec::new(),
            dropped_frames: Vec::new(),
            pending: Vec::new(),
            errors: Vec::new(),
            config,
            led: None,
            preview: Previews { frame_kind: "temporal maximum projection".into(), ..Previews::default() },
            resumes: Vec::new(),
            live_url: None,
            sequence: None,
        }
    }

    /// Read a session folder's `session.json`.
    pub fn load(dir: &Path) -> anyhow::Result<Self> {
        use anyhow::Context;
        let path = dir.join(SESSION_FILE);
        let text = crate::io::input::read_bounded(&path, crate::io::input::MAX_TEXT_BYTES)
            .with_context(|| format!("{}: cannot read the session file", path.display()))?;
        Self::from_json_slice(&text, &path.display().to_string())
    }

    /// Parse the bytes of a `session.json`; `origin` (the file) starts every error
    /// message. The format tag must be this version's.
    pub fn from_json_slice(bytes: &[u8], origin: &str) -> anyhow::Result<Self> {
        use anyhow::Context;
        let s: SessionFile = serde_json::from_slice(bytes).with_context(|| format!("{origin}: expected a rollcam session file ({SESSION_FORMAT})"))?;
        if s.format != SESSION_FORMAT {
            anyhow::bail!("{origin}: format '{}', expected '{SESSION_FORMAT}'", s.format);
        }
        Ok(s)
    }

    pub fn frame_mut(&mut self, sequence: u64) -> Option<&mut FrameEntry> {
        // Frames are appended in sequence order.
        let i = self.frames.binary_search_by_key(&sequence, |f| f.sequence).ok()?;
        self.frames.get_mut(i)
    }

    /// Recompute counters, latency summary and the pending list from the frames.
    pub fn refresh(&mut self) {
        let c = &mut self.counters;
        let count = |s: FrameState| self.frames.iter().filter(|f| f.status == s).count() as u64;
        c.recorded = self.frames.len() as u64;
        c.reconstructed = count(FrameState::Reconstructed);
        c.skipped = count(FrameState::Skipped);
        c.failed = count(FrameState::Failed);
        c.queued = count(FrameState::Recorded);
        c.reconstructing = count(FrameState::Reconstructing);
        c.incomplete = self.frames.iter().filter(|f| f.incomplete).count() as u64;
        c.dropped = self.dropped_frames.len() as u64;
        let mut lat: Vec<f64> = self.frames.iter().filter_map(|f| f.latency_ms).collect();
        lat.sort_by(f64::total_cmp);
        self.latency_ms.median = match lat.len() {
            0 => None,
            n if n % 2 == 1 => Some(lat[n / 2]),
            n => Some(0.5 * (lat[n / 2 - 1] + lat[n / 2])),
        };
        self.latency_ms.max = lat.last().copied();
        let timing = self.config.capture.timing();
        let last_start_us = timing.raw_row_starts_us().into_iter().fold(0.0, f64::max);
        let span = (last_start_us + timing.exposure_us) / 1e3;
        self.latency_ms.capture_span = Some(span);
        self.latency_ms.from_exposure_start_median = self.latency_ms.median.map(|v| v + span);
        self.latency_ms.from_exposure_start_max = self.latency_ms.max.map(|v| v + span);
        self.pending = self.frames.iter().filter(|f| needs_reconstruction(f)).map(|f| f.sequence).collect();
        self.updated_utc = utc_now();
    }

    /// Write `dir/session.json` atomically.
    pub fn write(&self, dir: &Path) -> Result<(), crate::io::IoError> {
        let path = dir.join(SESSION_FILE);
        let json = serde_json::to_string_pretty(self).expect("session serialises");
        crate::io::write_text_atomic(&path, &json)
    }
}

/// Whether a frame still wants a video: recorded, queued, interrupted or skipped;
/// not finished, not failed.
pub fn needs_reconstruction(f: &FrameEntry) -> bool {
    matches!(f.status, FrameState::Recorded | FrameState::Reconstructing | FrameState::Skipped)
}

pub use crate::io::utc::utc_string;

/// The current time as [`utc_string`].
pub fn utc_now() -> String {
    utc_string(rollcam_hw::camera::host_now_ns())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_strings() {
        assert_eq!(utc_string(0), "1970-01-01T00:00:00.000Z");
        // 2000-02-29 12:34:56.789 UTC
        assert_eq!(utc_string(951_827_696_789_000_000), "2000-02-29T12:34:56.789Z");
        // 2026-11-22 16:40:00 UTC
        assert_eq!(utc_string(1_795_365_600_000_000_000), "2026-11-22T16:40:00.000Z");
    }

    #[test]
    fn refresh_counts_and_median() {
        let cfg = SessionConfig {
            capture: crate::model::capture::CaptureConfig::new(4, 4, 10.0, 30.0, Default::default()),
            psf: "psf.tiff".into(),
            psf_source: "x".into(),
            policy: "catch-up".into(),
            queue: 2,
            workers: 1,
            frames_requested: None,
            min_free_mb: 0,
            solver: ValidSettings::default(),
            truth_dir: None,
            outputs: Default::default(),
            consecutive: None,
            background: None,
            psf_dark_subtracted: false,
        };
        let mut s = SessionFile::new("sim:x".into(), cfg);
        for (i, (st, lat)) in [
            (FrameState::Reconstructed, Some(30.0)),
            (FrameState::Reconstructed, Some(10.0)),
            (FrameState::Skipped, None),
            (FrameState::Recorded, None),
            (FrameState::Failed, None),
        ]
        .into_iter()
        .enumerate()
        {
            s.frames.push(FrameEntry {
                sequence: i as u64,
                frame_id: i as u64,
                raw: format!("raw/frame_{i:06}.tiff"),
                status: st,
                video: None,
                rec: None,
                host_timestamp_ns: 0,
                latency_ms: lat,
                solve_s: None,
                psnr_db: None,
                converged: None,
                incomplete: false,
                error: None,
                sequence_frames: None,
            });
        }
        s.dropped_frames.push(9);
        s.refresh();
        let c = &s.counters;
        assert_eq!((c.recorded, c.reconstructed, c.skipped, c.queued, c.failed, c.dropped), (5, 2, 1, 1, 1, 1));
        assert_eq!(s.latency_ms.median, Some(20.0));
        assert_eq!(s.latency_ms.max, Some(30.0));
        // Dual shutter, 4 rows, 10 us lines: the last rows start at 10 us and expose for
        // 30 us, so a frame spans 40 us before it can arrive.
        assert_eq!(s.latency_ms.capture_span, Some(0.04));
        assert_eq!(s.latency_ms.from_exposure_start_median, Some(20.04));
        assert_eq!(s.latency_ms.from_exposure_start_max, Some(30.04));
        assert_eq!(s.pending, vec![2, 3]);
        let back: SessionFile = serde_json::from_str(&serde_json::to_string(&s).unwrap()).unwrap();
        assert_eq!(back, s);
        assert!(serde_json::to_string(&s).unwrap().contains("\"state\":\"running\""));
    }
}
