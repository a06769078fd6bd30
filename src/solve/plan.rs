//! The one place a reconstruction's mode is chosen: [`SolvePlan::decide`].
//!
//! From the problem, the settings, the scene declaration and the number of processes
//! it picks the mode ([`Mode`]), settles and resolves the TV weight once for that mode,
//! and refuses ([`Refusal`]) what the solver, the device or a split cannot take,
//! naming the flag to change. Every front-end (one process, a split across MPI ranks,
//! the live pipeline, Python) solves the plan it returns; the plan is printed
//! (`rollcam reconstruct --explain`) and written to summary.json as `plan`.

use crate::model::capture::CaptureConfig;
use crate::model::data::DataTerm;
use crate::model::scene::{SceneError, SceneSpec};
use crate::solve::lipschitz::EigenStore;
use crate::solve::optimize::{Device, SolverKind};
use crate::solve::problem::{Problem, ReconstructError, SolveParams, ValidSettings};
pub use crate::solve::refusal::Refusal;
use crate::solve::start::StillReport;
use crate::solve::support::Support;
use crate::solve::tau::{Noise, TauScale};
use crate::solve::tau_search::TauSearchReport;
use rayon::prelude::*;
use serde::Serialize;
use std::sync::atomic::AtomicBool;

/// What a solve does with a capture.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Mode {
    /// The plain video on the whole grid, every frame.
    WholeGrid,
    /// A sparse scene: the plain video on its still image's support, probed against the
    /// whole grid, then fitted as sources that change only in brightness
    /// ([`crate::solve::support`], [`crate::solve::sources`]).
    SparseSources,
    /// One static image plus a dynamic video ([`crate::solve::static_dynamic`]),
    /// and why it was chosen.
    StaticDynamic(ModelChoice),
    /// The plain video with key frames as data terms beside the raw
    /// ([`crate::solve::keyframes`]).
    KeyFrames,
    /// The video restricted as `[scene]` declares ([`crate::model::scene`]).
    Declared,
}

impl Mode {
    /// The mode's key, as summary.json names it.
    pub fn key(self) -> &'static str {
        match self {
            Mode::WholeGrid => "whole-grid",
            Mode::SparseSources => "sparse-sources",
            Mode::StaticDynamic(_) => "static-dynamic",
            Mode::KeyFrames => "key-frames",
            Mode::Declared => "declared",
        }
    }

    /// The mode in a few words, as printed.
    pub fn name(self) -> &'static str {
        match self {
            Mode::WholeGrid => "the plain video on the whole grid",
            Mode::SparseSources => "a sparse scene: the video on its still image's support, then fitted as sources",
            Mode::StaticDynamic(_) => "the static + dynamic model (one static image and a moving part)",
            Mode::KeyFrames => "the plain video with the key frames",
            Mode::Declared => "the video as the scene declaration restricts it",
        }
    }
}

/// Why a capture was solved with the static + dynamic model
/// ([`crate::model::scene::SceneSpec::static_dynamic`]; summary.json's
/// `static_background.chosen_by`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(tag = "rule", rename_all = "kebab-case")]
pub enum ModelChoice {
    /// `[scene] static_background = true`.
    Declared,
    /// The default with key frames showing a small part of the grid changing (their
    /// [`crate::solve::keyframes::moving_share`]; `None`: not measured, one key frame).
    KeyFrames { moving_share: Option<f64> },
    /// The default where a still image explains the raw: its relative residual (the
    /// worst channel's) after the still check.
    MostlyStill { still_residual: f64 },
}

impl ModelChoice {
    /// The terminal's words for the choice, with how to solve the plain video instead
    /// (empty when declared).
    pub fn said(&self) -> String {
        match self {
            ModelChoice::Declared => String::new(),
            ModelChoice::KeyFrames { moving_share: Some(share) } => format!(
                "the default with key frames showing a small moving part: {:.1}% of the grid changes between them (under {:.0}%); --scene static_background=false solves the video as its departure from their interpolation",
                100.0 * share,
                100.0 * crate::solve::keyframes::SMALL_MOTION_SHARE
            ),
            ModelChoice::KeyFrames { moving_share: None } => "the default with one key frame; --scene static_background=false solves the video as its departure from it".into(),
            ModelChoice::MostlyStill { still_residual } => format!(
                "the default on a mostly still scene: a still image explains the raw to within {still_residual:.3}; --scene static_background=false solves the plain video"
            ),
        }
    }

