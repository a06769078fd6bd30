//! `rollcam reconstruct`: one raw capture + PSF + timing -> video folder.

use crate::cli::common::{claim_out, ctrl_c_flag, print_sensor, psf_or_calibration, CaptureFlags, ForceFlag, Progress, SensorFlags, SolverFlags};
use anyhow::{bail, Context, Result};
use clap::Args;
use rollcam::io;
use rollcam::io::cache::LipschitzCache;
use rollcam::io::output::{OutputSet, RECONSTRUCTION_FILES};
use rollcam::model::scene::SceneSpec;
use rollcam::request::capture::{Before, CaptureOutcome, CaptureRequest};
#[cfg(feature = "mpi")]
use rollcam::request::split::SplitRequest;
use rollcam::request::{Hooks, TraceRow, ValidSettings, ZERO_TRUTH};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct ReconstructArgs {
    /// Raw rolling-shutter capture (TIFF 8/16-bit or float, PNG, JPEG, .npy; grey or RGB).
    #[arg(long)]
    pub raw: PathBuf,
    /// Page of a multi-page TIFF raw to reconstruct (1 = the first); a multi-page raw
    /// without it is refused.
    #[arg(long, value_name = "N")]
    pub page: Option<usize>,
    /// PSF: image of a point source through the same optics, same size as the raw
    /// (default: the calibration's psf.tiff).
    #[arg(long)]
    pub psf: Option<PathBuf>,
    /// capture.toml describing the raw capture (flags below override it).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Ground-truth video (frames, rows, cols[, channels]) to report PSNR against.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Output folder: new or empty (or see --force); checked before any work.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub force: ForceFlag,
    #[command(flatten)]
    pub capture: CaptureFlags,
    #[command(flatten)]
    pub sensor: SensorFlags,
    #[command(flatten)]
    pub solver: SolverFlags,
    #[command(flatten)]
    pub scene: SceneFlags,
    /// Start a solve estimated beyond a day (refused without it).
    #[arg(long)]
    pub yes: bool,
    /// Decide the plan (mode, weight, stop rule, where it runs), print it and stop:
    /// the video is not solved and the output folder is not touched.
    #[arg(long)]
    pub explain: bool,
}

/// Scene declaration flags: each overrides the same key of capture.toml's `[scene]`.
#[derive(Args, Debug, Clone, Default)]
pub struct SceneFlags {
    /// The scene's colour: grey (an RGB raw is averaged and solved once) or rgb.
    #[arg(long, value_name = "grey|rgb")]
    pub scene_colour: Option<String>,
    /// Light only inside rows r0..r1, columns c0..c1 of the video grid.
    #[arg(long, value_name = "r0,r1,c0,c1", value_delimiter = ',')]
    pub support: Option<Vec<usize>>,
    /// The scene is dark outside frames a..b (half-open).
    #[arg(long, value_name = "a..b")]
    pub frames: Option<String>,
    /// Nothing moves: one frame is solved, without temporal TV.
    #[arg(long = "static")]
    pub static_scene: bool,
    /// TV weights (t, y, x) relative to tau; 0 leaves an axis out.
    #[arg(long, value_name = "t,y,x", value_delimiter = ',')]
    pub tv_weights: Option<Vec<f32>>,
    /// Any typed [scene] key as TOML, e.g. --scene 'support=[4, 40, 8, 70]'.
    #[arg(long = "scene", value_name = "KEY=VALUE")]
    pub keys: Vec<String>,
    /// Ignore every scene declaration and solve the full problem, on the whole grid
    /// (no support from a sparse scene's still image).
    #[arg(long)]
    pub full_grid: bool,
}

