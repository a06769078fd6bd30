//! One capture to one video: [`CaptureRequest`] -> [`CaptureOutcome`].

use crate::io::budget::check_reconstruction;
use crate::io::output::{write_reconstruction_set, Inputs, OutputSet, Solved};
use crate::io::sensor_files::SensorFiles;
use crate::io::IoError;
use crate::model::capture::CaptureConfig;
use crate::model::prepare::{prepare, Prepared, SensorReport};
use crate::model::scene::{Colour, SceneSpec};
use crate::request::RequestError;
use crate::solve::estimate::SolveEstimate;
use crate::solve::lipschitz::EigenStore;
use crate::solve::plan::{Processes, SolveOptions, SolvePlan};
use crate::solve::problem::{Problem, SolveParams, ValidSettings};
use crate::solve::reconstruct::{Hooks, Reconstruction};
use ndarray::{ArrayView3, ArrayView4};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// One capture to reconstruct, as read by the front-end: the raw and PSF images
/// (rows, cols, channels) with the names the summary gives them, the capture
/// description, the sensor's calibration and background, the checked solve settings,
/// the scene declaration and an optional truth. Built with [`CaptureRequest::new`] and
/// the `with_*` methods for what a front-end has beyond the images and settings.
pub struct CaptureRequest<'a> {
    pub raw: ArrayView3<'a, f32>,
    pub raw_name: &'a str,
    /// The raw file's sample full scale (its bit depth), when it came from a file.
    pub raw_full_scale: Option<f64>,
    pub psf: ArrayView3<'a, f32>,
    pub psf_name: &'a str,
    /// The PSF is the calibration's (already dark-subtracted).
    pub psf_clean: bool,
    /// The PSF's own black offset, counts (`None`: the capture's dark level or the
    /// PSF file's, else estimated).
    pub psf_dark_level: Option<f64>,
    pub cfg: &'a CaptureConfig,
    /// Where the capture description came from, for the summary (`None`: not a file).
    pub config_name: Option<&'a str>,
    pub sensor: &'a SensorFiles,
    pub settings: &'a ValidSettings,
    /// Scene declaration; `None`: capture.toml's `[scene]` (in `cfg`).
    pub scene: Option<SceneSpec>,
    /// A video (frames, rows, cols, channels) to report PSNR against, and its name.
    pub truth: Option<(ArrayView4<'a, f32>, &'a str)>,
    /// Told what sensor handling did to the capture, once it is prepared (default:
    /// [`log_sensor_warnings`]).
    pub on_sensor: &'a (dyn Fn(&SensorReport) + Sync),
}

