//! One interface over the solvers of `min D(A v) + R(v)`, `D` the data term
//! ([`DataTerm`]: `0.5||A v - b||^2`, one-sided at clipped pixels, over the ranks of a
//! split problem) and `R` the prior ([`Prox`], built from a
//! [`crate::solve::prox::prior::PriorSpec`]): FISTA, FISTA with adaptive restart, monotone
//! FISTA, ADMM (variable splitting, CG inner solves), ADMM with every update in closed
//! form (admm-split) and plain proximal gradient. All take the same
//! operator, data term, prior, stopping rule ([`StopRule`]) and observer (the trace is
//! one), and return the same [`SolveResult`]; all run in the same executor loop, whose
//! clock excludes observer time, so their traces compare run time fairly. A solver
//! minimises the objective as given or refuses what it cannot handle
//! ([`SolverKind::check_data`], [`SolverKind::check_prior`]).
//!
//! A new solver is a step in its own file (see [`crate::solve::optimize`]), a
//! [`SolverKind`] with its limits in the two checks, and its arm in [`solve`].

use crate::model::data::DataTerm;
use crate::model::op::Operator;
use crate::solve::metric::FrameMetric;
use crate::solve::optimize::admm::{Admm, AdmmParams};
use crate::solve::optimize::admm_split::{AdmmSplit, SplitParams};
use crate::solve::optimize::device::Device;
use crate::solve::optimize::fista::Fista;
use crate::solve::optimize::mfista::MFista;
use crate::solve::optimize::pgd::Pgd;
use crate::solve::optimize::types::{Observer, SolveResult, StopRule};
use crate::solve::prox::prior::PriorSpec;
use crate::solve::prox::Prox;
use serde::Serialize;

/// The solvers behind [`solve`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SolverKind {
    Fista,
    /// FISTA with adaptive restart: the default.
    #[default]
    FistaRestart,
    Admm,
    Pgd,
    /// Monotone FISTA: objective non-increasing by construction.
    Mfista,
    /// ADMM with every update in closed form (the convolution split off on the padded
    /// grid, a Sherman-Morrison update per sensor pixel).
    AdmmSplit,
}

impl SolverKind {
    pub const ALL: [SolverKind; 6] =
        [SolverKind::Fista, SolverKind::FistaRestart, SolverKind::Admm, SolverKind::Pgd, SolverKind::Mfista, SolverKind::AdmmSplit];
    pub fn name(self) -> &'static str {
        match self {
            SolverKind::Fista => "fista",
            SolverKind::FistaRestart => "fista-restart",
            SolverKind::Admm => "admm",
            SolverKind::Pgd => "pgd",
            SolverKind::Mfista => "mfista",
            SolverKind::AdmmSplit => "admm-split",
        }
    }

    /// Whether the solver shrinks the TV term itself (the ADMMs: no TV map, no L1, no
    /// static + dynamic model).
    pub fn shrinks_tv_itself(self) -> bool {
        matches!(self, SolverKind::Admm | SolverKind::AdmmSplit)
    }
}

impl SolverKind {
    /// Whether this solver minimises `data` as given; the error names the term it
    /// cannot handle. The one place each solver's limits on the data term are decided.
    pub fn check_data(self, data: &DataTerm) -> Result<(), String> {
        let clipped = data.lower_bounds().map_or(0, |l| l.iter().filter(|&&b| b).count());
        match self {
            SolverKind::Admm if clipped > 0 => Err(format!(
                "admm: lower bounds from clipped pixels ({clipped} pixels) are not supported (its data update treats every pixel as an equality); use fista, fista-restart, mfista or pgd"
            )),
            SolverKind::Admm if data.ranks().size() > 1 => Err("admm: a problem split across ranks is not supported; use fista, fista-restart, mfista or pgd".into()),
            SolverKind::AdmmSplit if data.ranks().size() > 1 => {
                Err("admm-split: a problem split across ranks is not supported (its v-update transforms whole frames); use fista, fista-restart, mfista or pgd".into())
            }
            _ => Ok(()),
        }
    }

    /// Whether this solver takes `op`; the error names what it cannot. Only admm-split
    /// asks: it needs the operator as one shutter-weighted convolution on its whole
    /// video grid ([`Operator::shutter_convolution`]).
    pub fn check_operator(self, op: &(impl Operator + ?Sized)) -> Result<(), String> {
        match self {
            SolverKind::AdmmSplit if op.shutter_convolution().is_none() => Err(
                "admm-split: the operator is not one capture's shutter-weighted convolution on its whole video grid (a scene's support or static scene, consecutive captures and the static + dynamic model are not split in closed form); use fista, fista-restart, mfista, pgd or admm".into(),
            ),
            _ => Ok(()),
        }
    }

