//! A bench session assembled from plain data ([`SessionRequest`], what `rollcam run`'s
//! flags say): the camera opened ([`open_bench`], through [`open_camera`]: the
//! simulated camera, a replayed recording or a device) and configured from the capture
//! description resolved against it, the PSF and the ground truth found, the LED
//! controller programmed ([`SessionLed`]), the session folder, the session file and
//! the raw capture description written, the reconstructor chosen ([`reconstructor`]).
//! [`PreparedSession::run`] then runs it through the pipeline.
//!
//! The capture description of a real or replayed camera is resolved here
//! ([`resolve_capture`]): the `capture.toml` read through `crate::io`, the request's
//! [`CaptureOverrides`] merged over it by the model. Error messages name the
//! `rollcam run` flag behind each field.

use super::consecutive::{self, ConsecutiveReconstructor};
use super::driver;
use super::folder::{create_folder, PsfInput, CAPTURE_TOML, PSF_TIFF, RAW_DIR};
use super::options::Options;
use super::session::{ConsecutiveSettings, SessionConfig, SessionFile};
use super::worker::{FrameReconstructor, SolverReconstructor};
pub use crate::io::capture_file::resolve_capture;
use crate::io::output::OutputSet;
use crate::io::sensor_files::SensorFiles;
use crate::lab::camera::{open_camera, CameraOptions, CameraTarget, OpenCamera};
use crate::lab::hardware;
use crate::lab::keycam::{KeyCameraRequest, KeyedCamera};
use crate::lab::simcam::{self, SceneSource, SimCamera, SimCameraSpec, SimScene};
use crate::model::capture::{CaptureConfig, CaptureOverrides, Fov};
use crate::model::shutter::ShutterMode;
use crate::solve::problem::ValidSettings;
use anyhow::{anyhow, bail, Context, Result};
use rollcam_hw::camera::replay::ReplayOptions;
use rollcam_hw::camera::{Camera, CameraSettings, CameraSpec};
use rollcam_hw::led::{ChannelConfig, LedController, LedSync, LinkOptions, LinkedEmulator, TriggerMode};
use rollcam_hw::record::{CaptureSession, SyncInfo};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

/// The simulated camera of a session: its scene, sensor and timing. `None` timing
/// values take the simulated camera's defaults ([`SimCameraSpec::new`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SimCameraRequest {
    /// `--sim-scene`: led-array or moving-disc; must agree with a scene named in the spec.
    /// Neither: led-array.
    pub scene: Option<String>,
    /// `--sim-size`: sensor rows and columns.
    pub rows: usize,
    pub cols: usize,
    /// `--sim-period-us`: LED periods of the led-array scene (empty: the scene's own).
    pub period_us: Vec<f64>,
    /// `--seed`: seed of the diffuser and the noise.
    pub seed: u64,
    pub line_time_us: Option<f64>,
    pub exposure_us: Option<f64>,
    /// Shutter mode to set on the simulated camera (default: its dual shutter).
    pub shutter: Option<ShutterMode>,
    pub downsample: Option<usize>,
    pub binning: Option<usize>,
    /// Video grid of the reconstructions.
    pub fov: Option<Fov>,
}

/// The camera of a session with what opening it needs.
#[derive(Clone, Debug)]
pub enum SessionCamera {
    /// The simulated camera (`sim`, `sim:<scene>`): it brings its own timing and PSF,
    /// and writes each frame's truth video to `sim/` in the session folder.
    Simulated { id: String, request: SimCameraRequest },
    /// A recorded capture folder played back, with its pace and injected faults.
    Replay { dir: PathBuf, options: ReplayOptions },
    /// A device.
    Device(CameraSpec),
}

