//! Pieces shared by the commands: capture-description flags, solver flags, progress.

use anyhow::Result;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use rollcam::io::sensor_files::SensorFiles;
use rollcam::model::capture::{CaptureConfig, CaptureOverrides, Fov};
use rollcam::model::prepare::SensorReport;
use rollcam::model::shutter::ShutterMode;
use rollcam::request::{
    parse_f32, Device, InvalidSetting, SolveSettings, SolverKind, Start, Tau, TraceRow, TvProxChoice, ValidSettings, DEFAULT_ALPHA, DEFAULT_ITERS,
    DEFAULT_OBJ_TOL,
};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Capture description given on the command line; each flag overrides capture.toml.
#[derive(Args, Debug, Clone, Default)]
pub struct CaptureFlags {
    /// Raw line time, microseconds.
    #[arg(long)]
    pub line_time_us: Option<f64>,
    /// Exposure of each row, microseconds.
    #[arg(long)]
    pub exposure_us: Option<f64>,
    /// Shutter mode: global (a still: one frame whatever the exposure; line time and
    /// exposure optional), rolling, dual (outside-in) or dual-center-out.
    #[arg(long)]
    pub shutter: Option<ShutterMode>,
    /// Spatial downsampling factor d (box mean of d x d raw pixels).
    #[arg(long)]
    pub downsample: Option<usize>,
    /// Temporal binning: frames of this many effective line times.
    #[arg(long)]
    pub binning: Option<usize>,
    /// Black offset of raw and PSF, counts (estimated from the darkest pixels if absent).
    #[arg(long)]
    pub dark_level: Option<f64>,
    /// Raw value at which pixels clip, counts (e.g. 4095 for a 12-bit sensor); clipped
    /// pixels stay in the data term as lower bounds (one-sided). Default: capture.toml's,
    /// the calibration's, a pile of pixels at the raw's maximum, or the file's full scale.
    #[arg(long)]
    pub saturation_level: Option<f64>,
    /// Video grid: sensor (default) or full (every point whose PSF reaches the sensor).
    #[arg(long)]
    pub fov: Option<Fov>,
}

/// `--force`: the flag every command that writes a folder has (see [`claim_out`]).
#[derive(Args, Debug, Clone, Default)]
pub struct ForceFlag {
    /// Write into an existing output folder that holds files: this command's files are
    /// replaced, every other file is left alone, and an input is never overwritten.
    #[arg(long)]
    pub force: bool,
}

/// Checks and creates an output folder before any work (the one rule for outputs:
/// `rollcam::io::out_dir`). `inputs` are the command's input files, `None` where a flag
/// was not given; a folder input (a calibration, a capture folder) stands for its files.
/// Start the live page's server on `dir` at `addr` (`serve`, `view`), warning when the
/// address lets other machines see it.
pub fn start_page(dir: &Path, addr: std::net::SocketAddr) -> Result<rollcam::lab::live::LiveServer> {
    let server = rollcam::lab::live::LiveServer::start(dir, addr)?;
    if !addr.ip().is_loopback() {
        tracing::warn!("serving on {addr}: the page is visible to other machines on the network");
    }
    Ok(server)
}

