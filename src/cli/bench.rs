//! `rollcam bench`: time FISTA iterations on the benchmark presets, one JSON line per
//! preset; `--all` runs every preset (each in its own process, so that peak memory is
//! the preset's own) and the time-to-PSNR run, and can write docs/performance.md.

use anyhow::{bail, Context, Result};
use clap::Args;
use rollcam::perf::bench::{self, PresetReport, PsnrReport, RunOptions};
use std::path::PathBuf;
use std::process::Command;

#[derive(Args, Debug, Clone)]
pub struct BenchArgs {
    /// Preset to time (small, paper-8x, paper-4x, full); repeat for several. Default:
    /// small and paper-8x.
    #[arg(long = "preset", value_name = "NAME")]
    pub presets: Vec<String>,
    /// Every preset and the time-to-PSNR run.
    #[arg(long)]
    pub all: bool,
    /// Also time FISTA to --target-db PSNR on paper-8x.
    #[arg(long)]
    pub psnr: bool,
    /// PSNR target of the time-to-PSNR run, dB.
    #[arg(long, default_value_t = 30.0)]
    pub target_db: f64,
    /// Iteration cap of the time-to-PSNR run.
    #[arg(long, default_value_t = 4000)]
    pub psnr_max_iters: usize,
    /// TV weight of the time-to-PSNR run, relative to max(A^T b).
    #[arg(long, default_value_t = rollcam::request::Tau::Relative(2e-4), value_parser = crate::cli::common::parse_tau_rel_fixed)]
    pub tau_rel: rollcam::request::Tau,
    /// Temporal TV weight of the time-to-PSNR run.
    #[arg(long, default_value_t = 1.0, value_parser = rollcam::request::parse_f32)]
    pub alpha: f32,
    /// Untimed iterations first.
    #[arg(long, default_value_t = 2)]
    pub warmup: usize,
    /// Timed iterations (the median is reported).
    #[arg(long, default_value_t = 10)]
    pub iters: usize,
    /// Repetitions of the forward + adjoint comparison with the 2D-FFT path (0: skip).
    #[arg(long, default_value_t = 3)]
    pub reference_reps: usize,
    /// Worker threads (default: one per logical CPU).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Write the results into this Markdown file, between the bench markers.
    #[arg(long)]
    pub markdown: Option<PathBuf>,
    /// Run in this process and print JSON only (used for the per-preset processes).
    #[arg(long, hide = true)]
    pub child: bool,
}

/// The highest PSNR a float32 video can reach against its truth (20 log10 2^24 dB):
/// a target above it runs to the iteration cap.
const MAX_TARGET_DB: f64 = 144.5;

