//! The folder of a solver comparison (`rollcam compare`): PSNR and objective against
//! run time (PNG and SVG), every run's trace (`traces.csv`), the summary as JSON
//! (`summary.json`) and as a Markdown table (`summary.md`). The runs themselves are in
//! [`crate::solve::compare`].

use crate::io::{self, PlotSpec, Series};
use crate::model::scene::ScenePlan;
use crate::solve::compare::{best_objective, RunDefaults, RunTrace, Savings, SolverSummary, ERROR_TOLERANCES};
use crate::solve::tau::TauChoice;
use crate::solve::trace::{to_csv, TraceRow};
use anyhow::Result;
use std::path::Path;

/// Everything a comparison folder records.
pub struct CompareReport<'a> {
    /// The inputs as given: raw, PSF, capture.toml, truth.
    pub raw: String,
    pub psf: String,
    pub config: String,
    pub truth: Option<String>,
    pub tau: f32,
    /// How tau was chosen (the rule, and what it read).
    pub tau_choice: TauChoice,
    pub alpha: f32,
    /// Frame interval of the videos (`videos/LABEL.npy`), microseconds.
    pub frame_time_us: f64,
    pub lipschitz: f64,
    pub lipschitz_seconds: f64,
    /// Settings of the runs that name none of their own.
    pub defaults: RunDefaults,
    pub plan: &'a ScenePlan,
    pub truth_objective: Option<f64>,
    pub traces: &'a [RunTrace],
    pub summaries: &'a [SolverSummary],
    pub savings: Option<&'a Savings>,
}

/// What [`write_compare`] wrote besides the traces and summaries.
pub struct CompareWritten {
    /// The PNG figures, by file name.
    pub figures: Vec<&'static str>,
    /// The text of `summary.md`.
    pub markdown: String,
}

/// Create the output folder (before the runs, so that a bad folder fails first).
/// Every file [`write_compare`] may write (for the output-folder check).
pub const COMPARE_FILES: &[&str] =
    &["psnr_vs_time.png", "psnr_vs_time.svg", "objective_vs_time.png", "objective_vs_time.svg", "traces.csv", "summary.json", "summary.md", VIDEOS_DIR];

/// The folder of each run's video (`videos/LABEL.npy`, written by `rollcam compare`).
pub const VIDEOS_DIR: &str = "videos";

/// Write the figures, `traces.csv`, `summary.json` and `summary.md` into `out`.
pub fn write_compare(out: &Path, r: &CompareReport) -> Result<CompareWritten> {
    std::fs::create_dir_all(out).map_err(|e| anyhow::anyhow!("{}: cannot create the folder: {e}", out.display()))?;
    let with_truth = r.truth.is_some();
    let best_obj = best_objective(r.traces);
    // Figures: PSNR (when a truth is given) and relative objective against run time.
    let series = |f: &dyn Fn(&TraceRow) -> Option<f64>| -> Vec<Series> {
        r.traces.iter().map(|t| Series { name: t.run.label.clone(), points: t.rows.iter().filter_map(|r| f(r).map(|y| (r.seconds, y))).collect() }).collect()
    };
    let mut figures = Vec::new();
    if with_truth {
        let spec = PlotSpec {
            title: "PSNR against run time".into(),
            x_label: "solver run time (s)".into(),
            y_label: "PSNR (dB)".into(),
            series: series(&|r| r.psnr_db),
            ..PlotSpec::default()
        };
        io::plot_lines(out.join("psnr_vs_time.png"), &spec)?;
        io::plot_lines(out.join("psnr_vs_time.svg"), &spec)?;
        figures.push("psnr_vs_time.png");
    }
    let spec = PlotSpec {
        title: "objective against run time".into(),
        x_label: "solver run time (s)".into(),
        y_label: "(F - F_best) / F_best".into(),
        series: series(&|r| Some((r.objective - best_obj) / best_obj.abs().max(1e-300))),
        log_y: true,
        ..PlotSpec::default()
    };
    io::plot_lines(out.join("objective_vs_time.png"), &spec)?;
    io::plot_lines(out.join("objective_vs_time.svg"), &spec)?;
    figures.push("objective_vs_time.png");
    io::write_text_atomic(&out.join("traces.csv"), &traces_csv(r.traces))?;

    let json = serde_json::json!({
        "raw": r.raw, "psf": r.psf, "config": r.config,
        "truth": r.truth,
        "tau": r.tau, "tau_choice": r.tau_choice, "alpha": r.alpha, "frame_time_us": r.frame_time_us, "videos": VIDEOS_DIR, "tv_prox": r.defaults.tv_prox.name(), "lipschitz": r.lipschitz, "lipschitz_seconds": r.lipschitz_seconds,
        "admm": {"cg_iters": r.defaults.admm_cg, "mu_rel": r.defaults.admm_mu},
        "plan": r.plan, "truth_objective": r.truth_objective, "solvers": r.summaries, "savings": r.savings, "figures": figures,
    });
    io::write_text_atomic(&out.join("summary.json"), &serde_json::to_string_pretty(&json)?)?;
    let markdown = summary_markdown(r);
    io::write_text_atomic(&out.join("summary.md"), &markdown)?;
    Ok(CompareWritten { figures, markdown })
}

