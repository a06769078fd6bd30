//! `rollcam reconstruct-sequence`: the raw frames of one capture folder as one
//! continuous video (joint, streaming or separate solves).

use crate::cli::common::{ctrl_c_flag, psf_or_calibration, CaptureFlags, Progress, SensorFlags, SolverFlags};
use anyhow::{bail, Context, Result};
use clap::Args;
use rollcam::io::cache::LipschitzCache;
use rollcam::request::sequence::SequenceRequest;
use rollcam::request::sequence::{Mode, TimeSource};
use rollcam::request::Hooks;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct SequenceArgs {
    /// Capture folder as `capture` (or `simulate --captures`) writes it.
    pub capture_dir: PathBuf,
    /// PSF image (default: the calibration's psf.tiff, else CAPTURE_DIR/psf.tiff).
    #[arg(long)]
    pub psf: Option<PathBuf>,
    /// capture.toml (default: CAPTURE_DIR/capture.toml); flags below override it.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Output folder: new or empty (or see --force); checked before any work.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub force: crate::cli::common::ForceFlag,
    /// Ground-truth video on the global grid (frames, rows, cols) to report PSNR against.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// joint (one solve), streaming (capture by capture, warm-started) or separate.
    #[arg(long, default_value = "joint")]
    pub mode: Mode,
    /// Place the captures from their sequence numbers times this period instead of
    /// their device timestamps (needed when the camera gives none).
    #[arg(long)]
    pub frame_period_us: Option<f64>,
    /// Streaming: frames of the result so far each window re-solves (default: K / 4).
    #[arg(long)]
    pub overlap_frames: Option<usize>,
    /// Streaming: start every window from zero instead of the result so far.
    #[arg(long)]
    pub cold_start: bool,
    /// Joint: refuse when the solve needs more (default: the byte budget, 90% of the
    /// available memory or ROLLCAM_MEMORY_LIMIT_GB).
    #[arg(long)]
    pub memory_limit_gb: Option<f64>,
    #[command(flatten)]
    pub capture: CaptureFlags,
    #[command(flatten)]
    pub sensor: SensorFlags,
    #[command(flatten)]
    pub solver: SolverFlags,
}

pub fn run(a: SequenceArgs) -> Result<()> {
    let settings = a.solver.settings()?;
    rollcam::request::sequence::check_settings(&settings).map_err(crate::cli::common::flag_error)?;
    let memory_limit_bytes = match a.memory_limit_gb {
        Some(gb) if gb.is_finite() && gb > 0.0 => Some((gb * 1e9) as u64),
        Some(gb) => bail!("--memory-limit-gb = {gb}: expected a positive number of gigabytes"),
        None => None,
    };
    let [calibration, background] = a.sensor.inputs();
    let inputs = [
        ("the capture folder", Some(a.capture_dir.as_path())),
        ("the PSF (--psf)", a.psf.as_deref()),
        ("the capture description (--config)", a.config.as_deref()),
        ("the truth (--truth)", a.truth.as_deref()),
        calibration,
        background,
    ];
    crate::cli::common::claim_out(&a.out, &a.force, rollcam::io::sequence_output::SEQUENCE_FILES, &inputs)?;
    let dir = &a.capture_dir;
    let config_path = a.config.clone().unwrap_or_else(|| dir.join("capture.toml"));
    // The file gives rows and cols (the shape is only used without one).
    let cfg = a.capture.resolve(Some(&config_path), (0, 0))?;
    // A sequence solves the plain video of every capture: say so when capture.toml
    // declares a scene (e.g. static_background), rather than leave it out unseen.
    let declared = rollcam::model::scene::SceneSpec::from_table(cfg.scene.as_ref()).with_context(|| config_path.display().to_string())?;
    if !declared.is_plain() {
        eprintln!(
            "warning: {}: the [scene] declaration is not applied by reconstruct-sequence (it solves the plain video of every capture); reconstruct one capture with `rollcam reconstruct` to use it",
            config_path.display()
        );
    }
    let sensor = a.sensor.load(Some(&config_path), &cfg)?;
    let psf_path = a.psf.clone().or_else(|| sensor.psf().is_none().then(|| dir.join("psf.tiff")));
    let (psf, psf_name, psf_clean) = psf_or_calibration(psf_path.as_deref(), &sensor)?;
    let request = SequenceRequest {
        capture_dir: dir,
        psf: psf.view(),
        psf_name: &psf_name,
        psf_clean,
        cfg: &cfg,
        config_name: config_path.display().to_string(),
        sensor: &sensor,
        settings: &settings,
        mode: a.mode,
        frame_period_us: a.frame_period_us,
        overlap_frames: a.overlap_frames,
        warm_start: !a.cold_start,
        memory_limit_bytes,
        truth: a.truth.as_deref(),
    };
    let loaded = request.load()?;
    let (input, grid) = (&loaded.input, &loaded.grid);
    let masked: usize = input.sensor.iter().map(|r| r.masked_pixels).sum();
    let clipped: usize = input.sensor.iter().map(|r| r.saturated_pixels).sum();
    if masked > 0 {
        println!("sensor: {masked} pixels left out of the data term over {} captures ({clipped} clipped raw pixels); summary.json: sensor", input.raws.len());
    }
    let progress = Progress::new(loaded.params.stop.max_iters * loaded.solves(), ctrl_c_flag());
    let on_row = |i: usize, row: &rollcam::request::TraceRow| progress.row(i, row);
    let hooks = Hooks { on_row: &on_row, stop: &progress.stop };
    let outcome = loaded.solve(&a.out, &LipschitzCache::default_location(), &hooks)?;
    progress.finish();
    let (f, mv, nv) = loaded.sequence.video_shape();
    let time = match input.source {
        TimeSource::DeviceTimestamps => "device timestamps".to_string(),
        TimeSource::FramePeriod { period_us } => format!("a frame period of {period_us} us"),
    };
    println!(
        "{} captures placed by {time} (largest rounding residue {:.2} us): {f} frames of {mv} x {nv} at {:.1} us, {} gap frames, {} shared frames, tau = {:.4e}",
        grid.captures(),
        grid.max_residue_us(),
        grid.frame_time_us,
        grid.gap_frames().len(),
        grid.shared_frames().len(),
        loaded.params.tau
    );
    let rec = &outcome.video;
    let iters: usize = rec.solves.iter().map(|s| s.stats.iterations).sum();
    let err = rec.error.map(|e| format!(", PSNR {:.2} dB, relative error {:.4}", e.psnr_db, e.rel_error)).unwrap_or_default();
    println!("{} mode: {} solves, {iters} iterations in {:.2} s{err}", a.mode, rec.solves.len(), outcome.seconds);
    println!("wrote {} files to {}", outcome.files.len(), a.out.display());
    if progress.stopped() {
        bail!("interrupted: the video holds the last iterate; {} is complete", a.out.join("summary.json").display());
    }
    Ok(())
}
