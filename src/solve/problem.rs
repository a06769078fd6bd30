//! A capture's problem, built once, and the solve a user asks for.
//!
//! [`SolveSettings`] is what a user chooses before any capture is seen (the command
//! line's solver flags, a bench session's settings, a library caller's): the TV weight
//! as given ([`Tau`]: absolute, relative to the capture's scale, or from the raw's
//! noise by default), the temporal
//! weight, the stopping rule, the solver and the TV map. It is checked once
//! ([`SolveSettings::validate`]) into [`ValidSettings`], the only settings a solve takes.
//!
//! [`Problem`] is one prepared capture's problem: the shutter weights (computed once
//! for every channel), each channel's imaging operator `A` with its Lipschitz cache key,
//! and the scale `max(A^T b)` with the raw's noise ([`TauScale`]). [`ValidSettings::resolve`] turns settings
//! into one solve's [`SolveParams`] against such a scale: the one place in rollcam where
//! a relative tau becomes absolute (see [`crate::solve::tau`]).

use crate::model::capture::{CaptureConfig, Fov};
use crate::model::data::DataTerm;
use crate::model::noise::{median_sigma, noise_sigma};
use crate::model::prepare::{DataMask, Plane, Prepared};
use crate::model::rolling::RollingShutterModel;
use crate::model::scene::{Restricted, SceneError, ScenePlan, SceneSpec};
use crate::model::shutter::ShutterWeights;
use crate::model::shutter::TimingError;
use crate::solve::lipschitz::{Eigen, EigenStore, Fingerprint, LIPSCHITZ_MARGIN};
use crate::solve::metric::{FrameMetric, FrameScaled};
use crate::solve::optimize::{Device, SolverKind, StopRule};
use crate::solve::prox::prior::{PriorSpec, TvPrior};
use crate::solve::prox::tv_dual::{TvProx, TvProxChoice};
use crate::solve::prox::TotalVariation;
use crate::solve::start::Start;
use crate::solve::tau::{keyed_static_tau, static_frame_tau, Noise, Tau, TauChoice, TauScale};
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::sync::{Arc, OnceLock};

/// Default weight of the temporal gradient relative to the spatial ones.
pub const DEFAULT_ALPHA: f32 = 5.0;
/// Default cap on solver iterations: a run whose objective settles first
/// ([`DEFAULT_OBJ_TOL`]) stops there and says it converged; one the cap ends says it did
/// not. Chosen on the scene suite (docs/scene-suite.md).
pub const DEFAULT_ITERS: usize = 600;

/// Default convergence test: the objective's relative change below this for
/// [`crate::solve::optimize::OBJ_TOL_PATIENCE`] iterations in a row, with the data term
/// settled ([`crate::solve::optimize::StopRule::obj_tol`]), ends the run. Chosen on the
/// scene suite (docs/scene-suite.md).
pub const DEFAULT_OBJ_TOL: f64 = 1e-4;

/// The parameters of one solve: [`SolveSettings`] with tau resolved against a capture's
/// scale. Made only by [`ValidSettings::resolve`] (the private `_resolved` field), so a
/// solve never meets an unchecked setting.
// Not `#[non_exhaustive]`: the private field keeps other modules of this crate from
// building one too.
#[allow(clippy::manual_non_exhaustive)]
#[derive(Clone, Debug, Serialize)]
pub struct SolveParams {
    /// TV weight tau (>= 0), in the units of the data (counts per frame interval).
    pub tau: f32,
    /// How tau was chosen (the rule, and what it read).
    pub tau_choice: TauChoice,
    /// Weight of the temporal gradient relative to the spatial ones.
    pub alpha: f32,
    pub stop: StopRule,
    pub fov: Fov,
    /// The solver.
    pub solver: SolverKind,
    /// TV proximal map of the gradient methods; `auto` picks the exact map at strong TV.
    pub tv_prox: TvProxChoice,
    /// Weight of an L1 (sparsity) term relative to tau; `None`: the scene model's
    /// default ([`default_l1`]).
    pub l1: Option<f32>,
    /// Rounds of reweighted L1 after the first solve (the static + dynamic model's
    /// dynamic part); `None`: [`reweight_plan`]'s default.
    pub l1_reweight: Option<usize>,
    /// Where the video solve starts ([`Start`]: the still solve's image by default).
    pub start: Start,
    /// Where the solver runs ([`Device`]).
    pub device: Device,
    #[serde(skip)]
    _resolved: (),
}

impl SolveParams {
    /// The prior of this solve, decided once: tau, alpha, the TV map and the L1 weight
    /// (as given, else the scene model's default: [`default_l1`] of
    /// `static_background`). Every solve builds its prior from it.
    pub fn prior(&self, static_background: bool) -> PriorRecipe {
        PriorRecipe { tau: self.tau, alpha: self.alpha, l1_rel: self.l1.unwrap_or(default_l1(static_background)), tv_prox: self.tv_prox }
    }
}

/// The prior of one solve ([`SolveParams::prior`]): the one place the L1 weight and a
/// declared scene's TV weight are decided, for captures, the MPI split, sequences, the
/// held-out search's candidates and the static + dynamic model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PriorRecipe {
    /// TV weight tau (absolute) of the video.
    pub tau: f32,
    /// Weight of the temporal gradient relative to the spatial ones.
    pub alpha: f32,
    /// Weight of the L1 term relative to tau (0: none).
    pub l1_rel: f32,
    /// TV proximal map of the gradient methods.
    pub tv_prox: TvProxChoice,
}

impl PriorRecipe {
    /// The same prior at TV weight `tau`.
    pub fn with_tau(self, tau: f32) -> PriorRecipe {
        PriorRecipe { tau, ..self }
    }

