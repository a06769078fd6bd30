//! A folder of consecutive captures to one continuous video: [`SequenceRequest`] ->
//! [`SequenceOutcome`], in two steps so that a front-end can size its progress report:
//! [`SequenceRequest::load`] reads and places the captures and resolves tau once for
//! all of them ([`LoadedSequence`]); [`LoadedSequence::solve`] solves and writes.

use crate::io::sensor_files::SensorFiles;
use crate::io::sequence_input::{load_capture_folder, SequenceInput};
use crate::io::sequence_output::{write_sequence, CaptureEntry, SequenceSummary};
use crate::io::IoError;
use crate::model::capture::CaptureConfig;
use crate::request::RequestError;
use crate::solve::lipschitz::EigenStore;
use crate::solve::problem::{InvalidSetting, SolveParams, ValidSettings};
use crate::solve::reconstruct::Hooks;
pub use crate::solve::sequence::{Mode, TimeSource};
use crate::solve::sequence::{Sequence, SequenceError, SequenceVideo, TimeGrid};
use ndarray::ArrayView3;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// A capture folder (as `capture` or `simulate --captures` writes it) to solve as one
/// video.
pub struct SequenceRequest<'a> {
    pub capture_dir: &'a Path,
    /// The PSF (rows, cols, channels), its name, and whether it is the calibration's.
    pub psf: ArrayView3<'a, f32>,
    pub psf_name: &'a str,
    pub psf_clean: bool,
    pub cfg: &'a CaptureConfig,
    /// The capture description's name for the summary.
    pub config_name: String,
    pub sensor: &'a SensorFiles,
    pub settings: &'a ValidSettings,
    pub mode: Mode,
    /// Place the captures from their sequence numbers times this period instead of
    /// their device timestamps.
    pub frame_period_us: Option<f64>,
    /// Streaming: frames of the result so far each window re-solves (default: K / 4).
    pub overlap_frames: Option<usize>,
    /// Streaming: start every window from the result so far.
    pub warm_start: bool,
    /// Joint: refuse when the solve needs more bytes (`None`: 90% of the available
    /// memory or ROLLCAM_MEMORY_LIMIT_GB).
    pub memory_limit_bytes: Option<u64>,
    /// A video (frames, rows, cols) on the global grid to report PSNR against.
    pub truth: Option<&'a Path>,
}

/// The captures read and placed on one time grid, tau resolved: ready to solve.
pub struct LoadedSequence<'a> {
    pub request: &'a SequenceRequest<'a>,
    pub input: SequenceInput,
    pub grid: TimeGrid,
    pub sequence: Sequence,
    /// The parameters of every solve (tau resolved once, on the whole sequence).
    pub params: SolveParams,
    truth: Option<Vec<f32>>,
}

/// What a sequence gave: the video and its solves' reports, the folder's files.
pub struct SequenceOutcome {
    pub video: SequenceVideo,
    pub seconds: f64,
    pub files: Vec<PathBuf>,
}

impl<'a> SequenceRequest<'a> {
    /// Read the captures, place them on the time grid, check the truth's shape and
    /// resolve tau against the whole sequence's scale.
    pub fn load(&'a self) -> Result<LoadedSequence<'a>, RequestError> {
        check_settings(self.settings)?;
        let cfg = self.cfg;
        crate::solve::plan::refuse_in_sequence(self.sensor.keyframes.len()).map_err(|e| RequestError::Invalid(format!("{}: {e}", self.config_name)))?;
        let input = load_capture_folder(self.capture_dir, self.psf, self.psf_name, cfg, &self.sensor.input(None, self.psf_clean), self.frame_period_us)?;
        let weights = cfg.timing().weights().map_err(SequenceError::from)?;
        let grid = TimeGrid::new(&input.start_us, &weights, input.source).map_err(SequenceError::from)?;
        tracing::info!(captures = grid.captures(), frames = grid.frames, gaps = grid.gap_frames().len(), max_residue_us = grid.max_residue_us(), "time grid");
        let sequence = Sequence::new(cfg, weights, input.psf.clone(), grid.clone(), input.raws.clone()).with_masks(input.masks.clone());
        let (f, mv, nv) = sequence.video_shape();
        let truth = match self.truth {
            Some(p) => {
                let t = crate::io::read_truth(p)?;
                let (tk, tm, tn, tc) = t.dim();
                if (tk, tm, tn, tc) != (f, mv, nv, 1) {
                    return Err(RequestError::Invalid(format!(
                        "{}: shape {:?} does not match the sequence video's (frames, rows, cols, channels) = {:?}",
                        p.display(),
                        [tk, tm, tn, tc],
                        [f, mv, nv, 1]
                    )));
                }
                Some(t.iter().cloned().collect::<Vec<f32>>())
            }
            None => None,
        };
        let params = self.settings.resolve(&sequence, cfg.fov);
        let prior = params.prior(false);
        crate::solve::tau::check_l1(prior.l1_rel, prior.tau, &sequence, false).map_err(|e| RequestError::Invalid(e.to_string()))?;
        Ok(LoadedSequence { request: self, input, grid, sequence, params, truth })
    }
}

/// Whether consecutive captures can be solved with `settings` (one tau for all, so no
/// held-out search; no still start): a front-end may ask before any work.
pub fn check_settings(settings: &ValidSettings) -> Result<(), InvalidSetting> {
    let invalid = |(field, value, expected)| InvalidSetting { field, value, expected };
    crate::solve::start::check_for_sequence(settings.start).map_err(invalid)?;
    crate::solve::sequence::solve::check_prior(settings).map_err(invalid)?;
    crate::solve::tau_search::check_for_sequence(settings).map_err(invalid)
}

impl LoadedSequence<'_> {
    /// Frames of the result so far each streaming window re-solves.
    pub fn overlap_frames(&self) -> usize {
        self.request.overlap_frames.unwrap_or((self.grid.capture_frames / 4).max(1))
    }

