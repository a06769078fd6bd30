//! `rollcam run --consecutive`: the stream of raw frames reconstructed as one
//! continuous video. [`ConsecutiveReconstructor`] feeds each recorded frame, in order,
//! to a [`Streamer`] (placed on the global time grid by its device timestamp or its
//! sequence number times a frame period, solved over its window warm-started from the
//! result so far) and rewrites `sequence/` (the video so far, `coverage.csv`,
//! `summary.json` with the frames that are final) after each. Frames must arrive in
//! sequence order: one worker, catch-up policy.

use super::session::{CapturePlacement, ConsecutiveSettings, FrameEntry, FrameState, SequenceStatus};
use super::worker::{FrameJob, FrameReconstructor, FrameVideo, ReconstructFailure};
use crate::io::cache::LipschitzCache;
use crate::io::output::OutputSet;
use crate::io::sensor_files::SensorFiles;
use crate::io::sequence_output::{write_sequence_with, CaptureEntry, SequenceSummary};
use crate::model::capture::CaptureConfig;
use crate::model::prepare::SensorReport;
use crate::request::sequence::{Mode, TimeSource};
use crate::request::stream::{Stream, StreamRequest};
use crate::request::{Hooks, SolveParams, TraceRow, ValidSettings};
use crate::solve::sequence::{SequenceVideo, TimeGrid};
use anyhow::{anyhow, bail, Context, Result};
use ndarray::Array3;
use rollcam_hw::camera::{FrameMeta, FrameStatus as RawStatus};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::time::Instant;

/// The continuous video's folder inside a session folder.
pub const SEQUENCE_DIR: &str = "sequence";

/// Warm-started streaming reconstruction of consecutive frames (see the module doc).
pub struct ConsecutiveReconstructor {
    cfg: CaptureConfig,
    psf: Array3<f32>,
    psf_name: String,
    config_name: String,
    session_dir: PathBuf,
    solver: ValidSettings,
    settings: ConsecutiveSettings,
    outputs: OutputSet,
    cache: &'static LipschitzCache,
    state: Mutex<StreamState>,
    /// The bench calibration and background, and whether the PSF is the calibration's.
    sensor: SensorFiles,
    psf_clean: bool,
}

#[derive(Default)]
struct StreamState {
    stream: Option<Stream<'static>>,
    /// First capture's sequence number and device timestamp.
    origin: Option<(u64, u64)>,
    last: Option<(u64, u64)>,
    files: Vec<String>,
    sequences: Vec<u64>,
    raw_dark: Vec<f64>,
    /// What sensor handling did to each capture.
    sensor: Vec<SensorReport>,
    psf_dark: f64,
    dark_estimated: bool,
    seconds: f64,
}

impl ConsecutiveReconstructor {
    /// `psf` is read now and checked against the capture size.
    pub fn new(
        cfg: CaptureConfig,
        psf: &Path,
        config_name: String,
        session_dir: &Path,
        solver: ValidSettings,
        settings: ConsecutiveSettings,
        outputs: OutputSet,
    ) -> Result<Self> {
        let psf_img = crate::io::read_image(psf)?;
        let (r, c, ch) = psf_img.dim();
        if (r, c) != (cfg.rows, cfg.cols) {
            bail!("{}: PSF is {r} x {c}, expected the capture's {} x {} (rows x cols)", psf.display(), cfg.rows, cfg.cols);
        }
        if ch != 1 {
            bail!("{}: PSF has {ch} channels; --consecutive reconstructs greyscale captures (one channel)", psf.display());
        }
        if let Some(p) = settings.frame_period_us {
            if !(p.is_finite() && p > 0.0) {
                bail!("--frame-period-us = {p}: expected a positive, finite time in microseconds");
            }
        }
        // The continuous video is the plain one: a scene declaration is not applied.
        let declared = crate::model::scene::SceneSpec::from_table(cfg.scene.as_ref()).with_context(|| config_name.clone())?;
        if !declared.is_plain() {
            tracing::warn!("{config_name}: the [scene] declaration is not applied by --consecutive (it solves the plain video of every capture)");
        }
        // One cache for the life of the process: the streamer borrows it.
        let cache: &'static LipschitzCache = Box::leak(Box::new(LipschitzCache::default_location()));
        Ok(ConsecutiveReconstructor {
            cfg,
            psf: psf_img,
            psf_name: psf.display().to_string(),
            config_name,
            session_dir: session_dir.to_path_buf(),
            solver,
            settings,
            outputs,
            cache,
            state: Mutex::new(StreamState::default()),
            sensor: SensorFiles::default(),
            psf_clean: false,
        })
    }

