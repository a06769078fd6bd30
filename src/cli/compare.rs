//! `rollcam compare`: the solvers on one capture, error against wall-clock time in one
//! plot, and a table of the time each needs to reach given errors.

use crate::cli::common::flag_error;
use anyhow::{bail, Context, Result};
use clap::Args;
use ndarray::Axis;
use rollcam::model::capture::CaptureConfig;
use rollcam::solve::optimize::{NoObserver, StopRule};
use rollcam::io::{self, PlotSpec, Series};
use rollcam::io::cache::LipschitzCache;
use rollcam::solve::lipschitz::LIPSCHITZ_MARGIN;
use rollcam::model::op::Operator;
use rollcam::model::prepare::prepare;
use rollcam::model::scene::SceneSpec;
use rollcam::solve::problem::{Problem, SolveSettings};
use rollcam::solve::scene::{build_problem, build_problem_with, scene_tau};
use rollcam::solve::optimize::{solve, SolverKind, SolverSettings};
use rollcam::solve::trace::{compare, to_csv, TraceRow};
use rollcam::solve::prox::tv::Prox;
use rollcam::solve::prox::tv_dual::TvProx;
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct CompareArgs {
    /// Raw rolling-shutter capture.
    #[arg(long)]
    pub raw: PathBuf,
    /// PSF image, same size as the raw.
    #[arg(long)]
    pub psf: PathBuf,
    /// capture.toml of the raw (its [scene] keys declare what the scene needs).
    #[arg(long)]
    pub config: PathBuf,
    /// Ground-truth video: the error is PSNR against it (else the objective).
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Solver runs, comma-separated: fista, fista-restart, admm, pgd, mfista, each
    /// optionally with its own settings after colons (same problem, other solver
    /// parameters): tv_prox=haar|dualN, cg=N (ADMM's CG steps), mu=X (ADMM's penalties
    /// over L). E.g. fista-restart,fista-restart:tv_prox=dual10,admm:cg=8.
    #[arg(long, value_delimiter = ',', default_values = ["fista", "fista-restart", "admm", "pgd"])]
    pub solvers: Vec<SolverRun>,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
    /// TV weight tau, absolute. Default: --tau-rel times max(A^T b).
    #[arg(long)]
    pub tau: Option<f32>,
    #[arg(long, default_value_t = 2e-3)]
    pub tau_rel: f32,
    /// Temporal TV weight (ignored when the scene declares tv_weights).
    #[arg(long, default_value_t = 5.0)]
    pub alpha: f32,
    /// Iterations per solver (ADMM: outer iterations).
    #[arg(long, default_value_t = 300)]
    pub iters: usize,
    /// Solver seconds per solver.
    #[arg(long)]
    pub time_budget_s: Option<f64>,
    #[arg(long, default_value_t = 0.0)]
    pub rel_tol: f64,
    /// TV prox of the gradient methods: haar or dualN (N inner iterations).
    #[arg(long, default_value = "haar")]
    pub tv_prox: TvProx,
    /// CG steps per ADMM iteration.
    #[arg(long, default_value_t = 4)]
    pub admm_cg: usize,
    /// ADMM initial penalties relative to the Lipschitz constant.
    #[arg(long, default_value_t = 1e-3)]
    pub admm_mu: f64,
    /// PSNR targets (dB) of the time-to-reach table.
    #[arg(long, value_delimiter = ',', default_values_t = vec![25.0, 30.0, 35.0])]
    pub targets_db: Vec<f64>,
    /// Colour channel to compare on (ignored for a grey scene).
    #[arg(long, default_value_t = 0)]
    pub channel: usize,
    /// Declare a typed scene key (a TOML value), over capture.toml's [scene]:
    /// e.g. --scene static=true --scene 'support=[4, 40, 8, 70]'.
    #[arg(long = "scene", value_name = "KEY=VALUE")]
    pub scene_keys: Vec<String>,
    /// Declare support = the truth's bounding box (light in any frame), grown by this
    /// many pixels: an oracle declaration, for studying what a support saves.
    #[arg(long)]
    pub support_from_truth: Option<usize>,
    /// Ignore the [scene] declaration and solve the full grid.
    #[arg(long)]
    pub full_grid: bool,
    /// Also time a few iterations of the undeclared (full) problem, to report what
    /// the declaration saved.
    #[arg(long)]
    pub measure_savings: bool,
}

