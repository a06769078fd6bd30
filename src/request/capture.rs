//! One capture to one video: [`CaptureRequest`] -> [`CaptureOutcome`].

use crate::io::output::{write_reconstruction_set, Inputs, OutputSet};
use crate::io::sensor_files::SensorFiles;
use crate::io::IoError;
use crate::model::capture::CaptureConfig;
use crate::model::prepare::{prepare, Prepared};
use crate::model::scene::{Colour, SceneSpec};
use crate::request::RequestError;
use crate::solve::lipschitz::EigenStore;
use crate::solve::problem::{Problem, SolveParams, ValidSettings};
use crate::solve::reconstruct::{reconstruct, Hooks, Reconstruction, SolveOptions};
use ndarray::{ArrayView3, ArrayView4};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// One capture to reconstruct, as read by the front-end: the raw and PSF images
/// (rows, cols, channels) with the names the summary gives them, the capture
/// description, the sensor's calibration and background, the checked solve settings,
/// the scene declaration and an optional truth.
pub struct CaptureRequest<'a> {
    pub raw: ArrayView3<'a, f32>,
    pub raw_name: &'a str,
    /// The raw file's sample full scale (its bit depth), when it came from a file.
    pub raw_full_scale: Option<f64>,
    pub psf: ArrayView3<'a, f32>,
    pub psf_name: &'a str,
    /// The PSF is the calibration's (already dark-subtracted).
    pub psf_clean: bool,
    pub cfg: &'a CaptureConfig,
    pub sensor: &'a SensorFiles,
    pub settings: &'a ValidSettings,
    /// Scene declaration; `None`: capture.toml's `[scene]` (in `cfg`).
    pub scene: Option<SceneSpec>,
    /// A video (frames, rows, cols, channels) to report PSNR against, and its name.
    pub truth: Option<(ArrayView4<'a, f32>, &'a str)>,
}

/// A request whose data are prepared (dark levels, calibration, downsampling), ready
/// to solve.
pub struct PreparedCapture<'a> {
    pub request: &'a CaptureRequest<'a>,
    pub prepared: Prepared,
}

/// What one capture gave: the video and its reports, the parameters solved with (tau
/// resolved), the prepared data and the solve's seconds.
pub struct CaptureOutcome {
    pub reconstruction: Reconstruction,
    pub params: SolveParams,
    pub prepared: Prepared,
    pub seconds: f64,
}

impl<'a> CaptureRequest<'a> {
    /// Prepare the raw and PSF.
    pub fn prepare(&'a self) -> Result<PreparedCapture<'a>, RequestError> {
        let sensor = self.sensor.input(self.raw_full_scale, self.psf_clean);
        let prepared = prepare(self.raw, self.raw_name, self.psf, self.psf_name, self.cfg, &sensor)?;
        Ok(PreparedCapture { request: self, prepared })
    }

    /// Prepare and reconstruct.
    pub fn run(&'a self, cache: &dyn EigenStore, hooks: &Hooks) -> Result<CaptureOutcome, RequestError> {
        self.prepare()?.reconstruct(cache, hooks)
    }
}

impl PreparedCapture<'_> {
    /// Channels the solve runs: one for a grey declaration of an RGB raw (for progress
    /// totals).
    pub fn solved_channels(&self) -> usize {
        let r = self.request;
        let declared = r.scene.clone().or_else(|| SceneSpec::from_table(r.cfg.scene.as_ref()).ok()).unwrap_or_default();
        if declared.colour == Colour::Grey {
            1
        } else {
            self.prepared.raw.len()
        }
    }

    /// Build the problem and solve it ([`crate::solve::reconstruct::reconstruct`]).
    pub fn reconstruct(self, cache: &dyn EigenStore, hooks: &Hooks) -> Result<CaptureOutcome, RequestError> {
        self.reconstruct_after(cache, hooks, |_| {})
    }

    /// [`Self::reconstruct`], calling `before` with the built problem before the solve
    /// starts (to estimate its time: [`crate::solve::estimate::estimate`]).
    pub fn reconstruct_after(self, cache: &dyn EigenStore, hooks: &Hooks, before: impl FnOnce(&Problem)) -> Result<CaptureOutcome, RequestError> {
        let r = self.request;
        let problem = Problem::new(&self.prepared, r.cfg, r.cfg.fov)?;
        before(&problem);
        let options = SolveOptions { scene: r.scene.clone(), ..SolveOptions::default() };
        let t0 = Instant::now();
        let (reconstruction, params) = reconstruct(&problem, r.settings, &options, r.truth, cache, hooks)?;
        let seconds = t0.elapsed().as_secs_f64();
        drop(problem);
        Ok(CaptureOutcome { reconstruction, params, prepared: self.prepared, seconds })
    }
}

impl CaptureOutcome {
    /// Write the video folder `dir` (the files of `set`; `inputs` names what it was made
    /// from in summary.json); returns the files written.
    pub fn write(&self, dir: &Path, cfg: &CaptureConfig, inputs: &Inputs, set: OutputSet) -> Result<Vec<PathBuf>, IoError> {
        write_reconstruction_set(dir, &self.reconstruction, cfg, &self.params, inputs, &self.prepared, self.seconds, set)
    }
}