    /// Every capture with this calibration and background; `psf_clean` when the PSF is
    /// the calibration's (already dark-subtracted).
    pub fn with_sensor(mut self, sensor: SensorFiles, psf_clean: bool) -> Self {
        self.sensor = sensor;
        self.psf_clean = psf_clean;
        self
    }

    /// The request every capture of the stream is prepared and solved under.
    fn request(&self) -> StreamRequest<'_> {
        StreamRequest {
            cfg: &self.cfg,
            psf: self.psf.view(),
            psf_name: &self.psf_name,
            psf_clean: self.psf_clean,
            sensor: &self.sensor,
            settings: &self.solver,
            overlap_frames: self.settings.overlap_frames,
            warm_start: self.settings.warm_start,
            source: match self.settings.frame_period_us {
                Some(period_us) => TimeSource::FramePeriod { period_us },
                None => TimeSource::DeviceTimestamps,
            },
        }
    }

    /// `--resume`: feed the frames the session already reconstructed, in order, so the
    /// stream continues where it stopped (every window is solved again: the solves are
    /// deterministic, the video is the one the session had). Only frames before the
    /// first one still to do are fed; a reconstructed frame after it is refused
    /// (the stream would lose its order).
    pub fn rebuild(&self, dir: &Path, frames: &[FrameEntry]) -> Result<usize> {
        let first_todo = frames.iter().filter(|f| super::session::needs_reconstruction(f)).map(|f| f.sequence).min();
        let done: Vec<&FrameEntry> = frames.iter().filter(|f| f.status == FrameState::Reconstructed).collect();
        if let Some(t) = first_todo {
            if let Some(late) = done.iter().find(|f| f.sequence > t) {
                bail!(
                    "{}: frame {} is reconstructed but frame {t} before it is not: the consecutive stream cannot be continued in order",
                    dir.join(super::session::SESSION_FILE).display(),
                    late.sequence
                );
            }
        }
        let stop = AtomicBool::new(false);
        for f in &done {
            let job = FrameJob {
                sequence: f.sequence,
                raw: dir.join(&f.raw),
                host_timestamp_ns: f.host_timestamp_ns,
                out: dir.join(format!("{}/frame_{:06}", super::folder::REC_DIR, f.sequence)),
            };
            self.push(&job, &stop, false).map_err(|e| anyhow!("rebuilding the stream at frame {}: {e}", f.sequence))?;
        }
        Ok(done.len())
    }

    fn push(&self, job: &FrameJob, stop: &AtomicBool, write_frame: bool) -> Result<FrameVideo, ReconstructFailure> {
        let mut st = self.state.lock().unwrap_or_else(|p| p.into_inner());
        let st = &mut *st;
        let (meta, raw) = read_frame(&job.raw)?;
        if meta.status != RawStatus::Complete {
            return Err(anyhow!("{}: not a complete frame", job.raw.display()).into());
        }
        if let Some((prev, _)) = st.last {
            if job.sequence <= prev {
                return Err(anyhow!("frame {} arrived after frame {prev}: consecutive captures must arrive in order", job.sequence).into());
            }
        }
        let raw_name = job.raw.display().to_string();
        let request = self.request();
        let p = request.prepare(raw.view(), &raw_name).map_err(anyhow::Error::from)?;
        let (seq0, t0) = *st.origin.get_or_insert((job.sequence, meta.device_timestamp_ns));
        let start_us = match self.settings.frame_period_us {
            Some(period) => (job.sequence - seq0) as f64 * period,
            None => {
                if let Some((_, prev_ts)) = st.last {
                    if meta.device_timestamp_ns == 0 {
                        return Err(anyhow!(
                            "{}: device_timestamp_ns is 0 (the camera gave no timestamp): pass --frame-period-us P to place the captures from their sequence numbers",
                            job.raw.with_extension("json").display()
                        )
                        .into());
                    }
                    if meta.device_timestamp_ns <= prev_ts {
                        return Err(anyhow!(
                            "{}: device_timestamp_ns = {} is not after the previous frame's ({prev_ts}): the timestamps are unreliable; pass --frame-period-us P",
                            job.raw.with_extension("json").display(),
                            meta.device_timestamp_ns
                        )
                        .into());
                    }
                }
                (meta.device_timestamp_ns - t0) as f64 / 1e3
            }
        };
        let stream = st.stream.get_or_insert_with(|| request.stream(self.cache));
        let on_row = |_: usize, _: &TraceRow| {};
        let hooks = Hooks { on_row: &on_row, stop };
        let t = Instant::now();
        let pushed = stream.push(p, start_us, &hooks).map_err(anyhow::Error::from)?;
        let step = pushed.step;
        st.seconds += t.elapsed().as_secs_f64();
        if st.files.is_empty() {
            st.psf_dark = pushed.psf_dark;
            st.dark_estimated = pushed.dark_estimated;
        }
        st.last = Some((job.sequence, meta.device_timestamp_ns));
        st.files.push(raw_name);
        st.sequences.push(job.sequence);
        st.raw_dark.push(pushed.raw_dark);
        st.sensor.push(pushed.sensor);
        if stop.load(Ordering::Relaxed) {
            return Err(ReconstructFailure::Interrupted);
        }
        let stream = st.stream.as_ref().expect("set above");
        let streamer = stream.streamer().expect("one capture pushed");
        let grid = streamer.grid().expect("one capture pushed").clone();
        let c = grid.captures() - 1;
        let frames = grid.frames_of(c);
        let prev_end = if c == 0 { frames.start } else { grid.frames_of(c - 1).end.min(frames.start) };
        let placement = CapturePlacement {
            frames: [frames.start, frames.end],
            capture: c,
            start_us: grid.start_us[c],
            gap_frames_before: (prev_end..frames.start).filter(|&f| grid.coverage[f] == 0.0).collect(),
        };
        let params = stream.params().expect("set with the streamer").clone();
        let status = SequenceStatus {
            dir: SEQUENCE_DIR.into(),
            captures: grid.captures(),
            frames: grid.frames,
            final_frames: step.final_frames.end,
            frame_time_us: grid.frame_time_us,
            gap_frames: grid.gap_frames(),
            tau: params.tau,
        };
        let (kf, mv, nv) = streamer.shape();
        let video = SequenceVideo { video: streamer.video().to_vec(), shape: (kf, mv, nv), solves: streamer.solves().to_vec(), error: None };
        // The capture's frames as they stand now (its preview: the temporal maximum).
        let fl = mv * nv;
        let mut preview = Array3::from_elem((mv, nv, 1), f32::NEG_INFINITY);
        for f in frames.clone() {
            for (i, &v) in video.video[f * fl..(f + 1) * fl].iter().enumerate() {
                let cell = &mut preview[(i / nv, i % nv, 0)];
                if v > *cell {
                    *cell = v;
                }
            }
        }
        if write_frame {
            self.write(st, &grid, &video, &params, &status).map_err(|e| anyhow!("{}: {e:#}", self.session_dir.join(SEQUENCE_DIR).display()))?;
            let report = serde_json::json!({
                "capture": c,
                "sequence": job.sequence,
                "placement": &placement,
                "solve": &step.report,
                "final_frames": status.final_frames,
                "video": format!("../../{SEQUENCE_DIR}/video.npy"),
            });
            let text = serde_json::to_vec_pretty(&report).expect("serialises");
            std::fs::create_dir_all(&job.out).with_context(|| format!("{}: cannot create the folder", job.out.display()))?;
            rollcam_hw::record::write_atomic(&job.out, "summary.json", &text).map_err(anyhow::Error::from)?;
        }
        Ok(FrameVideo {
            video: self.session_dir.join(SEQUENCE_DIR).join("video.npy"),
            solve_s: step.report.stats.seconds,
            psnr_db: None,
            converged: None,
            preview,
            sequence_frames: Some(placement),
            sequence: Some(status),
        })
    }

    /// Rewrite `sequence/` (every file atomically, `summary.json` last).
    fn write(&self, st: &StreamState, grid: &TimeGrid, video: &SequenceVideo, params: &SolveParams, status: &SequenceStatus) -> Result<()> {
        let captures = CaptureEntry::list(grid, &st.files, &st.sequences, &st.raw_dark);
        let (kf, mv, nv) = video.shape;
        let summary = SequenceSummary {
            rollcam_version: env!("CARGO_PKG_VERSION"),
            capture_dir: self.session_dir.join(super::folder::RAW_DIR).display().to_string(),
            psf: self.psf_name.clone(),
            config: self.config_name.clone(),
            truth: None,
            capture: &self.cfg,
            params,
            mode: Mode::Streaming,
            overlap_frames: Some(self.settings.overlap_frames.unwrap_or((grid.capture_frames / 4).max(1))),
            time_source: grid.source,
            timestamp_period_us: None,
            max_residue_us: grid.max_residue_us(),
            video_shape: [kf, mv, nv, 1],
            frame_time_us: grid.frame_time_us,
            frames_per_second: 1e6 / grid.frame_time_us,
            frames_per_capture: grid.capture_frames,
            captures,
            skipped: &[],
            gap_frames: grid.gap_frames(),
            shared_frames: grid.shared_frames(),
            coverage: &grid.coverage,
            psf_dark_level: st.psf_dark,
            dark_level_estimated: st.dark_estimated,
            calibration: self.sensor.calibration_name(),
            background: self.sensor.background_name(),
            sensor: &st.sensor,
            solves: &video.solves,
            seconds: st.seconds,
            joint_memory_bytes: 0,
            psnr_db: None,
            rel_error: None,
            files: Vec::new(),
        };
        let mut extra = serde_json::Map::new();
        extra.insert("live".into(), serde_json::json!({ "final_frames": status.final_frames, "warm_start": self.settings.warm_start }));
        write_sequence_with(&self.session_dir.join(SEQUENCE_DIR), video, grid, summary, extra, self.outputs)?;
        Ok(())
    }
}

