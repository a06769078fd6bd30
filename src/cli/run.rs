//! `rollcam run`: the live bench pipeline. Every frame the camera delivers is recorded
//! raw into the session folder, then reconstructed by the workers; `session.json` and
//! the previews follow it live. `--resume` finishes a session's unreconstructed frames.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use clap::Args;
use rollcam::lab::live::LiveServer;
use rollcam::io::output::OutputSet;
use rollcam::lab::pipeline::consecutive::ConsecutiveReconstructor;
use rollcam::lab::pipeline::session::{ConsecutiveSettings, SessionConfig, SessionFile, SolverSettings, State};
use rollcam::lab::pipeline::simbench::{BenchRenderer, BenchScene, BenchSpec};
use rollcam::lab::pipeline::worker::{FrameReconstructor, SolverReconstructor};
use rollcam::lab::pipeline::{self, Options, Policy, PsfInput, TestHooks};
use rollcam_hw::camera::replay::{Pace, ReplayCamera, ReplayFaults, ReplayOptions};
use rollcam_hw::camera::{self, Camera, CameraSettings, CameraSpec, PixelFormat, Roi, Trigger};
use rollcam_hw::record::{CaptureSession, SyncInfo};

use crate::cli::common::{ctrl_c_flag, CaptureFlags, SolverFlags};
use crate::cli::led::TriggerArg;

#[derive(Args, Debug)]
pub struct RunArgs {
    /// Camera: aravis:<id>, replay:<capture folder>, or sim (with --scene) / sim:led-array / sim:moving-disc.
    #[arg(long, required_unless_present = "resume")]
    pub camera: Option<String>,
    /// Session folder to create (must be new or empty).
    #[arg(long, required_unless_present = "resume")]
    pub out: Option<PathBuf>,
    /// Continue a session: reconstruct what was recorded but not yet reconstructed.
    #[arg(long, conflicts_with_all = ["camera", "out"])]
    pub resume: Option<PathBuf>,
    /// capture.toml of the bench (timing; the camera is configured from it). Default
    /// for replay: the replayed folder's capture.toml.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// PSF image of the optics (same size as the raw frames). Default: the replayed
    /// folder's psf.tiff, else a psf.tiff beside the --config file; the simulated
    /// camera brings its own.
    #[arg(long)]
    pub psf: Option<PathBuf>,
    /// Stop after this many frames (default: until Ctrl-C or the end of a replay).
    #[arg(long)]
    pub frames: Option<u64>,
    /// Live preview mode: reconstruct the newest frame; older queued ones are skipped
    /// (still recorded; --resume reconstructs them).
    #[arg(long)]
    pub live: bool,
    /// Work-queue length; further frames wait in the on-disk backlog (catch-up).
    #[arg(long, default_value_t = 2)]
    pub queue: usize,
    /// Reconstruction workers running at once.
    #[arg(long, default_value_t = 1)]
    pub workers: usize,
    /// Free space to keep on the session's disk, MB; recording stops cleanly below it.
    #[arg(long, default_value_t = 200)]
    pub min_free_mb: u64,
    /// How long to wait for each frame before warning, milliseconds.
    #[arg(long, default_value_t = 5000)]
    pub timeout_ms: u64,
    /// Stop the session when the camera stays silent this long (default: keep waiting).
    #[arg(long)]
    pub stall_limit_s: Option<f64>,
    /// Folder of ground-truth videos truth_NNNNNN.npy (frame NNNNNN): PSNR in each summary.
    /// The simulated camera writes its own (sim/ in the session); a replayed recording
    /// that holds truth_NNNNNN.npy files is compared against them.
    #[arg(long)]
    pub truth_dir: Option<PathBuf>,

    /// Simulated camera: scene (led-array or moving-disc).
    #[arg(long)]
    pub scene: Option<String>,
    /// Simulated camera: sensor size ROWSxCOLS.
    #[arg(long, default_value = "128x160")]
    pub sim_size: String,
    /// Simulated camera: LED periods for --scene led-array, microseconds (one or four).
    #[arg(long, value_delimiter = ',')]
    pub sim_period_us: Vec<f64>,
    /// Simulated camera: seed of the diffuser and the noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,