    /// The prior of the problem `spec` declares over a video of `frames` frames: a
    /// static scene's one frame stands for every frame of its window, so its TV counts
    /// once per frame it replaces ([`static_frame_tau`]) and the objective is the full
    /// problem's on static videos.
    pub fn for_scene(self, spec: &SceneSpec, frames: usize) -> PriorRecipe {
        let window = spec.frames.map(|[k0, k1]| k1.saturating_sub(k0)).unwrap_or(frames);
        if spec.static_scene {
            self.with_tau(static_frame_tau(self.tau, window))
        } else {
            self
        }
    }

    /// The TV weight of the static image of the static + dynamic model, one frame that
    /// stands for `frames` frames: [`static_frame_tau`], or [`keyed_static_tau`] when
    /// key frames are solved with the raw.
    pub fn static_tau(&self, frames: usize, keyframes: bool) -> f32 {
        if keyframes {
            keyed_static_tau(self.tau, frames)
        } else {
            static_frame_tau(self.tau, frames)
        }
    }

    /// The L1 weight beside a TV term of weight `tau` (0: none).
    pub fn l1(&self, tau: f32) -> f32 {
        self.l1_rel * tau
    }

    /// TV of a `(frames, rows, cols)` video at tau, axis weights `[alpha, 1, 1]`,
    /// non-negative.
    pub fn tv(&self, shape: (usize, usize, usize)) -> TotalVariation {
        TotalVariation::new(shape, self.tau, self.alpha)
    }

    /// The prior of the TV term `tv`: TV with this map (`auto` judged on `scale`, the
    /// problem's `max(A^T b)`) and L1 beside it at `l1_rel` times `tv`'s weight.
    pub fn of_tv(&self, tv: TotalVariation, scale: f64) -> PriorSpec {
        let l1 = self.l1(tv.tau);
        PriorSpec::Tv(TvPrior::new(tv, self.tv_prox, scale).with_l1(l1))
    }

    /// [`PriorRecipe::of_tv`] of [`PriorRecipe::tv`]: the plain video's prior.
    pub fn video(&self, shape: (usize, usize, usize), scale: f64) -> PriorSpec {
        self.of_tv(self.tv(shape), scale)
    }

    /// The key-frame video's prior: the plain video's TV (and L1) on the video's
    /// departure from `reference` (the key frames' interpolation), the video itself
    /// non-negative ([`crate::solve::prox::departure`]).
    pub fn departure(&self, shape: (usize, usize, usize), scale: f64, reference: std::sync::Arc<[f32]>) -> PriorSpec {
        let mut tv = self.tv(shape);
        tv.nonneg = false;
        match self.of_tv(tv, scale) {
            PriorSpec::Tv(part) => PriorSpec::Departure { part, reference },
            other => other,
        }
    }
}

/// The reweighted-L1 rounds of the static + dynamic model ([`reweight_plan`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ReweightPlan {
    /// Reweighted rounds after the first solve.
    pub rounds: usize,
    /// The iterations the first solve and the reweighted rounds share: each reweighted
    /// round runs the first round's length, at most what the rounds before it left of
    /// this budget (none runs when nothing is left). `None`: each runs the first
    /// round's length.
    pub budget_iters: Option<usize>,
    /// The shortest a reweighted round runs, whatever the first round's length (0: as
    /// long as the first).
    pub min_round_iters: usize,
}

/// The iteration budget of the default rounds, the first included ([`reweight_plan`]).
pub const REWEIGHT_BUDGET_ITERS: usize = 400;

/// The shortest reweighted round of the default plan ([`reweight_plan`]; chosen in
/// docs/dense-scenes.md, *The reweighted rounds*).
pub const MIN_ROUND_ITERS: usize = 100;

/// The reweighted-L1 rounds for `--l1-reweight` (`asked`). Asked for: that many rounds,
/// each as long as the first. Not asked for: rounds as long as the first, but at least
/// [`MIN_ROUND_ITERS`], until [`REWEIGHT_BUDGET_ITERS`] iterations are spent (the last
/// one shorter; at most [`MAX_L1_REWEIGHT`] rounds): a first round of 100 iterations
/// gets 3 more of 100, one of 172 gets 172 + 56, one of 44 gets 100 + 100 + 100 + 56,
/// one of 400 or more none.
/// Why this budget, and what it was measured on: docs/dense-scenes.md, *The reweighted
/// rounds*.
pub fn reweight_plan(asked: Option<usize>) -> ReweightPlan {
    match asked {
        Some(rounds) => ReweightPlan { rounds, budget_iters: None, min_round_iters: 0 },
        None => ReweightPlan { rounds: MAX_L1_REWEIGHT, budget_iters: Some(REWEIGHT_BUDGET_ITERS), min_round_iters: MIN_ROUND_ITERS },
    }
}

/// Most reweighted-L1 rounds accepted.
pub const MAX_L1_REWEIGHT: usize = 10;

/// The L1 weight (relative to tau) a scene model uses when none is given: none for the
/// plain video, [`DEFAULT_DYNAMIC_L1`] on the dynamic part of the static + dynamic model
/// (what moves over a still scene is sparse).
pub fn default_l1(static_background: bool) -> f32 {
    if static_background {
        DEFAULT_DYNAMIC_L1
    } else {
        0.0
    }
}

/// Default L1 weight (relative to tau) on the dynamic part of the static + dynamic
/// model (measured on the dense benchmark scene: docs/dense-scenes.md).
pub const DEFAULT_DYNAMIC_L1: f32 = 1.0;