    /// Whether this solver handles `prior`; the error names what it cannot. The one
    /// place each solver's limits on the prior are decided.
    pub fn check_prior(self, prior: &(impl Prox + ?Sized)) -> Result<(), String> {
        match self {
            SolverKind::Admm if prior.total_variation().is_none() => Err(
                "admm: only the TV prior (with non-negativity) is supported, not an L1 term or the static + dynamic model (its splitting shrinks TV itself); use fista, fista-restart, mfista or pgd".into(),
            ),
            SolverKind::AdmmSplit if prior.total_variation().is_none() => Err(
                "admm-split: only the TV prior (with non-negativity) is supported, not an L1 term or the static + dynamic model (its splitting shrinks TV itself); use fista, fista-restart, mfista or pgd".into(),
            ),
            _ => Ok(()),
        }
    }

    /// Whether this solver runs on `device`, and the device here; the error names what
    /// is missing. The one place each solver's devices are decided: every solver runs on
    /// the CPU; fista, fista-restart and admm-split also on a CUDA device.
    pub fn check_device(self, device: Device) -> Result<(), String> {
        if !self.runs_on(device) {
            return Err(format!("{self} runs on the CPU only; --device {device} is for fista, fista-restart and admm-split"));
        }
        device.check()
    }

    /// Whether this solver has a step for `device` ([`Self::check_device`] also asks
    /// whether the device is here).
    pub fn runs_on(self, device: Device) -> bool {
        device == Device::Cpu || matches!(self, SolverKind::Fista | SolverKind::FistaRestart | SolverKind::AdmmSplit)
    }

    /// Whether this solver's step on `device` takes this problem; the error names what
    /// it cannot. The one place the CUDA steps' limits are decided: FISTA on the device
    /// needs one capture's shutter-weighted convolution on its whole video grid, the TV
    /// prior alone through the Haar map, plain steps and one process (admm-split's
    /// limits are its own, the same on both devices: [`Self::check_operator`],
    /// [`Self::check_prior`], [`Self::check_data`]).
    pub fn check_on_device(
        self,
        device: Device,
        op: &(impl Operator + ?Sized),
        data: &DataTerm,
        prior: &(impl Prox + ?Sized),
        preconditioned: bool,
    ) -> Result<(), String> {
        if device == Device::Cpu || self == SolverKind::AdmmSplit {
            return Ok(());
        }
        let on = format!("{self} on --device {device}");
        if op.shutter_convolution().is_none() {
            return Err(format!(
                "{on}: the operator is not one capture's shutter-weighted convolution on its whole video grid (a scene's support or static scene, consecutive captures and the static + dynamic model run on the CPU)"
            ));
        }
        if prior.haar_tv().is_none() {
            return Err(format!("{on}: only the TV prior through the Haar map runs on the device (--tv-prox haar; not the exact dual map, an L1 term or the static + dynamic model)"));
        }
        if preconditioned {
            return Err(format!("{on}: the per-frame preconditioner runs on the CPU"));
        }
        if data.ranks().size() > 1 {
            return Err(format!("{on}: a problem split across ranks runs on the CPU"));
        }
        Ok(())
    }

    /// Whether `copies` device steps of this solver for `op` (channels solved at once)
    /// fit the device's free memory: asked by the commands before any solve, so that a
    /// capture too large is refused with both figures instead of failing at an
    /// allocation. Nothing to ask on the CPU.
    #[cfg_attr(not(feature = "cuda"), allow(unused_variables))]
    pub fn check_device_memory(self, device: Device, op: &(impl Operator + ?Sized), copies: usize) -> Result<(), String> {
        #[cfg(feature = "cuda")]
        if device == Device::Cuda {
            if let Some(sc) = op.shutter_convolution() {
                return crate::solve::optimize::cuda::check_memory(self == SolverKind::AdmmSplit, &sc, copies);
            }
        }
        Ok(())
    }

    /// Whether this solver can step in a per-frame metric at all: FISTA, with or
    /// without restart (what else it needs of the prior: [`Self::check_precondition`]).
    pub fn steps_in_frame_metric(self) -> bool {
        matches!(self, SolverKind::Fista | SolverKind::FistaRestart)
    }

    /// Whether this solver steps in a per-frame metric ([`crate::solve::metric`]) with
    /// `prior`; the error names what it cannot. The one place the preconditioner's
    /// limits are decided: FISTA (with or without restart) and a prior with a map in the
    /// metric (TV with non-negativity, by either map).
    pub fn check_precondition(self, prior: &(impl Prox + ?Sized)) -> Result<(), String> {
        if !self.steps_in_frame_metric() {
            return Err(format!("{self}: the per-frame preconditioner is for fista and fista-restart"));
        }
        if prior.metric_prox().is_none() {
            return Err(format!(
                "{self}: the per-frame preconditioner needs the TV prior alone (its proximal map in the frame metric), not an L1 term, the static + dynamic model or a problem split across ranks"
            ));
        }
        Ok(())
    }

    /// The TV map as reports name it: the prior's for the gradient methods, ADMM's own
    /// exact shrinkage (it ignores the map).
    pub fn tv_map_label(self, prior: &PriorSpec) -> String {
        if self.shrinks_tv_itself() {
            format!("exact shrinkage ({self})")
        } else {
            prior.tv_map_name()
        }
    }
}