    /// Camera region x,y,width,height (or WxH+X+Y); must give the config's rows x cols.
    #[arg(long)]
    pub roi: Option<Roi>,
    /// Mono8 | Mono10 | Mono12 | Mono14 | Mono16
    #[arg(long)]
    pub pixel_format: Option<PixelFormat>,
    /// free-run | software | hardware:<line>[:rising|falling|any]
    #[arg(long)]
    pub trigger: Option<Trigger>,
    #[arg(long)]
    pub frame_rate_hz: Option<f64>,
    /// Camera output line carrying exposure-active to the LED controller (e.g. Line1).
    #[arg(long)]
    pub exposure_output_line: Option<String>,

    /// LED controller: a serial port (/dev/ttyACM0), or `emulator` for the built-in one.
    #[arg(long)]
    pub led: Option<String>,
    /// LED periods, one per channel from channel 0, microseconds.
    #[arg(long, value_delimiter = ',', default_values_t = vec![1980u32])]
    pub led_period_us: Vec<u32>,
    /// LED duty cycle (0 < duty < 1).
    #[arg(long, default_value_t = 0.5)]
    pub led_duty: f64,
    /// Delay from the LED trigger to each channel's first rising edge, microseconds.
    #[arg(long, default_value_t = 0)]
    pub led_phase_us: u32,
    /// What starts the LED waveform: sw (at session start), rise or fall (the camera's
    /// exposure-active output wired to the controller's trigger input).
    #[arg(long, value_enum, default_value_t = TriggerArg::Sw)]
    pub led_trigger: TriggerArg,

    /// Serve the session's live page on ADDR while it runs (default 127.0.0.1:8080;
    /// port 0 picks a free port). The URL goes to stderr and session.json (`live_url`).
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "127.0.0.1:8080")]
    pub serve: Option<SocketAddr>,
    /// With --serve: keep the page up this many seconds after the session ends.
    #[arg(long, default_value_t = 0.0, requires = "serve")]
    pub serve_linger_s: f64,
    /// Files of each frame's folder: full (video TIFF and .npy, contact sheet, GIF, trace
    /// CSV/PNG/SVG, summary), video (video.npy, trace.csv, summary.json) or minimal
    /// (video.npy, summary.json). The heavy images dominate latency on small frames.
    #[arg(long, value_enum, default_value_t = OutputSet::Full)]
    pub outputs: OutputSet,
    /// Reconstruct the frames as one continuous video (sequence/), each capture placed
    /// on the global time grid and solved warm-started from the result so far; frames
    /// must arrive in order (one worker, catch-up).
    #[arg(long)]
    pub consecutive: bool,
    /// --consecutive: frames of the result so far each capture's window re-solves
    /// (default: a quarter of a capture's frames).
    #[arg(long, requires = "consecutive")]
    pub overlap_frames: Option<usize>,
    /// --consecutive: place captures by sequence number times this period instead of
    /// their device timestamps (needed when the camera gives none).
    #[arg(long, requires = "consecutive")]
    pub frame_period_us: Option<f64>,
    /// --consecutive: start every window from zero instead of the result so far.
    #[arg(long, requires = "consecutive")]
    pub cold_start: bool,

    #[command(flatten)]
    pub capture: CaptureFlags,
    #[command(flatten)]
    pub solver: SolverFlags,

    /// Test hook: each worker waits this long before each frame (a slow worker).
    #[arg(long, hide = true, default_value_t = 0)]
    pub worker_delay_ms: u64,
    /// Test hook: the worker panics on this frame.
    #[arg(long, hide = true)]
    pub test_panic_on_frame: Option<u64>,
    /// Test hook: the writer fails with "no space left on device" on this frame.
    #[arg(long, hide = true)]
    pub test_fail_write_at: Option<u64>,
    /// Test hook (replay): these recorded frames never arrive.
    #[arg(long, hide = true, value_delimiter = ',')]
    pub replay_drop: Vec<u64>,
    /// Test hook (replay): these frames arrive truncated to half.
    #[arg(long, hide = true, value_delimiter = ',')]
    pub replay_truncate: Vec<u64>,
    /// Test hook (replay): FRAME:MS, the camera goes silent before FRAME for MS.
    #[arg(long, hide = true)]
    pub replay_stall: Option<String>,
    /// Test hook (replay): the camera disappears before this frame.
    #[arg(long, hide = true)]
    pub replay_disconnect_at: Option<u64>,
    /// Replay at the recorded pace instead of as fast as consumed.
    #[arg(long, hide = true)]
    pub replay_recorded_pace: bool,
}

