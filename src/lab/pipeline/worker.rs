//! Reconstruction of one recorded frame: the one replaceable call of the pipeline
//! ([`FrameReconstructor`]). The default, [`SolverReconstructor`], reads the raw TIFF
//! back from disk, prepares it with the session's PSF and capture description, solves
//! with FISTA + TV and writes the frame's folder (`rec/frame_NNNNNN/`, `summary.json`
//! last). Another reconstructor (warm-started consecutive captures, say) plugs in by
//! implementing the trait.

use crate::io::cache::LipschitzCache;
use crate::io::output::OutputSet;
use crate::io::sensor_files::SensorFiles;
use crate::model::capture::CaptureConfig;
use crate::request::capture::CaptureRequest;
use crate::solve::reconstruct::Hooks;
use anyhow::{Context, Result};
use ndarray::{Array3, Axis};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use crate::solve::problem::ValidSettings;

/// One recorded frame to reconstruct.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameJob {
    pub sequence: u64,
    /// The recorded raw TIFF.
    pub raw: PathBuf,
    /// Host arrival time, ns since the Unix epoch (latency is measured from here).
    pub host_timestamp_ns: u64,
    /// The folder to write (`rec/frame_NNNNNN`).
    pub out: PathBuf,
}

/// What a reconstruction produced.
#[derive(Clone, Debug)]
pub struct FrameVideo {
    /// The video file (float32 TIFF stack).
    pub video: PathBuf,
    /// Solver wall time, seconds.
    pub solve_s: f64,
    pub psnr_db: Option<f64>,
    /// Whether every channel's solve converged (`None`: no solve ran for this frame).
    pub converged: Option<bool>,
    /// One image of the video for the preview (rows, cols, channels).
    pub preview: Array3<f32>,
    /// Consecutive captures: where this capture lies in the continuous video.
    pub sequence_frames: Option<super::session::CapturePlacement>,
    /// Consecutive captures: the continuous video after this capture.
    pub sequence: Option<super::session::SequenceStatus>,
}

/// Why a reconstruction did not produce a video.
#[derive(Debug, thiserror::Error)]
pub enum ReconstructFailure {
    /// The session is being abandoned; the frame stays pending for `--resume`.
    #[error("interrupted")]
    Interrupted,
    #[error("{0:#}")]
    Error(#[from] anyhow::Error),
}

/// Turns one recorded frame into its video folder. Called from several worker threads
/// at once; `stop` is raised when the session abandons its queue (second Ctrl-C): the
/// call should then return [`ReconstructFailure::Interrupted`] soon.
pub trait FrameReconstructor: Send + Sync {
    fn reconstruct(&self, job: &FrameJob, stop: &AtomicBool) -> Result<FrameVideo, ReconstructFailure>;
}

/// The solver of `rollcam reconstruct`, applied to each frame with one PSF and one
/// capture description.
pub struct SolverReconstructor {
    cfg: CaptureConfig,
    psf: Array3<f32>,
    psf_name: String,
    config_name: String,
    solver: ValidSettings,
    truth_dir: Option<PathBuf>,
    cache: LipschitzCache,
    outputs: OutputSet,
    /// The bench calibration and background, and whether the PSF is the calibration's.
    sensor: SensorFiles,
    psf_clean: bool,
}

impl SolverReconstructor {
    /// `psf` is read now (and checked against the capture size); `truth_dir` may hold
    /// `truth_NNNNNN.npy` videos to report PSNR against.
    pub fn new(cfg: CaptureConfig, psf: &Path, config_name: String, solver: ValidSettings, truth_dir: Option<PathBuf>) -> Result<Self> {
        let psf_img = crate::io::read_image(psf)?;
        let (r, c, _) = psf_img.dim();
        if (r, c) != (cfg.rows, cfg.cols) {
            anyhow::bail!("{}: PSF is {r} x {c}, expected the capture's {} x {} (rows x cols)", psf.display(), cfg.rows, cfg.cols);
        }
        Ok(SolverReconstructor {
            cfg,
            psf: psf_img,
            psf_name: psf.display().to_string(),
            config_name,
            solver,
            truth_dir,
            cache: LipschitzCache::default_location(),
            outputs: OutputSet::Full,
            sensor: SensorFiles::default(),
            psf_clean: false,
        })
    }