/// One curve of the comparison: a solver and the settings it runs with (those not
/// given come from the command's flags).
#[derive(Clone, Debug, PartialEq)]
pub struct SolverRun {
    /// As written on the command line: the curve's name.
    pub label: String,
    pub kind: SolverKind,
    pub tv_prox: Option<TvProx>,
    pub cg: Option<usize>,
    pub mu: Option<f64>,
}

impl std::str::FromStr for SolverRun {
    type Err = String;
    fn from_str(text: &str) -> Result<Self, String> {
        let mut parts = text.split(':');
        let kind: SolverKind = parts.next().unwrap_or_default().trim().parse()?;
        let mut run = SolverRun { label: text.trim().to_string(), kind, tv_prox: None, cg: None, mu: None };
        for setting in parts {
            let (key, value) = setting.split_once('=').ok_or_else(|| format!("'{text}': setting '{setting}' is not KEY=VALUE (keys: tv_prox, cg, mu)"))?;
            let bad = |what: &str| format!("'{text}': {key} = '{value}': expected {what}");
            match key.trim() {
                "tv_prox" => run.tv_prox = Some(value.trim().parse().map_err(|e: String| bad(&e))?),
                "cg" => run.cg = Some(value.trim().parse().ok().filter(|&n: &usize| n >= 1).ok_or_else(|| bad("a whole number of CG steps, at least 1"))?),
                "mu" => run.mu = Some(value.trim().parse().ok().filter(|x: &f64| *x > 0.0 && x.is_finite()).ok_or_else(|| bad("a positive penalty relative to L"))?),
                other => return Err(format!("'{text}': unknown setting '{other}': expected tv_prox, cg or mu")),
            }
        }
        if run.kind != SolverKind::Admm && (run.cg.is_some() || run.mu.is_some()) {
            return Err(format!("'{text}': cg and mu are ADMM's settings"));
        }
        if run.kind == SolverKind::Admm && run.tv_prox.is_some() {
            return Err(format!("'{text}': ADMM shrinks the TV term exactly; tv_prox is for the gradient methods"));
        }
        Ok(run)
    }
}

#[derive(Serialize)]
struct SolverSummary {
    solver: String,
    /// The TV map this run used ("exact shrinkage" for ADMM).
    tv_prox: String,
    iterations: usize,
    seconds: f64,
    seconds_per_iteration: f64,
    termination: String,
    objective: f64,
    objective_gap_vs_truth: Option<f64>,
    final_psnr_db: Option<f64>,
    best_psnr_db: Option<f64>,
    /// Seconds to first reach each target (None: never).
    time_to_target_s: Vec<(f64, Option<f64>)>,
    /// Seconds to reach objective within 1e-2 / 1e-3 of the best final objective.
    time_to_objective_s: Vec<(f64, Option<f64>)>,
}

#[derive(Serialize)]
struct Savings {
    full_unknowns: usize,
    solved_unknowns: usize,
    full_seconds_per_iteration: f64,
    solved_seconds_per_iteration: f64,
    full_iterate_bytes: usize,
    solved_iterate_bytes: usize,
}

fn first_time(rows: &[TraceRow], ok: impl Fn(&TraceRow) -> bool) -> Option<f64> {
    rows.iter().find(|r| ok(r)).map(|r| r.seconds)
}