pub fn run(a: RunArgs) -> Result<()> {
    if let Some(dir) = &a.resume {
        return resume(dir, &a);
    }
    let out = a.out.clone().expect("clap: --out required");
    let spec_text = a.camera.clone().expect("clap: --camera required");
    check_consecutive(a.consecutive, a.live, a.workers)?;
    if !(a.serve_linger_s.is_finite() && a.serve_linger_s >= 0.0) {
        bail!("--serve-linger-s = {}: expected a non-negative number of seconds", a.serve_linger_s);
    }
    // Refuse a used folder before touching any device.
    pipeline::check_new_folder(&out)?;
    let solver = solver_settings(&a.solver)?;
    // The page says it waits until the session folder and session.json exist.
    let server = match a.serve {
        Some(addr) => Some(serve(&out, addr)?),
        None => None,
    };

    // Camera, capture description and PSF.
    let bench = open_bench(&a, &spec_text, &out)?;
    let Bench { mut cam, cfg, cfg_origin, psf, truth_dir } = bench;
    let applied = cam.applied_settings()?;
    pipeline::check_timing(&cfg, &applied, &cfg_origin)?;
    let geometry = cam.geometry()?;

    // LED controller, programmed before acquisition.
    let mut led = match &a.led {
        Some(port) => Some(Led::setup(port, &a)?),
        None => None,
    };
    let led_json = match &led {
        Some(l) => Some(serde_json::to_value(&l.sync)?),
        None => None,
    };

    let psf_source = match &psf {
        PsfOwned::File(p) => p.display().to_string(),
        PsfOwned::Image(_) => format!("simulated diffuser (seed {})", a.seed),
    };
    let psf_path = pipeline::create_folder(
        &out,
        &cfg,
        match &psf {
            PsfOwned::File(p) => PsfInput::File(p),
            PsfOwned::Image(img) => PsfInput::Image(img),
        },
    )?;
    let config = SessionConfig {
        capture: cfg.clone(),
        psf: pipeline::PSF_TIFF.into(),
        psf_source,
        policy: if a.live { Policy::Live } else { Policy::CatchUp }.name().into(),
        queue: a.queue,
        workers: a.workers,
        frames_requested: a.frames,
        min_free_mb: a.min_free_mb,
        solver: solver.clone(),
        truth_dir: truth_dir.as_ref().map(|p| p.display().to_string()),
        outputs: a.outputs,
        consecutive: a.consecutive.then_some(ConsecutiveSettings {
            overlap_frames: a.overlap_frames,
            frame_period_us: a.frame_period_us,
            warm_start: !a.cold_start,
        }),
    };
    let mut session = SessionFile::new(cam.info().spec(), config.clone());
    session.led = led_json.clone();
    session.live_url = server.as_ref().map(|s| s.url());

    let mut raw = CaptureSession::new(cam.info().clone());
    raw.geometry = Some(geometry);
    raw.requested = camera_settings(&a, &cfg);
    raw.applied = Some(applied.clone());
    raw.frames_requested = a.frames;
    raw.sync = SyncInfo {
        led_phase_us: led.as_ref().map(|_| a.led_phase_us as f64),
        line_time_us: applied.line_time_us,
        trigger_chain: Vec::new(),
        led: led_json,
        notes: Some("recorded by rollcam run".into()),
    };

    let reconstructor = make_reconstructor(&out, &config, &psf_path, truth_dir)?;
    let opts = Options {
        frames: a.frames,
        policy: if a.live { Policy::Live } else { Policy::CatchUp },
        queue: a.queue,
        workers: a.workers,
        frame_timeout: Duration::from_millis(a.timeout_ms.max(1)),
        stall_limit: a.stall_limit_s.map(Duration::from_secs_f64),
        min_free_mb: a.min_free_mb,
        test: hooks(&a),
        ..Options::new(&out)
    };
    if let Some(l) = &mut led {
        l.start()?;
    }
    println!("session {}: camera {}, {} policy, {} worker(s); Ctrl-C stops", out.display(), cam.info().spec(), opts.policy.name(), opts.workers);
    let result = pipeline::run(cam, raw, session, reconstructor, opts, ctrl_c_flag());
    if let Some(l) = led {
        l.stop();
    }
    let reported = report(&out, &rollcam::lab::pipeline::consecutive::finalize(&out, result?)?);
    linger(server, a.serve_linger_s);
    reported
}