impl SceneFlags {
    /// The declaration: capture.toml's `[scene]` with the flags over it; `None` when no
    /// flag is given (the library then reads capture.toml itself).
    pub fn resolve(&self, table: Option<&toml::Table>) -> Result<Option<SceneSpec>> {
        if self.full_grid {
            return Ok(Some(SceneSpec { whole_grid: true, ..SceneSpec::default() }));
        }
        let any = self.scene_colour.is_some()
            || self.support.is_some()
            || self.frames.is_some()
            || self.static_scene
            || self.tv_weights.is_some()
            || !self.keys.is_empty();
        if !any {
            return Ok(None);
        }
        let mut t = table.cloned().unwrap_or_default();
        let ints = |v: &[usize]| toml::Value::Array(v.iter().map(|&x| toml::Value::Integer(x as i64)).collect());
        let mut given: Vec<&str> = Vec::new();
        for kv in &self.keys {
            let (key, value) = kv.split_once('=').with_context(|| format!("--scene {kv}: expected KEY=VALUE"))?;
            let key = key.trim();
            SceneSpec::check_key(key).with_context(|| format!("--scene {kv}"))?;
            if given.contains(&key) {
                bail!("--scene {kv:?}: {key} is declared twice: expected each scene key once");
            }
            given.push(key);
            let v: toml::Table =
                toml::from_str(&format!("v = {value}")).map_err(|e| anyhow::anyhow!("--scene {kv:?}: the value is not TOML: {}", e.message()))?;
            if v.len() != 1 {
                bail!("--scene {kv:?}: expected one KEY=VALUE (one value, on one line); give each declaration its own --scene");
            }
            t.insert(key.to_string(), v["v"].clone());
        }
        if let Some(c) = &self.scene_colour {
            t.insert("colour".into(), toml::Value::String(c.clone()));
        }
        if let Some(s) = &self.support {
            t.insert("support".into(), ints(s));
        }
        if let Some(f) = &self.frames {
            let (a, b) = f
                .split_once("..")
                .and_then(|(a, b)| Some((a.trim().parse::<usize>().ok()?, b.trim().parse::<usize>().ok()?)))
                .with_context(|| format!("--frames {f}: expected a..b (first frame, one past the last)"))?;
            t.insert("frames".into(), ints(&[a, b]));
        }
        if self.static_scene {
            t.insert("static".into(), toml::Value::Boolean(true));
        }
        if let Some(w) = &self.tv_weights {
            t.insert("tv_weights".into(), toml::Value::Array(w.iter().map(|&x| toml::Value::Float(x as f64)).collect()));
        }
        Ok(Some(SceneSpec::from_table(Some(&t)).context("scene declaration")?))
    }
}

/// What every solve of `rollcam reconstruct` starts from, read and checked once.
struct Loaded {
    settings: ValidSettings,
    cfg: rollcam::model::capture::CaptureConfig,
    config_name: Option<String>,
    raw: ndarray::Array3<f32>,
    raw_name: String,
    raw_full_scale: Option<f64>,
    psf: ndarray::Array3<f32>,
    psf_name: String,
    psf_clean: bool,
    sensor: rollcam::io::sensor_files::SensorFiles,
    truth: Option<(ndarray::Array4<f32>, String)>,
    scene: Option<SceneSpec>,
}

impl Loaded {
    /// The library's request for this capture (the sensor report on the terminal).
    fn request(&self) -> CaptureRequest<'_> {
        CaptureRequest::new(self.raw.view(), &self.raw_name, self.psf.view(), &self.psf_name, &self.cfg, &self.sensor, &self.settings)
            .with_full_scale(self.raw_full_scale)
            .with_clean_psf(self.psf_clean)
            .with_config_name(self.config_name.as_deref())
            .with_scene(self.scene.clone())
            .with_truth(self.truth.as_ref().map(|(t, name)| (t.view(), name.as_str())))
            .with_sensor_report(&print_sensor)
    }
}

/// A raw frame recorded with its own key frames (`frame_NNNNNN.toml` beside it, from
/// `--keyframe-camera`) reconstructs with those: a `--config` whose `[[keyframes]]`
/// name other files (another frame's key frames, taken at another moment) is refused.
fn check_own_keyframes(raw: &std::path::Path, config: Option<&std::path::Path>, cfg: &rollcam::model::capture::CaptureConfig) -> Result<()> {
    use rollcam::model::capture::CaptureConfig;
    let (Some(own_path), Some(config)) = (rollcam::lab::keycam::description_beside(raw), config) else { return Ok(()) };
    if cfg.keyframes.is_empty() {
        return Ok(());
    }
    let own = CaptureConfig::load(&own_path)?;
    let files = |c: &CaptureConfig| c.keyframes.iter().map(|k| k.file.clone()).collect::<Vec<_>>();
    if files(&own) != files(cfg) {
        bail!(
            "--config {}: its [[keyframes]] ({}) are not those of --raw {} ({}, in {}): give --config {}",
            config.display(),
            files(cfg).join(", "),
            raw.display(),
            files(&own).join(", "),
            own_path.display(),
            own_path.display()
        );
    }
    Ok(())
}