/// The default sensor report: each warning in the log.
pub fn log_sensor_warnings(report: &SensorReport) {
    for w in &report.warnings {
        tracing::warn!("{w}");
    }
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
    /// A request for `raw` with `psf` (as read, dark level included), nothing declared
    /// beyond `cfg`, no truth, sensor warnings logged.
    pub fn new(
        raw: ArrayView3<'a, f32>,
        raw_name: &'a str,
        psf: ArrayView3<'a, f32>,
        psf_name: &'a str,
        cfg: &'a CaptureConfig,
        sensor: &'a SensorFiles,
        settings: &'a ValidSettings,
    ) -> Self {
        CaptureRequest {
            raw,
            raw_name,
            raw_full_scale: None,
            psf,
            psf_name,
            psf_clean: false,
            psf_dark_level: None,
            cfg,
            config_name: None,
            sensor,
            settings,
            scene: None,
            truth: None,
            on_sensor: &log_sensor_warnings,
        }
    }

    /// The raw file's sample full scale ([`crate::io::sample_full_scale`]).
    pub fn with_full_scale(mut self, full_scale: Option<f64>) -> Self {
        self.raw_full_scale = full_scale;
        self
    }

    /// The PSF's own black offset, counts (`None`: the capture's or the PSF file's).
    pub fn with_psf_dark_level(mut self, level: Option<f64>) -> Self {
        self.psf_dark_level = level;
        self
    }

    /// Whether the PSF is the calibration's (already dark-subtracted).
    pub fn with_clean_psf(mut self, clean: bool) -> Self {
        self.psf_clean = clean;
        self
    }

    /// The capture description's file, named in the summary.
    pub fn with_config_name(mut self, name: Option<&'a str>) -> Self {
        self.config_name = name;
        self
    }

    /// A scene declaration over capture.toml's `[scene]` (`None`: the file's).
    pub fn with_scene(mut self, scene: Option<SceneSpec>) -> Self {
        self.scene = scene;
        self
    }

    /// A video to report the error against, and its name.
    pub fn with_truth(mut self, truth: Option<(ArrayView4<'a, f32>, &'a str)>) -> Self {
        self.truth = truth;
        self
    }

    /// Where the sensor report goes once the capture is prepared (e.g. the terminal).
    pub fn with_sensor_report(mut self, on_sensor: &'a (dyn Fn(&SensorReport) + Sync)) -> Self {
        self.on_sensor = on_sensor;
        self
    }

    /// What the video was made from, as summary.json names it: the request's names.
    pub fn inputs(&self) -> Inputs {
        Inputs {
            raw: Some(self.raw_name.to_string()),
            psf: Some(self.psf_name.to_string()),
            config: self.config_name.map(str::to_string),
            truth: self.truth.map(|(_, name)| name.to_string()),
            calibration: self.sensor.calibration_name(),
            background: self.sensor.background_name(),
        }
    }

    /// Prepare the raw and PSF, check that the solve fits the memory budget
    /// ([`crate::io::budget::check_reconstruction`]) and report the sensor.
    pub fn prepare(&'a self) -> Result<PreparedCapture<'a>, RequestError> {
        let prepared = self.prepare_data()?;
        check_reconstruction(self.cfg, self.cfg.fov, prepared.raw.len(), 1).map_err(Box::new)?;
        (self.on_sensor)(&prepared.sensor);
        Ok(PreparedCapture { request: self, prepared })
    }

    /// The raw and PSF prepared, nothing checked or reported.
    pub(crate) fn prepare_data(&self) -> Result<Prepared, RequestError> {
        let mut sensor = self.sensor.input(self.raw_full_scale, self.psf_clean);
        // The PSF is judged by its own file's bit depth, which may differ from the raw's.
        sensor.psf_full_scale = crate::io::sample_full_scale(self.psf_name);
        // A raw file's own black level (a DNG's) is its dark when nothing else gives one.
        sensor.file_dark_level = crate::io::sample_black_level(self.raw_name);
        sensor.psf_file_dark_level = crate::io::sample_black_level(self.psf_name);
        sensor.psf_dark_level = self.psf_dark_level;
        Ok(prepare(self.raw, self.raw_name, self.psf, self.psf_name, self.cfg, &sensor)?)
    }

    /// Channels the solve runs: one for a grey declaration of an RGB raw (for progress
    /// totals).
    pub fn solved_channels(&self) -> usize {
        let declared = self.scene.clone().or_else(|| SceneSpec::from_table(self.cfg.scene.as_ref()).ok()).unwrap_or_default();
        if declared.colour == Colour::Grey {
            1
        } else {
            self.raw.dim().2
        }
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
        self.request.solved_channels()
    }

    /// Build the problem, decide its plan and solve it.
    pub fn reconstruct(self, cache: &dyn EigenStore, hooks: &Hooks) -> Result<CaptureOutcome, RequestError> {
        Ok(self.reconstruct_after(cache, hooks, |_| true)?.expect("a solve nothing declines starts"))
    }

    /// [`Self::reconstruct`], calling `before` at each [`Before`] stage: with the
    /// solve's estimated time ([`crate::solve::estimate::estimate`], recorded in the
    /// reconstruction) once the problem is built, then with the plan
    /// ([`SolvePlan::decide`]) once it is decided; `before` returning false declines the
    /// solve (`None`: nothing solved).
    pub fn reconstruct_after(
        self,
        cache: &dyn EigenStore,
        hooks: &Hooks,
        mut before: impl FnMut(Before) -> bool,
    ) -> Result<Option<CaptureOutcome>, RequestError> {
        let r = self.request;
        let problem = Problem::new(&self.prepared, r.cfg, r.cfg.fov)?;
        let estimate = crate::solve::estimate::estimate(&problem, r.settings, self.solved_channels());
        if !before(Before::Estimate(&estimate)) {
            return Ok(None);
        }
        let options = SolveOptions { scene: r.scene.clone(), ..SolveOptions::default() };
        let t0 = Instant::now();
        let plan = SolvePlan::decide(&problem, r.settings, &options, Processes::One, cache, hooks.stop)?;
        if !before(Before::Plan(&plan)) {
            return Ok(None);
        }
        let mut reconstruction = crate::solve::reconstruct::solve(&problem, &plan, r.truth, cache, hooks)?;
        reconstruction.estimated_seconds = Some(estimate.seconds);
        let seconds = t0.elapsed().as_secs_f64();
        let params = plan.params;
        reconstruction.add_fit(&problem, &params);
        drop(problem);
        Ok(Some(CaptureOutcome { reconstruction, params, prepared: self.prepared, seconds }))
    }
}

/// The stages a front-end is told of before a solve, each of which it may decline.
pub enum Before<'a> {
    /// The solve's estimated time, before anything is solved.
    Estimate(&'a SolveEstimate),
    /// The plan decided (its still checks and weight search made), before the video is
    /// solved.
    Plan(&'a SolvePlan),
}

impl CaptureOutcome {
    /// Write the video folder `dir` (the files of `set`; `inputs` names what it was made
    /// from in summary.json); returns the files written.
    pub fn write(&self, dir: &Path, cfg: &CaptureConfig, inputs: &Inputs, set: OutputSet) -> Result<Vec<PathBuf>, IoError> {
        let solved = Solved { reconstruction: &self.reconstruction, cfg, params: &self.params, inputs, prepared: &self.prepared, seconds: self.seconds };
        write_reconstruction_set(dir, solved, set)
    }
}
