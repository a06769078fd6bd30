//! The TV weight tau: how a user gives it, what a relative weight is relative to, the
//! default rule from the raw's noise, and the static-frame rule.
//!
//! A user gives tau as [`Tau`] (absolute, relative to the capture's scale, or by default
//! from the raw's noise) inside [`SolveSettings`](crate::solve::problem::SolveSettings).
//! The scale is a [`TauScale`]: the largest entry of `A^T b` of one capture's
//! [`Problem`](crate::solve::problem::Problem), of a
//! [`Sequence`](crate::solve::sequence::Sequence), or a [`Peak`] measured otherwise
//! (reduced over MPI ranks with [`Peak::across_ranks`]), with the raw's noise
//! ([`Noise`], [`crate::model::noise`]) where the default rule needs it. The one place a
//! weight becomes absolute is
//! [`ValidSettings::resolve`](crate::solve::problem::ValidSettings::resolve), through
//! [`Tau::resolve`], which also says how ([`TauChoice`]); a frame that stands for
//! several frames of the video weighs [`static_frame_tau`].
//!
//! **The noise rule** (the default): `tau = NOISE_TAU_PER_SIGMA * sigma_b / sqrt(K)`,
//! `sigma_b` the raw's noise per pixel in the data's units and `K` the video's frames,
//! its ratio to `max(A^T b)` kept within [`NOISE_TAU_REL_RANGE`], a video's at least
//! [`VIDEO_TAU_REL_FLOOR`]; where key frames or the static + dynamic model's static image
//! hold the still scene the weight is [`HELD_STILL_TAU_FACTOR`] of it. A weight that follows
//! the noise follows the photons: the same photograph at 340x fewer photons wants a
//! weight 64x larger relative to its scale, which no fixed relative weight gives. Fitted
//! on the scene suite (docs/scene-suite.md: the best weight over the noise was
//! 0.009-0.05 on stills and, times `sqrt(K)`, 0.006-0.07 on 62- to 122-frame videos),
//! checked there by leaving each scene out, on two scenes added after the fit, and on
//! the real DiffuserCam hand.

use crate::model::op::{adjoint_peak, Operator};
use crate::model::ranks::Ranks;
use serde::{Deserialize, Serialize};

/// The relative weight where the raw's noise cannot be measured (a raw of under 64
/// usable 3 x 3 windows), where the held-out search starts, and the benchmarks' weight.
pub const FALLBACK_TAU_REL: f32 = 2.5e-4;

/// The noise rule's constant: `tau = NOISE_TAU_PER_SIGMA * sigma_b / sqrt(frames)`.
pub const NOISE_TAU_PER_SIGMA: f32 = 0.02;

/// The noise rule's weight relative to `max(A^T b)` is kept within this range (the
/// scene suite's best weights span 3e-5 to 8e-3): a raw without measurable noise (a
/// noiseless simulation) or with nothing but noise still gets a usable weight.
pub const NOISE_TAU_REL_RANGE: (f32, f32) = (1e-5, 1e-2);

/// The smallest weight relative to `max(A^T b)` the noise rule gives a video (more than
/// one frame). A video's best weight follows its signal more than its noise: on the
/// scene suite the videos' best `tau_rel` lie within 6.25e-5..5e-4, where the noise
/// rule alone spread them over 3.9e-5..5.2e-4, too light on bright flashing LEDs (their
/// best 1.25e-4, the rule's 3.9e-5; docs/scene-suite.md). A still keeps the whole range:
/// there the noise sets the weight (64x apart between one photograph at two light
/// levels).
pub const VIDEO_TAU_REL_FLOOR: f32 = 1.25e-4;

