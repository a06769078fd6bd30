//! Choosing the TV weight from the capture itself (`--tau-rel auto`): held-out pixels.
//!
//! A tenth of the sensor's pixels (a fixed pseudo-random set, [`HELD_OUT_FRACTION`]) is
//! left out of the data term. The video is solved from the rest at a ladder of
//! `tau_rel` (factors of [`SEARCH_STEP`] from the given one, or from the noise rule's,
//! [`crate::solve::tau`]), each solve as the final
//! one will be (from the still image, with the same prior, TV and L1, and the same
//! stop rule: the iteration count regularises too), and the forward model predicts the
//! pixels left out. The `tau_rel` whose video predicts them best is kept, and the
//! video is then solved from every pixel at that weight.
//!
//! ## Where it works, and where it does not (docs/dense-scenes.md, "Tau without tuning")
//! A held-out pixel's row sees the same frames as the kept pixels of its row, so the
//! prediction checks what the data can check: fitting the noise (tau too low) against
//! flattening the scene (tau too high). On mostly still scenes that is the whole error,
//! and the held-out choice matched the truth's best `tau_rel` on the dense benchmark
//! scene. Where things move, most of the error lies where no pixel looks (where a fast
//! object was between the rows that saw it), and the prediction cannot see it: on the
//! lone moving disc it chose 8x less TV than the truth's best. So the search runs only
//! where the still start's check finds a mostly still scene ([`STILL_RESIDUAL_MAX`]),
//! or on a one-frame capture (a global shutter's still cannot move: a dim still's raw
//! is far from its still image because of noise, which held-out pixels do see);
//! elsewhere the settings' own weight (the noise rule's by default) stands and the
//! report says why.
//! Bands of held-out rows, which hide whole time windows, were tried for moving scenes
//! and taken out: right on the moving disc, wrong on flashing LEDs and on a small disc.

use crate::model::data::DataTerm;
use crate::model::op::Operator;
use crate::model::prepare::DataMask;
use crate::solve::job::{run, ChannelJob};
use crate::solve::lipschitz::EigenStore;
use crate::solve::optimize::{IterInfo, OptimizerSettings, Termination};
use crate::solve::problem::{build_operator, Problem, SolveParams, SolveSettings, ValidSettings};
use crate::solve::prox::prior::PriorSpec;
use crate::solve::start::{check, video_start, Start, STILL_RESIDUAL_MAX};
use crate::solve::tau::FALLBACK_TAU_REL;
use serde::Serialize;
use std::sync::atomic::{AtomicBool, Ordering};

/// Share of the (unmasked, unclipped) sensor pixels left out of the search's solves.
pub const HELD_OUT_FRACTION: f64 = 0.1;
/// Ratio of neighbouring candidates.
pub const SEARCH_STEP: f32 = 2.0;
/// Most candidates tried.
pub const SEARCH_MAX_CANDIDATES: usize = 8;
/// The seed of the held-out set (fixed: the same capture gives the same choice).
const HELD_OUT_SEED: u64 = 0x7a75_5f73_6561_7263;

/// One candidate of the search.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TauCandidate {
    pub tau_rel: f32,
    /// `||A x - b||^2 / ||b||^2` over the held-out pixels (all channels).
    pub held_out_residual: f64,
}

/// What the search did (summary.json's `tau_search`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TauSearchReport {
    /// Whether candidates were solved (`false`: a moving scene, `tau_rel` kept).
    pub searched: bool,
    /// The `tau_rel` the video is solved with.
    pub tau_rel: f32,
    /// Why the search stopped or did not run.
    pub reason: String,
    pub held_out_pixels: usize,
    /// In the order solved.
    pub candidates: Vec<TauCandidate>,
    pub iterations_each: usize,
    /// The still start's relative residual on the kept pixels (worst channel).
    pub still_residual_rel: f64,
    /// Seconds of the whole search (still images included).
    pub seconds: f64,
}

/// A splitmix64 draw in `[0, 1)` for index `i`.
fn unit_draw(i: u64) -> f64 {
    let mut x = i.wrapping_add(HELD_OUT_SEED).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^= x >> 31;
    (x >> 11) as f64 / (1u64 << 53) as f64
}