/// `--consecutive` needs the frames in order: one worker, catch-up.
fn check_consecutive(consecutive: bool, live: bool, workers: usize) -> Result<()> {
    if consecutive && live {
        bail!("--consecutive with --live: the continuous video needs every frame in order, and --live skips frames; drop one of them");
    }
    if consecutive && workers > 1 {
        bail!("--consecutive with --workers {workers}: the continuous video is solved capture after capture, in order; use --workers 1");
    }
    Ok(())
}

/// The reconstructor a session's configuration asks for.
fn make_reconstructor(dir: &Path, config: &SessionConfig, psf: &Path, truth_dir: Option<PathBuf>) -> Result<Arc<dyn FrameReconstructor>> {
    let config_name = dir.join(pipeline::CAPTURE_TOML).display().to_string();
    Ok(match &config.consecutive {
        Some(c) => {
            if truth_dir.is_some() {
                tracing::info!("--consecutive: per-frame truth videos are not compared (the video is on the global grid)");
            }
            Arc::new(ConsecutiveReconstructor::new(config.capture.clone(), psf, config_name, dir, config.solver.clone(), c.clone(), config.outputs)?)
        }
        None => Arc::new(SolverReconstructor::new(config.capture.clone(), psf, config_name, config.solver.clone(), truth_dir)?.with_outputs(config.outputs)),
    })
}

/// Start the live page on the session folder; its URL goes to stderr.
fn serve(dir: &Path, addr: SocketAddr) -> Result<LiveServer> {
    let server = LiveServer::start(dir, addr).with_context(|| format!("--serve {addr}"))?;
    eprintln!("live page: {}", server.url());
    Ok(server)
}

/// Keep the live page up `linger_s` seconds (Ctrl-C ends the wait), then stop it.
fn linger(server: Option<LiveServer>, linger_s: f64) {
    let Some(server) = server else { return };
    if linger_s > 0.0 {
        eprintln!("live page stays up {linger_s} s at {} (Ctrl-C stops it)", server.url());
        let flag = ctrl_c_flag();
        flag.store(false, Ordering::SeqCst);
        let until = std::time::Instant::now() + Duration::from_secs_f64(linger_s);
        while std::time::Instant::now() < until && !flag.load(Ordering::SeqCst) {
            std::thread::sleep(Duration::from_millis(100));
        }
    }
    server.stop();
}

fn resume(dir: &Path, a: &RunArgs) -> Result<()> {
    let mut session = SessionFile::load(dir)?;
    if a.consecutive && session.config.consecutive.is_none() {
        bail!("--consecutive: {} was recorded without --consecutive; resume it without the flag", dir.join("session.json").display());
    }
    check_consecutive(session.config.consecutive.is_some(), false, a.workers)?;
    let psf = dir.join(&session.config.psf);
    let truth_dir = a.truth_dir.clone().or(session.config.truth_dir.as_ref().map(PathBuf::from));
    if session.config.consecutive.is_some() {
        let rebuilt = ConsecutiveReconstructor::new(
            session.config.capture.clone(),
            &psf,
            dir.join(pipeline::CAPTURE_TOML).display().to_string(),
            dir,
            session.config.solver.clone(),
            session.config.consecutive.clone().expect("checked"),
            session.config.outputs,
        )?;
        println!("resuming {}: rebuilding the continuous video from the recorded frames", dir.display());
        let n = rebuilt.rebuild(dir, &session.frames)?;
        tracing::info!(frames = n, "consecutive stream rebuilt");
        return resume_with(dir, a, &mut session, Arc::new(rebuilt));
    }
    let reconstructor = make_reconstructor(dir, &session.config, &psf, truth_dir)?;
    resume_with(dir, a, &mut session, reconstructor)
}