/// The noise rule's weight is multiplied by this when something other than the weight
/// holds the still scene (before its range is applied): key frames solved with the raw,
/// or the static image of the static + dynamic model (its own block, under its own
/// weight). A lighter weight then keeps more of what moves.
///
/// The static + dynamic model without key frames, two reweighted rounds, on 240 x 320 x
/// 122 discs over texture through the measured PSF (docs/dense-scenes.md): motion
/// errors 0.733 / 0.758 at half the weight against 0.783 / 0.820 at the full weight, and
/// 0.919 against 0.908 on the third. With key frames, measured on
/// disc-over-texture and the occluder through the measured PSF with key frames at the
/// first and last frame (docs/keyframes.md): at 150 x 200 x 77 half the weight gives
/// motion errors 0.679 / 0.759 against 0.709 / 0.790, relative errors 0.091 / 0.089
/// against 0.099 / 0.097; at 240 x 320 x 122, 0.804 against 0.933 on the disc, and a
/// quarter of it lost the occluder's track (p90 55 px, against 8.7 at half).
pub const HELD_STILL_TAU_FACTOR: f32 = 0.5;

/// The range the noise rule's relative weight is kept in for a video of `frames`
/// frames: [`NOISE_TAU_REL_RANGE`], its low end raised to [`VIDEO_TAU_REL_FLOOR`] for a
/// video.
pub fn noise_tau_rel_range(frames: usize) -> (f32, f32) {
    let (lo, hi) = NOISE_TAU_REL_RANGE;
    (if frames > 1 { lo.max(VIDEO_TAU_REL_FLOOR) } else { lo }, hi)
}

/// The TV weight as a user gives it (the command line's `--tau`/`--tau-rel`, Python's
/// `tau`/`tau_rel`, a bench session's `solver.tau`): the one representation of it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Tau {
    /// In the data's units (counts per frame interval).
    Absolute(f32),
    /// A fraction of the capture's `max(A^T b)`, the weight at which TV flattens
    /// everything: it follows the data's physical scale without rescaling the data.
    Relative(f32),
    /// The noise rule (the default): from the raw's noise and the video's frames.
    #[default]
    Noise,
    /// Chosen by held-out pixels ([`crate::solve::tau_search`]), the search starting
    /// from the relative weight given, or from the noise rule's (`None`); where no search
    /// runs it is that start.
    Auto(Option<f32>),
}
/// What the noise rule reads from a capture.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Noise {
    /// The raw's noise per pixel (standard deviation, the data's units), measured from
    /// the raw ([`crate::model::noise::noise_sigma`]).
    pub sigma: f32,
    /// The video's frames.
    pub frames: usize,
    /// Key frames solved with the raw ([`HELD_STILL_TAU_FACTOR`]).
    pub keyframes: usize,
    /// The scene is solved with the static + dynamic model ([`HELD_STILL_TAU_FACTOR`]).
    pub static_dynamic: bool,
}

/// How a solve's tau was chosen (summary.json's `params.tau_choice`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(tag = "rule", rename_all = "kebab-case")]
pub enum TauChoice {
    /// Given in the data's units.
    Absolute,
    /// Given relative to `max(A^T b)`.
    Relative { tau_rel: f32 },
    /// The noise rule: `sigma` and `frames` measured, `tau_rel` the weight's ratio to
    /// `max(A^T b)`, `bounded` when the rule's own ratio lay outside its range
    /// ([`noise_tau_rel_range`]) and was brought to its nearer end.
    ///
    /// `keyframes`: the key frames solved with the raw, when any; `static_dynamic`: the
    /// static + dynamic model, when solved with it ([`HELD_STILL_TAU_FACTOR`]).
    Noise {
        sigma: f32,
        frames: usize,
        #[serde(skip_serializing_if = "is_zero")]
        keyframes: usize,
        #[serde(skip_serializing_if = "is_false")]
        static_dynamic: bool,
        tau_rel: f32,
        bounded: bool,
    },
    /// The noise rule could not measure the raw's noise: [`FALLBACK_TAU_REL`].
    NoNoise { tau_rel: f32 },
}

