//! The TV weight tau: how a user gives it, what a relative weight is relative to, and
//! the static-frame rule.
//!
//! A user gives tau as [`Tau`] (absolute, or relative to the capture's scale) inside
//! [`SolveSettings`](crate::solve::problem::SolveSettings); the default relative weight
//! is [`DEFAULT_TAU_REL`]. The scale is a [`TauScale`]: the largest entry of `A^T b` of
//! one capture's [`Problem`](crate::solve::problem::Problem), of a
//! [`Sequence`](crate::solve::sequence::Sequence), or a [`Peak`] measured otherwise
//! (reduced over MPI ranks with [`Peak::across_ranks`]). The one place a weight becomes
//! absolute is [`ValidSettings::resolve`](crate::solve::problem::ValidSettings::resolve);
//! a frame that stands for several frames of the video weighs [`static_frame_tau`].

use crate::model::op::{adjoint_peak, Operator};
use crate::model::ranks::Ranks;
use serde::{Deserialize, Serialize};

/// Default TV weight relative to `max(A^T b)`.
pub const DEFAULT_TAU_REL: f32 = 2.5e-4;

/// The TV weight as a user gives it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Tau {
    /// In the data's units (counts per frame interval).
    Absolute(f32),
    /// A fraction of the capture's `max(A^T b)`, the weight at which TV flattens
    /// everything: it follows the data's physical scale without rescaling the data.
    Relative(f32),
}

impl Tau {
    /// An absolute weight when one is given, else the relative one: the one place this
    /// precedence is decided.
    pub fn from_given(tau: Option<f32>, tau_rel: f32) -> Tau {
        match tau {
            Some(t) => Tau::Absolute(t),
            None => Tau::Relative(tau_rel),
        }
    }

    /// The absolute weight against `scale` (asked only for a relative weight).
    pub(crate) fn absolute(self, scale: &dyn TauScale) -> f32 {
        match self {
            Tau::Absolute(t) => t,
            Tau::Relative(r) => r * scale.tau_scale(),
        }
    }
}

/// What a relative TV weight is relative to: the largest finite entry of `A^T b`.
pub trait TauScale {
    fn tau_scale(&self) -> f32;
}

/// A scale measured only if a relative weight asks for it: a closure giving
/// `max(A^T b)` (an absolute weight then costs no adjoint).
impl<F: Fn() -> f32> TauScale for F {
    fn tau_scale(&self) -> f32 {
        self()
    }
}

/// A scale already measured: `max(A^T b)` of an operator and its data, or that peak
/// reduced over the ranks that each hold a part of one problem.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Peak(pub f32);

impl Peak {
    /// `max(A^T b)` of `op` and `b`.
    pub fn of<A: Operator + ?Sized>(op: &A, b: &[f32]) -> Peak {
        Peak(adjoint_peak(op, b))
    }

    /// The largest of every rank's `local` peak (a collective: every rank calls it).
    pub fn across_ranks(local: f32, ranks: &dyn Ranks) -> Peak {
        let mut peak = [local as f64];
        ranks.max_f64(&mut peak);
        Peak(peak[0] as f32)
    }
}

impl TauScale for Peak {
    fn tau_scale(&self) -> f32 {
        self.0
    }
}

/// The TV weight of one frame that stands for `frames` frames of the video (a static
/// scene, the still image, the static part of the static + dynamic model): its TV
/// counts once per frame it replaces, so the objective is the video's on still scenes.
pub fn static_frame_tau(tau: f32, frames: usize) -> f32 {
    tau * frames as f32
}

/// `--tau-rel` (the command line's and Python's `tau_rel`): a number, or `auto` (held-out
/// pixels choose it, starting from [`DEFAULT_TAU_REL`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TauRel {
    Value(f32),
    Auto,
}

impl TauRel {
    /// The number given, or where the `auto` search starts.
    pub fn value(self) -> f32 {
        match self {
            TauRel::Value(v) => v,
            TauRel::Auto => DEFAULT_TAU_REL,
        }
    }

    pub fn is_auto(self) -> bool {
        self == TauRel::Auto
    }
}

impl Default for TauRel {
    fn default() -> Self {
        TauRel::Value(DEFAULT_TAU_REL)
    }
}

impl std::fmt::Display for TauRel {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        match self {
            TauRel::Value(v) => write!(f, "{v}"),
            TauRel::Auto => f.write_str("auto"),
        }
    }
}

/// Reads a setting given as text into the solver's f32: a number whose magnitude is over
/// f32's range (`1e308`) is refused by its own text, not turned into `inf` and refused
/// later as "inf". NaN and infinities pass through, for the setting's own check to name.
pub fn parse_f32(text: &str) -> Result<f32, String> {
    let wide: f64 = text.trim().parse().map_err(|_| format!("{text}: expected a number"))?;
    if wide.is_finite() && wide.abs() > f64::from(f32::MAX) {
        return Err(format!("{text}: expected a number within +-{:e} (a 32-bit float)", f32::MAX));
    }
    Ok(wide as f32)
}

impl std::str::FromStr for TauRel {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s.trim() == "auto" {
            return Ok(TauRel::Auto);
        }
        match s.trim().parse::<f64>() {
            Ok(_) => parse_f32(s).map(TauRel::Value),
            Err(_) => Err(format!("{s}: expected a number (e.g. {DEFAULT_TAU_REL:e}) or auto")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_setting_over_f32s_range_is_refused_by_its_text() {
        assert_eq!(parse_f32(" 2.5e-4 "), Ok(2.5e-4));
        let e = parse_f32("1e308").unwrap_err();
        assert!(e.starts_with("1e308: expected a number within"), "{e}");
        assert!(parse_f32("x").unwrap_err().contains("expected a number"));
        assert!(parse_f32("nan").unwrap().is_nan());
    }

    #[test]
    fn an_absolute_tau_wins_and_a_relative_one_scales() {
        assert_eq!(Tau::from_given(Some(0.5), 0.1), Tau::Absolute(0.5));
        assert_eq!(Tau::from_given(None, 0.1), Tau::Relative(0.1));
        assert_eq!(Tau::Absolute(0.5).absolute(&Peak(1000.0)), 0.5);
        assert_eq!(Tau::Relative(0.1).absolute(&Peak(1000.0)), 100.0);
    }

    #[test]
    fn tau_rel_reads_a_number_or_auto() {
        assert_eq!("auto".parse::<TauRel>(), Ok(TauRel::Auto));
        assert_eq!(" 1e-3 ".parse::<TauRel>(), Ok(TauRel::Value(1e-3)));
        assert_eq!(TauRel::Auto.value(), DEFAULT_TAU_REL);
        assert_eq!(TauRel::default(), TauRel::Value(DEFAULT_TAU_REL));
        assert_eq!("x".parse::<TauRel>().unwrap_err(), "x: expected a number (e.g. 2.5e-4) or auto");
        assert_eq!(TauRel::Auto.to_string(), "auto");
    }

    #[test]
    fn a_static_frame_counts_once_per_frame_it_replaces() {
        assert_eq!(static_frame_tau(0.5, 8), 4.0);
    }
}