    /// Every frame with this calibration and background; `psf_clean` when the PSF is
    /// the calibration's (already dark-subtracted).
    pub fn with_sensor(mut self, sensor: SensorFiles, psf_clean: bool) -> Self {
        self.sensor = sensor;
        self.psf_clean = psf_clean;
        self
    }

    /// The description and sensor files of a raw frame recorded with its own key frames
    /// (`frame_NNNNNN.toml` beside it, [`crate::lab::keycam`]): the session's, with
    /// that frame's `[[keyframes]]`; `None` for a frame without.
    fn with_frame_keyframes(&self, raw: &Path) -> Result<Option<(CaptureConfig, SensorFiles)>> {
        let Some(path) = crate::lab::keycam::description_beside(raw) else { return Ok(None) };
        let frame = CaptureConfig::load(&path)?;
        let sensor = self.sensor.clone().with_keyframes(&frame.keyframes, Some(&path))?;
        Ok(Some((CaptureConfig { keyframes: frame.keyframes, ..self.cfg.clone() }, sensor)))
    }

    /// Which files each frame's folder gets (default: all).
    pub fn with_outputs(mut self, outputs: OutputSet) -> Self {
        self.outputs = outputs;
        self
    }
}

impl FrameReconstructor for SolverReconstructor {
    fn reconstruct(&self, job: &FrameJob, stop: &AtomicBool) -> Result<FrameVideo, ReconstructFailure> {
        let cfg = &self.cfg;
        let raw = crate::io::read_image(&job.raw).map_err(anyhow::Error::from)?;
        let raw_name = job.raw.display().to_string();
        let full_scale = crate::io::sample_full_scale(&job.raw);
        let truth_path = self.truth_dir.as_ref().map(|d| d.join(format!("truth_{:06}.npy", job.sequence))).filter(|p| p.is_file());
        let truth = match &truth_path {
            Some(p) => Some(crate::io::read_npy(p).map_err(anyhow::Error::from)?),
            None => None,
        };
        let truth_name = truth_path.as_ref().map(|p| p.display().to_string()).unwrap_or_default();
        let keyed = self.with_frame_keyframes(&job.raw)?;
        let (cfg, sensor) = keyed.as_ref().map_or((cfg, &self.sensor), |(c, s)| (c, s));
        let request = CaptureRequest::new(raw.view(), &raw_name, self.psf.view(), &self.psf_name, cfg, sensor, &self.solver)
            .with_full_scale(full_scale)
            .with_clean_psf(self.psf_clean)
            .with_config_name(Some(&self.config_name))
            .with_truth(truth.as_ref().map(|t| (t.view(), truth_name.as_str())));
        let on_row = |_: usize, _: &crate::solve::trace::TraceRow| {};
        let hooks = Hooks { on_row: &on_row, stop };
        let prepared = request.prepare().map_err(anyhow::Error::from)?;
        let outcome = prepared.reconstruct(&self.cache, &hooks).with_context(|| format!("{raw_name}: reconstruction failed"))?;
        let rec = &outcome.reconstruction;
        if stop.load(std::sync::atomic::Ordering::Relaxed) {
            return Err(ReconstructFailure::Interrupted);
        }
        let inputs = request.inputs();
        outcome.write(&job.out, cfg, &inputs, self.outputs).map_err(anyhow::Error::from)?;
        let psnr_db = rec.channels.iter().filter_map(|c| c.stats.error.map(|e| e.psnr_db)).reduce(f64::min);
        Ok(FrameVideo {
            video: job.out.join(self.outputs.video_file()),
            solve_s: outcome.seconds,
            psnr_db,
            converged: Some(rec.converged()),
            preview: max_projection(&rec.video),
            sequence_frames: None,
            sequence: None,
        })
    }
}

/// The temporal maximum of a (frame, row, col, channel) video: every spot that lit up
/// at any time during the capture.
pub fn max_projection(video: &ndarray::Array4<f32>) -> Array3<f32> {
    video.fold_axis(Axis(0), f32::NEG_INFINITY, |&m, &v| if v > m { v } else { m })
}