#[derive(Debug, thiserror::Error)]
pub enum ReconstructError {
    #[error("{0}")]
    Timing(#[from] TimingError),
    #[error("{0}")]
    Unsupported(String),
    #[error(transparent)]
    Refused(#[from] crate::solve::refusal::Refusal),
    #[error("{what}: shape {got:?} does not match the video's (frames, rows, cols, channels) = {expected:?}")]
    TruthShape { what: String, got: Vec<usize>, expected: Vec<usize> },
    #[error("the capture's downsampled grid {cfg:?} does not match the prepared data {data:?}")]
    Grid { cfg: (usize, usize), data: (usize, usize) },
    #[error("{0}")]
    Scene(#[from] SceneError),
    #[error("the problem was built for the {problem:?} field of view, the parameters ask for {params:?}")]
    Fov { problem: Fov, params: Fov },
}

/// A solve setting outside its range: `field` is the setting's name (the command line
/// shows it as `--field-name`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field} = {value}: expected {expected}")]
pub struct InvalidSetting {
    pub field: &'static str,
    pub value: String,
    pub expected: &'static str,
}

/// The solve a user asks for, before any capture is seen. Serialised as a bench
/// session's `solver` settings; session files written before the weight and the solver
/// were one setting each (`tau`/`tau_rel`/`tau_auto`, `restart`/`solver`) still read
/// ([`SettingsFile`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(from = "SettingsFile")]
pub struct SolveSettings {
    /// The TV weight as given (the noise rule by default).
    pub tau: Tau,
    pub alpha: f32,
    pub iters: usize,
    /// Stop when the relative change of the iterate falls below this (0: off).
    pub rel_tol: f64,
    /// Stop after this many solver seconds.
    pub time_budget_s: Option<f64>,
    /// Stop when the objective's relative change stays below this (0: off).
    pub obj_tol: f64,
    /// The solver (FISTA with adaptive restart by default).
    pub solver: SolverKind,
    /// The TV proximal map of the gradient methods.
    pub tv_prox: TvProxChoice,
    /// L1 weight relative to tau; `None`: the scene model's default.
    pub l1: Option<f32>,
    /// Reweighted-L1 rounds (static + dynamic model); `None`: the default.
    pub l1_reweight: Option<usize>,
    /// Where the video solve starts.
    pub start: Start,
    /// Where the solver runs (a CUDA device for admm-split).
    pub device: Device,
}

/// A session file's `solver` settings as written now or before: the weight was three
/// keys (`tau` a number or null, `tau_rel`, `tau_auto`) and the solver two (`restart`,
/// `solver` or null); the keys written later are optional so older files still read.
#[derive(Deserialize)]
struct SettingsFile {
    #[serde(default)]
    tau: Option<TauFile>,
    #[serde(default)]
    tau_rel: Option<f32>,
    #[serde(default)]
    tau_auto: bool,
    alpha: f32,
    iters: usize,
    rel_tol: f64,
    time_budget_s: Option<f64>,
    /// Files without it ran to their iterations.
    #[serde(default)]
    obj_tol: f64,
    #[serde(default)]
    restart: Option<bool>,
    #[serde(default)]
    solver: Option<SolverKind>,
    #[serde(default)]
    tv_prox: TvProxChoice,
    #[serde(default)]
    l1: Option<f32>,
    #[serde(default)]
    l1_reweight: Option<usize>,
    #[serde(default)]
    start: Start,
    #[serde(default)]
    device: Device,
}

/// `tau` in a session file: [`Tau`] as written now, or an absolute number as before.
#[derive(Deserialize)]
#[serde(untagged)]
enum TauFile {
    Absolute(f32),
    Given(Tau),
}

impl From<SettingsFile> for SolveSettings {
    fn from(f: SettingsFile) -> SolveSettings {
        let tau = match f.tau {
            Some(TauFile::Given(t)) => t,
            Some(TauFile::Absolute(t)) => Tau::Absolute(t),
            None if f.tau_auto => Tau::Auto(f.tau_rel),
            None => f.tau_rel.map_or(Tau::Noise, Tau::Relative),
        };
        let solver = f.solver.unwrap_or(if f.restart.unwrap_or(true) { SolverKind::FistaRestart } else { SolverKind::Fista });
        SolveSettings {
            tau,
            alpha: f.alpha,
            iters: f.iters,
            rel_tol: f.rel_tol,
            time_budget_s: f.time_budget_s,
            obj_tol: f.obj_tol,
            solver,
            tv_prox: f.tv_prox,
            l1: f.l1,
            l1_reweight: f.l1_reweight,
            start: f.start,
            device: f.device,
        }
    }
}

impl Default for SolveSettings {
    fn default() -> Self {
        SolveSettings {
            tau: Tau::Noise,
            alpha: DEFAULT_ALPHA,
            iters: DEFAULT_ITERS,
            rel_tol: 0.0,
            time_budget_s: None,
            obj_tol: DEFAULT_OBJ_TOL,
            solver: SolverKind::FistaRestart,
            tv_prox: TvProxChoice::Auto,
            l1: None,
            l1_reweight: None,
            start: Start::Auto,
            device: Device::Cpu,
        }
    }
}

impl SolveSettings {
    /// The settings checked, the one check of them; the first setting out of range is
    /// named.
    pub fn validate(&self) -> Result<ValidSettings, InvalidSetting> {
        self.check()?;
        Ok(ValidSettings(self.clone()))
    }

    fn check(&self) -> Result<(), InvalidSetting> {
        let bad = |field, value: String, expected| Err(InvalidSetting { field, value, expected });
        match self.tau {
            Tau::Absolute(t) if !(t.is_finite() && t >= 0.0) => return bad("tau", t.to_string(), "a non-negative number"),
            Tau::Relative(r) | Tau::Auto(Some(r)) if !(r.is_finite() && r >= 0.0) => return bad("tau_rel", r.to_string(), "a non-negative number"),
            Tau::Auto(Some(r)) if r <= 0.0 => return bad("tau_rel", r.to_string(), "a positive start for the held-out search"),
            _ => {}
        }
        if !(self.alpha.is_finite() && self.alpha >= 0.0) {
            return bad("alpha", self.alpha.to_string(), "a non-negative number");
        }
        if let Some(l) = self.l1 {
            if !(l.is_finite() && l >= 0.0) {
                return bad("l1", l.to_string(), "a non-negative number (relative to tau)");
            }
            if l > 0.0 && self.solver.shrinks_tv_itself() {
                return bad("l1", l.to_string(), "0 with the admm and admm-split solvers (their splitting has no L1 term); use a gradient solver");
            }
        }
        if !self.solver.runs_on(self.device) {
            return bad("device", self.device.to_string(), "cpu unless the solver is fista, fista-restart or admm-split (the others run on the CPU only)");
        }
        if self.device == Device::Cuda && !self.solver.shrinks_tv_itself() {
            if !matches!(self.tv_prox, TvProxChoice::Auto | TvProxChoice::Fixed(TvProx::Haar)) {
                return bad("tv_prox", self.tv_prox.to_string(), "haar or auto with --device cuda (the device's FISTA step has the Haar map only)");
            }
            if self.l1.is_some_and(|l| l > 0.0) {
                return bad("l1", self.l1.unwrap_or(0.0).to_string(), "0 with --device cuda (the device's FISTA step has no L1 term)");
            }
        }
        if let Some(r) = self.l1_reweight {
            if r > MAX_L1_REWEIGHT {
                return bad("l1_reweight", r.to_string(), "at most 10 rounds");
            }
        }
        self.stop().check().or_else(|(field, value, expected)| bad(field, value, expected))
    }

    /// The TV map the solve asks for: as given, except that `auto` is the Haar map on a
    /// CUDA device (the map its FISTA step has).
    pub fn tv_map_choice(&self) -> TvProxChoice {
        match (self.device, self.tv_prox) {
            (Device::Cuda, TvProxChoice::Auto) => TvProxChoice::Fixed(TvProx::Haar),
            (_, choice) => choice,
        }
    }

    pub fn stop(&self) -> StopRule {
        StopRule {
            max_iters: self.iters,
            rel_tol: self.rel_tol,
            time_budget_s: self.time_budget_s,
            obj_tol: self.obj_tol,
            noise_floor: None,
            wait_for_iterate: true,
        }
    }
}

/// [`SolveSettings`] that passed [`SolveSettings::validate`]: the only settings a solve
/// takes. A bench session file is checked as it is read (old files still read).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "SolveSettings", into = "SolveSettings")]
pub struct ValidSettings(SolveSettings);

impl ValidSettings {
    /// The parameters of one solve: the one place a relative TV weight becomes absolute
    /// (against `scale`, the capture's or the sequence's `max(A^T b)`, asked only for
    /// a relative weight).
    pub fn resolve(&self, scale: &dyn TauScale, fov: Fov) -> SolveParams {
        let s = &self.0;
        let (tau, tau_choice) = s.tau.resolve(scale);
        SolveParams {
            tau,
            tau_choice,
            alpha: s.alpha,
            stop: s.stop(),
            fov,
            solver: s.solver,
            tv_prox: s.tv_map_choice(),
            l1: s.l1,
            l1_reweight: s.l1_reweight,
            start: s.start,
            device: s.device,
            _resolved: (),
        }
    }

    /// The same settings with the relative weight `tau_rel` instead (the held-out
    /// search's candidates and choice; non-negative, finite).
    pub fn with_tau_rel(&self, tau_rel: f32) -> ValidSettings {
        debug_assert!(tau_rel.is_finite() && tau_rel >= 0.0, "{tau_rel}");
        ValidSettings(SolveSettings { tau: Tau::Relative(tau_rel), ..self.0.clone() })
    }
}

impl std::ops::Deref for ValidSettings {
    type Target = SolveSettings;
    fn deref(&self) -> &SolveSettings {
        &self.0
    }
}

impl TryFrom<SolveSettings> for ValidSettings {
    type Error = InvalidSetting;
    fn try_from(s: SolveSettings) -> Result<Self, InvalidSetting> {
        s.validate()
    }
}

impl From<ValidSettings> for SolveSettings {
    fn from(v: ValidSettings) -> SolveSettings {
        v.0
    }
}

/// One prepared capture's problem: the shutter weights (computed once) and every
/// captured channel's undeclared [`ChannelProblem`] (its operator built once; a scene
/// declaration wraps the same operator, [`Problem::declare`]).
pub struct Problem<'a> {
    pub prepared: &'a Prepared,
    pub cfg: &'a CaptureConfig,
    pub fov: Fov,
    weights: ShutterWeights,
    channels: Vec<ChannelProblem>,
}

impl<'a> Problem<'a> {
    /// Build the operators of every channel of `prepared` (one adjoint each, for the
    /// scale).
    pub fn new(prepared: &'a Prepared, cfg: &'a CaptureConfig, fov: Fov) -> Result<Problem<'a>, ReconstructError> {
        Problem::build(prepared, cfg, fov, None)
    }

    /// [`Problem::new`] with each channel's `max(A^T b)` given (a split's, the largest
    /// of its ranks' blocks) instead of computed from a whole adjoint: no video-sized
    /// vector is made.
    pub fn with_peaks(prepared: &'a Prepared, cfg: &'a CaptureConfig, fov: Fov, peaks: &[f32]) -> Result<Problem<'a>, ReconstructError> {
        Problem::build(prepared, cfg, fov, Some(peaks))
    }