/// Read the inputs, resolve the capture and the scene declaration. `claim`: take the
/// output folder (the process that writes it).
fn load(a: &ReconstructArgs, claim: bool) -> Result<Loaded> {
    let settings = a.solver.settings()?;
    let [calibration, background] = a.sensor.inputs();
    let inputs = [
        ("the raw image (--raw)", Some(a.raw.as_path())),
        ("the PSF (--psf)", a.psf.as_deref()),
        ("the capture description (--config)", a.config.as_deref()),
        ("the truth (--truth)", a.truth.as_deref()),
        calibration,
        background,
    ];
    if claim {
        claim_out(&a.out, &a.force, RECONSTRUCTION_FILES, &inputs)?;
    }
    let raw = crate::cli::common::read_raw(&a.raw, a.page)?;
    let (rows, cols, _) = raw.dim();
    let cfg = a.capture.resolve(a.config.as_deref(), (rows, cols))?;
    crate::cli::common::check_bayer_grid(&a.raw, (rows, cols), &cfg)?;
    check_own_keyframes(&a.raw, a.config.as_deref(), &cfg)?;
    let sensor = a.sensor.load(a.config.as_deref(), &cfg)?;
    let (psf, psf_name, psf_clean) = psf_or_calibration(a.psf.as_deref(), &sensor)?;
    let truth = match &a.truth {
        Some(p) => Some((io::read_truth(p)?, p.display().to_string())),
        None => None,
    };
    let raw_name = a.raw.display().to_string();
    let scene = a.scene.resolve(cfg.scene.as_ref())?;
    let config_name = a.config.as_ref().map(|p| p.display().to_string());
    let raw_full_scale = io::sample_full_scale(&a.raw);
    Ok(Loaded { settings, cfg, config_name, raw, raw_name, raw_full_scale, psf, psf_name, psf_clean, sensor, truth, scene })
}

pub fn run(a: ReconstructArgs) -> Result<()> {
    if rollcam::cluster::MPI_BUILT && rollcam::cluster::launched_ranks().is_some() {
        return run_split(a);
    }
    let l = load(&a, !a.explain)?;
    let request = l.request();
    let prepared = request.prepare()?;
    if prepared.prepared.dark_estimated {
        tracing::info!(
            raw_dark = prepared.prepared.raw_dark,
            psf_dark = prepared.prepared.psf_dark,
            "dark levels estimated from the darkest pixels (give dark_level to fix them)"
        );
    }
    if l.settings.tau == rollcam::solve::tau::Tau::Noise && is_jpeg(&a.raw) {
        eprintln!(
            "warning: {}: a JPEG's compression smooths and correlates its noise, so the noise rule's weight (the default) reads it low: give --tau-rel (e.g. 2.5e-4), or --tau-rel auto on a still (docs/limits.md)",
            a.raw.display()
        );
    }
    let progress = Progress::new(l.settings.iters * prepared.solved_channels(), ctrl_c_flag());
    let on_row = |ch: usize, row: &TraceRow| progress.row(ch, row);
    let hooks = Hooks { on_row: &on_row, stop: &progress.stop };
    let mut refused = None;
    let outcome = prepared.reconstruct_after(&LipschitzCache::default_location(), &hooks, |stage| match stage {
        Before::Estimate(e) => {
            progress.println(&e.describe());
            if let Some(why) = e.needs_confirmation().filter(|_| !a.yes && !a.explain) {
                refused = Some(why);
                return false;
            }
            if e.is_long() && !a.explain {
                progress.println(&format!(
                    "warning: this solve is estimated to take about {}; --downsample or --iters shorten it, Ctrl-C keeps the last iterate",
                    rollcam::solve::estimate::human_duration(e.seconds)
                ));
            }
            true
        }
        Before::Plan(plan) => {
            plan.lines().iter().for_each(|l| progress.println(l));
            !a.explain
        }
    });
    progress.finish();
    if let Some(why) = refused {
        bail!("{why}: give --yes to start it, or shorten it (--iters, --obj-tol, --time-budget-s, --downsample)");
    }
    let outcome = outcome?;
    if a.explain {
        println!("--explain: the plan above was decided (its still checks and weight search made); the video was not solved and nothing was written");
        return Ok(());
    }
    let Some(outcome) = outcome else { bail!("the solve did not start") };
    report(&a, &l, &outcome, progress.stopped())
}

/// Whether `path` names a JPEG file (by its extension).
fn is_jpeg(path: &std::path::Path) -> bool {
    path.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("jpg") || e.eq_ignore_ascii_case("jpeg"))
}