/// The LED controller of a session, programmed before acquisition.
#[derive(Clone, Debug, PartialEq)]
pub struct LedRequest {
    /// `--led`: a serial port, or `emulator` for an in-process emulator.
    pub port: String,
    /// `--led-period-us`: one period per channel from channel 0, microseconds.
    pub period_us: Vec<u32>,
    /// `--led-duty`: duty cycle, 0 < duty < 1.
    pub duty: f64,
    /// `--led-phase-us`: delay from the trigger to each channel's first rising edge.
    pub phase_us: u32,
    /// `--led-trigger`: what starts the waveform.
    pub trigger: TriggerMode,
}

/// A bench session as plain data.
#[derive(Clone, Debug)]
pub struct SessionRequest {
    /// The camera as given (`--camera`), for messages.
    pub camera_name: String,
    pub camera: SessionCamera,
    /// `--config`: the bench's capture.toml (default for a replay: the replayed
    /// folder's). Not for the simulated bench.
    pub config: Option<PathBuf>,
    /// `--psf`: the PSF image (default: the replayed folder's psf.tiff, else a
    /// psf.tiff beside the config). Not for the simulated bench.
    pub psf: Option<PathBuf>,
    /// `--line-time-us`, `--exposure-us`, `--shutter`, `--downsample`, `--binning`,
    /// `--dark-level`, `--fov`: each one given replaces the config's value; without a
    /// config the timing ones are required. For real and replayed cameras (the
    /// simulated camera takes its own from [`SimCameraRequest`]).
    pub capture: CaptureOverrides,
    /// `--truth-dir`: ground-truth videos `truth_NNNNNN.npy` (default: the simulated
    /// bench's, or a replayed recording's own).
    pub truth_dir: Option<PathBuf>,
    /// Camera settings besides the timing (ROI, pixel format, trigger, frame rate,
    /// exposure output line); the timing comes from the capture description.
    pub camera_settings: CameraSettings,
    pub led: Option<LedRequest>,
    pub solver: ValidSettings,
    pub outputs: OutputSet,
    /// Reconstruct the frames as one continuous video.
    pub consecutive: Option<ConsecutiveSettings>,
    /// `--calibration`: the bench calibration folder (default: the capture
    /// description's `[calibration] dir`). Its PSF is used when `--psf` is not given.
    pub calibration: Option<PathBuf>,
    /// `--background`: a frame of the static background as shot.
    pub background: Option<PathBuf>,
    /// How the pipeline runs; `options.dir` is the session folder.
    pub options: Options,
    /// URL of the session's live page, recorded in `session.json`.
    pub live_url: Option<String>,
    /// `--keyframe-camera`: a key-frame camera fired with every frame; its frames and
    /// each raw frame's `[[keyframes]]` tables go beside the raw frames in `raw/`, and
    /// each frame reconstructs with its own.
    pub keyframe_camera: Option<KeyCameraRequest>,
}

/// Where a session's PSF comes from.
pub enum PsfSource {
    /// A calibration image on disk.
    File(PathBuf),
    /// The simulated bench's, in memory.
    Image(ndarray::Array3<f32>),
}

impl PsfSource {
    /// The PSF as the session folder takes it.
    pub fn input(&self) -> PsfInput<'_> {
        match self {
            PsfSource::File(p) => PsfInput::File(p),
            PsfSource::Image(img) => PsfInput::Image(img),
        }
    }
}

/// The bench of a session: the open, configured camera with its capture description,
/// PSF, ground truth and sensor files.
pub struct SessionBench {
    pub camera: OpenCamera,
    pub cfg: CaptureConfig,
    /// Where `cfg` came from (a file, "the command line", "simulated camera").
    pub cfg_origin: String,
    pub psf: PsfSource,
    /// The PSF's origin, for `session.json`.
    pub psf_source: String,
    /// The PSF is a calibration's (already dark-subtracted).
    pub psf_clean: bool,
    pub truth_dir: Option<PathBuf>,
    /// The calibration and background every frame uses.
    pub sensor: SensorFiles,
}