    fn build(prepared: &'a Prepared, cfg: &'a CaptureConfig, fov: Fov, peaks: Option<&[f32]>) -> Result<Problem<'a>, ReconstructError> {
        let weights = cfg.timing().weights()?;
        let mut channels = Vec::with_capacity(prepared.psf.len());
        for (ch, (psf, raw)) in prepared.psf.iter().zip(&prepared.raw).enumerate() {
            if (psf.rows, psf.cols) != cfg.grid() {
                return Err(ReconstructError::Grid { cfg: cfg.grid(), data: (psf.rows, psf.cols) });
            }
            let model = Arc::new(build_operator(psf, &weights, fov, &prepared.data_mask));
            let channel = ChannelProblem::undeclared(model, raw.data.clone(), prepared.data_mask.lower_bounds.clone(), psf.data.clone());
            match peaks.and_then(|p| p.get(ch)) {
                Some(&p) => {
                    let _ = channel.atb_max.set(p);
                }
                None => {
                    channel.atb_max();
                }
            }
            channels.push(channel);
        }
        Ok(Problem { prepared, cfg, fov, weights, channels })
    }

    /// The shutter weights every channel shares.
    pub fn weights(&self) -> &ShutterWeights {
        &self.weights
    }

    /// Channel `ch`'s undeclared problem.
    pub fn channel(&self, ch: usize) -> &ChannelProblem {
        &self.channels[ch]
    }

    /// Every channel's operator.
    pub fn models(&self) -> Vec<&RollingShutterModel> {
        self.channels.iter().map(ChannelProblem::model).collect()
    }

    pub fn channels(&self) -> usize {
        self.channels.len()
    }
}

