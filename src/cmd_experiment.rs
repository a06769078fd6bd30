//! `rollcam experiment led-sweep`: the temporal-resolution experiment in simulation
//! (hardware mode is not implemented: it simulates only).

use crate::cmd_common::ctrl_c_flag;
use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use rollcam::analysis::led_sweep::{run_sweep, SweepOptions, SweepSize, PERIODS_US};
use rollcam::reconstruct::Hooks;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct ExperimentArgs {
    #[command(subcommand)]
    pub which: Experiment,
}

#[derive(Subcommand, Debug)]
pub enum Experiment {
    /// Four LEDs flashing in unison at each period: simulate, reconstruct, analyse, report.
    LedSweep(LedSweepArgs),
}

#[derive(Args, Debug)]
pub struct LedSweepArgs {
    /// Square-wave periods, microseconds (comma-separated).
    #[arg(long, value_delimiter = ',', default_values_t = PERIODS_US.to_vec())]
    pub periods_us: Vec<f64>,
    /// Output folder.
    #[arg(long, default_value = "rollcam-led-sweep")]
    pub out: PathBuf,
    /// FISTA iterations per period.
    #[arg(long, default_value_t = 100)]
    pub iters: usize,
    /// Sensor size: small (64 x 80), demo (128 x 160) or paper-8x (270 x 320).
    #[arg(long, default_value = "demo")]
    pub size: SweepSize,
    /// LED spacing, raw pixels.
    #[arg(long, default_value_t = 6.0)]
    pub spacing_px: f64,
    /// TV weight relative to max(A^T b).
    #[arg(long, default_value_t = 2e-3)]
    pub tau_rel: f32,
    /// Temporal TV weight.
    #[arg(long, default_value_t = 5.0)]
    pub alpha: f32,
    /// Seed of the diffuser and the noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Also write DIR/led-sweep.md and DIR/figures/led-sweep*.png for the documentation.
    #[arg(long)]
    pub docs: Option<PathBuf>,
}

pub fn run(a: ExperimentArgs) -> Result<()> {
    match a.which {
        Experiment::LedSweep(s) => led_sweep(s),
    }
}

fn led_sweep(a: LedSweepArgs) -> Result<()> {
    let opts = SweepOptions { periods_us: a.periods_us.clone(), size: a.size, iters: a.iters, tau_rel: a.tau_rel, alpha: a.alpha, spacing_px: a.spacing_px, seed: a.seed };
    let periods: Vec<String> = a.periods_us.iter().map(|p| format!("{p}")).collect();
    let mut command = format!(
        "rollcam experiment led-sweep --periods-us {} --size {} --iters {} --spacing-px {} --tau-rel {} --alpha {} --seed {} --out {}",
        periods.join(","),
        a.size.name(),
        a.iters,
        a.spacing_px,
        a.tau_rel,
        a.alpha,
        a.seed,
        a.out.display()
    );
    if let Some(d) = &a.docs {
        command.push_str(&format!(" --docs {}", d.display()));
    }
    let stop = ctrl_c_flag();
    let nothing = |_: usize, _: &rollcam::trace::TraceRow| {};
    let hooks = Hooks { on_row: &nothing, stop: &stop };
    let (rows, cols) = a.size.sensor();
    println!("LED sweep on a {rows} x {cols} sensor, periods {:?} us, {} iterations each", a.periods_us, a.iters);
    let report = run_sweep(&opts, &a.out, &command, &hooks, &|r| {
        println!(
            "period {:.0} us: expected {:.1} Hz, peak {}, temporal contrast {:.2} (theory {:.2}), spatial contrast {:.2}, {}/{} LED pairs resolved, {:.1} s",
            r.period_us,
            r.expected_frequency_hz,
            r.measured_peak_hz.map_or("none".into(), |f| format!("{f:.1} Hz")),
            r.temporal_contrast,
            r.expected_temporal_contrast,
            r.spatial_contrast,
            r.pairs_resolved,
            r.pairs,
            r.seconds
        );
    })?;
    println!("report: {} ({})", a.out.join("report.md").display(), a.out.join("report.json").display());
    if let Some(docs) = &a.docs {
        let figs = docs.join("figures");
        std::fs::create_dir_all(&figs).with_context(|| format!("{}: cannot create the folder", figs.display()))?;
        std::fs::copy(a.out.join(&report.figure), figs.join("led-sweep.png")).with_context(|| format!("{}: cannot write", figs.join("led-sweep.png").display()))?;
        for r in &report.rows {
            let src = a.out.join(&r.folder).join("analysis").join("timecourse.png");
            let dst = figs.join(format!("led-sweep-timecourse-{:.0}us.png", r.period_us));
            std::fs::copy(&src, &dst).with_context(|| format!("{}: cannot write", dst.display()))?;
        }
        let mut md = rollcam::analysis::led_sweep::report_markdown(&report, "figures/led-sweep.png");
        md.push_str("\n## Time courses\n\n");
        for r in &report.rows {
            md.push_str(&format!("![time courses of the LED regions, period {0:.0} us](figures/led-sweep-timecourse-{0:.0}us.png)\n\n", r.period_us));
        }
        let path = docs.join("led-sweep.md");
        std::fs::write(&path, md).with_context(|| format!("{}: cannot write", path.display()))?;
        println!("documentation: {}", path.display());
    }
    Ok(())
}
