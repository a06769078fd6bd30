//! `rollcam demo`: the whole method on an embedded default, no hardware and no files:
//! simulate four LEDs flashing square waves through a synthetic diffuser on a dual
//! rolling shutter, reconstruct the video, and check each LED's time course.

use crate::cli::common::{ctrl_c_flag, flag_error, Progress};
use anyhow::{Context, Result};
use clap::Args;
use ndarray::Axis;
use rollcam::analysis::{correlation, region_time_course};
use rollcam::io::cache::LipschitzCache;
use rollcam::io::output::{Inputs, OutputSet};
use rollcam::io::sensor_files::SensorFiles;
use rollcam::lab::sim_output;
use rollcam::request::capture::CaptureRequest;
use rollcam::request::{parse_f32, Hooks, SolveSettings, Tau, TraceRow, DEFAULT_ALPHA, DEFAULT_ITERS};
use rollcam::sim::{SimParams, SimSetup};
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Output folder: new or empty (default: ./rollcam-demo, or rollcam-demo-2, -3, ...
    /// when that one holds files, so nothing is ever replaced).
    #[arg(long)]
    pub out: Option<PathBuf>,
    #[command(flatten)]
    pub force: crate::cli::common::ForceFlag,
    /// Most solver iterations (the default stop rule ends the solve earlier when its
    /// objective settles, as in reconstruct).
    #[arg(long, default_value_t = DEFAULT_ITERS)]
    pub iters: usize,
    /// TV weight relative to max(A^T b), or `noise` (the default: from the raw's noise).
    #[arg(long, default_value_t = Tau::default(), value_parser = crate::cli::common::parse_tau_rel_fixed)]
    pub tau_rel: Tau,
    /// Temporal TV weight.
    #[arg(long, default_value_t = DEFAULT_ALPHA, value_parser = parse_f32)]
    pub alpha: f32,
}

#[derive(Serialize)]
struct LedReport {
    led: usize,
    period_us: f64,
    row: usize,
    col: usize,
    correlation: f64,
}

pub fn run(a: DemoArgs) -> Result<()> {
    let settings = SolveSettings { tau: a.tau_rel, alpha: a.alpha, iters: a.iters, ..SolveSettings::default() };
    let settings = settings.validate().map_err(flag_error)?;
    let out = match &a.out {
        Some(out) => {
            crate::cli::common::claim_out(out, &a.force, &["sim", "rec", "demo.json"], &[])?;
            out.clone()
        }
        None => rollcam::io::out_dir::fresh_folder(std::path::Path::new("rollcam-demo")),
    };
    let t0 = Instant::now();
    let sim_dir = out.join("sim");
    let rec_dir = out.join("rec");
    let sim_params = SimParams::default();
    let simulated = SimSetup::led_array(&sim_params).map_err(anyhow::Error::from).and_then(|setup| {
        let (cfg, sim) = setup.simulate()?;
        sim_output::write_capture(&sim_dir, &setup, &cfg, &sim)?;
        Ok((cfg, sim))
    });
    let (cfg, sim) = simulated.context("simulation failed")?;
    println!(
        "simulated: {} x {} raw, {} shutter, line time {} us, exposure {} us, {} LEDs with periods {:?} us ({:.2} s)",
        cfg.rows,
        cfg.cols,
        cfg.shutter,
        cfg.line_time_us,
        cfg.exposure_us,
        sim_params.leds,
        sim_params.period_us,
        t0.elapsed().as_secs_f64()
    );

    let raw = sim.raw.view().insert_axis(Axis(2)).to_owned();
    let psf_img = rollcam::io::read_image(sim_dir.join("psf.tiff"))?;
    let truth = sim.truth.view().insert_axis(Axis(3)).to_owned();
    let sensor = SensorFiles::default();
    let request = CaptureRequest::new(raw.view(), "raw.tiff", psf_img.view(), "psf.tiff", &cfg, &sensor, &settings).with_truth(Some((truth.view(), "truth")));
    let progress = Progress::new(a.iters, ctrl_c_flag());
    let on_row = |ch: usize, row: &TraceRow| progress.row(ch, row);
    let hooks = Hooks { on_row: &on_row, stop: &progress.stop };
    let outcome = request.run(&LipschitzCache::default_location(), &hooks)?;
    let (rec, seconds) = (&outcome.reconstruction, outcome.seconds);
    progress.finish();
    let inputs = Inputs {
        raw: Some(sim_dir.join("raw.tiff").display().to_string()),
        psf: Some(sim_dir.join("psf.tiff").display().to_string()),
        config: Some(sim_dir.join("capture.toml").display().to_string()),
        truth: Some(sim_dir.join("truth.npy").display().to_string()),
        ..request.inputs()
    };
    outcome.write(&rec_dir, &cfg, &inputs, OutputSet::Full)?;

    // Each LED's time course against its true square wave (averaged over each frame).
    let leds = sim_params.led_array(cfg.rows, cfg.cols)?;
    let d = cfg.downsample;
    let k = rec.video.dim().0;
    let mut reports = Vec::new();
    for led in 0..leds.leds() {
        let (r, c) = leds.centre_px(led);
        let (row, col) = ((r / d as f64) as usize, (c / d as f64) as usize);
        let got = region_time_course(rec.video.view(), 0, row, col, 1);
        let want: Vec<f64> = (0..k).map(|f| leds.waveform(led, f as f64 * rec.frame_time_us, (f + 1) as f64 * rec.frame_time_us)).collect();
        let period_us = leds.period_us(led);
        reports.push(LedReport { led, period_us, row, col, correlation: correlation(&got, &want) });
    }
    let json = serde_json::to_string_pretty(&reports)?;
    rollcam::io::write_text_atomic(&rec_dir.join("leds.json"), &json)?;

    let ch = &rec.channels[0];
    let (kk, m, n, _) = rec.video.dim();
    println!(
        "reconstructed: {kk} frames of {m} x {n} at {:.0} fps in {:.2} s ({} iterations, {:.3} s each)",
        1e6 / rec.frame_time_us,
        seconds,
        ch.stats.iterations,
        ch.stats.seconds / ch.stats.iterations.max(1) as f64
    );
    println!("solver: {}", ch.stop_line());
    if let Some(s) = &ch.support {
        println!("{}", s.line(ch.channel));
    }
    if let Some(err) = ch.error_line() {
        println!("against the truth: {err}");
    }
    if let Some(w) = rec.frame_sensitivity.warning() {
        println!("{w}");
    }
    if let Some(f) = &rec.fit {
        println!("{}", f.line());
        f.warnings.iter().for_each(|w| crate::cli::common::stderr_line(&format!("warning: {w}")));
    }
    for l in &reports {
        println!("LED {} (period {} us) at ({}, {}): time course correlates with the truth at r = {:.3}", l.led, l.period_us, l.row, l.col, l.correlation);
    }
    println!("simulation: {}", sim_dir.display());
    println!("video: {} (video.tiff, video.npy, contact.png, video.gif)", rec_dir.display());
    println!("error against run time: {}, {}", rec_dir.join("trace.png").display(), rec_dir.join("trace.csv").display());
    println!("summary: {}", rec_dir.join("summary.json").display());
    Ok(())
}