/// One channel's problem, the one type every solve path takes: its operator `A`
/// (built once, restricted as a scene declaration says or not at all), the data `b`
/// with the clipped pixels' lower bounds, the PSF, the Lipschitz cache key,
/// `max(A^T b)` ([`DeclaredProblem`] holds it with its [`Declaration`]). The undeclared problem of
/// each channel lives in [`Problem`] (its TV weight is not chosen yet: the weight's
/// scale is `max(A^T b)` over these); [`Problem::declare`] gives the problem a solve
/// takes, sharing the operator unless the declaration changes the operator itself (a
/// frame window, a grey scene's mean PSF).
pub struct ChannelProblem {
    pub op: Restricted<Arc<RollingShutterModel>>,
    pub b: Vec<f32>,
    /// The capture's clipped pixels (lower bounds of the data term), when any.
    pub lower_bounds: Option<Vec<bool>>,
    /// PSF the operator convolves with (the channels' mean for a grey scene).
    pub psf: Vec<f32>,
    key: Fingerprint,
    atb_max: OnceLock<f32>,
}

/// A channel's problem as [`Problem::declare`] gave it: the problem a solve takes and
/// its [`Declaration`]; it reads as its [`ChannelProblem`].
pub struct DeclaredProblem {
    pub problem: ChannelProblem,
    pub declaration: Declaration,
}

impl DeclaredProblem {
    /// The TV term at the chosen weight.
    pub fn tv(&self) -> &TotalVariation {
        &self.declaration.tv
    }

    /// What the declaration kept and left out.
    pub fn plan(&self) -> &ScenePlan {
        &self.declaration.plan
    }

    /// The reduced unknowns of a truth given on the full (frames, rows, cols) grid.
    pub fn restrict_truth(&self, full: &[f32]) -> Vec<f32> {
        let plan = self.plan();
        let (k, m, n) = plan.full_shape;
        let (k0, k1) = plan.frames;
        let window = &full[k0 * m * n..k1 * m * n];
        debug_assert_eq!(full.len(), k * m * n);
        self.problem.op.restrict(window, false)
    }
}

impl std::ops::Deref for DeclaredProblem {
    type Target = ChannelProblem;
    fn deref(&self) -> &ChannelProblem {
        &self.problem
    }
}

/// What [`Problem::declare`] fixed of a channel's problem: the TV term at the chosen
/// weight, what the scene declaration kept and left out, and the undeclared operator
/// (all frames, the whole grid) that checks the declared solution.
pub struct Declaration {
    pub tv: TotalVariation,
    pub plan: ScenePlan,
    pub full: Arc<RollingShutterModel>,
}

impl ChannelProblem {
    /// The problem of `op` on `b`.
    pub fn new(op: Restricted<Arc<RollingShutterModel>>, b: Vec<f32>, lower_bounds: Option<Vec<bool>>, psf: Vec<f32>) -> ChannelProblem {
        let key = operator_key(&psf, &op.inner, Some(&op));
        ChannelProblem { op, b, lower_bounds, psf, key, atb_max: OnceLock::new() }
    }

    /// This problem with its declaration (the TV term, the plan, the undeclared
    /// operator).
    pub fn declared(self, declaration: Declaration) -> DeclaredProblem {
        DeclaredProblem { problem: self, declaration }
    }

    /// The problem of `model` itself (nothing restricted).
    pub fn undeclared(model: Arc<RollingShutterModel>, b: Vec<f32>, lower_bounds: Option<Vec<bool>>, psf: Vec<f32>) -> ChannelProblem {
        let (_, mv, nv) = model.video_shape();
        ChannelProblem::new(Restricted::new(model, 0..mv, 0..nv, false), b, lower_bounds, psf)
    }

    /// The same operator (shared, not rebuilt) restricted to the box `rows` x `cols`,
    /// one frame for every frame when `static_scene`. An identity restriction keeps
    /// this problem's key and scale.
    pub fn restricted(&self, rows: Range<usize>, cols: Range<usize>, static_scene: bool) -> ChannelProblem {
        let op = Restricted::new(Arc::clone(&self.op.inner), rows, cols, static_scene);
        let mut p = ChannelProblem::new(op, self.b.clone(), self.lower_bounds.clone(), self.psf.clone());
        if p.op.is_identity() && self.op.is_identity() {
            p.atb_max = self.atb_max.clone();
        }
        p
    }

