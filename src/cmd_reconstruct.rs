//! `rollcam reconstruct`: one raw capture + PSF + timing -> video folder.

use crate::cmd_common::{ctrl_c_flag, CaptureFlags, Progress, SolverFlags};
use anyhow::{bail, Context, Result};
use clap::Args;
use rollcam::io;
use rollcam::lipschitz::LipschitzCache;
use rollcam::output::{write_reconstruction, Inputs};
use rollcam::prepare::prepare;
use rollcam::reconstruct::{reconstruct, tau_scale, Hooks};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct ReconstructArgs {
    /// Raw rolling-shutter capture (TIFF 8/16-bit or float, PNG, .npy; grey or RGB).
    #[arg(long)]
    pub raw: PathBuf,
    /// PSF: image of a point source through the same optics, same size as the raw.
    #[arg(long)]
    pub psf: PathBuf,
    /// capture.toml describing the raw capture (flags below override it).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Ground-truth video (frames, rows, cols[, channels]) to report PSNR against.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub capture: CaptureFlags,
    #[command(flatten)]
    pub solver: SolverFlags,
}

pub fn run(a: ReconstructArgs) -> Result<()> {
    let raw = io::read_image(&a.raw)?;
    let psf = io::read_image(&a.psf)?;
    let (rows, cols, _) = raw.dim();
    let cfg = a.capture.resolve(a.config.as_deref(), (rows, cols))?;
    let truth = match &a.truth {
        Some(p) => Some(io::read_stack(p)?),
        None => None,
    };
    let raw_name = a.raw.display().to_string();
    let psf_name = a.psf.display().to_string();
    let prepared = prepare(raw.view(), &raw_name, psf.view(), &psf_name, cfg.rows, cfg.cols, cfg.downsample, cfg.dark_level)?;
    if prepared.dark_estimated {
        tracing::info!(raw_dark = prepared.raw_dark, psf_dark = prepared.psf_dark, "dark levels estimated from the darkest pixels (give dark_level to fix them)");
    }
    let tau = match a.solver.tau {
        Some(t) => t,
        None => a.solver.tau_rel * tau_scale(&prepared, &cfg, cfg.fov)?,
    };
    let params = a.solver.params(tau, cfg.fov)?;
    let inputs = Inputs {
        raw: Some(raw_name),
        psf: Some(psf_name),
        config: a.config.as_ref().map(|p| p.display().to_string()),
        truth: a.truth.as_ref().map(|p| p.display().to_string()),
    };
    let truth_name = inputs.truth.clone().unwrap_or_default();
    let progress = Progress::new(params.stop.max_iters * prepared.raw.len(), ctrl_c_flag());
    let on_row = |ch: usize, row: &rollcam::trace::TraceRow| progress.row(ch, row);
    let hooks = Hooks { on_row: &on_row, stop: &progress.stop };
    let t0 = Instant::now();
    let rec = reconstruct(
        &prepared,
        &cfg,
        &params,
        truth.as_ref().map(|t| (t.view(), truth_name.as_str())),
        &LipschitzCache::default_location(),
        &hooks,
    )
    .context("reconstruction failed")?;
    let seconds = t0.elapsed().as_secs_f64();
    progress.finish();
    let files = write_reconstruction(
        &a.out,
        &rec,
        &cfg,
        &params,
        &inputs,
        (prepared.raw_dark, prepared.psf_dark, prepared.dark_estimated),
        seconds,
    )?;
    let (k, m, n, c) = rec.video.dim();
    println!("video: {k} frames of {m} x {n} x {c} at {:.1} fps ({:.1} us per frame), tau = {tau:.4e}", 1e6 / rec.frame_time_us, rec.frame_time_us);
    for ch in &rec.channels {
        let err = ch.error.map(|e| format!(", PSNR {:.2} dB, relative error {:.4}", e.psnr_db, e.rel_error)).unwrap_or_default();
        println!("channel {}: {} iterations in {:.2} s ({:?}){err}", ch.channel, ch.iterations, ch.seconds, ch.termination);
    }
    println!("wrote {} files to {}", files.len(), a.out.display());
    if progress.stopped() {
        bail!("interrupted: the video holds the last iterate; {} is complete", a.out.join("summary.json").display());
    }
    Ok(())
}