/// Open the camera ([`open_camera`]), configure it from the capture description and
/// find the PSF.
pub fn open_bench(req: &SessionRequest) -> Result<SessionBench> {
    let truth_flag = req.truth_dir.as_ref().map(|p| std::fs::canonicalize(p).with_context(|| format!("--truth-dir {}: not found", p.display()))).transpose()?;
    let (target, options, replay_dir) = match &req.camera {
        SessionCamera::Simulated { id, request } => {
            let options = CameraOptions { simulated: Some(sim_camera_spec(req, id, request)?), ..CameraOptions::default() };
            (CameraTarget::Simulated { id: id.clone() }, options, None)
        }
        SessionCamera::Replay { dir, options } => {
            (CameraTarget::Replay(dir.clone()), CameraOptions { replay: options.clone(), ..CameraOptions::default() }, Some(dir.clone()))
        }
        SessionCamera::Device(spec) => (CameraTarget::Device(spec.clone()), CameraOptions::default(), None),
    };
    match open_camera(&target, options)? {
        OpenCamera::Simulated(cam) => configure_simulated(req, cam, truth_flag),
        OpenCamera::Device(cam) => configure_device(req, cam, replay_dir, truth_flag),
    }
}

/// The bench's camera as the pipeline drives it: with the request's key-frame camera
/// fired beside it ([`KeyedCamera`], writing into the session's `raw/`), or alone.
fn session_camera(req: &SessionRequest, main: OpenCamera, cfg: &CaptureConfig) -> Result<Box<dyn Camera>> {
    Ok(match (&req.keyframe_camera, main) {
        (Some(key), main) => Box::new(KeyedCamera::open(main, key, cfg, &req.options.dir.join(RAW_DIR))?),
        (None, OpenCamera::Simulated(c)) => c,
        (None, OpenCamera::Device(c)) => c,
    })
}

/// A device or replayed recording: its capture description resolved from the config
/// and flags, then applied; the PSF found on disk.
fn configure_device(req: &SessionRequest, mut cam: Box<dyn Camera>, replay_dir: Option<PathBuf>, truth_flag: Option<PathBuf>) -> Result<SessionBench> {
    let name = &req.camera_name;
    let default_in = |file: &str| replay_dir.as_ref().map(|d| d.join(file)).filter(|p| p.is_file());
    let config = req.config.clone().or_else(|| default_in("capture.toml"));
    // Without --psf: the replay's own, else a psf.tiff beside the config file.
    let beside_config = || config.as_ref().and_then(|c| c.parent()).map(|d| d.join("psf.tiff")).filter(|p| p.is_file());
    let origin = config.as_ref().map(|p| p.display().to_string()).unwrap_or_else(|| format!("camera {name}"));
    let mut cfg = match config.as_deref() {
        Some(file) => {
            let current = cam.applied_settings()?;
            let (w, h) = match req.camera_settings.roi {
                Some(r) => (r.width, r.height),
                None => current.image_size(),
            };
            let cfg = resolve_capture(Some(file), &req.capture, (h as usize, w as usize))?;
            let settings = hardware::camera_settings(&cfg, req.camera_settings.clone());
            cam.configure(&settings).with_context(|| format!("configuring camera {name} with the timing of {origin}"))?;
            cfg
        }
        None => described_by_camera(cam.as_mut(), req)?,
    };
    let sensor = session_sensor(req, config.as_deref(), &mut cfg)?;
    // --psf, else the calibration's, else the replay's own, else a psf.tiff beside the config.
    let calibration_psf = sensor.psf_path();
    let psf_clean = req.psf.is_none() && calibration_psf.is_some();
    let psf = req.psf.clone().or(calibration_psf).or_else(|| default_in("psf.tiff")).or_else(beside_config).with_context(|| {
        format!("camera {name}: no PSF: give --psf or --calibration, or put psf.tiff beside the --config file (an image of a point source through the same optics, the size of the frames)")
    })?;
    // A replayed recording that carries its truth videos is compared against them.
    let recorded_truth = replay_dir.as_ref().filter(|d| d.join("truth_000000.npy").is_file()).map(|d| std::fs::canonicalize(d).unwrap_or_else(|_| d.clone()));
    Ok(SessionBench {
        camera: OpenCamera::Device(cam),
        cfg,
        cfg_origin: origin,
        psf_source: psf.display().to_string(),
        psf: PsfSource::File(psf),
        psf_clean,
        truth_dir: truth_flag.or(recorded_truth),
        sensor,
    })
}