/// The held-out pixels of a sensor of `len` pixels: about [`HELD_OUT_FRACTION`] of those
/// the data term counts (`mask` non-zero) and that are not clipped (`lower_bounds`).
pub fn held_out_pixels(len: usize, mask: Option<&[f32]>, lower_bounds: Option<&[bool]>) -> Vec<bool> {
    (0..len)
        .map(|i| {
            let counted = mask.map_or(true, |m| m[i] != 0.0) && lower_bounds.map_or(true, |l| !l[i]);
            counted && unit_draw(i as u64) < HELD_OUT_FRACTION
        })
        .collect()
}

/// The settings to solve `problem` with: `settings` as given, or with `tau_rel` chosen
/// by held-out pixels when `settings.tau` is [`Tau::Auto`] (and the search's report). `stop` (the
/// solve's stop flag, Ctrl-C) ends the search early; the given `tau_rel` then stands.
pub fn settle(settings: &ValidSettings, problem: &Problem, cache: &dyn EigenStore, stop: &AtomicBool) -> (ValidSettings, Option<TauSearchReport>) {
    if !settings.tau.is_auto() {
        return (settings.clone(), None);
    }
    let report = search(settings, problem, cache, stop);
    // A search that did not run leaves the weight to the settings' own rule (the
    // report says why).
    let settled = if report.searched { settings.with_tau_rel(report.tau_rel) } else { settings.clone() };
    (settled, Some(report))
}

/// Consecutive captures share one tau resolved before any is solved; the held-out
/// search is for single captures. The error is (field, value, expected), as
/// [`crate::solve::start::check_for_sequence`]'s.
pub fn check_for_sequence(settings: &SolveSettings) -> Result<(), (&'static str, String, &'static str)> {
    if settings.tau.is_auto() {
        return Err((
            "tau_rel",
            "auto".into(),
            "a number or noise for consecutive captures (the held-out search is for single captures; run one capture with --tau-rel auto and give the tau_rel it chose)",
        ));
    }
    Ok(())
}

/// The prior of a candidate on channel `ch`: the plain video's, as the final solve
/// builds it from the candidate's parameters.
fn candidate_prior(params: &SolveParams, problem: &Problem, ch: usize, shape: (usize, usize, usize)) -> PriorSpec {
    params.prior(false).video(shape, problem.channel(ch).atb_max() as f64)
}

/// One channel's share of the search: the model without the held-out pixels, the
/// held-out set, the capture and the full model's Lipschitz constant.
struct ChannelSearch<'p> {
    ch: usize,
    train: crate::model::rolling::RollingShutterModel,
    held: Vec<bool>,
    b: &'p [f32],
    lipschitz: f64,
}