/// Keep the page up until Ctrl-C, then stop its server.
pub fn serve_until_ctrl_c(server: rollcam::lab::live::LiveServer) {
    let stop = ctrl_c_flag();
    while !stop.load(Ordering::SeqCst) {
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    server.stop();
    println!("stopped");
}

/// Refuse to run as one of several processes started by an MPI launcher unless this
/// command splits its work across them (`splits`) and this build has MPI (cargo
/// feature `mpi`): otherwise `mpirun -np R rollcam ...` would start R copies of the
/// same command writing the same folder.
pub fn refuse_mpi_launch(splits: bool) -> Result<()> {
    let Some((size, var)) = rollcam::cluster::launched_ranks() else { return Ok(()) };
    if !rollcam::cluster::MPI_BUILT {
        if size == 1 {
            // One copy writes one folder: the command runs as without a launcher.
            return Ok(());
        }
        anyhow::bail!(
            "started as one of {size} MPI processes ({var}={size}), but this rollcam was built without MPI support (cargo feature `mpi`): {size} copies would run the same command into the same folder; run it without mpirun, or build with --features mpi"
        );
    }
    if !splits && size > 1 {
        anyhow::bail!(
            "started as one of {size} MPI processes ({var}={size}), but only `reconstruct` and `bench --preset` split their work across MPI ranks: {size} copies of this command would run the same work into the same place; run it without mpirun"
        );
    }
    Ok(())
}

/// Write `line` and a newline to stderr in one write: the lines of several MPI ranks,
/// which the launcher forwards to one terminal, then do not interleave.
pub fn stderr_line(line: &str) {
    use std::io::Write;
    let _ = std::io::stderr().lock().write_all(format!("{line}\n").as_bytes());
}

pub fn claim_out(out: &Path, force: &ForceFlag, writes: &[&str], inputs: &[(&str, Option<&Path>)]) -> Result<rollcam::io::out_dir::OutputFolder> {
    let mut files: Vec<(String, PathBuf)> = Vec::new();
    for (role, path) in inputs {
        let Some(path) = path else { continue };
        if path.is_dir() {
            if let Ok(entries) = std::fs::read_dir(path) {
                for e in entries.flatten() {
                    files.push((format!("{role}: {}", e.file_name().to_string_lossy()), e.path()));
                }
            }
        } else {
            files.push((role.to_string(), path.to_path_buf()));
        }
    }
    let inputs: Vec<(&str, &Path)> = files.iter().map(|(r, p)| (r.as_str(), p.as_path())).collect();
    Ok(rollcam::io::out_dir::claim(out, force.force, writes, &inputs)?)
}

/// The bench's sensor: a calibration folder and a background frame.
#[derive(Args, Debug, Clone, Default)]
pub struct SensorFlags {
    /// Bench calibration folder made by `rollcam calibrate` (per-pixel dark, defect
    /// map, saturation level, PSF, background). Default: capture.toml's
    /// `[calibration] dir`. Its psf.tiff is used when --psf is not given.
    #[arg(long)]
    pub calibration: Option<PathBuf>,
    /// A frame of the static background as shot (same exposure, moving object absent),
    /// subtracted in place of the dark. Default: the calibration's background.tiff.
    #[arg(long)]
    pub background: Option<PathBuf>,
}

impl SensorFlags {
    /// The files these flags name, for [`claim_out`].
    pub fn inputs(&self) -> [(&'static str, Option<&Path>); 2] {
        [("the calibration (--calibration)", self.calibration.as_deref()), ("the background frame (--background)", self.background.as_deref())]
    }
    /// Load the calibration and background for a capture described by `cfg` (read
    /// from `config`, whose `[calibration] dir` is relative to its folder).
    pub fn load(&self, config: Option<&Path>, cfg: &CaptureConfig) -> Result<SensorFiles> {
        Ok(SensorFiles::load(self.calibration.as_deref(), self.background.as_deref(), config, cfg.calibration.as_ref())?
            .with_keyframes(&cfg.keyframes, config)?)
    }
}

/// Reads the raw (`--raw`), taking page `--page N` of a multi-page TIFF; a multi-page raw
/// read without `--page` is refused naming the flag (other inputs have no page choice).
pub fn read_raw(raw: &Path, page: Option<usize>) -> Result<ndarray::Array3<f32>> {
    rollcam::io::read_image_page(raw, page).map_err(|e| match e {
        rollcam::io::IoError::PageRequired { pages, .. } => {
            anyhow::anyhow!("--raw {}: holds {pages} pages where one image was expected; choose one with --page N (N from 1 to {pages})", raw.display())
        }
        e => e.into(),
    })
}

/// A Bayer raw (DNG, CFA TIFF) reads as its half grid: a capture description of
/// another size is refused here, naming the half grid and the line time it should give
/// (docs/capture-toml.md), before the generic size check would only say the sizes differ.
pub fn check_bayer_grid(raw: &Path, raw_shape: (usize, usize), cfg: &CaptureConfig) -> Result<()> {
    let Some(info) = rollcam::io::raw_info(raw) else { return Ok(()) };
    if (cfg.rows, cfg.cols) == raw_shape {
        return Ok(());
    }
    let (r, c) = raw_shape;
    let sensor = if (cfg.rows, cfg.cols) == (info.sensor_rows, info.sensor_cols) { ", the sensor's" } else { "" };
    anyhow::bail!(
        "--raw {}: a {} Bayer raw of {} x {} sensor pixels, read as R, G, B on its half grid of {r} x {c}; the capture description says rows x cols = {} x {}{sensor}: describe the half grid (rows = {r}, cols = {c}, line_time_us = twice the sensor's line time: one half-grid row is two sensor rows; docs/capture-toml.md)",
        raw.display(),
        info.pattern.name(),
        info.sensor_rows,
        info.sensor_cols,
        cfg.rows,
        cfg.cols
    )
}

/// The PSF: the `--psf` image, else the calibration's (already dark-subtracted: the
/// third value says so), with its name for messages.
pub fn psf_or_calibration(psf: Option<&Path>, sensor: &SensorFiles) -> Result<(ndarray::Array3<f32>, String, bool)> {
    match (psf, sensor.psf()) {
        (Some(p), _) => Ok((rollcam::io::read_image(p)?, p.display().to_string(), false)),
        (None, Some((name, img))) => Ok((img.clone(), name, true)),
        (None, None) => anyhow::bail!(
            "no PSF: give --psf (an image of a point source through the same optics), or --calibration with a folder that has a psf.tiff{}",
            sensor.calibration_name().map(|d| format!(" ({d} has none)")).unwrap_or_default()
        ),
    }
}

/// Print what sensor handling did to a capture (and its warnings, on stderr).
pub fn print_sensor(r: &SensorReport) {
    let level = match (r.saturation_level, r.saturation_source) {
        (Some(l), Some(s)) => format!("saturation level {l} ({})", s.describe()),
        _ => "saturation level unknown".into(),
    };
    println!(
        "sensor: dark from {}, {level}: {} clipped pixels ({:.3}%; {} one-sided in the data term), {} calibration defects, {} hot and {} dead outliers found (each left out of its block's mean); {} pixels ({:.3}%) left out of the data term (a solved pixel whose block has fewer than half good pixels)",
        r.dark_source.describe(),
        r.saturated_pixels,
        100.0 * r.saturated_fraction,
        r.lower_bound_pixels,
        r.calibration_defects,
        r.outliers_hot,
        r.outliers_dead,
        r.masked_pixels,
        100.0 * r.masked_fraction
    );
    if r.psf_downsampled > 1 {
        println!("sensor: the PSF is {k} times the raw's size on both axes: box-averaged by {k} to match it", k = r.psf_downsampled);
    }
    if r.psf_repaired > 0 {
        println!("sensor: {} PSF pixels repaired from their neighbours (defects, clipped)", r.psf_repaired);
    }
    for w in &r.warnings {
        eprintln!("warning: {w}");
    }
}

impl CaptureFlags {
    /// The flags as plain data (the model's [`CaptureOverrides`]).
    pub fn overrides(&self) -> CaptureOverrides {
        CaptureOverrides {
            line_time_us: self.line_time_us,
            exposure_us: self.exposure_us,
            shutter: self.shutter,
            downsample: self.downsample,
            binning: self.binning,
            dark_level: self.dark_level,
            saturation_level: self.saturation_level,
            fov: self.fov,
        }
    }

    /// Merge with a capture.toml (flags win); without a file, rows/cols come from the
    /// raw image and the timing flags are required.
    pub fn resolve(&self, config: Option<&Path>, raw_shape: (usize, usize)) -> Result<CaptureConfig> {
        rollcam::io::capture_file::resolve_capture(config, &self.overrides(), raw_shape)
    }
}

/// Solver flags.
#[derive(Args, Debug, Clone)]
pub struct SolverFlags {
    /// TV weight tau, absolute (data units). Default: --tau-rel times the largest
    /// entry of A^T b (the scale at which TV would flatten everything).
    #[arg(long, value_parser = parse_f32)]
    pub tau: Option<f32>,
    /// TV weight relative to max(A^T b), used when --tau is not given; `noise` (the
    /// default): from the raw's noise and the video's frames (0.02 sigma / sqrt(frames),
    /// docs/usage.md); `auto`: chosen by held-out pixels on a mostly still scene (a few
    /// short solves first, from the noise rule's weight), else the noise rule's.
    #[arg(long, default_value_t = Tau::default())]
    pub tau_rel: Tau,
    /// Weight of the temporal gradient relative to the spatial ones.
    #[arg(long, default_value_t = DEFAULT_ALPHA, value_parser = parse_f32)]
    pub alpha: f32,
    /// Most solver iterations (a run whose objective settles first stops there; see
    /// --obj-tol). summary.json's `converged` says which ended it.
    #[arg(long, default_value_t = DEFAULT_ITERS)]
    pub iters: usize,
    /// Stop when the relative change of the iterate falls below this (0: off).
    #[arg(long, default_value_t = 0.0)]
    pub rel_tol: f64,
    /// Stop after this many solver seconds.
    #[arg(long)]
    pub time_budget_s: Option<f64>,
    /// Converged when the objective's relative change stays below this for 5
    /// iterations in a row (0: off, run to --iters).
    #[arg(long, default_value_t = DEFAULT_OBJ_TOL)]
    pub obj_tol: f64,
    /// Plain FISTA momentum, without adaptive restart (same as --solver fista).
    #[arg(long)]
    pub no_restart: bool,
    /// Solver: fista, fista-restart (default), mfista, admm, pgd or admm-split (ADMM with every update in closed form).
    #[arg(long)]
    pub solver: Option<SolverKind>,
    /// TV proximal map: auto (default: the exact dual map at strong TV, else the fast
    /// Haar map), haar, or dualN (exact, N inner iterations per call).
    #[arg(long, default_value = "auto")]
    pub tv_prox: TvProxChoice,
    /// Weight of an L1 (sparsity) term relative to tau. Default: none for a plain
    /// video; 1 on the dynamic part of a static_background scene.
    #[arg(long, value_parser = parse_f32)]
    pub l1: Option<f32>,
    /// Rounds of reweighted L1 after the first solve, on the dynamic part of the
    /// static + dynamic model, each as long as the first and starting from the last
    /// (default: such rounds, each at least 100 iterations, until 400 iterations in all
    /// are spent, at most 10; 0: none).
    #[arg(long)]
    pub l1_reweight: Option<usize>,
    /// Where the video solve starts: auto (default: the still image, solved first and
    /// repeated in every frame, when it explains the raw to within 10% (a mostly still
    /// scene), else zero), still (the still image whatever its residual), or zero.
    #[arg(long, default_value = "auto")]
    pub start: Start,
    /// Where the solver runs: cpu (default) or cuda (fista, fista-restart or admm-split
    /// on an NVIDIA GPU; a build with `--features cuda`, docs/gpu.md).
    #[arg(long, default_value = "cpu")]
    pub device: Device,
}

/// `--tau-rel` of the commands without the held-out search (compare, demo, the LED
/// sweep): a number or `noise`.
pub fn parse_tau_rel_fixed(text: &str) -> Result<Tau, String> {
    match text.parse::<Tau>()? {
        Tau::Auto(_) => Err(format!("{text}: expected a number or noise (the held-out search, auto, is reconstruct's and run's)")),
        given => Ok(given),
    }
}

impl SolverFlags {
    /// The settings as given, validated once; an error names the flag.
    pub fn settings(&self) -> Result<ValidSettings> {
        let s = SolveSettings {
            tau: given_tau(self.tau, self.tau_rel)?,
            alpha: self.alpha,
            iters: self.iters,
            rel_tol: self.rel_tol,
            time_budget_s: self.time_budget_s,
            obj_tol: self.obj_tol,
            solver: self.solver.unwrap_or(if self.no_restart { SolverKind::Fista } else { SolverKind::FistaRestart }),
            tv_prox: self.tv_prox,
            l1: self.l1,
            l1_reweight: self.l1_reweight,
            start: self.start,
            device: self.device,
        };
        let valid = s.validate().map_err(flag_error)?;
        // The device itself, once: the error says what is missing here.
        valid.solver.check_device(valid.device).map_err(|e| anyhow::anyhow!(e))?;
        Ok(valid)
    }
}

/// The TV weight of `--tau` and `--tau-rel`: `--tau` wins, except over `auto` (refused).
pub fn given_tau(tau: Option<f32>, tau_rel: Tau) -> Result<Tau> {
    Tau::from_given(tau, tau_rel).ok_or_else(|| {
        flag_error(InvalidSetting {
            field: "tau",
            value: tau.unwrap_or_default().to_string(),
            expected: "no absolute tau when tau_rel is auto (chosen by held-out pixels)",
        })
    })
}

/// A library setting error in the command line's words (`tau_rel` is `--tau-rel`).
pub fn flag_error(e: InvalidSetting) -> anyhow::Error {
    anyhow::anyhow!("--{} = {}: expected {}", e.field.replace('_', "-"), e.value, e.expected)
}

/// [`flag_error`] of a check that names (field, value, expected).
pub fn check_error((field, value, expected): (&'static str, String, &'static str)) -> anyhow::Error {
    flag_error(InvalidSetting { field, value, expected })
}

/// The longest wait a flag may ask for, seconds (a week).
pub const MAX_WAIT_S: f64 = 7.0 * 86_400.0;

/// A wait given in seconds by `flag`: finite, non-negative and at most [`MAX_WAIT_S`].
pub fn wait_seconds(flag: &str, seconds: f64) -> anyhow::Result<std::time::Duration> {
    if !(seconds.is_finite() && (0.0..=MAX_WAIT_S).contains(&seconds)) {
        anyhow::bail!("--{flag} = {seconds}: expected a number of seconds from 0 to {MAX_WAIT_S} (a week)");
    }
    Ok(std::time::Duration::from_secs_f64(seconds))
}

/// Progress for solves: a bar on a terminal, periodic log lines otherwise.
pub struct Progress {
    bar: Option<ProgressBar>,
    every: usize,
    pub stop: Arc<AtomicBool>,
}

impl Progress {
    pub fn new(total_iters: usize, stop: Arc<AtomicBool>) -> Self {
        let bar = std::io::stderr().is_terminal().then(|| {
            let b = ProgressBar::new(total_iters as u64);
            b.set_style(
                ProgressStyle::with_template("{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} it, {msg}").unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            b
        });
        Progress { bar, every: (total_iters / 10).max(1), stop }
    }

    pub fn row(&self, channel: usize, row: &TraceRow) {
        if let Some(b) = &self.bar {
            b.inc(1);
            let psnr = row.psnr_db.map(|p| format!("  PSNR {p:.2} dB")).unwrap_or_default();
            let left = b.length().unwrap_or(0).saturating_sub(b.position());
            b.set_message(format!("{}  objective {:.4e}{psnr}", eta_at_measured_rate(row, left), row.objective));
        } else if row.iteration % self.every == 0 {
            tracing::info!(channel, iteration = row.iteration, seconds = row.seconds, objective = row.objective, psnr_db = row.psnr_db, "FISTA");
        }
    }

    /// A line above the bar (on stdout without a terminal).
    pub fn println(&self, line: &str) {
        match &self.bar {
            Some(b) => b.println(line),
            None => println!("{line}"),
        }
    }

    pub fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }

    pub fn stopped(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }
}

/// The time left at the rate the solver's own clock measured so far (its seconds per
/// iteration, which leave out what came before the first iteration: the step size,
/// the still start), for `left` iterations: the most it takes, since the stop rule
/// usually ends a solve before the cap.
pub fn eta_at_measured_rate(row: &TraceRow, left: u64) -> String {
    if row.iteration == 0 || !(row.seconds > 0.0) {
        return "ETA -".into();
    }
    let per_iteration_s = row.seconds / row.iteration as f64;
    format!("ETA at most {:.0} s ({:.3} s/it measured)", per_iteration_s * left as f64, per_iteration_s)
}

/// A stop flag raised by Ctrl-C (installed once per process).
pub fn ctrl_c_flag() -> Arc<AtomicBool> {
    static FLAG: std::sync::OnceLock<Arc<AtomicBool>> = std::sync::OnceLock::new();
    FLAG.get_or_init(|| {
        let f = Arc::new(AtomicBool::new(false));
        let g = f.clone();
        if let Err(e) = ctrlc::set_handler(move || g.store(true, Ordering::SeqCst)) {
            tracing::warn!("cannot install the Ctrl-C handler: {e}");
        }
        f
    })
    .clone()
}

/// The second, global-shutter key-frame camera of `capture` and `run`.
#[derive(Args, Debug, Clone, Default)]
pub struct KeyCameraFlags {
    /// Key-frame camera, same syntax as --camera: sim or sim:<name> (the simulated key
    /// camera, beside --camera sim...; a spec other than --camera's) or a device (aravis:<id>). Fired with every raw frame; its frames
    /// are written beside the raw ones (keyframe_NNNNNN_JJ.tiff) with each raw frame's
    /// [[keyframes]] tables (frame_NNNNNN.toml; capture.toml gets frame 0's).
    #[arg(long, value_name = "SPEC")]
    pub keyframe_camera: Option<String>,
    /// When each key frame starts, per raw frame, comma-separated: microseconds on the
    /// capture's time axis (0: the raw's first row starts), first or last (the first /
    /// last video frame's start), as simulate --keyframes. Default: first.
    #[arg(long, value_delimiter = ',', requires = "keyframe_camera")]
    pub keyframes: Vec<String>,
    /// Exposure of every key frame, microseconds (default: one video frame time).
    #[arg(long, requires = "keyframe_camera")]
    pub keyframe_exposure_us: Option<f64>,
    /// What fires the key camera: software (rollcam, at each time after it fires the
    /// main camera) or hardware:<line>[:rising|falling|any] (the key camera's input
    /// line, wired from the main camera's exposure output or an LED pulser channel).
    #[arg(long, default_value = "software", requires = "keyframe_camera")]
    pub keyframe_trigger: String,
    /// Where the tables' start_us come from: shared (measured from the two cameras'
    /// device timestamps: only when they share one clock, e.g. PTP) or commanded (the
    /// trigger's times). Default: shared on the simulated key camera, commanded on a device.
    #[arg(long, requires = "keyframe_camera")]
    pub keyframe_clock: Option<String>,
}

impl KeyCameraFlags {
    /// The key camera asked for, checked against the main camera's spec (`None`: none).
    pub fn request(&self, main: &str, timeout_ms: u64) -> Result<Option<rollcam::lab::keycam::KeyCameraRequest>> {
        let Some(spec) = &self.keyframe_camera else { return Ok(None) };
        let main = rollcam::lab::camera::CameraTarget::parse(main)?;
        let mut req = rollcam::lab::keycam::KeyCameraRequest::new(spec, &main, &self.keyframes, self.keyframe_exposure_us, &self.keyframe_trigger)?;
        req.clock = self.keyframe_clock.as_deref().map(str::parse).transpose().map_err(|e: String| anyhow::anyhow!("--keyframe-clock {e}"))?;
        req.frame_timeout = std::time::Duration::from_millis(timeout_ms);
        Ok(Some(req))
    }
}

/// An error and its chain of causes, each said once (a message that already quotes its
/// cause, as the file errors do, is not followed by it again).
pub fn error_text(e: &anyhow::Error) -> String {
    let mut text = e.to_string();
    for cause in e.chain().skip(1) {
        let c = cause.to_string();
        if !text.contains(&c) {
            text.push_str(": ");
            text.push_str(&c);
        }
    }
    text
}