/// Without a capture.toml: the camera configured with the flags given, and the
/// capture description of what it then applied ([`hardware::capture_config`]); a
/// field it does not report and no flag gives is refused by name.
fn described_by_camera(cam: &mut dyn Camera, req: &SessionRequest) -> Result<CaptureConfig> {
    let name = &req.camera_name;
    let given = &req.capture;
    let settings = CameraSettings {
        exposure_us: given.exposure_us,
        line_time_us: given.line_time_us,
        shutter: given.shutter.and_then(hardware::camera_shutter),
        ..req.camera_settings.clone()
    };
    let applied = cam.configure(&settings).with_context(|| format!("configuring camera {name}"))?;
    let (w, h) = applied.image_size();
    let cfg = hardware::capture_config(h as usize, w as usize, &applied, given).with_context(|| format!("camera {name}: no capture.toml given"))?;
    cfg.validate().with_context(|| format!("camera {name}: the timing it applied"))?;
    Ok(cfg)
}

/// The session's calibration and background, loaded; `cfg.calibration` becomes the
/// folder's absolute path, so the session's own `capture.toml` names it from anywhere.
fn session_sensor(req: &SessionRequest, config: Option<&Path>, cfg: &mut CaptureConfig) -> Result<SensorFiles> {
    let sensor =
        SensorFiles::load(req.calibration.as_deref(), req.background.as_deref(), config, cfg.calibration.as_ref())?.with_keyframes(&cfg.keyframes, config)?;
    if let Some(dir) = &sensor.calibration_dir {
        let abs = std::fs::canonicalize(dir).with_context(|| format!("calibration folder {}", dir.display()))?;
        cfg.calibration = Some(crate::model::capture::CalibrationRef { dir: abs.display().to_string() });
    }
    Ok(sensor)
}

/// The simulated camera a session asks for: the scene named by the spec or
/// `--sim-scene`, truth videos in `sim/` of the session.
fn sim_camera_spec(req: &SessionRequest, id: &str, sim: &SimCameraRequest) -> Result<SimCameraSpec> {
    if req.config.is_some() || req.psf.is_some() {
        bail!("--camera sim brings its own timing and PSF; --config and --psf apply to real and replayed cameras (use --line-time-us, --exposure-us, --shutter, --downsample, --binning)");
    }
    let scene_name = match (id, &sim.scene) {
        ("", Some(s)) => s.clone(),
        ("", None) => "led-array".into(),
        (id, None) => id.to_string(),
        (id, Some(s)) if id == s => s.clone(),
        (id, Some(s)) => bail!("--camera sim:{id} and --sim-scene {s} disagree"),
    };
    let mut scene: SimScene = scene_name.parse().map_err(|e: String| anyhow!("--sim-scene: {e}"))?;
    if let (SimScene::LedArray { period_us }, false) = (&mut scene, sim.period_us.is_empty()) {
        *period_us = sim.period_us.clone();
    }
    let d = SimCameraSpec::new(SceneSource::Catalogue(scene));
    // Refuse a sensor whose diffuser and frame planes (a few f32 images of its size)
    // cannot fit, before they are made; the session's own check then counts the solves.
    crate::io::ByteBudget::system()
        .check_array(
            || format!("the simulated camera's {} x {} sensor (its PSF and a frame's planes, 8 images as f32)", sim.rows, sim.cols),
            &[sim.rows, sim.cols],
            32,
        )
        .context("--sim-size")?;
    Ok(SimCameraSpec {
        rows: sim.rows,
        cols: sim.cols,
        line_time_us: sim.line_time_us.unwrap_or(d.line_time_us),
        exposure_us: sim.exposure_us.unwrap_or(d.exposure_us),
        frame_rate_hz: req.camera_settings.frame_rate_hz.unwrap_or(d.frame_rate_hz),
        seed: sim.seed,
        truth_dir: Some(req.options.dir.join("sim")),
        downsample: sim.downsample.unwrap_or(d.downsample),
        binning: sim.binning.unwrap_or(d.binning),
        ..d
    })
}