    /// The unrestricted operator.
    pub fn model(&self) -> &RollingShutterModel {
        &self.op.inner
    }

    /// The Lipschitz cache key of the operator (the unrestricted model's own key when
    /// nothing is restricted).
    pub fn key(&self) -> Fingerprint {
        self.key
    }

    /// The largest finite entry of `A^T b` (one adjoint, the first time).
    pub fn atb_max(&self) -> f32 {
        *self.atb_max.get_or_init(|| adjoint_peak(&self.op, &self.b))
    }

    /// The data term: `b`, one-sided at the clipped pixels.
    pub fn data(&self) -> DataTerm<'_> {
        DataTerm::new(&self.b).with_lower_bounds(self.lower_bounds.as_deref())
    }

    /// The largest eigenvalue of `A^T A` from `store`, or measured, and whether it came
    /// from the store.
    pub fn eigen(&self, store: &dyn EigenStore) -> (Eigen, bool) {
        store.get_or_measure(self.key, &self.op)
    }

    /// The Lipschitz constant (with margin) from `store`, or measured, and whether it
    /// came from the store.
    pub fn lipschitz(&self, store: &dyn EigenStore) -> crate::solve::lipschitz::Lipschitz {
        let (e, cached) = self.eigen(store);
        crate::solve::lipschitz::Lipschitz { value: e.lambda_max * LIPSCHITZ_MARGIN, cached }
    }

    /// The Lipschitz constant measured again (and stored), for a solve that went
    /// non-finite on a stored one.
    pub fn remeasure_lipschitz(&self, store: &dyn EigenStore) -> f64 {
        store.measure(self.key, &self.op).lambda_max * LIPSCHITZ_MARGIN
    }

    /// The per-frame metric of the preconditioned gradient methods: each solved frame's
    /// sensitivity ([`RollingShutterModel::frame_sensitivity`] of the frames the
    /// operator holds; one frame of weight 1 for a static scene).
    pub fn frame_metric(&self) -> FrameMetric {
        let (k, m, n) = self.op.shape();
        let s = self.op.inner.frame_sensitivity(&self.psf);
        if self.op.static_scene || s.len() != k {
            return FrameMetric::identity(k, m * n);
        }
        FrameMetric::from_sensitivity(&s, m * n)
    }

    /// The Lipschitz constant (with margin) in `metric`, `lambda_max(P^{-1/2} A^T A
    /// P^{-1/2})`, from `store` (keyed by the operator and the metric's weights, never
    /// the plain constant) or measured, and whether it came from the store.
    pub fn lipschitz_in(&self, metric: &FrameMetric, store: &dyn EigenStore) -> crate::solve::lipschitz::Lipschitz {
        let key = self.key.bytes(b"frame-metric-v1").f32s(metric.weights());
        let (e, cached) = store.get_or_measure(key, &FrameScaled { op: &self.op, metric });
        crate::solve::lipschitz::Lipschitz { value: e.lambda_max * LIPSCHITZ_MARGIN, cached }
    }
}

/// The scale of the TV weight: `max(A^T b)` over the channels; the noise rule's
/// input: the median of the channels' raw noise, and the capture's frames.
impl TauScale for Problem<'_> {
    fn tau_scale(&self) -> f32 {
        self.channels.iter().fold(0.0f32, |m, c| m.max(c.atb_max()))
    }
    fn noise(&self) -> Option<Noise> {
        prepared_noise(self.prepared, self.weights.frames())
    }
}

/// The noise rule's input for a prepared capture whose video has `frames` frames: the
/// median over its channels of the raw's noise, each measured on the pixels the data
/// term keeps.
pub fn prepared_noise(prepared: &Prepared, frames: usize) -> Option<Noise> {
    let sigma = median_sigma(prepared.raw.iter().map(|raw| noise_sigma(&raw.data, raw.rows, raw.cols, &prepared.data_mask)))?;
    Some(Noise { sigma, frames, keyframes: prepared.keyframes.len(), static_dynamic: false })
}

pub use crate::model::op::adjoint_peak;

/// The imaging operator of one channel: its PSF on the `fov` grid under `weights`,
/// with the data term's mask (defects left out, clipped pixels one-sided).
pub fn build_operator(psf: &Plane, weights: &ShutterWeights, fov: Fov, mask: &DataMask) -> RollingShutterModel {
    RollingShutterModel::of_psf(&psf.data, psf.rows, psf.cols, fov, weights.clone()).with_data_mask(mask)
}

/// The Lipschitz cache key of an operator: its PSF, weights, shapes and mask.
pub fn fingerprint(psf: &[f32], model: &RollingShutterModel) -> Fingerprint {
    operator_key(psf, model, None)
}

/// The one layout of the operators' cache keys: `model`'s PSF, weights, shapes and
/// mask, and, when `restriction` leaves unknowns out (a support box, a static scene),
/// that restriction under a tag of its own, so that a restricted operator never takes
/// the full one's constant. An identity restriction is the model itself and has its key.
fn operator_key(psf: &[f32], model: &RollingShutterModel, restriction: Option<&Restricted<Arc<RollingShutterModel>>>) -> Fingerprint {
    let (k, mv, nv) = model.video_shape();
    let (m, n) = model.conv().sensor_shape();
    let restriction = restriction.filter(|r| !r.is_identity());
    let tag: &[u8] = if restriction.is_some() { b"rolling-shutter-restricted-v1" } else { b"rolling-shutter-v1" };
    let mut key = Fingerprint::default().bytes(tag).f32s(psf).f32s(model.weights().as_slice()).usize(k).usize(mv).usize(nv).usize(m).usize(n);
    if let Some(r) = restriction {
        let (ks, ms, ns) = r.shape();
        key = key.usize(r.rows.start).usize(r.cols.start).usize(ks).usize(ms).usize(ns).usize(r.static_scene as usize);
    }
    with_mask_key(key, model)
}

