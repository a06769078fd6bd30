//! Consecutive captures as they arrive (the live pipeline's `--consecutive`):
//! [`StreamRequest::prepare`] prepares each capture and reports its sensor;
//! [`Stream::push`] places it on the global time grid and solves its window,
//! warm-started from the result so far. The weight is resolved once, on the first
//! capture (its scale and noise stand for the stream's: the later captures are not
//! seen yet).

use crate::io::sensor_files::SensorFiles;
use crate::model::capture::CaptureConfig;
use crate::model::noise::noise_sigma;
use crate::model::op::adjoint_peak;
use crate::model::prepare::{prepare, Prepared, SensorReport};
use crate::request::capture::log_sensor_warnings;
use crate::request::RequestError;
use crate::solve::lipschitz::EigenStore;
use crate::solve::problem::{build_operator, SolveParams, ValidSettings};
use crate::solve::reconstruct::Hooks;
use crate::solve::sequence::{SequenceError, StreamStep, StreamWindows, Streamer, TimeSource};
use crate::solve::tau::{LazyScale, Noise};
use ndarray::ArrayView3;

/// What every capture of a stream shares: the capture description, the PSF as read,
/// the sensor, the settings and the streaming choices.
pub struct StreamRequest<'a> {
    pub cfg: &'a CaptureConfig,
    pub psf: ArrayView3<'a, f32>,
    pub psf_name: &'a str,
    /// The PSF is the calibration's (already dark-subtracted).
    pub psf_clean: bool,
    pub sensor: &'a SensorFiles,
    pub settings: &'a ValidSettings,
    /// Frames of the result so far each window re-solves (default: K / 4).
    pub overlap_frames: Option<usize>,
    /// Start every window from the result so far.
    pub warm_start: bool,
    /// How the captures are placed in time.
    pub source: TimeSource,
}

/// The stream so far: nothing before the first push.
pub struct Stream<'c> {
    cfg: CaptureConfig,
    settings: ValidSettings,
    overlap_frames: Option<usize>,
    warm_start: bool,
    source: TimeSource,
    cache: &'c dyn EigenStore,
    streamer: Option<Streamer<'c>>,
    params: Option<SolveParams>,
}

/// What one capture pushed gave: the window's solve, and what preparing the capture
/// found (its dark level, the PSF's, whether they were estimated, its sensor report).
pub struct Pushed {
    pub step: StreamStep,
    pub raw_dark: f64,
    pub psf_dark: f64,
    pub dark_estimated: bool,
    pub sensor: SensorReport,
}

impl StreamRequest<'_> {
    /// Prepare one capture (`raw`, named `raw_name`) and log its sensor warnings.
    pub fn prepare(&self, raw: ArrayView3<f32>, raw_name: &str) -> Result<Prepared, RequestError> {
        let p = prepare(raw, raw_name, self.psf, self.psf_name, self.cfg, &self.sensor.input(None, self.psf_clean))?;
        log_sensor_warnings(&p.sensor);
        Ok(p)
    }

    /// An empty stream; the Lipschitz constants are kept in `cache`.
    pub fn stream<'c>(&self, cache: &'c dyn EigenStore) -> Stream<'c> {
        Stream {
            cfg: self.cfg.clone(),
            settings: self.settings.clone(),
            overlap_frames: self.overlap_frames,
            warm_start: self.warm_start,
            source: self.source,
            cache,
            streamer: None,
            params: None,
        }
    }
}

impl<'c> Stream<'c> {
    /// Add the next capture (prepared; its first row's exposure starts at `start_us`
    /// on the stream's clock) and solve its window. The first capture resolves the
    /// weight: its `max(A^T b)` and noise are measured only for a rule that reads them.
    pub fn push(&mut self, mut p: Prepared, start_us: f64, hooks: &Hooks) -> Result<Pushed, RequestError> {
        let plane = p.raw.remove(0);
        let mask = std::mem::take(&mut p.data_mask);
        if self.streamer.is_none() {
            let psf_plane = p.psf.remove(0);
            let weights = self.cfg.timing().weights().map_err(SequenceError::from)?;
            let first_capture_scale = LazyScale {
                peak: || adjoint_peak(&build_operator(&psf_plane, &weights, self.cfg.fov, &mask), &plane.data),
                noise: || {
                    noise_sigma(&plane.data, plane.rows, plane.cols, &mask).map(|sigma| Noise {
                        sigma,
                        frames: weights.frames(),
                        keyframes: 0,
                        static_dynamic: false,
                    })
                },
            };
            let params = self.settings.resolve(&first_capture_scale, self.cfg.fov);
            let prior = params.prior(false);
            crate::solve::tau::check_l1(prior.l1_rel, prior.tau, &first_capture_scale, false).map_err(|e| RequestError::Invalid(e.to_string()))?;
            let overlap = self.overlap_frames.unwrap_or((weights.frames() / 4).max(1));
            let windows = StreamWindows { overlap, warm: self.warm_start };
            // The shutter weights, computed once here, serve every capture of the stream.
            self.streamer = Some(Streamer::new(&self.cfg, weights, psf_plane, params.clone(), windows, self.source, self.cache));
            self.params = Some(params);
        }
        let streamer = self.streamer.as_mut().expect("set above");
        let step = streamer.push(plane, mask, start_us, hooks)?;
        Ok(Pushed { step, raw_dark: p.raw_dark, psf_dark: p.psf_dark, dark_estimated: p.dark_estimated, sensor: p.sensor })
    }

    /// The streaming solver, once a capture is pushed.
    pub fn streamer(&self) -> Option<&Streamer<'c>> {
        self.streamer.as_ref()
    }

    /// The parameters of every window (the weight resolved on the first capture).
    pub fn params(&self) -> Option<&SolveParams> {
        self.params.as_ref()
    }
}
