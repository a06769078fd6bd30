//! `rollcam compare`: the solvers on one capture, error against wall-clock time in one
//! plot, and a table of the time each needs to reach given errors.

use crate::cli::common::{flag_error, print_sensor, psf_or_calibration, SensorFlags};
use anyhow::{bail, Context, Result};
use clap::Args;
use rollcam::analysis::compare::{write_compare, CompareReport, VIDEOS_DIR};
use rollcam::io::{self, cache::LipschitzCache};
use rollcam::model::capture::CaptureConfig;
use rollcam::model::prepare::prepare;
use rollcam::model::scene::SceneSpec;
use rollcam::solve::compare::{
    duplicate_label, measure_savings, run_solvers, summarize, support_from_truth, truth_objective, truth_on_grid, truth_window, RunDefaults, RunTrace,
    SolverRun,
};
use rollcam::solve::lipschitz::LIPSCHITZ_MARGIN;
use rollcam::solve::optimize::StopRule;
use rollcam::solve::problem::{Problem, SolveSettings, DEFAULT_ALPHA};
use rollcam::solve::prox::tv_dual::TvProx;
use rollcam::solve::scene::{build_problem, build_problem_with};
use rollcam::solve::start::Start;
use rollcam::solve::tau::Tau;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct CompareArgs {
    /// Raw rolling-shutter capture.
    #[arg(long)]
    pub raw: PathBuf,
    /// Page of a multi-page TIFF raw (1 = the first); a multi-page raw without it is
    /// refused.
    #[arg(long, value_name = "N")]
    pub page: Option<usize>,
    /// PSF image, same size as the raw (default: the calibration's psf.tiff).
    #[arg(long)]
    pub psf: Option<PathBuf>,
    /// capture.toml of the raw (its [scene] keys declare what the scene needs).
    #[arg(long)]
    pub config: PathBuf,
    /// Ground-truth video: the error is PSNR against it (else the objective).
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Solver runs, comma-separated: fista, fista-restart, admm, pgd, mfista, admm-split, each
    /// optionally with its own settings after colons (same problem, other solver
    /// parameters): tv_prox=haar|dualN, start=auto|still|zero, cg=N (ADMM's CG steps),
    /// mu=X (ADMM's penalties over L; admm-split's TV and non-negativity penalties over its own scale),
    /// precond=frames|none (fista, fista-restart: steps in the per-frame metric), device=cpu|cuda (fista, fista-restart, admm-split on an NVIDIA GPU; a build with `--features cuda`, docs/gpu.md). E.g.
    /// fista-restart,fista-restart:start=zero,fista-restart:tv_prox=dual10,admm:cg=8,fista-restart:precond=frames.
    #[arg(long, value_delimiter = ',', default_values = ["fista", "fista-restart", "admm", "pgd"])]
    pub solvers: Vec<SolverRun>,
    /// Output folder: new or empty (or see --force); checked before any work.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub force: crate::cli::common::ForceFlag,
    /// TV weight tau, absolute. Default: --tau-rel times max(A^T b).
    #[arg(long, value_parser = rollcam::solve::tau::parse_f32)]
    pub tau: Option<f32>,
    /// TV weight relative to max(A^T b), or `noise` (the default: from the raw's noise,
    /// as reconstruct's).
    #[arg(long, default_value_t = Tau::default(), value_parser = crate::cli::common::parse_tau_rel_fixed)]
    pub tau_rel: Tau,
    /// Temporal TV weight (ignored when the scene declares tv_weights).
    #[arg(long, default_value_t = DEFAULT_ALPHA, value_parser = rollcam::solve::tau::parse_f32)]
    pub alpha: f32,
    /// Iterations per solver (ADMM: outer iterations).
    #[arg(long, default_value_t = 300)]
    pub iters: usize,
    /// Solver seconds per solver.
    #[arg(long)]
    pub time_budget_s: Option<f64>,
    #[arg(long, default_value_t = 0.0)]
    pub rel_tol: f64,
    /// Stop a run when the objective's relative change stays below this for 5
    /// iterations in a row (0: off).
    #[arg(long, default_value_t = 0.0)]
    pub obj_tol: f64,
    /// TV prox of the gradient methods: haar or dualN (N inner iterations).
    #[arg(long, default_value = "haar")]
    pub tv_prox: TvProx,
    /// Where the runs start: auto (the still image wherever the video has more than
    /// one frame; its seconds count in the run's), still or zero.
    #[arg(long, default_value = "auto")]
    pub start: Start,
    /// CG steps per ADMM iteration.
    #[arg(long, default_value_t = 4)]
    pub admm_cg: usize,
    /// ADMM initial penalties relative to the Lipschitz constant.
    #[arg(long, default_value_t = 1e-3)]
    pub admm_mu: f64,
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
    #[command(flatten)]
    pub sensor: SensorFlags,
}