/// The simulated camera: timing and PSF its own (its calibration), truth videos where
/// its spec writes them.
fn configure_simulated(req: &SessionRequest, mut cam: Box<SimCamera>, truth_flag: Option<PathBuf>) -> Result<SessionBench> {
    let SessionCamera::Simulated { request: sim, .. } = &req.camera else { unreachable!("a simulated camera is opened for a simulated session") };
    let full = cam.applied_settings()?.roi;
    if let Some(roi) = req.camera_settings.roi.filter(|r| *r != full) {
        bail!(
            "--roi {}x{}+{}+{}: the simulated camera renders its whole {} x {} sensor only; set its size with --sim-size",
            roi.width,
            roi.height,
            roi.x,
            roi.y,
            full.height,
            full.width
        );
    }
    let mut settings = CameraSettings { trigger: req.camera_settings.trigger.clone(), frame_rate_hz: req.camera_settings.frame_rate_hz, ..Default::default() };
    if let Some(s) = sim.shutter {
        settings.shutter = hardware::camera_shutter(s);
    }
    cam.configure(&settings)?;
    let (psf, mut cfg) = simcam::calibration(&mut cam)?;
    if let Some(f) = sim.fov {
        cfg.fov = f;
    }
    let sensor = session_sensor(req, None, &mut cfg)?;
    // A calibration's PSF (the point-source shots `calibrate` made of this camera) is
    // the one the session reconstructs with, as for any camera; else the simulator's own.
    let (psf, psf_source, psf_clean) = match sensor.psf_path() {
        Some(file) => {
            tracing::info!(psf = %file.display(), "the calibration's PSF, not the simulator's");
            (PsfSource::File(file.clone()), file.display().to_string(), true)
        }
        None => (PsfSource::Image(psf), format!("simulated diffuser (seed {})", sim.seed), false),
    };
    Ok(SessionBench {
        camera: OpenCamera::Simulated(cam),
        cfg,
        cfg_origin: "simulated camera".into(),
        psf,
        psf_source,
        psf_clean,
        truth_dir: truth_flag.or(Some(req.options.dir.join("sim"))),
        sensor,
    })
}

/// The continuous-video reconstructor of a session folder `dir` whose configuration
/// asks for one (`config.consecutive`), reading the PSF at `psf`.
pub fn consecutive_reconstructor(dir: &Path, config: &SessionConfig, psf: &Path) -> Result<ConsecutiveReconstructor> {
    let settings = config.consecutive.clone().context("the session does not reconstruct one continuous video")?;
    let config_name = dir.join(CAPTURE_TOML).display().to_string();
    let sensor = config_sensor(config)?;
    Ok(ConsecutiveReconstructor::new(config.capture.clone(), psf, config_name, dir, config.solver.clone(), settings, config.outputs)?
        .with_sensor(sensor, config.psf_dark_subtracted))
}

/// The calibration (`capture.calibration`, an absolute path) and background a
/// session's configuration names.
fn config_sensor(config: &SessionConfig) -> Result<SensorFiles> {
    Ok(SensorFiles::load(None, config.background.as_deref().map(Path::new), None, config.capture.calibration.as_ref())?)
}