/// `traces.csv`: every run's rows, the channel column holding the run's index in the
/// header's list of labels.
pub fn traces_csv(traces: &[RunTrace]) -> String {
    let labels: Vec<&str> = traces.iter().map(|t| t.run.label.as_str()).collect();
    let csv_rows: Vec<(usize, &[TraceRow])> = traces.iter().enumerate().map(|(i, t)| (i, t.rows.as_slice())).collect();
    let mut csv = String::from("# channel column = index of the solver run in: ");
    csv.push_str(&labels.join(","));
    csv.push('\n');
    csv.push_str(&to_csv(&csv_rows));
    csv
}

/// `summary.md`: the problem, what the declaration left out and saved, and one table
/// row per run (with a truth: the relative errors after the best scale and the times to
/// within 10% and 1% of the best run's; the times to the objective tolerances).
pub fn summary_markdown(r: &CompareReport) -> String {
    let plan = r.plan;
    let with_truth = r.truth.is_some();
    let (k, m, n) = plan.solved_shape;
    let (tau, lipschitz) = (r.tau, r.lipschitz);
    let mut md = String::new();
    md.push_str(&format!(
        "Problem: {k} frames of {m} x {n} (full grid {} x {} x {}), {} channel(s) solved of {}; tau = {tau:.4e} ({}); TV axes {:?}; TV prox {} (where a run names none); L = {lipschitz:.4e}.\n\n",
        plan.full_shape.0, plan.full_shape.1, plan.full_shape.2, plan.channels_solved, plan.channels_captured, r.tau_choice, plan.tv_axes, r.defaults.tv_prox.name()
    ));
    if !plan.left_out.is_empty() {
        md.push_str("Left out by the scene declaration:\n\n");
        for l in &plan.left_out {
            md.push_str(&format!("- {l}\n"));
        }
        md.push('\n');
    }
    if let Some(s) = r.savings {
        md.push_str(&format!(
            "Saved: unknowns {} -> {} ({:.1}x less iterate memory), FISTA time per iteration {:.4} s -> {:.4} s ({:.1}x).\n\n",
            s.full_unknowns,
            s.solved_unknowns,
            s.full_unknowns as f64 / s.solved_unknowns.max(1) as f64,
            s.full_seconds_per_iteration,
            s.solved_seconds_per_iteration,
            s.full_seconds_per_iteration / s.solved_seconds_per_iteration.max(1e-12)
        ));
    }
    let fmt_t = |t: Option<f64>| t.map(|s| format!("{s:.2}")).unwrap_or_else(|| "—".into());
    md.push_str("| solver | TV prox | iterations | s/iteration | final objective |");
    if with_truth {
        md.push_str(" gap vs truth's objective | final rel. error (best scale) | lowest rel. error |");
        for tol in ERROR_TOLERANCES {
            md.push_str(&format!(" s to {}% of the best error |", 100.0 * tol));
        }
    }
    md.push_str(" s to 1e-2 of best F | s to 1e-3 of best F |\n|");
    let cols = 5 + if with_truth { 3 + ERROR_TOLERANCES.len() } else { 0 } + 2;
    md.push_str(&"---|".repeat(cols));
    md.push('\n');
    for s in r.summaries {
        md.push_str(&format!("| {} | {} | {} | {:.4} | {:.6e} |", s.solver, s.tv_prox, s.iterations, s.seconds_per_iteration, s.objective));
        if with_truth {
            md.push_str(&format!(
                " {:+.3e} | {:.4} | {:.4} |",
                s.objective_gap_vs_truth.unwrap_or(f64::NAN),
                s.final_rel_error_scaled.unwrap_or(f64::NAN),
                s.best_rel_error_scaled.unwrap_or(f64::NAN)
            ));
            for (_, t) in &s.time_to_error_s {
                md.push_str(&format!(" {} |", fmt_t(*t)));
            }
        }
        for (_, t) in &s.time_to_objective_s {
            md.push_str(&format!(" {} |", fmt_t(*t)));
        }
        md.push('\n');
    }
    md
}