    /// The model as a refusal names it: the declaration, or the default and how to
    /// solve the plain video instead.
    pub fn named(&self) -> &'static str {
        match self {
            ModelChoice::Declared => "[scene] static_background = true",
            ModelChoice::KeyFrames { .. } => "the static + dynamic model (the default with [[keyframes]] showing a small moving part; [scene] static_background = false solves the key-frame video)",
            ModelChoice::MostlyStill { .. } => {
                "the static + dynamic model (the default on a mostly still scene; [scene] static_background = false solves the plain video)"
            }
        }
    }
}

/// Where the solve runs: one process, or a split across `ranks` MPI ranks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum Processes {
    One,
    Split { ranks: usize },
}

/// What a front-end asks of the scene beyond the settings: a declaration (else
/// capture.toml's `[scene]`).
#[derive(Clone, Debug, Serialize)]
pub struct SolveOptions {
    /// `None`: capture.toml's `[scene]`.
    pub scene: Option<SceneSpec>,
    /// When a declaration leaves something out, time one forward + adjoint of the
    /// undeclared operator to estimate what the full problem would cost per iteration.
    pub measure_full: bool,
}

impl SolveOptions {
    /// The declaration and where it was made: these options', else `cfg`'s `[scene]`.
    pub fn declared(&self, cfg: &CaptureConfig) -> Result<(SceneSpec, &'static str), SceneError> {
        match &self.scene {
            Some(s) => Ok((s.clone(), "options")),
            None => Ok((SceneSpec::from_table(cfg.scene.as_ref())?, "capture.toml")),
        }
    }
}

impl Default for SolveOptions {
    fn default() -> Self {
        SolveOptions { scene: None, measure_full: true }
    }
}

/// A reconstruction decided: the mode and why, the weight resolved once for it, the
/// still checks and support it was chosen from, where it runs.
#[derive(Clone, Debug)]
pub struct SolvePlan {
    pub mode: Mode,
    pub spec: SceneSpec,
    /// Where the scene was declared: `options` or `capture.toml`.
    pub declared_in: &'static str,
    /// The parameters every stage solves with (tau resolved for the mode).
    pub params: SolveParams,
    /// The held-out search that settled `tau_rel` (`None`: the weight as given).
    pub tau_search: Option<TauSearchReport>,
    /// The still checks the mode was chosen from, one per captured channel (empty when
    /// none was made); the still start goes on from them.
    pub still_checks: Vec<StillReport>,
    /// [`Mode::SparseSources`]' support.
    pub support: Option<Support>,
    /// [`SolveOptions::measure_full`].
    pub measure_full: bool,
    pub processes: Processes,
    /// Frames of the video.
    pub frames: usize,
    /// Key frames solved with the raw.
    pub keyframes: usize,
    /// The share of the grid the key frames show changing, when it decided the mode
    /// ([`crate::solve::keyframes::moving_share`]).
    pub moving_share: Option<f64>,
}

/// summary.json's `plan`: what was decided and why, in words and figures.
#[derive(Clone, Debug, Serialize)]
pub struct PlanReport {
    /// [`Mode::key`].
    pub mode: &'static str,
    /// Why the static + dynamic model was chosen, in that mode.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model: Option<ModelChoice>,
    pub why: String,
    pub processes: Processes,
    pub declared_in: &'static str,
    pub tau: f32,
    pub tau_choice: String,
    pub alpha: f32,
    pub solver: SolverKind,
    pub device: Device,
    pub max_iters: usize,
    pub stop: String,
    pub keyframes: usize,
    /// [`SolvePlan::moving_share`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub keyframe_moving_share: Option<f64>,
    pub still_checks: usize,
    pub still_check_seconds: f64,
    pub support_pixels: Option<usize>,
}