/// Under an MPI launcher: every rank solves its block of frames
/// ([`rollcam::request::split`]); rank 0 claims the folder, gathers the video and
/// writes it. An error on any rank ends every rank (MPI abort), so none waits forever.
#[cfg(feature = "mpi")]
fn run_split(a: ReconstructArgs) -> Result<()> {
    let mpi = rollcam::cluster::mpi::Mpi::init()?;
    if let Some(w) = rollcam::cluster::binding_warning(rollcam::model::ranks::Ranks::rank(&mpi), rayon::current_num_threads()) {
        crate::cli::common::stderr_line(&format!("warning: {w}"));
    }
    match solve_split(&a, &mpi) {
        Ok(()) => Ok(()),
        Err(e) => {
            crate::cli::common::stderr_line(&format!(
                "error (MPI rank {} of {}): {}",
                rollcam::model::ranks::Ranks::rank(&mpi),
                rollcam::model::ranks::Ranks::size(&mpi),
                crate::cli::common::error_text(&e)
            ));
            mpi.abort(1)
        }
    }
}

#[cfg(not(feature = "mpi"))]
fn run_split(_: ReconstructArgs) -> Result<()> {
    crate::cli::common::refuse_mpi_launch(false)
}

#[cfg(feature = "mpi")]
fn solve_split(a: &ReconstructArgs, mpi: &rollcam::cluster::mpi::Mpi) -> Result<()> {
    use rollcam::model::ranks::Ranks;
    let root = mpi.rank() == 0;
    let l = load(a, root && !a.explain)?;
    let request = l.request();
    let on_plan = |plan: &rollcam::request::SolvePlan| {
        if root {
            plan.lines().iter().for_each(|l| println!("{l}"));
        }
        !a.explain
    };
    let split = SplitRequest {
        capture: &request,
        ranks: mpi,
        ranks_here: rollcam::cluster::ranks_on_this_machine().unwrap_or(mpi.size()),
        peak_memory: &rollcam::perf::bench::peak_rss_bytes,
        on_plan: &on_plan,
    };
    let progress = Progress::new(if root { l.settings.iters * split.solved_channels() } else { 0 }, ctrl_c_flag());
    let on_row = |ch: usize, row: &TraceRow| {
        if root {
            progress.row(ch, row)
        }
    };
    let hooks = Hooks { on_row: &on_row, stop: &progress.stop };
    let outcome = split.run(&LipschitzCache::default_location(), &hooks)?;
    progress.finish();
    let Some(outcome) = outcome else {
        if root {
            println!("--explain: the plan above was decided (its still checks made); the video was not solved and nothing was written");
        }
        return Ok(());
    };
    let Some(capture) = outcome.outcome else { return Ok(()) };
    let r = &outcome.report;
    let blocks: Vec<String> =
        r.per_rank.iter().map(|p| format!("{}..{} ({} thread{})", p.frames[0], p.frames[1], p.threads, if p.threads == 1 { "" } else { "s" })).collect();
    println!("split across {} MPI ranks: frames {}", r.ranks, blocks.join(", "));
    report(a, &l, &capture, progress.stopped())
}