/// A key extended by the operator's mask (unchanged without one, so unmasked entries
/// of the cache stay valid).
pub fn with_mask_key(key: Fingerprint, model: &RollingShutterModel) -> Fingerprint {
    match model.mask() {
        None => key,
        Some(m) => key.bytes(b"mask").f32s(m),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::op::Operator;
    use crate::model::shutter::ShutterMode;

    #[test]
    fn settings_resolve_against_a_scale_only_for_a_relative_tau() {
        let s = SolveSettings { tau: Tau::Relative(0.1), ..SolveSettings::default() }.validate().unwrap();
        let p = s.resolve(&crate::solve::tau::Peak(1000.0, None), Fov::Full);
        assert_eq!((p.tau, p.alpha, p.fov, p.solver), (100.0, DEFAULT_ALPHA, Fov::Full, SolverKind::FistaRestart));
        assert_eq!(p.stop.max_iters, DEFAULT_ITERS);
        let s = SolveSettings { tau: Tau::Absolute(0.5), ..SolveSettings::default() }.validate().unwrap();
        assert_eq!(s.resolve(&crate::solve::tau::Peak(f32::NAN, None), Fov::Sensor).tau, 0.5);
    }

    #[test]
    fn settings_name_the_first_bad_field() {
        let ok = SolveSettings::default();
        assert_eq!(ok.validate(), Ok(ValidSettings::default()));
        let e = SolveSettings { tau: Tau::Relative(f32::NAN), ..ok.clone() }.validate().unwrap_err();
        assert_eq!(e.field, "tau_rel");
        let e = SolveSettings { rel_tol: f64::NAN, ..ok.clone() }.validate().unwrap_err();
        assert_eq!(e.field, "rel_tol");
        let e = SolveSettings { time_budget_s: Some(-1.0), ..ok.clone() }.validate().unwrap_err();
        assert_eq!(e.field, "time_budget_s");
        let e = SolveSettings { iters: 0, ..ok.clone() }.validate().unwrap_err();
        assert_eq!(e.to_string(), "iters = 0: expected at least one iteration");
    }

    #[test]
    fn old_session_settings_still_read() {
        let old = r#"{"tau":null,"tau_rel":0.002,"alpha":5.0,"iters":200,"rel_tol":0.0,"time_budget_s":null,"restart":true}"#;
        let s: SolveSettings = serde_json::from_str(old).unwrap();
        // Read as written; what the file leaves out takes the value that keeps its
        // behaviour (no convergence test: such sessions ran to their iterations).
        assert_eq!(s, SolveSettings { tau: Tau::Relative(0.002), iters: 200, obj_tol: 0.0, ..SolveSettings::default() });
        let checked: ValidSettings = serde_json::from_str(old).unwrap();
        assert_eq!(*checked, s);
        let bad = old.replace("\"alpha\":5.0", "\"alpha\":-1.0");
        assert!(serde_json::from_str::<ValidSettings>(&bad).unwrap_err().to_string().contains("alpha = -1: expected a non-negative number"));
        // The former two solver switches: `restart` false without a solver named is
        // plain FISTA; a solver named wins.
        let plain: SolveSettings = serde_json::from_str(&old.replace("\"restart\":true", "\"restart\":false")).unwrap();
        assert_eq!(plain.solver, SolverKind::Fista);
        let named: SolveSettings = serde_json::from_str(&old.replace("\"restart\":true", "\"restart\":false,\"solver\":\"pgd\"")).unwrap();
        assert_eq!(named.solver, SolverKind::Pgd);
        // The former weight keys: an absolute number, and the held-out search from a start.
        let absolute: SolveSettings = serde_json::from_str(&old.replace("\"tau\":null", "\"tau\":0.5")).unwrap();
        assert_eq!(absolute.tau, Tau::Absolute(0.5));
        let auto: SolveSettings = serde_json::from_str(&old.replace("\"restart\":true", "\"restart\":true,\"tau_auto\":true")).unwrap();
        assert_eq!(auto.tau, Tau::Auto(Some(0.002)));
        let none: SolveSettings = serde_json::from_str(&old.replace("\"tau_rel\":0.002,", "")).unwrap();
        assert_eq!(none.tau, Tau::Noise);
        // Written now and read back, every form of the weight.
        for tau in [Tau::Absolute(0.5), Tau::Relative(1e-3), Tau::Noise, Tau::Auto(None), Tau::Auto(Some(1e-3))] {
            let now = SolveSettings { tau, solver: SolverKind::Mfista, ..s.clone() };
            let text = serde_json::to_string(&now).unwrap();
            assert_eq!(serde_json::from_str::<SolveSettings>(&text).unwrap(), now, "{text}");
        }
    }

    #[test]
    fn the_scale_is_the_largest_adjoint_entry_over_channels() {
        let (m, n) = (6, 5);
        let cfg = CaptureConfig::new(m, n, 10.0, 30.0, ShutterMode::Rolling);
        let plane = |seed: u64| Plane { rows: m, cols: n, data: crate::model::op::pseudo_random(m * n, seed).iter().map(|v| v.abs()).collect() };
        let prepared = Prepared {
            raw: vec![plane(1), plane(2)],
            psf: vec![plane(3), plane(4)],
            raw_dark: 0.0,
            psf_dark: 0.0,
            dark_estimated: false,
            ..Prepared::default()
        };
        let p = Problem::new(&prepared, &cfg, Fov::Sensor).unwrap();
        for ch in 0..2 {
            let model = p.channel(ch).model();
            let mut atb = vec![0.0f32; model.input_len()];
            model.adjoint(&prepared.raw[ch].data, &mut atb);
            assert_eq!(p.channel(ch).atb_max(), atb.iter().cloned().fold(0.0, f32::max));
        }
        assert_eq!(p.tau_scale(), p.channel(0).atb_max().max(p.channel(1).atb_max()));
        let half = SolveSettings { tau: Tau::Relative(0.5), ..SolveSettings::default() }.validate().unwrap();
        assert_eq!(half.resolve(&p, Fov::Sensor).tau, 0.5 * p.tau_scale());
        assert_eq!(p.channel(0).model().weights().as_slice(), p.weights().as_slice());
    }

    #[test]
    fn the_noise_rule_reads_the_median_channel_noise_and_the_captures_frames() {
        let (m, n) = (24, 20);
        let cfg = CaptureConfig::new(m, n, 10.0, 30.0, ShutterMode::Rolling);
        // Channels of noise 1, 2 and 8 around 50: the median channel's noise is 2.
        let plane =
            |amp: f32, seed: u64| Plane { rows: m, cols: n, data: crate::model::op::pseudo_random(m * n, seed).iter().map(|v| 50.0 + amp * v).collect() };
        let prepared = Prepared { raw: vec![plane(1.0, 1), plane(2.0, 2), plane(8.0, 3)], psf: vec![plane(0.0, 4); 3], ..Prepared::default() };
        let p = Problem::new(&prepared, &cfg, Fov::Sensor).unwrap();
        let one = |ch: usize| noise_sigma(&prepared.raw[ch].data, m, n, &DataMask::default()).unwrap();
        let noise = p.noise().unwrap();
        assert_eq!((noise.sigma, noise.frames), (one(1), p.weights().frames()));
        assert!(one(0) < noise.sigma && noise.sigma < one(2));
        // The default settings resolve through it and say so.
        let params = ValidSettings::default().resolve(&p, Fov::Sensor);
        match params.tau_choice {
            TauChoice::Noise { sigma, frames, tau_rel, .. } => {
                assert_eq!((sigma, frames), (noise.sigma, noise.frames));
                assert!((params.tau - tau_rel * p.tau_scale()).abs() <= 1e-6 * params.tau);
            }
            other => panic!("{other:?}"),
        }
    }
}

/// Video-sized volumes one channel's solve holds at its peak: the iterate, the
/// extrapolated point, the previous iterate and the gradient (FISTA), plus one for the
/// TV prox's work and the written video. Measured: peak resident memory over one
/// volume is 4.3 at 256 x 320 x 130 (sensor grid) and 4.0 at 511 x 639 x 130 (full
/// grid), `reconstruct --iters 5`.
pub const VOLUMES_PER_CHANNEL: u64 = 5;

/// What a reconstruction will hold in memory, estimated from the capture description
/// alone, before anything of that size is built (so that a typo such as an exposure in
/// nanoseconds is refused with the figure instead of exhausting the machine).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MemoryEstimate {
    /// The whole estimate, bytes.
    pub bytes: u64,
    /// (frames, rows, cols) of the video grid.
    pub video_shape: (usize, usize, usize),
    pub channels: usize,
    /// Bytes of one video volume (f32).
    pub volume_bytes: u64,
    /// Bytes of the shutter-weight table while it is built.
    pub weights_bytes: u64,
    /// The raw, PSF and FFT buffers of every channel, bytes.
    pub model_bytes: u64,
}