pub fn run(a: CompareArgs) -> Result<()> {
    let inputs = [
        ("the raw image (--raw)", Some(a.raw.as_path())),
        ("the PSF (--psf)", a.psf.as_deref()),
        ("the capture description (--config)", Some(a.config.as_path())),
        ("the truth (--truth)", a.truth.as_deref()),
    ];
    if a.solvers.is_empty() {
        bail!("--solvers: expected at least one of fista, fista-restart, admm, pgd");
    }
    if let Some(dup) = duplicate_label(&a.solvers) {
        bail!("--solvers: '{dup}' is given twice: each run is one curve");
    }
    let stop = StopRule { max_iters: a.iters, rel_tol: a.rel_tol, time_budget_s: a.time_budget_s, obj_tol: a.obj_tol };
    stop.check().map_err(crate::cli::common::check_error)?;
    let defaults = RunDefaults { tv_prox: a.tv_prox, admm_cg: a.admm_cg, admm_mu: a.admm_mu, start: a.start };
    defaults.check().map_err(anyhow::Error::msg)?;
    // Every file the command writes, each run's video included, is checked against the
    // inputs before any solve.
    let videos = video_files(a.solvers.iter().map(|s| s.label.as_str()));
    let writes: Vec<&str> = rollcam::analysis::compare::COMPARE_FILES.iter().copied().chain(videos.iter().map(String::as_str)).collect();
    crate::cli::common::claim_out(&a.out, &a.force, &writes, &inputs)?;
    let cfg = CaptureConfig::load(&a.config)?;
    let raw = crate::cli::common::read_raw(&a.raw, a.page)?;
    rollcam::io::budget::check_reconstruction(&cfg, cfg.fov, 1, 1)?;
    let sensor = a.sensor.load(Some(&a.config), &cfg)?;
    let (psf, pn, psf_clean) = psf_or_calibration(a.psf.as_deref(), &sensor)?;
    let rn = a.raw.display().to_string();
    let prepared = prepare(raw.view(), &rn, psf.view(), &pn, &cfg, &sensor.input(io::sample_full_scale(&a.raw), psf_clean))?;
    print_sensor(&prepared.sensor);
    if a.channel >= prepared.raw.len() {
        bail!("--channel = {}: expected a channel below {}", a.channel, prepared.raw.len());
    }
    let truth_stack = match &a.truth {
        Some(p) => Some(io::read_truth(p)?),
        None => None,
    };
    let spec = if a.full_grid {
        SceneSpec::default()
    } else {
        let mut table = cfg.scene.clone().unwrap_or_default();
        for kv in &a.scene_keys {
            let (key, value) = kv.split_once('=').with_context(|| format!("--scene {kv}: expected KEY=VALUE"))?;
            let v: toml::Table =
                toml::from_str(&format!("v = {value}")).map_err(|e| anyhow::anyhow!("--scene {kv}: the value is not TOML: {}", e.message()))?;
            table.insert(key.trim().to_string(), v["v"].clone());
        }
        if let (Some(margin), Some(t)) = (a.support_from_truth, &truth_stack) {
            if let Some(sup) = support_from_truth(t.view(), margin) {
                table.insert("support".into(), toml::Value::Array(sup.iter().map(|&x| toml::Value::Integer(x as i64)).collect()));
            }
        }
        SceneSpec::from_table(Some(&table)).with_context(|| format!("{}", a.config.display()))?
    };
    if spec.static_background {
        bail!(
            "static_background = true: compare runs the solvers on the plain (or declared) video; the static + dynamic model is solved by `rollcam reconstruct` (judge it with `rollcam analyze --truth`), or give --full-grid"
        );
    }
    // tau from the data scale of the undeclared problem, as `reconstruct` resolves it,
    // so that a declaration changes the unknowns, not the objective.
    let settings = SolveSettings { tau: crate::cli::common::given_tau(a.tau, a.tau_rel)?, alpha: a.alpha, ..SolveSettings::default() };
    let settings = settings.validate().map_err(flag_error)?;
    let full = Problem::new(&prepared, &cfg, cfg.fov)?;
    let resolved = settings.resolve(&full, full.fov);
    let tau = resolved.prior(false).for_scene(&spec, full.weights().frames()).tau;
    let problem = build_problem_with(&prepared, full.weights(), cfg.fov, &spec, tau, a.alpha, a.channel)?;
    drop(full);
    let plan = &problem.plan;
    let truth_full: Option<Vec<f32>> = match (&a.truth, truth_stack) {
        (Some(p), Some(t)) => Some(truth_on_grid(plan, t.view(), a.channel).map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?),
        _ => None,
    };
    let truth = truth_full.as_ref().map(|t| problem.restrict_truth(t));
    let truth_window = truth_full.as_ref().map(|t| truth_window(plan, t));
    let t_l = Instant::now();
    // Cached per operator (ROLLCAM_CACHE_DIR), so runs on one capture measure it once.
    let cache = LipschitzCache::default_location();
    let (eig, _) = cache.get_or_measure(problem.fingerprint(), &problem.op);
    let lipschitz = eig.lambda_max * LIPSCHITZ_MARGIN;
    let lipschitz_s = t_l.elapsed().as_secs_f64();
    let (k, m, n) = plan.solved_shape;
    println!(
        "problem: {k} frames of {m} x {n} (full grid {:?}), tau = {tau:.4e} ({}), TV axes {:?}, L = {lipschitz:.4e} ({} power iterations, {lipschitz_s:.2} s)",
        plan.full_shape, resolved.tau_choice, plan.tv_axes, eig.iterations
    );
    for l in &plan.left_out {
        println!("left out: {l}");
    }
    let truth_objective = truth.as_ref().map(|t| truth_objective(&problem, t));

    let traces = run_solvers(&problem, &a.solvers, &defaults, lipschitz, &cache, &stop, truth_window.as_deref(), |t| {
        let r = &t.result;
        println!(
            "{}: {} iterations in {:.2} s ({:?}), objective {:.6e}{}",
            t.run.label,
            r.iterations,
            r.seconds,
            r.termination,
            r.data_term + r.reg_term,
            t.rows.last().and_then(|l| l.psnr_db).map(|p| format!(", PSNR {p:.2} dB")).unwrap_or_default()
        );
    })
    .map_err(|e| anyhow::anyhow!(e))?;
    let summaries = summarize(&traces, &defaults, truth_objective);

    // What the declaration saved: a few FISTA iterations on the full problem.
    let savings = if a.measure_savings && !plan.left_out.is_empty() {
        let full = build_problem(&prepared, &cfg, cfg.fov, &SceneSpec::default(), tau, a.alpha, a.channel)?;
        Some(measure_savings(&full, &problem, lipschitz))
    } else {
        None
    };

    let report = CompareReport {
        raw: rn,
        psf: pn,
        config: a.config.display().to_string(),
        truth: a.truth.as_ref().map(|p| p.display().to_string()),
        tau,
        tau_choice: resolved.tau_choice,
        alpha: a.alpha,
        frame_time_us: cfg.timing().frame_time_us(),
        lipschitz,
        lipschitz_seconds: lipschitz_s,
        defaults,
        plan,
        truth_objective,
        traces: &traces,
        summaries: &summaries,
        savings: savings.as_ref(),
    };
    let written = write_compare(&a.out, &report)?;
    let videos = write_videos(&a.out, &problem, &traces)?;
    print!("{}", written.markdown);
    println!("wrote summary.md, summary.json, traces.csv, {}, {} to {}", written.figures.join(", "), videos.join(", "), a.out.display());
    Ok(())
}

