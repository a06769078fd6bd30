//! `rollcam compare`: the solvers on one capture, error against wall-clock time in one
//! plot, and a table of the time each needs to reach given errors.

use crate::cli::common::{flag_error, print_sensor, psf_or_calibration, SensorFlags};
use anyhow::{bail, Context, Result};
use clap::Args;
use rollcam::analysis::compare::{write_compare, CompareReport, VIDEOS_DIR};
use rollcam::io::{self, cache::LipschitzCache};
use rollcam::model::capture::CaptureConfig;
use rollcam::request::capture::CaptureRequest;
use rollcam::request::compare::{duplicate_label, CompareRequest, LoadedCompare, RunDefaults, RunTrace, SolverRun, StopRule, TvProx};
use rollcam::request::{parse_f32, SolveSettings, Start, Tau, DEFAULT_ALPHA};
use std::path::PathBuf;

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
    #[arg(long, value_parser = parse_f32)]
    pub tau: Option<f32>,
    /// TV weight relative to max(A^T b), or `noise` (the default: from the raw's noise,
    /// as reconstruct's).
    #[arg(long, default_value_t = Tau::default(), value_parser = crate::cli::common::parse_tau_rel_fixed)]
    pub tau_rel: Tau,
    /// Temporal TV weight (ignored when the scene declares tv_weights).
    #[arg(long, default_value_t = DEFAULT_ALPHA, value_parser = parse_f32)]
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
    let stop =
        StopRule { max_iters: a.iters, rel_tol: a.rel_tol, time_budget_s: a.time_budget_s, obj_tol: a.obj_tol, noise_floor: None, wait_for_iterate: true };
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
    let sensor = a.sensor.load(Some(&a.config), &cfg)?;
    let (psf, pn, psf_clean) = psf_or_calibration(a.psf.as_deref(), &sensor)?;
    let rn = a.raw.display().to_string();
    let channels = raw.dim().2;
    if a.channel >= channels {
        bail!("--channel = {}: expected a channel below {channels}", a.channel);
    }
    let truth = match &a.truth {
        Some(p) => Some((io::read_truth(p)?, p.display().to_string())),
        None => None,
    };
    let scene = if a.full_grid {
        None
    } else {
        let mut table = cfg.scene.clone().unwrap_or_default();
        for kv in &a.scene_keys {
            let (key, value) = kv.split_once('=').with_context(|| format!("--scene {kv}: expected KEY=VALUE"))?;
            let v: toml::Table =
                toml::from_str(&format!("v = {value}")).map_err(|e| anyhow::anyhow!("--scene {kv}: the value is not TOML: {}", e.message()))?;
            table.insert(key.trim().to_string(), v["v"].clone());
        }
        Some(table)
    };
    let settings = SolveSettings { tau: crate::cli::common::given_tau(a.tau, a.tau_rel)?, alpha: a.alpha, ..SolveSettings::default() };
    let settings = settings.validate().map_err(flag_error)?;
    let config_name = a.config.display().to_string();
    let request = CompareRequest {
        capture: CaptureRequest::new(raw.view(), &rn, psf.view(), &pn, &cfg, &sensor, &settings)
            .with_full_scale(io::sample_full_scale(&a.raw))
            .with_clean_psf(psf_clean)
            .with_config_name(Some(&config_name))
            .with_truth(truth.as_ref().map(|(t, name)| (t.view(), name.as_str())))
            .with_sensor_report(&print_sensor),
        scene,
        support_from_truth: a.support_from_truth,
        channel: a.channel,
        runs: &a.solvers,
        defaults,
        stop,
        measure_savings: a.measure_savings,
    };
    // Cached per operator (ROLLCAM_CACHE_DIR), so runs on one capture measure it once.
    let cache = LipschitzCache::default_location();
    let loaded = request.load(&cache)?;
    let (plan, tau, lipschitz) = (loaded.problem.plan(), loaded.tau, loaded.lipschitz);
    let (k, m, n) = plan.solved_shape;
    println!(
        "problem: {k} frames of {m} x {n} (full grid {:?}), tau = {tau:.4e} ({}), TV axes {:?}, L = {lipschitz:.4e} ({} power iterations, {:.2} s)",
        plan.full_shape, loaded.params.tau_choice, plan.tv_axes, loaded.power_iterations, loaded.lipschitz_seconds
    );
    for l in &plan.left_out {
        println!("left out: {l}");
    }
    let outcome = loaded.run(&cache, |t| {
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
    })?;

    let report = CompareReport {
        raw: rn.clone(),
        psf: pn.clone(),
        config: config_name.clone(),
        truth: a.truth.as_ref().map(|p| p.display().to_string()),
        tau,
        tau_choice: loaded.params.tau_choice,
        alpha: a.alpha,
        frame_time_us: cfg.timing().frame_time_us(),
        lipschitz,
        lipschitz_seconds: loaded.lipschitz_seconds,
        defaults,
        plan,
        truth_objective: loaded.truth_objective,
        traces: &outcome.traces,
        summaries: &outcome.summaries,
        savings: outcome.savings.as_ref(),
    };
    let written = write_compare(&a.out, &report)?;
    let videos = write_videos(&a.out, &loaded, &outcome.traces)?;
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
fn write_videos(out: &std::path::Path, loaded: &LoadedCompare, traces: &[RunTrace]) -> Result<Vec<String>> {
    let dir = out.join(VIDEOS_DIR);
    std::fs::create_dir_all(&dir).with_context(|| format!("{}: cannot create the folder", dir.display()))?;
    let names = video_files(traces.iter().map(|t| t.run.label.as_str()));
    for (t, name) in traces.iter().zip(&names) {
        io::write_npy(out.join(name), loaded.full_video(t).view())?;
    }
    Ok(names)
}
