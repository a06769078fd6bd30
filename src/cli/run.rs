//! `rollcam run`: the live bench pipeline. Every frame the camera delivers is recorded
//! raw into the session folder, then reconstructed by the workers; `session.json` and
//! the previews follow it live. `--resume` finishes a session's unreconstructed frames.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use clap::builder::{PossibleValuesParser, TypedValueParser};
use clap::Args;
use rollcam::io::output::OutputSet;
use rollcam::lab::camera::CameraTarget;
use rollcam::lab::live::LiveServer;
use rollcam::lab::pipeline::session::{ConsecutiveSettings, SessionFile, State};
use rollcam::lab::pipeline::setup::{self, LedRequest, PreparedSession, SessionCamera, SessionRequest, SimCameraRequest};
use rollcam::lab::pipeline::worker::FrameReconstructor;
use rollcam::lab::pipeline::{self, Options, Policy, TestHooks};
use rollcam::request::ValidSettings;
use rollcam_hw::camera::replay::{Pace, ReplayFaults, ReplayOptions};
use rollcam_hw::camera::{CameraSettings, PixelFormat, Roi, Trigger};

use crate::cli::common::{ctrl_c_flag, wait_seconds, CaptureFlags, SensorFlags, SolverFlags};
use crate::cli::led::TriggerArg;

#[derive(Args, Debug)]
pub struct RunArgs {
    /// Camera: aravis:<id>, replay:<capture folder>, or sim (with --sim-scene) / sim:led-array / sim:moving-disc.
    #[arg(long, required_unless_present = "resume")]
    pub camera: Option<String>,
    /// Session folder to create (must be new or empty).
    #[arg(long, required_unless_present = "resume")]
    pub out: Option<PathBuf>,
    /// Continue a session: reconstruct what was recorded but not yet reconstructed.
    #[arg(long, conflicts_with_all = ["camera", "out"])]
    pub resume: Option<PathBuf>,
    #[command(flatten)]
    pub keys: crate::cli::common::KeyCameraFlags,
    /// With --resume: reconstruct again the frames whose reconstruction failed (an
    /// incomplete frame stays failed: the camera delivered only part of it).
    #[arg(long, requires = "resume")]
    pub retry_failed: bool,
    /// capture.toml of the bench (timing; the camera is configured from it). Default
    /// for replay: the replayed folder's capture.toml; without one, the timing the
    /// camera reports (after the timing flags below are applied to it).
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
    #[arg(long, value_name = "led-array|moving-disc")]
    pub sim_scene: Option<String>,
    /// Renamed --sim-scene (refused with a pointer: `reconstruct --scene` declares a scene).
    #[arg(long = "scene", hide = true)]
    pub old_scene: Option<String>,
    /// Simulated camera: sensor size ROWSxCOLS.
    #[arg(long, default_value = "128x160")]
    pub sim_size: String,
    /// Simulated camera: LED periods for --sim-scene led-array, microseconds (one or four).
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
    #[arg(
        long,
        default_value_t = OutputSet::Full,
        value_parser = PossibleValuesParser::new(OutputSet::ALL.map(OutputSet::name)).map(|s| s.parse::<OutputSet>().expect("a listed name"))
    )]
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
    pub sensor: SensorFlags,
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
    if a.retry_failed && a.resume.is_none() {
        bail!("--retry-failed: expected with --resume SESSION_DIR (it reconstructs again the failed frames of a session); a new session has none");
    }
    if let Some(t) = &a.truth_dir {
        if !t.is_dir() {
            let found = if t.exists() { "a file" } else { "nothing there" };
            bail!("--truth-dir {}: expected a folder of truth videos (truth_NNNNNN.npy), found {found}", t.display());
        }
    }
    if let Some(dir) = &a.resume {
        return resume(dir, &a);
    }
    if let Some(s) = &a.old_scene {
        bail!("--scene {s}: the simulated camera's scene is --sim-scene {s} (--scene declares a scene in reconstruct)");
    }
    let out = a.out.clone().expect("clap: --out required");
    let spec_text = a.camera.clone().expect("clap: --camera required");
    check_consecutive(a.consecutive, a.live, a.workers)?;
    if a.consecutive && a.keys.keyframe_camera.is_some() {
        bail!("--keyframe-camera: each frame reconstructs with its own key frames; the continuous video (--consecutive) takes none: expected one of them");
    }
    if a.consecutive {
        rollcam::request::sequence::check_settings(&a.solver.settings()?).map_err(crate::cli::common::flag_error)?;
    }
    let linger_for = wait_seconds("serve-linger-s", a.serve_linger_s)?;
    // Refuse a used folder before touching any device.
    pipeline::check_new_folder(&out)?;
    let solver = solver_settings(&a.solver)?;
    // The page says it waits until the session folder and session.json exist.
    let server = match a.serve {
        Some(addr) => Some(serve(&out, addr)?),
        None => None,
    };

    // Camera, capture description, PSF, LED controller, session folder, reconstructor.
    let request = session_request(&a, spec_text, out.clone(), solver, server.as_ref().map(|s| s.url()))?;
    let mut ready = PreparedSession::prepare(&request)?;
    ready.start_led()?;
    println!(
        "session {}: camera {}, {} policy, {} worker(s); Ctrl-C stops",
        out.display(),
        ready.camera.info().spec(),
        ready.options.policy.name(),
        ready.options.workers
    );
    let result = ready.run(ctrl_c_flag());
    let reported = report(&out, &result?);
    linger(server, linger_for);
    reported
}