fn resume_with(dir: &Path, a: &RunArgs, session: &mut SessionFile, reconstructor: Arc<dyn FrameReconstructor>) -> Result<()> {
    let server = match a.serve {
        Some(addr) => Some(serve(dir, addr)?),
        None => None,
    };
    if let Some(s) = &server {
        session.live_url = Some(s.url());
        session.write(dir)?;
    }
    println!("resuming {}: {} frames pending", dir.display(), session.pending.len());
    let s = pipeline::resume(dir, reconstructor, a.workers, Duration::from_millis(500), ctrl_c_flag())?;
    let reported = report(dir, &rollcam::lab::pipeline::consecutive::finalize(dir, s)?);
    linger(server, a.serve_linger_s);
    reported
}

fn report(dir: &Path, s: &SessionFile) -> Result<()> {
    let c = &s.counters;
    println!(
        "frames: captured {}, recorded {}, reconstructed {}, skipped {}, dropped {}, failed {}, queued {}, unrecorded {}",
        c.captured, c.recorded, c.reconstructed, c.skipped, c.dropped, c.failed, c.queued, c.unrecorded
    );
    let ms = |v: Option<f64>| v.map(|x| format!("{x:.0} ms")).unwrap_or_else(|| "-".into());
    let l = &s.latency_ms;
    println!("latency (frame arrival to finished video): median {}, max {}", ms(l.median), ms(l.max));
    if let Some(span) = l.capture_span.filter(|_| l.median.is_some()) {
        println!(
            "latency from exposure start (at least; the frame's own exposure and readout take {span:.1} ms): median {}, max {}",
            ms(l.from_exposure_start_median),
            ms(l.from_exposure_start_max)
        );
    }
    for e in &s.errors {
        println!("  {e}");
    }
    if !s.pending.is_empty() {
        println!("{} recorded frames are not reconstructed yet: rollcam run --resume {}", s.pending.len(), dir.display());
    }
    let reason = s.stop_reason.clone().unwrap_or_default();
    println!("session {}: {} ({reason})", dir.display(), state_name(s.state));
    if s.state == State::Failed {
        bail!("session {} failed: {reason}; every recorded frame is in {}", dir.display(), dir.join(pipeline::RAW_DIR).display());
    }
    Ok(())
}

fn state_name(s: State) -> &'static str {
    match s {
        State::Running => "running",
        State::Finished => "finished",
        State::Stopped => "stopped",
        State::Failed => "failed",
    }
}

fn solver_settings(f: &SolverFlags) -> Result<SolverSettings> {
    // Same checks as `reconstruct`.
    f.params(f.tau.unwrap_or(0.0), Default::default())?;
    if !(f.tau_rel.is_finite() && f.tau_rel >= 0.0) {
        bail!("--tau-rel = {}: expected a non-negative number", f.tau_rel);
    }
    Ok(SolverSettings {
        tau: f.tau,
        tau_rel: f.tau_rel,
        alpha: f.alpha,
        iters: f.iters,
        rel_tol: f.rel_tol,
        time_budget_s: f.time_budget_s,
        restart: !f.no_restart,
    })
}

fn hooks(a: &RunArgs) -> TestHooks {
    TestHooks {
        worker_delay: Duration::from_millis(a.worker_delay_ms),
        panic_on_frame: a.test_panic_on_frame,
        fail_write_at: a.test_fail_write_at,
    }
}

/// Settings sent to the camera: timing from the capture description, the rest from flags.
fn camera_settings(a: &RunArgs, cfg: &rollcam::model::capture::CaptureConfig) -> CameraSettings {
    CameraSettings {
        exposure_us: Some(cfg.exposure_us),
        line_time_us: Some(cfg.line_time_us),
        frame_rate_hz: a.frame_rate_hz,
        shutter: pipeline::camera_shutter(cfg.shutter),
        roi: a.roi,
        binning: None,
        pixel_format: a.pixel_format,
        trigger: a.trigger.clone(),
        exposure_output_line: a.exposure_output_line.clone(),
    }
}

enum PsfOwned {
    File(PathBuf),
    Image(ndarray::Array3<f32>),
}