impl std::fmt::Display for TauChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        match *self {
            TauChoice::Absolute => f.write_str("given"),
            TauChoice::Relative { tau_rel } => write!(f, "tau_rel {tau_rel:e} given"),
            TauChoice::Noise { sigma, frames, keyframes, static_dynamic, tau_rel, bounded } => {
                let keys = match (keyframes, static_dynamic) {
                    (0, false) => String::new(),
                    (0, true) => format!(", x{HELD_STILL_TAU_FACTOR} for the static + dynamic model"),
                    (k, _) => format!(", x{HELD_STILL_TAU_FACTOR} with {k} key frame(s)"),
                };
                if sigma > 0.0 {
                    // Three significant digits at any scale (a 0-1 raw's noise is 1e-4).
                    let digits = (2 - sigma.log10().floor() as i32).clamp(0, 12) as usize;
                    write!(f, "from the raw's noise: sigma {sigma:.digits$} over {frames} frame(s){keys}, tau_rel {tau_rel:.3e}")?;
                } else {
                    write!(f, "from the raw's noise: none measured (the raw is noise-free, e.g. a synthetic frame){keys}, tau_rel {tau_rel:.3e}")?;
                }
                if bounded {
                    let (lo, hi) = noise_tau_rel_range(frames);
                    let whose = if frames > 1 { ", a video's range" } else { "" };
                    write!(f, " (brought into {lo:e}..{hi:e}{whose})")?;
                }
                Ok(())
            }
            TauChoice::NoNoise { tau_rel } => write!(f, "tau_rel {tau_rel:e}: the raw's noise could not be measured"),
        }
    }
}

impl Tau {
    /// The weight given as `--tau-rel` (a number, `noise` or `auto`) unless an absolute
    /// `tau` is given: the one place this precedence is decided. `None` when both an
    /// absolute weight and the held-out search are asked for (the caller names the
    /// conflict).
    pub fn from_given(tau: Option<f32>, tau_rel: Tau) -> Option<Tau> {
        match (tau, tau_rel) {
            (Some(_), Tau::Auto(_)) => None,
            (Some(t), _) => Some(Tau::Absolute(t)),
            (None, given) => Some(given),
        }
    }

    /// The relative weight given (`Relative`, or where `Auto` starts), if any.
    pub fn relative(self) -> Option<f32> {
        match self {
            Tau::Relative(r) | Tau::Auto(Some(r)) => Some(r),
            _ => None,
        }
    }

    pub fn is_auto(self) -> bool {
        matches!(self, Tau::Auto(_))
    }

    /// The absolute weight against `scale` (whose peak and noise are asked only by the
    /// rules that need them), and how it was chosen.
    pub(crate) fn resolve(self, scale: &dyn TauScale) -> (f32, TauChoice) {
        match self {
            Tau::Absolute(t) => (t, TauChoice::Absolute),
            Tau::Relative(r) | Tau::Auto(Some(r)) => (r * scale.tau_scale(), TauChoice::Relative { tau_rel: r }),
            Tau::Noise | Tau::Auto(None) => match scale.noise() {
                Some(n) => noise_rule(n, scale.tau_scale()),
                None => (FALLBACK_TAU_REL * scale.tau_scale(), TauChoice::NoNoise { tau_rel: FALLBACK_TAU_REL }),
            },
        }
    }
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

fn is_false(b: &bool) -> bool {
    !*b
}

/// The noise rule's weight for `noise` against `peak` (`max(A^T b)`).
fn noise_rule(noise: Noise, peak: f32) -> (f32, TauChoice) {
    let (frames, keyframes, static_dynamic) = (noise.frames.max(1), noise.keyframes, noise.static_dynamic);
    let factor = if keyframes > 0 || static_dynamic { HELD_STILL_TAU_FACTOR } else { 1.0 };
    let tau = factor * NOISE_TAU_PER_SIGMA * noise.sigma / (frames as f32).sqrt();
    let (lo, hi) = noise_tau_rel_range(frames);
    if !(peak.is_finite() && peak > 0.0) {
        // No light to scale against (an all-zero raw): nothing to bound.
        let tau = if tau.is_finite() { tau } else { 0.0 };
        return (tau, TauChoice::Noise { sigma: noise.sigma, frames, keyframes, static_dynamic, tau_rel: 0.0, bounded: false });
    }
    let own = tau / peak;
    let tau_rel = if own.is_finite() { own.clamp(lo, hi) } else { FALLBACK_TAU_REL };
    (tau_rel * peak, TauChoice::Noise { sigma: noise.sigma, frames, keyframes, static_dynamic, tau_rel, bounded: tau_rel != own })
}

/// What a relative TV weight is relative to (the largest finite entry of `A^T b`), and
/// what the noise rule reads (the raw's noise and the video's frames; `None` where it
/// cannot be measured).
pub trait TauScale {
    fn tau_scale(&self) -> f32;
    fn noise(&self) -> Option<Noise>;
}

/// A scale measured only if a rule asks for it: closures giving `max(A^T b)` and the
/// noise (an absolute weight then costs no adjoint).
pub struct LazyScale<P: Fn() -> f32, N: Fn() -> Option<Noise>> {
    pub peak: P,
    pub noise: N,
}

impl<P: Fn() -> f32, N: Fn() -> Option<Noise>> TauScale for LazyScale<P, N> {
    fn tau_scale(&self) -> f32 {
        (self.peak)()
    }
    fn noise(&self) -> Option<Noise> {
        (self.noise)()
    }
}

/// A scale already measured: `max(A^T b)` of an operator and its data, or that peak
/// reduced over the ranks that each hold a part of one problem, with the raw's noise
/// where it is known ([`Peak::with_noise`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Peak(pub f32, pub Option<Noise>);

impl Peak {
    /// `max(A^T b)` of `op` and `b` (no noise known).
    pub fn of<A: Operator + ?Sized>(op: &A, b: &[f32]) -> Peak {
        Peak(adjoint_peak(op, b), None)
    }