/// The reconstructor a session's configuration asks for: one continuous video, or
/// each frame on its own (compared with `truth_dir`'s videos when given).
pub fn reconstructor(dir: &Path, config: &SessionConfig, psf: &Path, truth_dir: Option<PathBuf>) -> Result<Arc<dyn FrameReconstructor>> {
    Ok(match &config.consecutive {
        Some(_) => {
            if truth_dir.is_some() {
                tracing::info!("--consecutive: per-frame truth videos are not compared (the video is on the global grid)");
            }
            Arc::new(consecutive_reconstructor(dir, config, psf)?)
        }
        None => {
            let config_name = dir.join(CAPTURE_TOML).display().to_string();
            Arc::new(
                SolverReconstructor::new(config.capture.clone(), psf, config_name, config.solver.clone(), truth_dir)?
                    .with_outputs(config.outputs)
                    .with_sensor(config_sensor(config)?, config.psf_dark_subtracted),
            )
        }
    })
}

/// A session ready to run: the configured camera, the raw capture description, the
/// session file (already in the new session folder with capture.toml and the PSF),
/// the reconstructor, the pipeline options and the programmed LED controller.
pub struct PreparedSession {
    pub camera: Box<dyn Camera>,
    pub raw: CaptureSession,
    pub session: SessionFile,
    pub reconstructor: Arc<dyn FrameReconstructor>,
    pub options: Options,
    led: Option<SessionLed>,
    led_started: bool,
}

impl PreparedSession {
    /// Open and configure the bench, check the capture description against what the
    /// camera applied, program the LED controller, create the session folder and
    /// choose the reconstructor.
    pub fn prepare(req: &SessionRequest) -> Result<PreparedSession> {
        let out = &req.options.dir;
        req.options.check()?;
        let SessionBench { camera, cfg, cfg_origin, psf, psf_source, psf_clean, truth_dir, sensor } = open_bench(req)?;
        let mut camera = session_camera(req, camera, &cfg)?;
        let applied = camera.applied_settings()?;
        hardware::check_timing(&cfg, &applied, &cfg_origin)?;
        // Every worker holds one frame's solve: refuse a session that cannot fit them,
        // with the figure, before the folder is created or a frame recorded.
        crate::io::budget::check_reconstruction(&cfg, cfg.fov, 1, req.options.workers)?;
        let geometry = camera.geometry()?;

        let led = req.led.as_ref().map(SessionLed::setup).transpose()?;
        let led_json = led.as_ref().map(|l| serde_json::to_value(&l.sync)).transpose()?;

        let psf_path = create_folder(out, &cfg, psf.input())?;
        let opts = &req.options;
        let config = SessionConfig {
            capture: cfg.clone(),
            psf: PSF_TIFF.into(),
            psf_source,
            policy: opts.policy.name().into(),
            queue: opts.queue,
            workers: opts.workers,
            frames_requested: opts.frames,
            min_free_mb: opts.min_free_mb,
            solver: req.solver.clone(),
            truth_dir: truth_dir.as_ref().map(|p| p.display().to_string()),
            outputs: req.outputs,
            consecutive: req.consecutive.clone(),
            background: sensor.background_path.as_ref().map(|p| std::fs::canonicalize(p).unwrap_or_else(|_| p.clone()).display().to_string()),
            psf_dark_subtracted: psf_clean,
        };
        let mut session = SessionFile::new(camera.info().spec(), config.clone());
        session.led = led_json.clone();
        session.live_url = req.live_url.clone();

        let mut raw = CaptureSession::new(camera.info().clone());
        raw.geometry = Some(geometry);
        raw.requested = hardware::camera_settings(&cfg, req.camera_settings.clone());
        raw.applied = Some(applied.clone());
        raw.frames_requested = opts.frames;
        raw.sync = SyncInfo {
            led_phase_us: req.led.as_ref().map(|l| l.phase_us as f64),
            line_time_us: applied.line_time_us,
            trigger_chain: req.keyframe_camera.iter().map(|k| k.trigger_link(&camera.info().spec())).collect(),
            led: led_json,
            notes: Some("recorded by rollcam run".into()),
        };

        let reconstructor = reconstructor(out, &config, &psf_path, truth_dir)?;
        Ok(PreparedSession { camera, raw, session, reconstructor, options: opts.clone(), led, led_started: false })
    }