/// Each run's video file in the output folder, `videos/LABEL.npy` (the label with
/// characters other than letters, digits, `-`, `_` and `.` as `_`; a name met before
/// gets the run's number).
fn video_files<'a>(labels: impl Iterator<Item = &'a str>) -> Vec<String> {
    let mut names: Vec<String> = Vec::new();
    for label in labels {
        let mut name: String = label.chars().map(|c| if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') { c } else { '_' }).collect();
        if names.contains(&format!("{VIDEOS_DIR}/{name}.npy")) {
            name = format!("{name}-{}", names.len() + 1);
        }
        names.push(format!("{VIDEOS_DIR}/{name}.npy"));
    }
    names
}

/// Each run's last iterate as a video on the full grid (zero outside a declared
/// window or support), in its [`video_files`] name, for `rollcam view` to play side by
/// side.
fn write_videos(out: &std::path::Path, problem: &rollcam::solve::scene::SceneProblem, traces: &[RunTrace]) -> Result<Vec<String>> {
    let (k, mv, nv) = problem.plan.full_shape;
    let (k0, _) = problem.plan.frames;
    let dir = out.join(VIDEOS_DIR);
    std::fs::create_dir_all(&dir).with_context(|| format!("{}: cannot create the folder", dir.display()))?;
    let names = video_files(traces.iter().map(|t| t.run.label.as_str()));
    for (t, name) in traces.iter().zip(&names) {
        let window = problem.op.embed(&t.result.x);
        let mut video = vec![0.0f32; k * mv * nv];
        video[k0 * mv * nv..k0 * mv * nv + window.len()].copy_from_slice(&window);
        let video = ndarray::Array4::from_shape_vec((k, mv, nv, 1), video).context("a run's video on the full grid")?;
        io::write_npy(out.join(name), video.view())?;
    }
    Ok(names)
}