    /// The largest of every rank's `local` peak (a collective: every rank calls it).
    pub fn across_ranks(local: f32, ranks: &dyn Ranks) -> Peak {
        let mut peak = [local as f64];
        ranks.max_f64(&mut peak);
        Peak(peak[0] as f32, None)
    }

    /// The same peak with the raw's noise (`None`: not measurable).
    pub fn with_noise(self, noise: Option<Noise>) -> Peak {
        Peak(self.0, noise)
    }
}

impl TauScale for Peak {
    fn tau_scale(&self) -> f32 {
        self.0
    }
    fn noise(&self) -> Option<Noise> {
        self.1
    }
}

/// The TV weight of one frame that stands for `frames` frames of the video (a static
/// scene, the still image, the static part of the static + dynamic model): its TV
/// counts once per frame it replaces, so the objective is the video's on still scenes.
pub fn static_frame_tau(tau: f32, frames: usize) -> f32 {
    tau * frames as f32
}

/// The TV weight of the static image of the static + dynamic model when key frames are
/// solved with the raw: `tau sqrt(frames)`, the noise rule's weight for one frame of the
/// same raw (the rule's `1 / sqrt(frames)` undone), where [`static_frame_tau`] gives
/// `tau frames`. The key frames see the still scene directly and sharply; a weight that
/// counts once per frame the image stands for smoothed away the texture they show.
/// Measured on the 240 x 320 x 122 disc and occluder through the measured PSF with key
/// frames at the first and last frame (docs/keyframes.md): still-scene correlation
/// 0.980 -> 0.998 and 0.999, relative error 0.10 -> 0.053 and 0.033; 0.02 to 0.09 of
/// `tau frames` gave the same, 0.25 of it 0.086-0.093 in twice the iterations.
pub fn keyed_static_tau(tau: f32, frames: usize) -> f32 {
    tau * (frames as f32).sqrt()
}

/// An L1 weight that zeroes every pixel, found by [`check_l1`] (its message names the
/// setting, the weight and the scale it is measured against).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ZeroingL1 {
    /// The L1 weight relative to tau (`--l1`).
    pub l1_rel: f32,
    /// The TV weight tau it multiplies.
    pub tau: f32,
    /// The data's scale `max(A^T b)`.
    pub peak: f32,
    /// The weight is on the dynamic part of the static + dynamic model.
    pub dynamic_part: bool,
}

impl std::fmt::Display for ZeroingL1 {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        let what = if self.dynamic_part { "a zero dynamic part (a video that does not move)" } else { "the all-zero video" };
        write!(
            f,
            "l1 = {:e} (--l1, relative to tau): the L1 weight l1 x tau = {:e} is at least the data's scale max(A^T b) = {:e}, where {what} is the exact minimiser: expected l1 below max(A^T b) / tau = {:e}",
            self.l1_rel,
            self.l1_rel * self.tau,
            self.peak,
            self.peak / self.tau
        )
    }
}