/// The held-out search on every channel of `problem` from `settings.tau_rel`, or from
/// the noise rule's weight when none is given (until `stop` is set).
pub fn search(settings: &ValidSettings, problem: &Problem, cache: &dyn EigenStore, stop: &AtomicBool) -> TauSearchReport {
    let clock = std::time::Instant::now();
    // The weight as the settings give it, resolved once: the search's start and the
    // still check's prior. Validated: no absolute tau with the search, so the rule
    // always gives a ratio.
    let given = settings.resolve(problem, problem.fov);
    let base = given.tau_choice.tau_rel().unwrap_or(FALLBACK_TAU_REL);
    let prepared = problem.prepared;
    let mut report = TauSearchReport {
        searched: false,
        tau_rel: base,
        reason: String::new(),
        held_out_pixels: 0,
        candidates: Vec::new(),
        iterations_each: settings.iters,
        still_residual_rel: 0.0,
        seconds: 0.0,
    };
    let mut channels = Vec::new();
    for (ch, model) in problem.models().iter().enumerate() {
        let len = model.output_len();
        let lower = prepared.data_mask.lower_bounds.as_deref();
        let held = held_out_pixels(len, model.mask(), lower);
        let kept: Vec<f32> = (0..len).map(|i| if held[i] { 0.0 } else { model.mask().map_or(1.0, |m| m[i]) }).collect();
        let train = build_operator(&prepared.psf[ch], problem.weights(), problem.fov, &DataMask { mask: Some(kept), lower_bounds: None });
        let b = &prepared.raw[ch].data[..];
        let data = DataTerm::new(b).with_lower_bounds(lower);
        if let Err(refused) = settings.solver.check_data(&data) {
            // The solve itself refuses it too, with the same words.
            report.reason = refused;
            report.seconds = clock.elapsed().as_secs_f64();
            return report;
        }
        let prior = candidate_prior(&given, problem, ch, train.video_shape());
        let (residual_rel, still) = check(&train, &data, &prior).map_or((f64::INFINITY, false), |r| (r.residual_rel, r.used));
        report.still_residual_rel = report.still_residual_rel.max(residual_rel);
        report.held_out_pixels += held.iter().filter(|&&h| h).count();
        // A one-frame video cannot move: nothing lies where no pixel looks.
        if !still && problem.weights().frames() > 1 {
            report.reason = format!(
                "channel {ch}: the still image leaves {:.3} of the raw unexplained (more than {STILL_RESIDUAL_MAX}): where the scene moves, held-out pixels cannot see most of the error, so tau_rel {base:e} stands",
                report.still_residual_rel
            );
            report.seconds = clock.elapsed().as_secs_f64();
            tracing::info!("tau search not run: {}", report.reason);
            return report;
        }
        let lipschitz = problem.channel(ch).lipschitz(cache).value;
        channels.push(ChannelSearch { ch, train, held, b, lipschitz });
    }
    if report.held_out_pixels == 0 {
        report.reason = "no pixel could be held out (the sensor is too small or masked)".into();
        report.seconds = clock.elapsed().as_secs_f64();
        return report;
    }
    report.searched = true;

    // Down the ladder from the given tau_rel while the prediction improves; up instead
    // when the first step down is worse.
    let mut tried: Vec<TauCandidate> = Vec::new();
    let evaluate = |tau_rel: f32, channels: &[ChannelSearch], tried: &mut Vec<TauCandidate>| -> Option<f64> {
        let r = held_out_residual(tau_rel, settings, problem, channels, stop)?;
        tracing::info!(tau_rel, held_out_residual = r, "tau search candidate");
        tried.push(TauCandidate { tau_rel, held_out_residual: r });
        Some(r)
    };
    let stopped = || format!("stopped (the solve's stop flag) before a choice; tau_rel {base:e} stands");
    let reason = match evaluate(base, &channels, &mut tried) {
        None if stop.load(Ordering::Relaxed) => stopped(),
        None => format!("the solve at tau_rel {base:e} went non-finite; tau_rel {base:e} stands"),
        Some(mut best) => {
            let mut best_tau = base;
            let mut step = 1.0 / SEARCH_STEP;
            let mut tau_rel = base * step;
            let mut turned = false;
            let reason = loop {
                if tried.len() >= SEARCH_MAX_CANDIDATES {
                    break format!("stopped after {SEARCH_MAX_CANDIDATES} candidates, still improving");
                }
                let Some(r) = evaluate(tau_rel, &channels, &mut tried) else {
                    if stop.load(Ordering::Relaxed) {
                        best_tau = base;
                        break stopped();
                    }
                    break format!("the solve at tau_rel {tau_rel:e} went non-finite");
                };
                if r < best {
                    best = r;
                    best_tau = tau_rel;
                    tau_rel *= step;
                } else if !turned && best_tau == base {
                    // The first step down was worse: go up from the given one.
                    turned = true;
                    step = SEARCH_STEP;
                    tau_rel = base * step;
                } else {
                    break format!("the held-out residual rose at tau_rel {tau_rel:e}");
                }
            };
            report.tau_rel = best_tau;
            reason
        }
    };
    report.candidates = tried;
    report.reason = reason;
    report.seconds = clock.elapsed().as_secs_f64();
    tracing::info!(tau_rel = report.tau_rel, candidates = report.candidates.len(), seconds = report.seconds, "tau chosen by held-out pixels");
    report
}