/// Write the folder and say what was made (the process that writes).
fn report(a: &ReconstructArgs, l: &Loaded, outcome: &CaptureOutcome, stopped: bool) -> Result<()> {
    let files = outcome.write(&a.out, &l.cfg, &l.request().inputs(), OutputSet::Full)?;
    let (rec, params) = (&outcome.reconstruction, &outcome.params);
    let (k, m, n, c) = rec.video.dim();
    if let Some(t) = &rec.tau_search {
        let tried: Vec<String> = t.candidates.iter().map(|c| format!("{:e}: {:.4e}", c.tau_rel, c.held_out_residual)).collect();
        if t.searched {
            println!(
                "tau_rel {:e} chosen by {} held-out pixels in {:.2} s ({}); held-out residual per candidate: {}",
                t.tau_rel,
                t.held_out_pixels,
                t.seconds,
                t.reason,
                tried.join(", ")
            );
        } else {
            println!("tau_rel {:e} kept ({:.2} s): {}", t.tau_rel, t.seconds, t.reason);
        }
    }
    if l.cfg.timing().is_still() {
        println!("still: one image of {m} x {n} x {c} (global shutter: the exposure holds no time), tau = {:.4e} ({})", params.tau, params.tau_choice);
    } else {
        println!(
            "video: {k} frames of {m} x {n} x {c} at {:.1} fps ({:.1} us per frame), tau = {:.4e} ({})",
            1e6 / rec.frame_time_us,
            rec.frame_time_us,
            params.tau,
            params.tau_choice
        );
    }
    for ch in &rec.channels {
        println!(
            "channel {}: {} {} iterations in {:.2} s, TV prox {}: {}",
            ch.channel,
            ch.solver,
            ch.stats.iterations,
            ch.stats.seconds,
            ch.tv_prox,
            ch.stop_line()
        );
        if let Some(err) = ch.error_line() {
            println!("channel {}: {err}", ch.channel);
        } else if l.truth.is_some() {
            println!("channel {}: no error figures: {}", ch.channel, ZERO_TRUTH);
        }
        let (line, warnings) = rollcam::solve::keyframes::report_lines(&ch.keyframes);
        if let Some(line) = line {
            println!("channel {}: {line}", ch.channel);
        }
        if let Some(c) = &ch.coarse {
            println!("channel {}: {}", ch.channel, c.line());
        }
        if let Some(i) = &ch.interpolation {
            println!("channel {}: {}", ch.channel, i.line());
        }
        if let Some(s) = &ch.support {
            println!("{}", s.line(ch.channel));
        }
        warnings.iter().for_each(|w| crate::cli::common::stderr_line(&format!("warning: {w}")));
    }
    if let Some(w) = rec.frame_sensitivity.warning() {
        println!("{w}");
    }
    if let Some(f) = &rec.fit {
        println!("{}", f.line());
        f.warnings.iter().for_each(|w| crate::cli::common::stderr_line(&format!("warning: {w}")));
    }
    if let Some(s) = &rec.scene {
        for l in &s.plan.left_out {
            println!("left out: {l}");
        }
        let full = s.seconds_per_iteration_full_estimate.map(|f| format!("{f:.4} s (estimated) -> ")).unwrap_or_default();
        println!(
            "saved: unknowns {} -> {} ({:.1} MB -> {:.1} MB per video vector), seconds per iteration {full}{:.4} s",
            s.unknowns_full,
            s.unknowns_solved,
            s.vector_bytes_full as f64 / 1e6,
            s.vector_bytes_solved as f64 / 1e6,
            s.seconds_per_iteration_solved
        );
        for w in &s.warnings {
            crate::cli::common::stderr_line(&format!("warning: {w}"));
        }
    }
    if let Some(sb) = &rec.static_background {
        let r = &sb.report;
        // Chosen by default: say why and how to get the plain video.
        let why = match r.chosen_by.said() {
            w if w.is_empty() => w,
            w => format!("; {w}"),
        };
        println!(
            "static + dynamic model: unknowns {} -> {} per channel (one static image added; static.tiff, dynamic.npy; video.npy is their sum{why})",
            r.unknowns_plain, r.unknowns_solved
        );
        for c in &r.channels {
            println!(
                "channel {}: static image holds {:.1}% of the light; residual {:.4} of the data; Lipschitz static {:.3e}, dynamic {:.3e} (steps per block, ratio {:.0}); tau static {:.3e}, dynamic {:.3e}, L1 {:.3e}; rounds {}; {}",
                c.channel,
                100.0 * c.static_share,
                c.residual_rel,
                c.lipschitz_static,
                c.lipschitz_dynamic,
                c.step_dynamic / c.step_static,
                c.tau_static,
                c.tau_dynamic,
                c.l1_dynamic,
                c.round_iterations.iter().map(|n| n.to_string()).collect::<Vec<_>>().join(" + "),
                refits_said(&c.dynamic_gains, c.round_iterations.len())
            );
        }
    }
    println!("wrote {} files to {}", files.len(), a.out.display());
    let shown = rollcam::io::contact_sheet_frames(k);
    if shown.len() < k && files.iter().any(|f| f.ends_with("contact.png")) {
        println!("contact.png shows {} of the {k} frames, evenly spaced, each labelled with its number (summary.json: contact_sheet_frames)", shown.len());
    }
    if stopped {
        bail!("interrupted: the video holds the last iterate; {} is complete", a.out.join("summary.json").display());
    }
    Ok(())
}

/// The static + dynamic model's refits of the moving part's scale
/// (`dynamic_gains`) after `rounds` rounds, in words.
fn refits_said(gains: &[f64], rounds: usize) -> String {
    let listed = gains.iter().map(|g| format!("x{g:.2}")).collect::<Vec<_>>().join(", ");
    match gains.len() {
        n if n < rounds => format!(
            "the moving part's scale refitted to the data after {n} of the {rounds} rounds{} (not after the rest: a gain past {} refused, its shape not the data's, or a stop, the time budget or a non-finite iterate ended the round)",
            if n > 0 { format!(": {listed}") } else { String::new() },
            rollcam::solve::static_dynamic::MAX_DYNAMIC_GAIN
        ),
        _ => format!("the moving part's scale refitted to the data after each: {listed}"),
    }
}