impl SolvePlan {
    /// Decide how `problem` is solved: the scene (`scene`, else capture.toml's), the
    /// weight (`settings`, its held-out search run here in one process), the mode
    /// (declared, key frames, or chosen by the still checks: static + dynamic when a
    /// still image explains every channel's raw, sparse sources when the still images
    /// show light on a small part of the grid, else the whole grid), the weight resolved
    /// for the mode, and the refusals. `processes`: a split refuses what it cannot
    /// solve rather than solving another problem.
    pub fn decide(
        problem: &Problem,
        settings: &ValidSettings,
        scene: &SolveOptions,
        processes: Processes,
        cache: &dyn EigenStore,
        stop: &AtomicBool,
    ) -> Result<SolvePlan, ReconstructError> {
        let (spec, declared_in) = scene.declared(problem.cfg)?;
        let keyframes = problem.prepared.keyframes.len();
        let frames = problem.channel(0).model().video_shape().0;
        if let Processes::Split { .. } = processes {
            refuse_split_early(&spec, settings, keyframes)?;
        }
        let (settings, tau_search) = crate::solve::tau_search::settle(settings, problem, cache, stop);
        // The checks judge the still with the plain video's weight.
        let check_params = settings.resolve(problem, problem.fov);
        let mut checks = None;
        // With key frames, the share of the grid they show changing (the worst
        // channel's): a small moving part is the static + dynamic model's.
        let moving_share = (keyframes > 0 && spec.static_background.is_none())
            .then(|| {
                (0..problem.channels())
                    .filter_map(|ch| crate::solve::keyframes::moving_share(problem.prepared, ch, problem.channel(ch).model()))
                    .reduce(f64::max)
            })
            .flatten();
        let small_motion = keyframes > 0 && !moving_share.is_some_and(|s| s >= crate::solve::keyframes::SMALL_MOTION_SHARE);
        let model = spec
            .static_dynamic(small_motion, || {
                keyframes == 0 && {
                    checks = still_checks(problem, &check_params);
                    checks.as_ref().is_some_and(|c| c.iter().all(|r| r.used))
                }
            })
            .then(|| match (spec.static_background, keyframes > 0) {
                (Some(true), _) => ModelChoice::Declared,
                (_, true) => ModelChoice::KeyFrames { moving_share },
                // The worst channel's residual.
                _ => ModelChoice::MostlyStill { still_residual: checks.iter().flatten().map(|r| r.residual_rel).fold(0.0, f64::max) },
            });
        // The plain video of an undeclared scene: the checks' still images say whether
        // the scene is sparse (made here when the model's choice did not need them).
        let plain = model.is_none() && spec.is_plain() && !spec.whole_grid && keyframes == 0;
        if plain && checks.is_none() {
            checks = still_checks(problem, &check_params);
        }
        let support = checks.as_ref().filter(|_| plain).and_then(|c| {
            let images: Option<Vec<&[f32]>> = c.iter().map(|r| r.image.as_deref()).collect();
            let (_, rows, cols) = problem.channel(0).model().video_shape();
            Support::from_still(&images?, (rows, cols))
        });
        let mode = match (model, support.is_some()) {
            (Some(m), _) => Mode::StaticDynamic(m),
            (None, true) => Mode::SparseSources,
            (None, false) if keyframes > 0 => Mode::KeyFrames,
            (None, false) if !spec.is_plain() => Mode::Declared,
            (None, false) => Mode::WholeGrid,
        };
        let params = settings.resolve(&ModeScale { problem, static_dynamic: model.is_some() }, problem.fov);
        let plan = SolvePlan {
            mode,
            spec,
            declared_in,
            params,
            tau_search,
            still_checks: checks.unwrap_or_default(),
            support,
            measure_full: scene.measure_full,
            processes,
            frames,
            keyframes,
            moving_share,
        };
        plan.refuse(problem)?;
        Ok(plan)
    }

    /// Whether the static + dynamic model is solved.
    pub fn static_dynamic(&self) -> bool {
        matches!(self.mode, Mode::StaticDynamic(_))
    }

    /// Seconds of the still checks (the slowest channel's; they run in parallel).
    pub fn check_seconds(&self) -> f64 {
        self.still_checks.iter().map(|r| r.seconds).fold(0.0, f64::max)
    }