pub fn run(args: BenchArgs) -> Result<()> {
    let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
    if let Some(t) = args.threads.filter(|&t| t == 0 || t > 4 * cpus) {
        bail!("--threads = {t}: expected 1 to {} (four per logical CPU; more only adds switching)", 4 * cpus);
    }
    if !(args.target_db.is_finite() && args.target_db > 0.0 && args.target_db <= MAX_TARGET_DB) {
        bail!(
            "--target-db = {}: expected a positive PSNR of at most {MAX_TARGET_DB:.1} dB (float32 video: its rounding, 20 log10 2^24, bounds any reconstruction's PSNR)",
            args.target_db
        );
    }
    if let Some(path) = &args.markdown {
        bench::markdown_target(path).with_context(|| format!("--markdown {}", path.display()))?;
    }
    if let Some(t) = args.threads {
        rayon::ThreadPoolBuilder::new().num_threads(t).build_global().context("cannot set the thread count")?;
    }
    let mut presets = if args.all { bench::PRESETS.iter().map(|p| p.name.to_string()).collect() } else { args.presets.clone() };
    if presets.is_empty() && !args.psnr {
        presets = vec!["small".into(), "paper-8x".into()];
    }
    for p in &presets {
        if bench::preset(p).is_none() {
            bail!("unknown preset '{p}': expected one of {}", bench::PRESETS.map(|p| p.name).join(", "));
        }
    }
    if args.iters < 1 {
        bail!("--iters = 0: expected at least one timed iteration");
    }
    let psnr = args.psnr || args.all;
    if rollcam::cluster::MPI_BUILT && rollcam::cluster::launched_ranks().is_some() {
        if psnr || args.markdown.is_some() {
            bail!("under mpirun, bench times the presets given by --preset split across the ranks; --all, --psnr and --markdown run without mpirun");
        }
        return run_split(&presets, &args);
    }
    let jobs = presets.len() + usize::from(psnr);
    if args.child || (jobs == 1 && args.markdown.is_none()) {
        for p in &presets {
            let report = run_one(p, &args);
            println!("{}", serde_json::to_string(&report)?);
        }
        if psnr {
            println!("{}", serde_json::to_string(&run_psnr(&args)?)?);
        }
        return Ok(());
    }
    // One process per job: VmHWM is then each preset's own peak.
    let exe = std::env::current_exe().context("cannot find the rollcam executable")?;
    let mut reports: Vec<PresetReport> = Vec::new();
    let mut psnr_report: Option<PsnrReport> = None;
    let child_args = |extra: &[String]| -> Result<String> {
        let mut c = Command::new(&exe);
        c.arg("bench").arg("--child").args(extra);
        c.args(["--warmup", &args.warmup.to_string(), "--iters", &args.iters.to_string(), "--reference-reps", &args.reference_reps.to_string()]);
        c.args(["--target-db", &args.target_db.to_string(), "--psnr-max-iters", &args.psnr_max_iters.to_string()]);
        c.args(["--tau-rel", &args.tau_rel.to_string(), "--alpha", &args.alpha.to_string()]);
        if let Some(t) = args.threads {
            c.args(["--threads", &t.to_string()]);
        }
        let out = c.output().with_context(|| format!("cannot run {}", exe.display()))?;
        if !out.status.success() {
            bail!("bench {extra:?} failed: {}", String::from_utf8_lossy(&out.stderr));
        }
        let text = String::from_utf8(out.stdout)?;
        let line = text.lines().last().unwrap_or_default().to_string();
        println!("{line}");
        Ok(line)
    };
    for p in &presets {
        eprintln!("bench: {p} ...");
        let line = child_args(&["--preset".into(), p.clone()])?;
        reports.push(serde_json::from_str(&line).with_context(|| format!("bench {p}: unreadable report"))?);
    }
    if psnr {
        eprintln!("bench: time to {} dB on paper-8x ...", args.target_db);
        let line = child_args(&["--psnr".into()])?;
        psnr_report = Some(serde_json::from_str(&line).context("bench psnr: unreadable report")?);
    }
    if let Some(path) = &args.markdown {
        let command = std::env::args().skip(1).fold(String::from("rollcam"), |a, b| a + " " + &b);
        // Each block is replaced only by a run that measured it.
        bench::update_markdown_file(path, &reports, psnr_report.as_ref(), &command).with_context(|| format!("cannot write {}", path.display()))?;
        eprintln!("bench: wrote {}", path.display());
    }
    Ok(())
}

fn run_one(name: &str, args: &BenchArgs) -> PresetReport {
    let p = bench::preset(name).expect("checked");
    bench::run_preset(&p, &RunOptions::for_preset(&p, args.warmup, args.iters, args.reference_reps))
}

fn run_psnr(args: &BenchArgs) -> Result<PsnrReport> {
    let settings = rollcam::request::SolveSettings { tau: args.tau_rel, alpha: args.alpha, ..Default::default() };
    let settings = settings.validate().map_err(crate::cli::common::flag_error)?;
    let p = bench::preset("paper-8x").expect("preset exists");
    Ok(bench::time_to_psnr(&p, args.target_db, args.psnr_max_iters, &settings))
}

/// Under an MPI launcher: each preset split across the ranks; rank 0 prints one JSON
/// line per preset. An error on any rank ends every rank (MPI abort).
#[cfg(feature = "mpi")]
fn run_split(presets: &[String], args: &BenchArgs) -> Result<()> {
    use rollcam::model::ranks::Ranks;
    let mpi = rollcam::cluster::mpi::Mpi::init()?;
    if let Some(w) = rollcam::cluster::binding_warning(mpi.rank(), rayon::current_num_threads()) {
        crate::cli::common::stderr_line(&format!("warning: {w}"));
    }
    let ranks_here = rollcam::cluster::ranks_on_this_machine().unwrap_or(mpi.size());
    for name in presets {
        let p = bench::preset(name).expect("checked");
        match bench::run_preset_split(&p, &RunOptions::for_preset(&p, args.warmup, args.iters, 0), &mpi, ranks_here) {
            Ok(report) => {
                if mpi.rank() == 0 {
                    println!("{}", serde_json::to_string(&report)?);
                }
            }
            Err(e) => {
                crate::cli::common::stderr_line(&format!("error (MPI rank {} of {}): {e}", mpi.rank(), mpi.size()));
                mpi.abort(1)
            }
        }
    }
    Ok(())
}

#[cfg(not(feature = "mpi"))]
fn run_split(_: &[String], _: &BenchArgs) -> Result<()> {
    crate::cli::common::refuse_mpi_launch(false)
}
