//! Pieces shared by the commands: capture-description flags, solver flags, progress.

use anyhow::Result;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use rollcam::model::capture::{CaptureConfig, CaptureOverrides, Fov};
use rollcam::model::shutter::ShutterMode;
use rollcam::solve::optimize::SolverKind;
use rollcam::solve::problem::{InvalidSetting, SolveSettings, DEFAULT_ALPHA, DEFAULT_ITERS, DEFAULT_TAU_REL};
use rollcam::solve::prox::tv_dual::TvProxChoice;
use rollcam::solve::trace::TraceRow;
use std::io::IsTerminal;
use std::path::Path;
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
    /// Shutter mode: global, rolling, dual (outside-in) or dual-center-out.
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
    /// Video grid: sensor (default) or full (every point whose PSF reaches the sensor).
    #[arg(long)]
    pub fov: Option<Fov>,
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
    #[arg(long)]
    pub tau: Option<f32>,
    /// TV weight relative to max(A^T b), used when --tau is not given.
    #[arg(long, default_value_t = DEFAULT_TAU_REL)]
    pub tau_rel: f32,
    /// Weight of the temporal gradient relative to the spatial ones.
    #[arg(long, default_value_t = DEFAULT_ALPHA)]
    pub alpha: f32,
    /// Maximum solver iterations.
    #[arg(long, default_value_t = DEFAULT_ITERS)]
    pub iters: usize,
    /// Stop when the relative change of the iterate falls below this (0: off).
    #[arg(long, default_value_t = 0.0)]
    pub rel_tol: f64,
    /// Stop after this many solver seconds.
    #[arg(long)]
    pub time_budget_s: Option<f64>,
    /// Plain FISTA momentum, without adaptive restart (same as --solver fista).
    #[arg(long)]
    pub no_restart: bool,
    /// Solver: fista, fista-restart (default), mfista, admm or pgd.
    #[arg(long)]
    pub solver: Option<SolverKind>,
    /// TV proximal map: auto (default: the exact dual map at strong TV, else the fast
    /// Haar map), haar, or dualN (exact, N inner iterations per call).
    #[arg(long, default_value = "auto")]
    pub tv_prox: TvProxChoice,
}

impl SolverFlags {
    /// The settings as given, validated once; an error names the flag.
    pub fn settings(&self) -> Result<SolveSettings> {
        let s = SolveSettings {
            tau: self.tau,
            tau_rel: self.tau_rel,
            alpha: self.alpha,
            iters: self.iters,
            rel_tol: self.rel_tol,
            time_budget_s: self.time_budget_s,
            restart: !self.no_restart,
            solver: self.solver,
            tv_prox: self.tv_prox,
        };
        s.validate().map_err(flag_error)?;
        Ok(s)
    }
}

/// A library setting error in the command line's words (`tau_rel` is `--tau-rel`).
pub fn flag_error(e: InvalidSetting) -> anyhow::Error {
    anyhow::anyhow!("--{} = {}: expected {}", e.field.replace('_', "-"), e.value, e.expected)
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
                ProgressStyle::with_template("{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} it  {msg}").unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            b
        });
        Progress { bar, every: (total_iters / 10).max(1), stop }
    }

    pub fn row(&self, channel: usize, row: &TraceRow) {
        if let Some(b) = &self.bar {
            b.inc(1);
            let psnr = row.psnr_db.map(|p| format!("  PSNR {p:.2} dB")).unwrap_or_default();
            b.set_message(format!("objective {:.4e}{psnr}", row.objective));
        } else if row.iteration % self.every == 0 {
            tracing::info!(channel, iteration = row.iteration, seconds = row.seconds, objective = row.objective, psnr_db = row.psnr_db, "FISTA");
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