    /// Why this mode, in words.
    pub fn why(&self) -> String {
        let residual = || self.still_checks.iter().map(|r| r.residual_rel).fold(0.0, f64::max);
        match self.mode {
            Mode::StaticDynamic(ModelChoice::Declared) => format!("declared ([scene] static_background = true, in {})", self.declared_in),
            Mode::StaticDynamic(m) => m.said(),
            Mode::SparseSources => format!(
                "the still check's image shows light on {} of {} pixels",
                self.support.as_ref().map_or(0, Support::pixels),
                self.support.as_ref().map_or(0, |s| s.shape.0 * s.shape.1)
            ),
            Mode::KeyFrames => match self.moving_share {
                Some(share) if self.spec.static_background.is_none() => format!(
                    "{} key frame(s) showing {:.1}% of the grid changing (from {:.0}%, more than one static image and a small moving part): the video as its departure from their interpolation; --scene static_background=true solves the static + dynamic model",
                    self.keyframes,
                    100.0 * share,
                    100.0 * crate::solve::keyframes::SMALL_MOTION_SHARE
                ),
                _ => format!("{} key frame(s), [scene] static_background = false: the video as its departure from their interpolation", self.keyframes),
            },
            Mode::Declared => format!("declared in {}", self.declared_in),
            Mode::WholeGrid if self.spec.whole_grid => "--full-grid".into(),
            Mode::WholeGrid if self.spec.static_background == Some(false) => "[scene] static_background = false".into(),
            Mode::WholeGrid if self.still_checks.is_empty() => "no still check applies (one frame, an ADMM solver or a device)".into(),
            Mode::WholeGrid => {
                format!("the still check leaves residual {:.3} (a moving scene) and its light covers much of the grid", residual())
            }
        }
    }

    /// The plan as summary.json records it.
    pub fn report(&self) -> PlanReport {
        let p = &self.params;
        PlanReport {
            mode: self.mode.key(),
            model: match self.mode {
                Mode::StaticDynamic(m) => Some(m),
                _ => None,
            },
            why: self.why(),
            processes: self.processes,
            declared_in: self.declared_in,
            tau: p.tau,
            tau_choice: p.tau_choice.to_string(),
            alpha: p.alpha,
            solver: p.solver,
            device: p.device,
            max_iters: p.stop.max_iters,
            stop: stop_said(&p.stop),
            keyframes: self.keyframes,
            keyframe_moving_share: self.moving_share,
            still_checks: self.still_checks.len(),
            still_check_seconds: self.check_seconds(),
            support_pixels: self.support.as_ref().map(Support::pixels),
        }
    }

    /// The plan in lines, as the terminal prints it before the solve.
    pub fn lines(&self) -> Vec<String> {
        let p = &self.params;
        let r = self.report();
        let place = match self.processes {
            Processes::One => "one process".to_string(),
            Processes::Split { ranks } => format!("split across {ranks} MPI ranks"),
        };
        let mut lines = vec![
            format!("plan: {} ({place})", self.mode.name()),
            format!("plan: why: {}", r.why),
            format!("plan: weight tau = {:.4e} ({}), alpha {}", p.tau, p.tau_choice, p.alpha),
            format!("plan: {} on the {}, {}", p.solver, p.device, r.stop),
        ];
        if self.mode == Mode::SparseSources {
            lines.push("plan: --full-grid solves the whole grid instead".into());
        }
        if !self.still_checks.is_empty() {
            lines.push(format!(
                "plan: chosen from {} still check(s) of {} iterations ({:.2} s)",
                self.still_checks.len(),
                self.still_checks.iter().map(|c| c.iterations).max().unwrap_or(0),
                self.check_seconds()
            ));
        }
        lines
    }