struct Bench {
    cam: Box<dyn Camera>,
    cfg: rollcam::model::capture::CaptureConfig,
    cfg_origin: String,
    psf: PsfOwned,
    truth_dir: Option<PathBuf>,
}

fn parse_size(s: &str) -> Result<(usize, usize)> {
    let (r, c) = s.split_once('x').with_context(|| format!("--sim-size {s}: expected ROWSxCOLS, e.g. 48x64"))?;
    let p = |v: &str| v.trim().parse::<usize>().ok().filter(|&n| n >= 8);
    match (p(r), p(c)) {
        (Some(r), Some(c)) => Ok((r, c)),
        _ => bail!("--sim-size {s}: expected ROWSxCOLS with at least 8 of each, e.g. 48x64"),
    }
}

/// Open the camera, configure it from the capture description and find the PSF.
fn open_bench(a: &RunArgs, spec_text: &str, out: &Path) -> Result<Bench> {
    let spec: CameraSpec = if spec_text == "sim" { CameraSpec { backend: "sim".into(), id: String::new() } } else { spec_text.parse()? };
    let truth_flag = a.truth_dir.as_ref().map(|p| std::fs::canonicalize(p).with_context(|| format!("--truth-dir {}: not found", p.display()))).transpose()?;
    match spec.backend.as_str() {
        "sim" => {
            if a.config.is_some() || a.psf.is_some() {
                bail!("--camera sim brings its own timing and PSF; --config and --psf apply to real and replayed cameras (use --line-time-us, --exposure-us, --shutter, --downsample, --binning)");
            }
            let scene_name = match (spec.id.as_str(), &a.scene) {
                ("", Some(s)) => s.clone(),
                ("", None) => "led-array".into(),
                (id, None) => id.to_string(),
                (id, Some(s)) if id == s => s.clone(),
                (id, Some(s)) => bail!("--camera sim:{id} and --scene {s} disagree"),
            };
            let mut scene: BenchScene = scene_name.parse().map_err(|e: String| anyhow::anyhow!("--scene: {e}"))?;
            if let (BenchScene::LedArray { period_us }, false) = (&mut scene, a.sim_period_us.is_empty()) {
                *period_us = a.sim_period_us.clone();
            }
            let (rows, cols) = parse_size(&a.sim_size)?;
            let truth_dir = out.join("sim");
            let bench = BenchSpec {
                scene,
                rows,
                cols,
                line_time_us: a.capture.line_time_us.unwrap_or(220.0),
                exposure_us: a.capture.exposure_us.unwrap_or(660.0),
                frame_rate_hz: a.frame_rate_hz.unwrap_or(20.0),
                seed: a.seed,
                truth_dir: Some(truth_dir.clone()),
                downsample: a.capture.downsample.unwrap_or(1),
                binning: a.capture.binning.unwrap_or(1),
            };
            let renderer = BenchRenderer::new(bench).map_err(|e| anyhow::anyhow!("simulated camera: {e}"))?;
            let psf = renderer.psf_image();
            let mut cam = renderer.into_camera();
            let mut settings = CameraSettings { trigger: a.trigger.clone(), ..Default::default() };
            if let Some(s) = a.capture.shutter {
                settings.shutter = pipeline::camera_shutter(s);
            }
            let applied = cam.configure(&settings)?;
            let mut cfg = cam.renderer().capture_config(&applied).map_err(|e| anyhow::anyhow!("simulated camera: {e}"))?;
            if let Some(f) = a.capture.fov {
                cfg.fov = f;
            }
            Ok(Bench { cam: Box::new(cam), cfg, cfg_origin: "simulated camera".into(), psf: PsfOwned::Image(psf), truth_dir: truth_flag.or(Some(truth_dir)) })
        }
        backend => {
            let replay_dir = (backend == "replay").then(|| PathBuf::from(&spec.id));
            let mut cam: Box<dyn Camera> = match &replay_dir {
                Some(dir) => Box::new(ReplayCamera::open(dir, replay_options(a)?).with_context(|| format!("opening camera {spec_text}"))?),
                None => camera::open(&spec).with_context(|| format!("opening camera {spec_text}"))?,
            };
            let default_in = |name: &str| replay_dir.as_ref().map(|d| d.join(name)).filter(|p| p.is_file());
            let config = a.config.clone().or_else(|| default_in("capture.toml"));
            // Without --psf: the replay's own, else a psf.tiff beside the config file.
            let beside_config = || config.as_ref().and_then(|c| c.parent()).map(|d| d.join("psf.tiff")).filter(|p| p.is_file());
            let psf = a.psf.clone().or_else(|| default_in("psf.tiff")).or_else(beside_config).with_context(|| {
                format!("camera {spec_text}: no PSF: give --psf, or put psf.tiff beside the --config file (an image of a point source through the same optics, the size of the frames)")
            })?;
            let current = cam.applied_settings()?;
            let (w, h) = match a.roi {
                Some(r) => (r.width, r.height),
                None => current.image_size(),
            };
            let cfg = a.capture.resolve(config.as_deref(), (h as usize, w as usize))?;
            let origin = config.as_ref().map(|p| p.display().to_string()).unwrap_or_else(|| "the command line".into());
            let settings = camera_settings(a, &cfg);
            cam.configure(&settings).with_context(|| format!("configuring camera {spec_text} with the timing of {origin}"))?;
            // A replayed recording that carries its truth videos is compared against them.
            let recorded_truth = replay_dir.as_ref().filter(|d| d.join("truth_000000.npy").is_file()).map(|d| std::fs::canonicalize(d).unwrap_or_else(|_| d.clone()));
            Ok(Bench { cam, cfg, cfg_origin: origin, psf: PsfOwned::File(psf), truth_dir: truth_flag.or(recorded_truth) })
        }
    }
}