impl MemoryEstimate {
    /// A line for messages: "130 frames of 256 x 320 x 1: 5 volumes of 42.6 MB ...".
    pub fn describe(&self) -> String {
        let (k, m, n) = self.video_shape;
        format!(
            "{k} frames of {m} x {n} x {}: {VOLUMES_PER_CHANNEL} video volumes of {:.1} MB per channel, {:.1} MB of shutter weights, {:.1} MB of model buffers",
            self.channels,
            self.volume_bytes as f64 / 1e6,
            self.weights_bytes as f64 / 1e6,
            self.model_bytes as f64 / 1e6
        )
    }
}

/// The memory a reconstruction of `cfg` on `fov` with `channels` channels needs (see
/// [`MemoryEstimate`]). Saturating: absurd descriptions give huge figures, never wrap.
pub fn memory_estimate(cfg: &CaptureConfig, fov: Fov, channels: usize) -> MemoryEstimate {
    let (m, n) = cfg.grid();
    let (mv, nv) = match fov {
        Fov::Sensor => (m, n),
        Fov::Full => ((2 * m).saturating_sub(1), (2 * n).saturating_sub(1)),
    };
    let frames_f = cfg.timing().frames_estimate().ceil().max(1.0);
    let frames = if frames_f >= usize::MAX as f64 { usize::MAX } else { frames_f as usize + 1 };
    let mul = |xs: &[usize]| xs.iter().fold(1u64, |a, &x| a.saturating_mul(x as u64));
    let volume_bytes = mul(&[frames, mv, nv, 4]);
    // f64 accumulation plus the f32 table, rows x frames.
    let weights_bytes = mul(&[m, frames, 12]);
    // Raw and PSF, a sensor-sized padded spectrum pair per channel (complex f32, 2x2 padding).
    let model_bytes = mul(&[channels, m, n, 4 * 2]).saturating_add(mul(&[channels, 2 * m, 2 * n, 8 * 2]));
    let bytes = volume_bytes.saturating_mul(VOLUMES_PER_CHANNEL).saturating_mul(channels as u64).saturating_add(weights_bytes).saturating_add(model_bytes);
    MemoryEstimate { bytes, video_shape: (frames, mv, nv), channels, volume_bytes, weights_bytes, model_bytes }
}