    /// Start the LED waveform now if it waits for a software trigger ([`Self::run`]
    /// does it if not done yet).
    pub fn start_led(&mut self) -> Result<()> {
        if !self.led_started {
            if let Some(l) = &mut self.led {
                l.start()?;
            }
            self.led_started = true;
        }
        Ok(())
    }

    /// Run the session until it stops (see [`driver::run`]), stop the LED
    /// controller, and finish the continuous video if there is one.
    pub fn run(mut self, interrupt: Arc<AtomicBool>) -> Result<SessionFile> {
        self.start_led()?;
        let dir = self.options.dir.clone();
        let result = driver::run(self.camera, self.raw, self.session, self.reconstructor, self.options, interrupt);
        if let Some(l) = self.led {
            l.stop();
        }
        consecutive::finalize(&dir, result?)
    }
}

/// The LED controller of a session (and the in-process emulator behind `emulator`).
pub struct SessionLed {
    ctl: LedController,
    trigger: TriggerMode,
    /// The controller's settings as it reports them (recorded in `session.json` and
    /// `raw/capture.json`).
    pub sync: LedSync,
    _emulator: Option<LinkedEmulator>,
}

impl SessionLed {
    /// Open the controller, configure one channel per period, arm it.
    pub fn setup(req: &LedRequest) -> Result<SessionLed> {
        let port = &req.port;
        let (path, emulator) = if port == "emulator" {
            let link = std::env::temp_dir().join(format!("rollcam-led-{}", std::process::id()));
            let e = LinkedEmulator::create(&link, Default::default()).context("starting the LED emulator")?;
            (e.link().display().to_string(), Some(e))
        } else {
            (port.to_string(), None)
        };
        let opts = LinkOptions { ready_timeout: Duration::from_millis(if emulator.is_some() { 1000 } else { 2500 }), ..LinkOptions::default() };
        let mut ctl = LedController::open_with(&path, opts).with_context(|| format!("--led {port}"))?;
        let info = ctl.identify().with_context(|| format!("--led {port}: no answer from the LED controller"))?;
        if req.period_us.len() > info.channels as usize {
            bail!("--led-period-us: {} periods given, the controller on {port} has {} channels", req.period_us.len(), info.channels);
        }
        for (c, &p) in req.period_us.iter().enumerate() {
            let cfg = ChannelConfig::with_duty(p, req.duty).map_err(|e| anyhow!("--led-period-us/--led-duty: {e}"))?.phase(req.phase_us);
            ctl.configure(c as u8, cfg).with_context(|| format!("--led {port}: configuring channel {c}"))?;
        }
        let trigger = req.trigger;
        ctl.arm(trigger).with_context(|| format!("--led {port}: arming"))?;
        let sync = ctl.sync_summary(trigger)?;
        tracing::info!(port = port.as_str(), channels = sync.channels.len(), "LED controller programmed");
        Ok(SessionLed { ctl, trigger, sync, _emulator: emulator })
    }

    /// Start the waveform now when it waits for a software trigger.
    pub fn start(&mut self) -> Result<()> {
        if self.trigger == TriggerMode::Software {
            self.ctl.trigger().context("LED controller: software trigger")?;
        }
        Ok(())
    }

    /// Stop the waveform (a failure is logged).
    pub fn stop(mut self) {
        if let Err(e) = self.ctl.stop() {
            tracing::warn!("stopping the LED controller: {e}");
        }
    }
}