pub fn run(a: CompareArgs) -> Result<()> {
    if a.solvers.is_empty() {
        bail!("--solvers: expected at least one of fista, fista-restart, admm, pgd");
    }
    let labels: Vec<&str> = a.solvers.iter().map(|r| r.label.as_str()).collect();
    if let Some(dup) = labels.iter().enumerate().find(|(i, l)| labels[..*i].contains(l)).map(|(_, l)| l) {
        bail!("--solvers: '{dup}' is given twice: each run is one curve");
    }
    if a.iters == 0 {
        bail!("--iters = 0: expected at least one iteration");
    }
    let cfg = CaptureConfig::load(&a.config)?;
    let raw = io::read_image(&a.raw)?;
    let psf = io::read_image(&a.psf)?;
    let (rn, pn) = (a.raw.display().to_string(), a.psf.display().to_string());
    let prepared = prepare(raw.view(), &rn, psf.view(), &pn, cfg.rows, cfg.cols, cfg.downsample, cfg.dark_level)?;
    if a.channel >= prepared.raw.len() {
        bail!("--channel = {}: expected a channel below {}", a.channel, prepared.raw.len());
    }
    let truth_stack = match &a.truth {
        Some(p) => Some(io::read_stack(p)?),
        None => None,
    };
    let spec = if a.full_grid {
        SceneSpec::default()
    } else {
        let mut table = cfg.scene.clone().unwrap_or_default();
        for kv in &a.scene_keys {
            let (key, value) = kv.split_once('=').with_context(|| format!("--scene {kv}: expected KEY=VALUE"))?;
            let v: toml::Table = toml::from_str(&format!("v = {value}")).map_err(|e| anyhow::anyhow!("--scene {kv}: the value is not TOML: {}", e.message()))?;
            table.insert(key.trim().to_string(), v["v"].clone());
        }
        if let (Some(margin), Some(t)) = (a.support_from_truth, &truth_stack) {
            let (_, tm, tn, _) = t.dim();
            let (mut r0, mut r1, mut c0, mut c1) = (usize::MAX, 0, usize::MAX, 0);
            for ((_, r, c, _), &v) in t.indexed_iter() {
                if v > 0.0 {
                    (r0, r1, c0, c1) = (r0.min(r), r1.max(r + 1), c0.min(c), c1.max(c + 1));
                }
            }
            if r0 < r1 {
                let sup = [r0.saturating_sub(margin), (r1 + margin).min(tm), c0.saturating_sub(margin), (c1 + margin).min(tn)];
                table.insert("support".into(), toml::Value::Array(sup.iter().map(|&x| toml::Value::Integer(x as i64)).collect()));
            }
        }
        SceneSpec::from_table(Some(&table)).with_context(|| format!("{}", a.config.display()))?
    };
    // tau from the data scale of the undeclared problem, as `reconstruct` resolves it,
    // so that a declaration changes the unknowns, not the objective.
    let settings = SolveSettings { tau: a.tau, tau_rel: a.tau_rel, alpha: a.alpha, ..SolveSettings::default() };
    settings.validate().map_err(flag_error)?;
    let full = Problem::new(&prepared, &cfg, cfg.fov)?;
    let tau = scene_tau(&spec, full.resolve_tau(settings.tau()), full.weights().frames());
    let problem = build_problem_with(&prepared, full.weights(), cfg.fov, &spec, tau, a.alpha, a.channel)?;
    drop(full);
    let plan = &problem.plan;
    let truth_full: Option<Vec<f32>> = match (&a.truth, truth_stack) {
        (Some(p), Some(t)) => {
            let (tk, tm, tn, tc) = t.dim();
            let (k, m, n) = plan.full_shape;
            if (tk, tm, tn) != (k, m, n) {
                bail!("{}: truth is {tk} x {tm} x {tn}: expected the video grid (frames, rows, cols) = {k} x {m} x {n}", p.display());
            }
            let ch = if plan.channels_solved == 1 && plan.channels_captured > 1 {
                // Grey scene: the truth's channels averaged, as the raw is.
                t.mean_axis(Axis(3)).expect("the truth has channels")
            } else {
                t.index_axis(Axis(3), a.channel.min(tc - 1)).to_owned()
            };
            Some(ch.iter().cloned().collect())
        }
        _ => None,
    };
    let truth = truth_full.as_ref().map(|t| problem.restrict_truth(t));
    // Errors are measured on the full grid (frames of the window): an estimate
    // restricted to a support is zero outside it, as the scene is declared to be.
    let truth_window: Option<Vec<f32>> = truth_full.as_ref().map(|t| {
        let (_, m, n) = plan.full_shape;
        let (k0, k1) = plan.frames;
        t[k0 * m * n..k1 * m * n].to_vec()
    });
    let t_l = Instant::now();
    // Cached per operator (ROLLCAM_CACHE_DIR), so runs on one capture measure it once.
    let (eig, _) = LipschitzCache::default_location().get_or_measure(problem.fingerprint(), &problem.op);
    let lipschitz = eig.lambda_max * LIPSCHITZ_MARGIN;
    let lipschitz_s = t_l.elapsed().as_secs_f64();
    let (k, m, n) = plan.solved_shape;
    println!(
        "problem: {k} frames of {m} x {n} (full grid {:?}), tau = {tau:.4e}, TV axes {:?}, L = {lipschitz:.4e} ({} power iterations, {lipschitz_s:.2} s)",
        plan.full_shape, plan.tv_axes, eig.iterations
    );
    for l in &plan.left_out {
        println!("left out: {l}");
    }
    let truth_objective = truth.as_ref().map(|t| {
        let mut at = vec![0.0f32; problem.op.output_len()];
        problem.op.forward(t, &mut at);
        let d: f64 = 0.5 * at.iter().zip(&problem.b).map(|(&p, &q)| ((p - q) as f64).powi(2)).sum::<f64>();
        d + problem.tv.value(t)
    });

    std::fs::create_dir_all(&a.out).with_context(|| format!("{}: cannot create the folder", a.out.display()))?;
    let stop = StopRule { max_iters: a.iters, rel_tol: a.rel_tol, time_budget_s: a.time_budget_s };
    let mut traces: Vec<(&SolverRun, Vec<TraceRow>, rollcam::solve::optimize::SolveResult)> = Vec::new();
    for run in &a.solvers {
        let kind = run.kind;
        let mut s = SolverSettings::new(kind, lipschitz, stop.clone());
        s.tv_prox = run.tv_prox.unwrap_or(a.tv_prox);
        s.admm.cg_iters = run.cg.unwrap_or(a.admm_cg);
        s.admm.mu_tv_rel = run.mu.unwrap_or(a.admm_mu);
        s.admm.mu_nn_rel = run.mu.unwrap_or(a.admm_mu);
        let mut rows: Vec<TraceRow> = Vec::new();
        let mut rec = |i: &rollcam::solve::optimize::IterInfo| {
            let err = truth_window.as_ref().map(|t| compare(&problem.op.embed(i.x), t));
            rows.push(TraceRow::from_info(i, err));
            true
        };
        let r = solve(&s, &problem.op, &problem.b, &problem.tv, None, &mut rec);
        let last = rows.last().cloned();
        println!(
            "{}: {} iterations in {:.2} s ({:?}), objective {:.6e}{}",
            run.label,
            r.iterations,
            r.seconds,
            r.termination,
            r.data_term + r.reg_term,
            last.and_then(|l| l.psnr_db).map(|p| format!(", PSNR {p:.2} dB")).unwrap_or_default()
        );
        traces.push((run, rows, r));
    }
    let best_obj = traces.iter().flat_map(|(_, rows, _)| rows.iter().map(|r| r.objective)).fold(f64::INFINITY, f64::min);
    let summaries: Vec<SolverSummary> = traces
        .iter()
        .map(|(run, rows, r)| {
            let psnrs: Vec<f64> = rows.iter().filter_map(|r| r.psnr_db).collect();
            let obj = r.data_term + r.reg_term;
            SolverSummary {
                solver: run.label.clone(),
                tv_prox: if run.kind == SolverKind::Admm { "exact shrinkage".into() } else { run.tv_prox.unwrap_or(a.tv_prox).name() },
                iterations: r.iterations,
                seconds: r.seconds,
                seconds_per_iteration: r.seconds / r.iterations.max(1) as f64,
                termination: format!("{:?}", r.termination),
                objective: obj,
                objective_gap_vs_truth: truth_objective.map(|t| (obj - t) / t.abs().max(1e-300)),
                final_psnr_db: psnrs.last().cloned(),
                best_psnr_db: psnrs.iter().cloned().reduce(f64::max),
                time_to_target_s: if truth.is_some() {
                    a.targets_db.iter().map(|&db| (db, first_time(rows, |r| r.psnr_db.is_some_and(|p| p >= db)))).collect()
                } else {
                    Vec::new()
                },
                time_to_objective_s: [1e-2, 1e-3]
                    .iter()
                    .map(|&tol| (tol, first_time(rows, |r| r.objective <= best_obj * (1.0 + tol))))
                    .collect(),
            }
        })
        .collect();

    // Figures: PSNR (when a truth is given) and relative objective against run time.
    let series = |f: &dyn Fn(&TraceRow) -> Option<f64>| -> Vec<Series> {
        traces.iter().map(|(run, rows, _)| Series { name: run.label.clone(), points: rows.iter().filter_map(|r| f(r).map(|y| (r.seconds, y))).collect() }).collect()
    };
    let mut figures = Vec::new();
    if truth.is_some() {
        let spec = PlotSpec {
            title: "PSNR against run time".into(),
            x_label: "solver run time (s)".into(),
            y_label: "PSNR (dB)".into(),
            series: series(&|r| r.psnr_db),
            ..PlotSpec::default()
        };
        io::plot_lines(a.out.join("psnr_vs_time.png"), &spec)?;
        io::plot_lines(a.out.join("psnr_vs_time.svg"), &spec)?;
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
    io::plot_lines(a.out.join("objective_vs_time.png"), &spec)?;
    io::plot_lines(a.out.join("objective_vs_time.svg"), &spec)?;
    figures.push("objective_vs_time.png");
    let csv_rows: Vec<(usize, &[TraceRow])> = traces.iter().enumerate().map(|(i, (_, rows, _))| (i, rows.as_slice())).collect();
    let mut csv = String::from("# channel column = index of the solver run in: ");
    csv.push_str(&labels.join(","));
    csv.push('\n');
    csv.push_str(&to_csv(&csv_rows));
    std::fs::write(a.out.join("traces.csv"), csv)?;

    // What the declaration saved: a few FISTA iterations on the full problem.
    let savings = if a.measure_savings && !plan.left_out.is_empty() {
        let full = build_problem(&prepared, &cfg, cfg.fov, &SceneSpec::default(), tau, a.alpha, a.channel)?;
        let it = 10;
        let time = |p: &rollcam::solve::scene::SceneProblem| {
            let s = SolverSettings::new(SolverKind::FistaRestart, lipschitz, StopRule::iterations(it));
            solve(&s, &p.op, &p.b, &p.tv, None, &mut NoObserver).seconds / it as f64
        };
        let (fu, su) = plan.unknowns();
        let per_channel = plan.channels_captured as f64 / plan.channels_solved as f64;
        Some(Savings {
            full_unknowns: fu,
            solved_unknowns: su,
            full_seconds_per_iteration: time(&full) * per_channel,
            solved_seconds_per_iteration: time(&problem),
            full_iterate_bytes: fu * 4,
            solved_iterate_bytes: su * 4,
        })
    } else {
        None
    };

    let json = serde_json::json!({
        "raw": rn, "psf": pn, "config": a.config.display().to_string(),
        "truth": a.truth.as_ref().map(|p| p.display().to_string()),
        "tau": tau, "alpha": a.alpha, "tv_prox": a.tv_prox.name(), "lipschitz": lipschitz, "lipschitz_seconds": lipschitz_s,
        "admm": {"cg_iters": a.admm_cg, "mu_rel": a.admm_mu},
        "plan": plan, "truth_objective": truth_objective, "solvers": summaries, "savings": savings, "figures": figures,
    });
    std::fs::write(a.out.join("summary.json"), serde_json::to_string_pretty(&json)?)?;

    let mut md = String::new();
    md.push_str(&format!(
        "Problem: {k} frames of {m} x {n} (full grid {} x {} x {}), {} channel(s) solved of {}; tau = {tau:.4e}; TV axes {:?}; TV prox {} (where a run names none); L = {lipschitz:.4e}.\n\n",
        plan.full_shape.0, plan.full_shape.1, plan.full_shape.2, plan.channels_solved, plan.channels_captured, plan.tv_axes, a.tv_prox.name()
    ));
    if !plan.left_out.is_empty() {
        md.push_str("Left out by the scene declaration:\n\n");
        for l in &plan.left_out {
            md.push_str(&format!("- {l}\n"));
        }
        md.push('\n');
    }
    if let Some(s) = &savings {
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
    if truth.is_some() {
        md.push_str(" gap vs truth's objective | final PSNR (dB) |");
        for db in &a.targets_db {
            md.push_str(&format!(" s to {db} dB |"));
        }
    }
    md.push_str(" s to 1e-2 of best F | s to 1e-3 of best F |\n|");
    let cols = 5 + if truth.is_some() { 2 + a.targets_db.len() } else { 0 } + 2;
    md.push_str(&"---|".repeat(cols));
    md.push('\n');
    for s in &summaries {
        md.push_str(&format!("| {} | {} | {} | {:.4} | {:.6e} |", s.solver, s.tv_prox, s.iterations, s.seconds_per_iteration, s.objective));
        if truth.is_some() {
            md.push_str(&format!(" {:+.3e} | {:.2} |", s.objective_gap_vs_truth.unwrap_or(f64::NAN), s.final_psnr_db.unwrap_or(f64::NAN)));
            for (_, t) in &s.time_to_target_s {
                md.push_str(&format!(" {} |", fmt_t(*t)));
            }
        }
        for (_, t) in &s.time_to_objective_s {
            md.push_str(&format!(" {} |", fmt_t(*t)));
        }
        md.push('\n');
    }
    std::fs::write(a.out.join("summary.md"), &md)?;
    print!("{md}");
    println!("wrote summary.md, summary.json, traces.csv, {} to {}", figures.join(", "), a.out.display());
    Ok(())
}