impl std::fmt::Display for SolverKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for SolverKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        SolverKind::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| format!("unknown solver '{s}': expected one of fista, fista-restart, admm, pgd, mfista, admm-split"))
    }
}

/// Everything a solve needs besides the problem (operator, data term, prior).
#[derive(Clone, Debug, Serialize)]
pub struct OptimizerSettings {
    pub kind: SolverKind,
    /// Largest eigenvalue of `A^T A` (with margin): the step of the gradient methods and
    /// the scale of ADMM's penalties.
    pub lipschitz: f64,
    pub stop: StopRule,
    pub admm: AdmmParams,
    /// admm-split's penalties.
    pub split: SplitParams,
    /// Where the solver runs ([`SolverKind::check_device`]).
    pub device: Device,
    /// The per-frame metric the gradient steps are taken in (`None`: plain steps); with
    /// one, `lipschitz` is the metric's ([`crate::solve::metric::FrameScaled`]).
    pub metric: Option<FrameMetric>,
    /// How fista-restart judges a restart ([`crate::solve::optimize::fista::RestartTest`];
    /// the objective unless a solve says otherwise).
    pub restart_test: crate::solve::optimize::fista::RestartTest,
}

impl OptimizerSettings {
    pub fn new(kind: SolverKind, lipschitz: f64, stop: StopRule) -> Self {
        OptimizerSettings {
            kind,
            lipschitz,
            stop,
            admm: AdmmParams::default(),
            split: SplitParams::default(),
            device: Device::Cpu,
            metric: None,
            restart_test: Default::default(),
        }
    }
}

/// Solve `min D(A v) + R(v)` (`data`, `prior`) with the chosen solver from `x0` (zeros
/// when `None`).
///
/// # Panics
/// When the solver refuses the data term or the prior ([`SolverKind::check_data`],
/// [`SolverKind::check_prior`]), a metric it cannot step in
/// ([`SolverKind::check_precondition`]) or its device ([`SolverKind::check_device`]): callers check first and report the error.
pub fn solve<A: Operator + ?Sized, R: Prox + ?Sized>(
    s: &OptimizerSettings,
    op: &A,
    data: &DataTerm,
    prior: &R,
    x0: Option<Vec<f32>>,
    observer: &mut dyn Observer,
) -> SolveResult {
    if let Err(e) = s.kind.check_data(data).and_then(|()| s.kind.check_prior(prior)).and_then(|()| s.kind.check_operator(op)) {
        panic!("{e}");
    }
    if let Err(e) = s
        .metric
        .as_ref()
        .map_or(Ok(()), |_| s.kind.check_precondition(prior))
        .and_then(|()| s.kind.check_device(s.device))
        .and_then(|()| s.kind.check_on_device(s.device, op, data, prior, s.metric.is_some()))
    {
        panic!("{e}");
    }
    let (lipschitz, stop) = (s.lipschitz, s.stop.clone());
    match s.kind {
        #[cfg(feature = "cuda")]
        SolverKind::Fista | SolverKind::FistaRestart if s.device == Device::Cuda => {
            let (sc, tv) = (op.shutter_convolution().expect("checked: one convolution"), prior.haar_tv().expect("checked: the Haar map"));
            let fista = Fista { lipschitz, stop, restart: (s.kind == SolverKind::FistaRestart).then_some(s.restart_test) };
            crate::solve::optimize::cuda::fista::solve(&fista, sc, data, tv, x0, observer)
        }
        SolverKind::Fista | SolverKind::FistaRestart => {
            let fista = Fista { lipschitz, stop, restart: (s.kind == SolverKind::FistaRestart).then_some(s.restart_test) };
            match &s.metric {
                None => fista.solve(op, data, prior, x0, observer),
                Some(m) => fista.solve_in(m, op, data, prior, x0, observer),
            }
        }
        SolverKind::Pgd => Pgd { lipschitz, stop }.solve(op, data, prior, x0, observer),
        SolverKind::Mfista => MFista { lipschitz, stop }.solve(op, data, prior, x0, observer),
        SolverKind::Admm => {
            let tv = prior.total_variation().expect("checked: ADMM's prior is TV");
            Admm { lipschitz, stop, params: s.admm.clone() }.solve(op, data, tv, x0, observer)
        }
        #[cfg(feature = "cuda")]
        SolverKind::AdmmSplit if s.device == Device::Cuda => {
            let (sc, tv) = (op.shutter_convolution().expect("checked: one convolution"), prior.total_variation().expect("checked: admm-split's prior is TV"));
            crate::solve::optimize::cuda::split::solve(&stop, &s.split, sc, data, tv, x0, observer)
        }
        SolverKind::AdmmSplit => {
            let tv = prior.total_variation().expect("checked: admm-split's prior is TV");
            AdmmSplit { stop, params: s.split.clone() }.solve(op, data, tv, x0, observer)
        }
    }
}