/// The session the flags describe.
fn session_request(a: &RunArgs, camera_name: String, out: PathBuf, solver: ValidSettings, live_url: Option<String>) -> Result<SessionRequest> {
    let camera = match CameraTarget::parse(&camera_name)? {
        CameraTarget::Simulated { id } => SessionCamera::Simulated { id, request: sim_camera(a)? },
        CameraTarget::Replay(dir) => SessionCamera::Replay { dir, options: replay_options(a)? },
        CameraTarget::Device(spec) => SessionCamera::Device(spec),
    };
    let options = Options {
        frames: a.frames,
        policy: if a.live { Policy::Live } else { Policy::CatchUp },
        queue: a.queue,
        workers: a.workers,
        frame_timeout: Duration::from_millis(a.timeout_ms.max(1)),
        stall_limit: a.stall_limit_s.map(|s| wait_seconds("stall-limit-s", s)).transpose()?,
        min_free_mb: a.min_free_mb,
        test: hooks(a),
        ..Options::new(out)
    };
    let keyframe_camera = a.keys.request(&camera_name, a.timeout_ms)?;
    Ok(SessionRequest {
        keyframe_camera,
        camera_name,
        camera,
        config: a.config.clone(),
        psf: a.psf.clone(),
        calibration: a.sensor.calibration.clone(),
        background: a.sensor.background.clone(),
        capture: a.capture.overrides(),
        truth_dir: a.truth_dir.clone(),
        camera_settings: CameraSettings {
            frame_rate_hz: a.frame_rate_hz,
            roi: a.roi,
            pixel_format: a.pixel_format,
            trigger: a.trigger.clone(),
            exposure_output_line: a.exposure_output_line.clone(),
            ..CameraSettings::default()
        },
        led: a.led.as_ref().map(|port| LedRequest {
            port: port.clone(),
            period_us: a.led_period_us.clone(),
            duty: a.led_duty,
            phase_us: a.led_phase_us,
            trigger: a.led_trigger.into(),
        }),
        solver,
        outputs: a.outputs,
        consecutive: a.consecutive.then_some(ConsecutiveSettings {
            overlap_frames: a.overlap_frames,
            frame_period_us: a.frame_period_us,
            warm_start: !a.cold_start,
        }),
        options,
        live_url,
    })
}