/// At the end of a session that left nothing to do: every frame of the continuous
/// video is final (no capture follows). Updates `session.json` and
/// `sequence/summary.json`; returns the session as written.
pub fn finalize(dir: &Path, mut session: super::session::SessionFile) -> Result<super::session::SessionFile> {
    let Some(st) = session.sequence.as_mut() else { return Ok(session) };
    if !session.pending.is_empty() || st.final_frames == st.frames {
        return Ok(session);
    }
    st.final_frames = st.frames;
    let frames = st.frames;
    let summary = dir.join(SEQUENCE_DIR).join("summary.json");
    let mut v: serde_json::Value = serde_json::from_slice(
        &crate::io::input::read_bounded(&summary, crate::io::input::MAX_TEXT_BYTES).with_context(|| format!("{}: cannot read", summary.display()))?,
    )
    .with_context(|| format!("{}: expected a sequence summary", summary.display()))?;
    v["live"]["final_frames"] = frames.into();
    rollcam_hw::record::write_atomic(&dir.join(SEQUENCE_DIR), "summary.json", &serde_json::to_vec_pretty(&v).expect("serialises"))?;
    session.write(dir)?;
    Ok(session)
}

impl FrameReconstructor for ConsecutiveReconstructor {
    fn reconstruct(&self, job: &FrameJob, stop: &AtomicBool) -> Result<FrameVideo, ReconstructFailure> {
        self.push(job, stop, true)
    }
}

/// A recorded frame's sidecar and pixels (as `f32`, one channel).
fn read_frame(raw: &Path) -> Result<(FrameMeta, Array3<f32>)> {
    let side = raw.with_extension("json");
    let bytes = crate::io::input::read_bounded(&side, crate::io::input::MAX_TEXT_BYTES)
        .with_context(|| format!("{}: cannot read the frame's metadata", side.display()))?;
    let meta: FrameMeta = serde_json::from_slice(&bytes).with_context(|| format!("{}: expected frame metadata", side.display()))?;
    let (w, h, pixels) = rollcam_hw::record::decode_tiff16(raw)?;
    if (w, h) != (meta.width, meta.height) {
        bail!("{}: image is {w} x {h}, its sidecar says {} x {}", raw.display(), meta.width, meta.height);
    }
    let img = Array3::from_shape_vec((h as usize, w as usize, 1), pixels.iter().map(|&v| v as f32).collect())
        .map_err(|_| anyhow!("{}: {} samples for {w} x {h}", raw.display(), pixels.len()))?;
    Ok((meta, img))
}