    /// What the solver, the device, the mode and the processes cannot take together,
    /// refused before any solve.
    fn refuse(&self, problem: &Problem) -> Result<(), Refusal> {
        let params = &self.params;
        let kind = params.solver;
        let keyframes = self.keyframes > 0;
        let static_dynamic = self.static_dynamic();
        if let Mode::StaticDynamic(m) = self.mode {
            if kind.shrinks_tv_itself() {
                return Err(Refusal::ModelSolver { model: m.named(), solver: kind });
            }
            if params.device != Device::Cpu {
                return Err(Refusal::ModelDevice { model: m.named(), device: params.device });
            }
        }
        let lower = problem.prepared.data_mask.lower_bounds.as_deref();
        if let Some(b) = problem.prepared.raw.first() {
            kind.check_data(&DataTerm::new(&b.data).with_lower_bounds(lower)).map_err(Refusal::Data)?;
        }
        if keyframes {
            let with = if static_dynamic {
                None
            } else if !self.spec.is_plain() {
                Some("a declared [scene] (support, frames, static, colour, tv_weights)".to_string())
            } else if params.device != Device::Cpu {
                Some(format!("--device {}", params.device))
            } else {
                None
            };
            if let Some(with) = with {
                return Err(Refusal::KeyFrames { with });
            }
        } else {
            // Key frames add data of their own (the exact rule is for the capture's data alone).
            let recipe = params.prior(static_dynamic);
            crate::solve::tau::check_l1(recipe.l1_rel, recipe.tau, problem, static_dynamic).map_err(|e| Refusal::L1(e.to_string()))?;
        }
        if params.l1_reweight.is_some_and(|r| r > 0) && !static_dynamic {
            return Err(Refusal::L1Reweight);
        }
        if let Processes::Split { .. } = self.processes {
            let not_split = |what: String, instead: &str| Refusal::NotSplit { what, instead: instead.into() };
            match self.mode {
                Mode::SparseSources => {
                    return Err(not_split(
                        format!("one process solves this capture as {} ({})", Mode::SparseSources.name(), self.why()),
                        "the split solves the whole grid only: give --full-grid to solve the whole grid (one process gives the same video), or run it without mpirun",
                    ))
                }
                Mode::StaticDynamic(_) => {
                    return Err(not_split(
                        format!("one process solves this capture with {} ({})", self.mode.name(), self.why()),
                        "its static image is shared by every frame and is not split: give --scene static_background=false to solve the plain video, or run it without mpirun",
                    ))
                }
                Mode::KeyFrames => return Err(not_split("[[keyframes]]: key frames are solved in one process".into(), "run it without mpirun (or leave the key frames out)")),
                Mode::WholeGrid | Mode::Declared => {}
            }
        }
        Ok(())
    }
}

/// What a split refuses whatever the still checks say, before any of them runs (and
/// before any collective: every rank refuses alike).
fn refuse_split_early(spec: &SceneSpec, settings: &ValidSettings, keyframes: usize) -> Result<(), Refusal> {
    let no = |what: String| Err(Refusal::NotSplit { what, instead: "run it without mpirun".into() });
    if settings.solver.shrinks_tv_itself() {
        return no(format!("the {} solver is not split (fista, fista-restart, mfista and pgd are)", settings.solver));
    }
    if spec.static_background == Some(true) {
        return no("the static + dynamic model ([scene] static_background) is not split (its static image is shared by every frame)".into());
    }
    if settings.device != Device::Cpu {
        return no(format!("the ranks solve on their CPUs (--device {} is for one process)", settings.device));
    }
    if spec.static_scene {
        return no("a static scene ([scene] static = true) is one frame, nothing to split".into());
    }
    if settings.l1_reweight.is_some_and(|r| r > 0) {
        return no("reweighted L1 belongs to the static + dynamic model, which is not split".into());
    }
    if keyframes > 0 {
        return Err(Refusal::NotSplit {
            what: "[[keyframes]]: key frames are solved in one process, not split".into(),
            instead: "run it without mpirun (or leave the key frames out)".into(),
        });
    }
    if settings.tau.is_auto() {
        return Err(Refusal::NotSplit {
            what: "--tau-rel auto (the held-out search) is not split".into(),
            instead: "run it once without mpirun and give the tau_rel it chose (summary.json: tau_search)".into(),
        });
    }
    Ok(())
}