/// Refuse an L1 weight at which the solve's answer is zero whatever the data: the one
/// rule for it, judged against the data's scale `peak = max(A^T b)` (the [`TauScale`]
/// every solve resolves tau against, asked only when there is an L1 term) before any
/// solve.
///
/// Why zero: the objective is `F(x) = 0.5 ||A x - b||^2 + tau TV(x) + l1 sum_i x_i` over
/// `x >= 0` (the L1 term `l1 sum |x_i|` is `l1 sum x_i` there; a clipped pixel's
/// one-sided loss has the same gradient at 0, `b_i > 0 = (A 0)_i`). The data term is
/// convex with gradient `-A^T b` at 0, so for every `x >= 0`
/// `F(x) - F(0) >= -<A^T b, x> + tau TV(x) + l1 sum_i x_i >= sum_i (l1 - (A^T b)_i) x_i`,
/// which is `>= 0` when `l1 >= max(A^T b)`: 0 is a minimiser (the only one when the
/// inequality is strict), whatever tau. On the static + dynamic model, where the L1
/// term is on the dynamic part alone, the same holds for the dynamic part against the
/// residual of the best static image, whose `A^T` is at most `A^T b` (non-negative PSF
/// and image), so the dynamic part is zero. With several channels `peak` is their
/// largest, so every channel is zero. A weaker weight may still zero the video (TV
/// helps); this bound is the one that is exact.
pub fn check_l1(l1_rel: f32, tau: f32, scale: &dyn TauScale, dynamic_part: bool) -> Result<(), ZeroingL1> {
    let l1 = l1_rel * tau;
    if !(l1 > 0.0) {
        // No L1 term: nothing to measure (the scale may cost an adjoint).
        return Ok(());
    }
    let peak = scale.tau_scale();
    if peak.is_finite() && peak > 0.0 && l1 >= peak {
        return Err(ZeroingL1 { l1_rel, tau, peak, dynamic_part });
    }
    Ok(())
}

impl TauChoice {
    /// The weight's ratio to `max(A^T b)`, where a rule gave one (not for an absolute
    /// weight).
    pub fn tau_rel(&self) -> Option<f32> {
        match *self {
            TauChoice::Absolute => None,
            TauChoice::Relative { tau_rel } | TauChoice::Noise { tau_rel, .. } | TauChoice::NoNoise { tau_rel } => Some(tau_rel),
        }
    }
}