fn replay_options(a: &RunArgs) -> Result<ReplayOptions> {
    let stall_at = match &a.replay_stall {
        None => None,
        Some(s) => {
            let (f, ms) = s.split_once(':').context("--replay-stall: expected FRAME:MS")?;
            Some((f.parse().context("--replay-stall: FRAME")?, Duration::from_millis(ms.parse().context("--replay-stall: MS")?)))
        }
    };
    Ok(ReplayOptions {
        pace: if a.replay_recorded_pace { Pace::Recorded } else { Pace::AsFastAsConsumed },
        faults: ReplayFaults { drop: a.replay_drop.clone(), truncate: a.replay_truncate.clone(), stall_at, disconnect_at: a.replay_disconnect_at },
    })
}

/// The LED controller for a session (and the in-process emulator behind `--led emulator`).
struct Led {
    ctl: rollcam_hw::led::LedController,
    trigger: rollcam_hw::led::TriggerMode,
    sync: rollcam_hw::led::LedSync,
    _emulator: Option<rollcam_hw::led::LinkedEmulator>,
}

impl Led {
    fn setup(port: &str, a: &RunArgs) -> Result<Led> {
        use rollcam_hw::led::{ChannelConfig, LedController, LinkOptions, LinkedEmulator};
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
        if a.led_period_us.len() > info.channels as usize {
            bail!("--led-period-us: {} periods given, the controller on {port} has {} channels", a.led_period_us.len(), info.channels);
        }
        for (c, &p) in a.led_period_us.iter().enumerate() {
            let cfg = ChannelConfig::with_duty(p, a.led_duty).map_err(|e| anyhow::anyhow!("--led-period-us/--led-duty: {e}"))?.phase(a.led_phase_us);
            ctl.configure(c as u8, cfg).with_context(|| format!("--led {port}: configuring channel {c}"))?;
        }
        let trigger = a.led_trigger.into();
        ctl.arm(trigger).with_context(|| format!("--led {port}: arming"))?;
        let sync = ctl.sync_summary(trigger)?;
        tracing::info!(port, channels = sync.channels.len(), "LED controller programmed");
        Ok(Led { ctl, trigger, sync, _emulator: emulator })
    }

    /// Start the waveform now when it waits for a software trigger.
    fn start(&mut self) -> Result<()> {
        if self.trigger == rollcam_hw::led::TriggerMode::Software {
            self.ctl.trigger().context("LED controller: software trigger")?;
        }
        Ok(())
    }

    fn stop(mut self) {
        if let Err(e) = self.ctl.stop() {
            tracing::warn!("stopping the LED controller: {e}");
        }
    }
}