/// What a sequence of consecutive captures, solved as one video
/// ([`crate::solve::sequence`]), refuses of its capture description: key frames, which
/// one capture's plan solves.
pub fn refuse_in_sequence(keyframes: usize) -> Result<(), Refusal> {
    if keyframes > 0 {
        return Err(Refusal::NotInSequence {
            what: "[[keyframes]]",
            why: "key frames are solved with one capture (`rollcam reconstruct`); a sequence does not take them (leave them out of its capture description)",
        });
    }
    Ok(())
}

/// The stop rule in words.
fn stop_said(stop: &crate::solve::optimize::StopRule) -> String {
    let mut s = format!("at most {} iterations", stop.max_iters);
    if stop.obj_tol > 0.0 {
        s += &format!(", settled at obj_tol {:e}", stop.obj_tol);
    }
    if stop.rel_tol > 0.0 {
        s += &format!(", rel_tol {:e}", stop.rel_tol);
    }
    if let Some(t) = stop.time_budget_s {
        s += &format!(", within {t} s");
    }
    s
}

/// Every channel's still check ([`crate::solve::start::check`]: `used` when the still
/// image explains the raw within [`crate::solve::start::STILL_RESIDUAL_MAX`] after a
/// short still solve): all used, a still scene with something moving over it. `None`
/// for a capture of one frame, where the static + dynamic model does not run (an ADMM
/// solver, a device), and when a channel's still solve went non-finite.
fn still_checks(problem: &Problem, params: &SolveParams) -> Option<Vec<StillReport>> {
    let frames = problem.channel(0).model().video_shape().0;
    if frames < 2 || params.solver.shrinks_tv_itself() || params.device != Device::Cpu {
        return None;
    }
    let lower = problem.prepared.data_mask.lower_bounds.as_deref();
    (0..problem.channels())
        .into_par_iter()
        .map(|ch| {
            let c = problem.channel(ch);
            let model = c.model();
            let data = DataTerm::new(&problem.prepared.raw[ch].data).with_lower_bounds(lower);
            let prior = params.prior(false).video(model.video_shape(), c.atb_max() as f64);
            crate::solve::start::check(model, &data, &prior)
        })
        .collect()
}

/// The problem's scale for the noise rule, told whether the static + dynamic model is
/// solved ([`crate::solve::tau::HELD_STILL_TAU_FACTOR`]).
struct ModeScale<'a> {
    problem: &'a Problem<'a>,
    static_dynamic: bool,
}

impl TauScale for ModeScale<'_> {
    fn tau_scale(&self) -> f32 {
        TauScale::tau_scale(self.problem)
    }
    fn noise(&self) -> Option<Noise> {
        TauScale::noise(self.problem).map(|n| Noise { static_dynamic: self.static_dynamic, ..n })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solve::problem::SolveSettings;

    fn valid(s: SolveSettings) -> ValidSettings {
        s.validate().unwrap()
    }

    /// What a split refuses before any still check, by name: among them a CUDA device
    /// (the ranks solve on their CPUs), admm-split, key frames and the held-out search;
    /// the plain CPU settings pass.
    #[test]
    fn a_split_refuses_the_device_the_splitting_solvers_and_key_frames_by_name() {
        let plain = SceneSpec::default();
        assert!(refuse_split_early(&plain, &valid(SolveSettings::default()), 0).is_ok());
        let cuda = valid(SolveSettings { device: Device::Cuda, ..SolveSettings::default() });
        let e = refuse_split_early(&plain, &cuda, 0).unwrap_err().to_string();
        assert!(e.contains("split across MPI ranks: the ranks solve on their CPUs (--device cuda is for one process)"), "{e}");
        let admm = valid(SolveSettings { solver: SolverKind::AdmmSplit, ..SolveSettings::default() });
        assert!(refuse_split_early(&plain, &admm, 0).unwrap_err().to_string().contains("the admm-split solver is not split"));
        let e = refuse_split_early(&plain, &valid(SolveSettings::default()), 2).unwrap_err();
        assert!(matches!(e, Refusal::NotSplit { .. }) && e.to_string().contains("[[keyframes]]"), "{e}");
        let auto = valid(SolveSettings { tau: crate::solve::tau::Tau::Auto(None), ..SolveSettings::default() });
        assert!(refuse_split_early(&plain, &auto, 0).unwrap_err().to_string().contains("--tau-rel auto"));
    }
}