/// The simulated camera the flags describe.
fn sim_camera(a: &RunArgs) -> Result<SimCameraRequest> {
    let (rows, cols) = parse_size(&a.sim_size)?;
    Ok(SimCameraRequest {
        scene: a.sim_scene.clone(),
        rows,
        cols,
        period_us: a.sim_period_us.clone(),
        seed: a.seed,
        line_time_us: a.capture.line_time_us,
        exposure_us: a.capture.exposure_us,
        shutter: a.capture.shutter,
        downsample: a.capture.downsample,
        binning: a.capture.binning,
        fov: a.capture.fov,
    })
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

/// Start the live page on the session folder; its URL goes to stderr.
fn serve(dir: &Path, addr: SocketAddr) -> Result<LiveServer> {
    let server = LiveServer::start(dir, addr).with_context(|| format!("--serve {addr}"))?;
    eprintln!("live page: {}", server.url());
    Ok(server)
}

/// Keep the live page up `linger` (Ctrl-C ends the wait), then stop it.
fn linger(server: Option<LiveServer>, linger: Duration) {
    let Some(server) = server else { return };
    if !linger.is_zero() {
        eprintln!("live page stays up {} s at {} (Ctrl-C stops it)", linger.as_secs_f64(), server.url());
        let flag = ctrl_c_flag();
        flag.store(false, Ordering::SeqCst);
        let until = std::time::Instant::now() + linger;
        while std::time::Instant::now() < until && !flag.load(Ordering::SeqCst) {
            std::thread::sleep(Duration::from_millis(100));
        }
    }
    server.stop();
}

fn resume(dir: &Path, a: &RunArgs) -> Result<()> {
    // Before anything reads the session: a second resume waits for none of it.
    let lock = pipeline::lock::SessionLock::acquire(dir)?;
    let mut session = SessionFile::load(dir)?;
    if a.consecutive && session.config.consecutive.is_none() {
        bail!("--consecutive: {} was recorded without --consecutive; resume it without the flag", dir.join("session.json").display());
    }
    check_consecutive(session.config.consecutive.is_some(), false, a.workers)?;
    let psf = dir.join(&session.config.psf);
    let truth_dir = a.truth_dir.clone().or(session.config.truth_dir.as_ref().map(PathBuf::from));
    if session.config.consecutive.is_some() {
        let rebuilt = setup::consecutive_reconstructor(dir, &session.config, &psf)?;
        println!("resuming {}: rebuilding the continuous video from the recorded frames", dir.display());
        let n = rebuilt.rebuild(dir, &session.frames)?;
        tracing::info!(frames = n, "consecutive stream rebuilt");
        return resume_with(&lock, dir, a, &mut session, Arc::new(rebuilt));
    }
    let reconstructor = setup::reconstructor(dir, &session.config, &psf, truth_dir)?;
    resume_with(&lock, dir, a, &mut session, reconstructor)
}

fn resume_with(
    lock: &pipeline::lock::SessionLock,
    dir: &Path,
    a: &RunArgs,
    session: &mut SessionFile,
    reconstructor: Arc<dyn FrameReconstructor>,
) -> Result<()> {
    let linger_for = wait_seconds("serve-linger-s", a.serve_linger_s)?;
    let server = match a.serve {
        Some(addr) => Some(serve(dir, addr)?),
        None => None,
    };
    if let Some(s) = &server {
        session.live_url = Some(s.url());
        session.write(dir)?;
    }
    println!("resuming {}: {} frames pending", dir.display(), session.pending.len());
    let s = pipeline::resume(lock, dir, reconstructor, a.workers, Duration::from_millis(500), ctrl_c_flag(), a.retry_failed)?;
    let reported = report(dir, &rollcam::lab::pipeline::consecutive::finalize(dir, s)?);
    linger(server, linger_for);
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
    // Any failed frame makes the run fail (session.json says why for each); those whose
    // reconstruction failed can be retried, an incomplete frame cannot.
    let failed: Vec<&rollcam::lab::pipeline::session::FrameEntry> =
        s.frames.iter().filter(|f| f.status == rollcam::lab::pipeline::session::FrameState::Failed).collect();
    if !failed.is_empty() {
        let list = |fs: Vec<u64>| {
            let mut t: Vec<String> = fs.iter().take(10).map(|q| q.to_string()).collect();
            if fs.len() > 10 {
                t.push(format!("and {} more", fs.len() - 10));
            }
            t.join(", ")
        };
        let (incomplete, retry): (Vec<&rollcam::lab::pipeline::session::FrameEntry>, Vec<_>) = failed.iter().partition(|f| f.incomplete);
        let mut parts = Vec::new();
        if !retry.is_empty() {
            parts.push(format!(
                "{} failed to reconstruct (sequence {}): retry with rollcam run --resume {} --retry-failed",
                retry.len(),
                list(retry.iter().map(|f| f.sequence).collect()),
                dir.display()
            ));
        }
        if !incomplete.is_empty() {
            parts.push(format!(
                "{} arrived incomplete from the camera (sequence {}; the part that arrived is in {})",
                incomplete.len(),
                list(incomplete.iter().map(|f| f.sequence).collect()),
                dir.join(pipeline::RAW_DIR).display()
            ));
        }
        bail!("{} frame(s) failed; session.json says why for each: {}", failed.len(), parts.join("; "));
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

fn solver_settings(f: &SolverFlags) -> Result<ValidSettings> {
    f.settings()
}

fn hooks(a: &RunArgs) -> TestHooks {
    TestHooks { worker_delay: Duration::from_millis(a.worker_delay_ms), panic_on_frame: a.test_panic_on_frame, fail_write_at: a.test_fail_write_at }
}

fn parse_size(s: &str) -> Result<(usize, usize)> {
    let (r, c) = s.split_once('x').with_context(|| format!("--sim-size {s}: expected ROWSxCOLS, e.g. 48x64"))?;
    let side = rollcam::model::shutter::MAX_SENSOR_SIDE;
    let p = |v: &str| v.trim().parse::<usize>().ok().filter(|&n| (8..=side).contains(&n));
    match (p(r), p(c)) {
        (Some(r), Some(c)) => Ok((r, c)),
        _ => bail!("--sim-size {s}: expected ROWSxCOLS with 8 to {side} of each, e.g. 48x64"),
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