    /// Solves the mode runs (one joint solve, or one per capture).
    pub fn solves(&self) -> usize {
        if self.request.mode == Mode::Joint {
            1
        } else {
            self.grid.captures()
        }
    }

    /// Solve as the request's mode asks and write the folder `out`.
    pub fn solve(&self, out: &Path, cache: &dyn EigenStore, hooks: &Hooks) -> Result<SequenceOutcome, RequestError> {
        let r = self.request;
        let truth_name = r.truth.map(|p| p.display().to_string()).unwrap_or_default();
        let t = self.truth.as_deref().map(|t| (t, truth_name.as_str()));
        let (seq, params) = (&self.sequence, &self.params);
        let t0 = Instant::now();
        let video = match r.mode {
            Mode::Joint => {
                let limit = r.memory_limit_bytes.unwrap_or_else(|| crate::io::ByteBudget::system().limit_bytes);
                seq.solve_joint(params, t, cache, hooks, limit)
            }
            Mode::Streaming => seq.solve_streaming(params, self.overlap_frames(), r.warm_start, t, cache, hooks),
            Mode::Separate => seq.solve_separate(params, t, cache, hooks),
        }
        .map_err(RequestError::SequenceSolve)?;
        let seconds = t0.elapsed().as_secs_f64();
        let files = self.write(out, &video, seconds)?;
        Ok(SequenceOutcome { video, seconds, files })
    }

    fn write(&self, out: &Path, video: &SequenceVideo, seconds: f64) -> Result<Vec<PathBuf>, IoError> {
        let (r, input, grid) = (self.request, &self.input, &self.grid);
        let (f, mv, nv) = self.sequence.video_shape();
        let summary = SequenceSummary {
            rollcam_version: env!("CARGO_PKG_VERSION"),
            capture_dir: r.capture_dir.display().to_string(),
            psf: r.psf_name.to_string(),
            config: r.config_name.clone(),
            truth: r.truth.map(|p| p.display().to_string()),
            capture: r.cfg,
            params: &self.params,
            mode: r.mode,
            overlap_frames: (r.mode == Mode::Streaming).then_some(self.overlap_frames()),
            time_source: input.source,
            timestamp_period_us: input.timestamp_period_us,
            max_residue_us: grid.max_residue_us(),
            video_shape: [f, mv, nv, 1],
            frame_time_us: grid.frame_time_us,
            frames_per_second: 1e6 / grid.frame_time_us,
            frames_per_capture: grid.capture_frames,
            captures: CaptureEntry::list(grid, &input.files, &input.sequence, &input.raw_dark),
            skipped: &input.skipped,
            gap_frames: grid.gap_frames(),
            shared_frames: grid.shared_frames(),
            coverage: &grid.coverage,
            psf_dark_level: input.psf_dark,
            dark_level_estimated: input.dark_estimated,
            calibration: r.sensor.calibration_name(),
            background: r.sensor.background_name(),
            sensor: &input.sensor,
            solves: &video.solves,
            seconds,
            joint_memory_bytes: self.sequence.joint_bytes(),
            psnr_db: video.error.map(|e| e.psnr_db),
            rel_error: video.error.map(|e| e.rel_error),
            files: Vec::new(),
        };
        write_sequence(out, video, grid, summary)
    }
}
