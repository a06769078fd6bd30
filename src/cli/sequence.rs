//! `rollcam reconstruct-sequence`: the raw frames of one capture folder as one
//! continuous video (joint, streaming or separate solves).

use crate::cli::common::{ctrl_c_flag, psf_or_calibration, CaptureFlags, Progress, SensorFlags, SolverFlags};
use anyhow::{bail, Context, Result};
use clap::Args;
use rollcam::io;
use rollcam::io::cache::LipschitzCache;
use rollcam::io::sequence_input::load_capture_folder;
use rollcam::io::sequence_output::{write_sequence, CaptureEntry, SequenceSummary};
use rollcam::solve::problem::Tau;
use rollcam::solve::reconstruct::Hooks;
use rollcam::solve::sequence::{Mode, Sequence, TimeGrid};
use std::path::PathBuf;
use std::time::Instant;

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
    rollcam::solve::start::check_for_sequence(settings.start).map_err(crate::cli::common::check_error)?;
    rollcam::solve::tau_search::check_for_sequence(&settings).map_err(crate::cli::common::check_error)?;
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
    if declared != rollcam::model::scene::SceneSpec::default() {
        eprintln!(
            "warning: {}: the [scene] declaration is not applied by reconstruct-sequence (it solves the plain video of every capture); reconstruct one capture with `rollcam reconstruct` to use it",
            config_path.display()
        );
    }
    let sensor = a.sensor.load(Some(&config_path), &cfg)?;
    let psf_path = a.psf.clone().or_else(|| sensor.psf().is_none().then(|| dir.join("psf.tiff")));
    let (psf, psf_name, psf_clean) = psf_or_calibration(psf_path.as_deref(), &sensor)?;
    let input = load_capture_folder(dir, psf.view(), &psf_name, &cfg, &sensor.input(None, psf_clean), a.frame_period_us)?;
    let masked: usize = input.sensor.iter().map(|r| r.masked_pixels).sum();
    let clipped: usize = input.sensor.iter().map(|r| r.saturated_pixels).sum();
    if masked > 0 {
        println!("sensor: {masked} pixels left out of the data term over {} captures ({clipped} clipped raw pixels); summary.json: sensor", input.raws.len());
    }
    let source = input.source;
    let grid = TimeGrid::new(&input.start_us, &cfg.timing().weights()?, source);
    tracing::info!(captures = grid.captures(), frames = grid.frames, gaps = grid.gap_frames().len(), max_residue_us = grid.max_residue_us(), "time grid");
    let seq = Sequence::new(&cfg, input.psf.clone(), grid.clone(), input.raws.clone())?.with_masks(input.masks.clone());
    let (f, mv, nv) = seq.video_shape();
    let truth = match &a.truth {
        Some(p) => {
            let t = io::read_truth(p)?;
            let (tk, tm, tn, tc) = t.dim();
            if (tk, tm, tn, tc) != (f, mv, nv, 1) {
                bail!(
                    "{}: shape {:?} does not match the sequence video's (frames, rows, cols, channels) = {:?}",
                    p.display(),
                    [tk, tm, tn, tc],
                    [f, mv, nv, 1]
                );
            }
            Some(t.iter().cloned().collect::<Vec<f32>>())
        }
        None => None,
    };
    let tau = match settings.tau() {
        Tau::Absolute(t) => t,
        relative => relative.resolve(seq.tau_scale()),
    };
    let params = settings.params_with_tau(tau, cfg.fov);
    let overlap = a.overlap_frames.unwrap_or((grid.capture_frames / 4).max(1));
    let solves = if a.mode == Mode::Joint { 1 } else { grid.captures() };
    let progress = Progress::new(params.stop.max_iters * solves, ctrl_c_flag());
    let on_row = |i: usize, row: &rollcam::solve::trace::TraceRow| progress.row(i, row);
    let hooks = Hooks { on_row: &on_row, stop: &progress.stop };
    let cache = LipschitzCache::default_location();
    let truth_name = a.truth.as_ref().map(|p| p.display().to_string()).unwrap_or_default();
    let t = truth.as_deref().map(|t| (t, truth_name.as_str()));
    let t0 = Instant::now();
    let rec = match a.mode {
        Mode::Joint => {
            let limit = match a.memory_limit_gb {
                Some(gb) if gb.is_finite() && gb > 0.0 => (gb * 1e9) as u64,
                Some(gb) => bail!("--memory-limit-gb = {gb}: expected a positive number of gigabytes"),
                None => rollcam::io::ByteBudget::system().limit_bytes,
            };
            seq.solve_joint(&params, t, &cache, &hooks, limit)
        }
        Mode::Streaming => seq.solve_streaming(&params, overlap, !a.cold_start, t, &cache, &hooks),
        Mode::Separate => seq.solve_separate(&params, t, &cache, &hooks),
    }
    .context("sequence reconstruction failed")?;
    let seconds = t0.elapsed().as_secs_f64();
    progress.finish();
    let captures = CaptureEntry::list(&grid, &input.files, &input.sequence, &input.raw_dark);
    let summary = SequenceSummary {
        rollcam_version: env!("CARGO_PKG_VERSION"),
        capture_dir: dir.display().to_string(),
        psf: psf_name,
        config: config_path.display().to_string(),
        truth: a.truth.as_ref().map(|p| p.display().to_string()),
        capture: &cfg,
        params: &params,
        mode: a.mode,
        overlap_frames: (a.mode == Mode::Streaming).then_some(overlap),
        time_source: source,
        timestamp_period_us: input.timestamp_period_us,
        max_residue_us: grid.max_residue_us(),
        video_shape: [f, mv, nv, 1],
        frame_time_us: grid.frame_time_us,
        frames_per_second: 1e6 / grid.frame_time_us,
        frames_per_capture: grid.capture_frames,
        captures,
        skipped: &input.skipped,
        gap_frames: grid.gap_frames(),
        shared_frames: grid.shared_frames(),
        coverage: &grid.coverage,
        psf_dark_level: input.psf_dark,
        dark_level_estimated: input.dark_estimated,
        calibration: sensor.calibration_name(),
        background: sensor.background_name(),
        sensor: &input.sensor,
        solves: &rec.solves,
        seconds,
        joint_memory_bytes: seq.joint_bytes(),
        psnr_db: rec.error.map(|e| e.psnr_db),
        rel_error: rec.error.map(|e| e.rel_error),
        files: Vec::new(),
    };
    let files = write_sequence(&a.out, &rec, &grid, summary)?;
    let time = match source {
        rollcam::solve::sequence::TimeSource::DeviceTimestamps => "device timestamps".to_string(),
        rollcam::solve::sequence::TimeSource::FramePeriod { period_us } => format!("a frame period of {period_us} us"),
    };
    println!(
        "{} captures placed by {time} (largest rounding residue {:.2} us): {f} frames of {mv} x {nv} at {:.1} us, {} gap frames, {} shared frames, tau = {tau:.4e}",
        grid.captures(),
        grid.max_residue_us(),
        grid.frame_time_us,
        grid.gap_frames().len(),
        grid.shared_frames().len()
    );
    let iters: usize = rec.solves.iter().map(|s| s.stats.iterations).sum();
    let err = rec.error.map(|e| format!(", PSNR {:.2} dB, relative error {:.4}", e.psnr_db, e.rel_error)).unwrap_or_default();
    println!("{} mode: {} solves, {iters} iterations in {seconds:.2} s{err}", a.mode, rec.solves.len());
    println!("wrote {} files to {}", files.len(), a.out.display());
    if progress.stopped() {
        bail!("interrupted: the video holds the last iterate; {} is complete", a.out.join("summary.json").display());
    }
    Ok(())
}