/// `--tau-rel`'s text (the command line's and Python's `tau_rel`): a number (relative),
/// `noise` (the default) or `auto` (held-out pixels choose it, starting from the noise
/// rule's weight); an absolute weight shows as `tau=VALUE`.
impl std::fmt::Display for Tau {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        match self {
            Tau::Relative(v) => write!(f, "{v}"),
            Tau::Noise => f.write_str("noise"),
            Tau::Auto(None) => f.write_str("auto"),
            Tau::Auto(Some(v)) => write!(f, "auto from {v}"),
            Tau::Absolute(v) => write!(f, "tau={v}"),
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

/// `--tau-rel`'s text: a number (a relative weight), `noise` or `auto`.
impl std::str::FromStr for Tau {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim() {
            "auto" => return Ok(Tau::Auto(None)),
            "noise" => return Ok(Tau::Noise),
            _ => {}
        }
        match s.trim().parse::<f64>() {
            Ok(_) => parse_f32(s).map(Tau::Relative),
            Err(_) => Err(format!("{s}: expected a number (e.g. {FALLBACK_TAU_REL:e}), noise or auto")),
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
    fn an_absolute_tau_wins_a_relative_one_scales_and_the_noise_rule_is_the_default() {
        assert_eq!(Tau::from_given(Some(0.5), Tau::Relative(0.1)), Some(Tau::Absolute(0.5)));
        assert_eq!(Tau::from_given(Some(0.5), Tau::Noise), Some(Tau::Absolute(0.5)));
        assert_eq!(Tau::from_given(None, Tau::Relative(0.1)), Some(Tau::Relative(0.1)));
        assert_eq!(Tau::from_given(None, Tau::Noise), Some(Tau::Noise));
        assert_eq!(Tau::from_given(Some(0.5), Tau::Auto(None)), None);
        let peak = Peak(1000.0, None);
        assert_eq!(Tau::Absolute(0.5).resolve(&peak), (0.5, TauChoice::Absolute));
        assert_eq!(Tau::Relative(0.1).resolve(&peak), (100.0, TauChoice::Relative { tau_rel: 0.1 }));
        // No noise known: the fallback weight, said.
        assert_eq!(Tau::Noise.resolve(&peak), (FALLBACK_TAU_REL * 1000.0, TauChoice::NoNoise { tau_rel: FALLBACK_TAU_REL }));
        // Where no search runs, `auto` is its start.
        assert_eq!(Tau::Auto(Some(0.1)).resolve(&peak), Tau::Relative(0.1).resolve(&peak));
        assert_eq!(Tau::Auto(None).resolve(&peak), Tau::Noise.resolve(&peak));
    }

    #[test]
    fn the_noise_rule_follows_the_noise_and_the_frames_within_its_range() {
        let at = |sigma: f32, frames: usize, peak: f32| Tau::Noise.resolve(&Peak(peak, Some(Noise { sigma, frames, keyframes: 0, static_dynamic: false })));
        // tau = 0.02 sigma / sqrt(K): linear in sigma, a quarter at 16 frames.
        let (still, choice) = at(50.0, 1, 1e4);
        assert!((still - 1.0).abs() < 1e-6, "{still}");
        assert_eq!(choice, TauChoice::Noise { sigma: 50.0, frames: 1, keyframes: 0, static_dynamic: false, tau_rel: 1e-4, bounded: false });
        assert!((at(100.0, 1, 1e4).0 - 2.0).abs() < 1e-6);
        assert!((at(50.0, 16, 1e3).0 - 0.25).abs() < 1e-6);
        // Key frames solved with the raw take HELD_STILL_TAU_FACTOR of the weight, said.
        let (keyed, choice) = Tau::Noise.resolve(&Peak(500.0, Some(Noise { sigma: 50.0, frames: 16, keyframes: 2, static_dynamic: false })));
        assert!((keyed - HELD_STILL_TAU_FACTOR * 0.25).abs() < 1e-6, "{keyed}");
        assert_eq!(
            choice,
            TauChoice::Noise { sigma: 50.0, frames: 16, keyframes: 2, static_dynamic: false, tau_rel: HELD_STILL_TAU_FACTOR * 0.25 / 500.0, bounded: false }
        );
        assert!(choice.to_string().contains("over 16 frame(s), x0.5 with 2 key frame(s), tau_rel 2.500e-4"), "{choice}");
        assert!(!at(50.0, 16, 500.0).1.to_string().contains("key frame"));
        // So does the static + dynamic model without key frames (once, with both).
        for keyframes in [0, 2] {
            let (held, choice) = Tau::Noise.resolve(&Peak(500.0, Some(Noise { sigma: 50.0, frames: 16, keyframes, static_dynamic: true })));
            assert!((held - keyed).abs() < 1e-9, "{held}");
            let said = if keyframes == 0 { "x0.5 for the static + dynamic model" } else { "x0.5 with 2 key frame(s)" };
            assert!(choice.to_string().contains(said), "{choice}");
        }
        // A video's weight is at least VIDEO_TAU_REL_FLOOR of the peak: 0.25 / 1e4 =
        // 2.5e-5 is raised to 1.25e-4, said; a still at the same ratio is not.
        let (video, choice) = at(50.0, 16, 1e4);
        assert!((video - VIDEO_TAU_REL_FLOOR * 1e4).abs() < 1e-5, "{video}");
        assert_eq!(choice, TauChoice::Noise { sigma: 50.0, frames: 16, keyframes: 0, static_dynamic: false, tau_rel: VIDEO_TAU_REL_FLOOR, bounded: true });
        assert!(choice.to_string().contains("brought into 1.25e-4..1e-2, a video's range"), "{choice}");
        let (_, still) = at(12.5, 1, 1e4);
        assert!((still.tau_rel().unwrap() - 2.5e-5).abs() < 1e-9 && !still.to_string().contains("brought"), "{still}");
        // The peak does not move an unbounded weight.
        assert!((at(50.0, 1, 2e4).0 - 1.0).abs() < 1e-6);
        // A noiseless raw gets the range's low end, a raw of noise alone its high end.
        let (lo, hi) = NOISE_TAU_REL_RANGE;
        assert_eq!(at(0.0, 1, 1e4), (lo * 1e4, TauChoice::Noise { sigma: 0.0, frames: 1, keyframes: 0, static_dynamic: false, tau_rel: lo, bounded: true }));
        let (t, c) = at(1e6, 1, 1e4);
        assert_eq!((t, c.tau_rel()), (hi * 1e4, Some(hi)));
        // No light: no scale to bound against, never NaN; zero frames count as one.
        assert_eq!(at(2.0, 0, 0.0).0, 0.04);
        assert!(at(f32::NAN, 4, 0.0).0 == 0.0 && at(f32::NAN, 4, 1e4).0.is_finite());
        let shown = TauChoice::Noise { sigma: 0.0, frames: 3, keyframes: 0, static_dynamic: false, tau_rel: lo, bounded: true }.to_string();
        assert!(shown.contains("none measured (the raw is noise-free") && shown.contains("brought into"), "{shown}");
        let shown = TauChoice::Noise { sigma: 2.5e-4, frames: 3, keyframes: 0, static_dynamic: false, tau_rel: lo, bounded: false }.to_string();
        assert!(shown.contains("sigma 0.000250 over 3 frame(s)"), "{shown}");
        assert!(TauChoice::Noise { sigma: 41.23, frames: 1, keyframes: 0, static_dynamic: false, tau_rel: lo, bounded: false }
            .to_string()
            .contains("sigma 41.2 over"));
    }

    #[test]
    fn tau_rel_reads_a_number_noise_or_auto() {
        assert_eq!("auto".parse::<Tau>(), Ok(Tau::Auto(None)));
        assert_eq!(" noise ".parse::<Tau>(), Ok(Tau::Noise));
        assert_eq!(" 1e-3 ".parse::<Tau>(), Ok(Tau::Relative(1e-3)));
        assert_eq!(Tau::Auto(None).relative(), None);
        assert_eq!(Tau::Relative(1e-3).relative(), Some(1e-3));
        assert_eq!(Tau::default(), Tau::Noise);
        assert_eq!("x".parse::<Tau>().unwrap_err(), "x: expected a number (e.g. 2.5e-4), noise or auto");
        assert_eq!(Tau::Auto(None).to_string(), "auto");
        assert_eq!(Tau::Noise.to_string(), "noise");
        assert_eq!(Tau::Relative(2e-4).to_string().parse::<Tau>(), Ok(Tau::Relative(2e-4)));
    }

    #[test]
    fn an_l1_weight_at_the_datas_scale_is_refused_below_it_accepted() {
        let at = |peak: f32| Peak(peak, None);
        // l1 x tau against max(A^T b) = 100: 1e4 x 0.01 = 100 zeroes the video.
        let e = check_l1(1e4, 0.01, &at(100.0), false).unwrap_err();
        let shown = e.to_string();
        assert!(shown.contains("--l1") && shown.contains("all-zero video") && shown.contains("max(A^T b) = 1e2"), "{shown}");
        assert!(check_l1(9e3, 0.01, &at(100.0), false).is_ok());
        assert!(check_l1(1.8e19, 1e-3, &at(3e4), true).unwrap_err().to_string().contains("dynamic part"));
        // No L1 (or no TV weight to scale it), or no light to judge against: nothing refused.
        assert!(check_l1(0.0, 1.0, &at(100.0), false).is_ok());
        assert!(check_l1(1.8e19, 0.0, &at(100.0), false).is_ok());
        assert!(check_l1(1.8e19, 1.0, &at(0.0), false).is_ok());
        // A product past f32's range is refused, not passed as inf.
        assert!(check_l1(3e38, 10.0, &at(100.0), false).is_err());
    }

    #[test]
    fn a_static_frame_counts_once_per_frame_it_replaces() {
        assert_eq!(static_frame_tau(0.5, 8), 4.0);
    }
}