/// Solve every channel at `tau_rel` as the video will be solved (from the still image
/// at that weight unless the settings start from zero, with their stop rule), on the
/// kept pixels, and return the held-out residual energy over the held-out data energy;
/// `None` when a solve went non-finite or `stop` was set.
fn held_out_residual(tau_rel: f32, settings: &ValidSettings, problem: &Problem, channels: &[ChannelSearch], stop: &AtomicBool) -> Option<f64> {
    let (mut num, mut den) = (0.0f64, 0.0f64);
    let frames = problem.weights().frames();
    let lower = problem.prepared.data_mask.lower_bounds.as_deref();
    for c in channels {
        let candidate = settings.with_tau_rel(tau_rel).resolve(problem, problem.fov);
        let data = DataTerm::new(c.b).with_lower_bounds(lower);
        let prior = candidate_prior(&candidate, problem, c.ch, c.train.video_shape());
        // The scene is mostly still (checked), so `auto` takes the still image too.
        let start = if settings.start == Start::Zero { Start::Zero } else { Start::Still };
        let (x0, _) = video_start(start, &c.train, &data, &prior, frames, &|v| v, None);
        let st = OptimizerSettings::new(settings.solver, c.lipschitz, settings.stop());
        let mut observer = |_: &IterInfo| !stop.load(Ordering::Relaxed);
        let r = run(ChannelJob { settings: &st, operator: &c.train, data: &data, prior: prior.build(None).as_ref(), start: x0 }, &mut observer);
        if stop.load(Ordering::Relaxed) || matches!(r.termination, Termination::NonFinite { .. }) || !r.x.iter().all(|v| v.is_finite()) {
            return None;
        }
        let full = problem.channel(c.ch).model();
        let mut ax = vec![0.0f32; full.output_len()];
        full.forward(&r.x, &mut ax);
        for (i, (&p, &q)) in ax.iter().zip(c.b).enumerate() {
            if c.held[i] {
                num += ((p - q) as f64).powi(2);
                den += (q as f64).powi(2);
            }
        }
    }
    Some(if den > 0.0 { num / den } else { num })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn about_a_tenth_of_the_counted_pixels_is_held_out_the_same_every_time() {
        let n = 100_000;
        let held = held_out_pixels(n, None, None);
        let share = held.iter().filter(|&&h| h).count() as f64 / n as f64;
        assert!((share - HELD_OUT_FRACTION).abs() < 0.005, "{share}");
        assert_eq!(held, held_out_pixels(n, None, None), "a fixed set");
        // Masked and clipped pixels are never held out.
        let mask: Vec<f32> = (0..n).map(|i| if i % 3 == 0 { 0.0 } else { 1.0 }).collect();
        let clipped: Vec<bool> = (0..n).map(|i| i % 3 == 1).collect();
        let some = held_out_pixels(n, Some(&mask), Some(&clipped));
        assert!(some.iter().enumerate().all(|(i, &h)| !h || i % 3 == 2));
        let share = some.iter().filter(|&&h| h).count() as f64 / (n / 3) as f64;
        assert!((share - HELD_OUT_FRACTION).abs() < 0.01, "{share}");
    }

    #[test]
    fn only_auto_searches_and_sequences_refuse_it() {
        let given = SolveSettings::default();
        assert!(check_for_sequence(&given).is_ok());
        let auto = SolveSettings { tau: Tau::Auto(None), ..SolveSettings::default() };
        let (field, value, _) = check_for_sequence(&auto).unwrap_err();
        assert_eq!((field, value.as_str()), ("tau_rel", "auto"));
        // An absolute tau with the search is refused where both are given, a zero
        // start by the settings' check.
        use crate::solve::tau::Tau;
        assert_eq!(Tau::from_given(Some(0.1), auto.tau), None);
        assert_eq!(SolveSettings { tau: Tau::Auto(Some(0.0)), ..auto }.validate().unwrap_err().field, "tau_rel");
    }
}
