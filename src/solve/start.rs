//! Where a video solve starts: from zero, or from the still image that explains the
//! capture best ([`Start`]).
//!
//! ## Why a still start
//! The video problem has `K` times more unknowns than measurements. A pixel of frame
//! `k` is seen only by the few sensor rows exposed during frame `k`; what the other
//! frames know about it reaches it through the temporal TV term, one frame per
//! iteration. So a solve from zero spends hundreds of iterations spreading what does
//! not move (most of a dense bench scene, and the mean light of a sparse one) over the
//! frames. The still problem has one image for all rows: the video operator on videos
//! constant in time ([`crate::model::still::Still`], one convolution per call, about a
//! tenth of a video iteration), with the video's spatial TV weighted by `K` (a still
//! video costs the same in both problems). Its solution, repeated in every frame, is
//! the start; the video solve then only has to carve out what changes.
//!
//! ## When `auto` takes it
//! Only where the scene is mostly still: the still image must explain the raw to within
//! [`STILL_RESIDUAL_MAX`] (relative residual) after [`STILL_CHECK_ITERS`] iterations.
//! Where the light itself changes (flashing LEDs), the still image holds their mean.
//! The video solve then needs more iterations to build the modulation back up against
//! the temporal TV. At the LED sweep's 100 iterations the fundamental contrast was
//! 0.63 against 0.88 from zero (period 2640 us; at 300 iterations 0.98). There `auto`
//! starts from zero, and the check's few iterations are the only cost.
//!
//! Measured in docs/dense-scenes.md ("Faster convergence"): on the dense benchmark
//! scene (still residual 0.02) the video solve from the still start passes, in its
//! first iteration, the error a solve from zero reaches after 200.

use crate::model::data::DataTerm;
use crate::model::op::{adjoint_peak, Operator};
use crate::model::rolling::RollingShutterModel;
use crate::model::still::Still;
use crate::solve::job::{run, ChannelJob};
use crate::solve::lipschitz::{power_iteration, LIPSCHITZ_MARGIN};
use crate::solve::optimize::{NoObserver, OptimizerSettings, SolverKind, StopRule, Termination};
use crate::solve::prox::prior::PriorSpec;
use crate::solve::prox::Prox;
use serde::{Deserialize, Serialize};

/// How a video solve starts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Start {
    /// The still start wherever the video has more than one frame; zero otherwise.
    #[default]
    Auto,
    /// From the still solve's image in every frame.
    Still,
    /// From zero (every solver's start before the still start).
    Zero,
}

impl Start {
    pub const ALL: [Start; 3] = [Start::Auto, Start::Still, Start::Zero];
    pub fn name(self) -> &'static str {
        match self {
            Start::Auto => "auto",
            Start::Still => "still",
            Start::Zero => "zero",
        }
    }
    /// Whether a video of `frames` frames starts from the still solve.
    pub fn uses_still(self, frames: usize) -> bool {
        match self {
            Start::Auto => frames > 1,
            Start::Still => true,
            Start::Zero => false,
        }
    }
}

impl std::fmt::Display for Start {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Start {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Start::ALL.into_iter().find(|k| k.name() == s).ok_or_else(|| format!("unknown start '{s}': expected auto, still or zero"))
    }
}

/// Consecutive captures solved as one video ([`crate::solve::sequence`]) start each
/// window from the result so far (or zero): there `auto` means that, and `still` is
/// refused. The error is (field, value, expected), as [`StopRule::check`]'s.
pub fn check_for_sequence(start: Start) -> Result<(), (&'static str, String, &'static str)> {
    match start {
        Start::Still => Err((
            "start",
            start.name().into(),
            "auto or zero for consecutive captures: each window starts from the result so far (from zero with --cold-start); the still start is for single captures",
        )),
        Start::Auto | Start::Zero => Ok(()),
    }
}

/// Iterations of the still solve. Measured on the 240 x 320 LED and dense scenes
/// (docs/dense-scenes.md): 100 leave the LED video 0.12 above the error 300 give; 1000
/// gain little more. At about a tenth of a video iteration each, 300 cost about 30
/// video iterations.
pub const STILL_ITERS: usize = 300;

/// Iterations after which `auto` checks the still image's residual.
pub const STILL_CHECK_ITERS: usize = 50;

/// The largest relative residual `||A x0 - b|| / ||b||` of the still image at which
/// `auto` starts from it: a mostly still scene. Measured residuals: 0.02 on the dense
/// benchmark scene; 0.59 (LED array) and 0.81 (moving disc) at paper-8x.
pub const STILL_RESIDUAL_MAX: f64 = 0.1;

/// What the still solve did (summary.json's `start`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StillReport {
    /// Whether the video solve started from the still image (`false`: its residual was
    /// above [`STILL_RESIDUAL_MAX`] after the check, and the solve started from zero).
    pub used: bool,
    pub iterations: usize,
    /// Seconds of the still solve, its Lipschitz measurement included (and the still
    /// check's it went on from, [`still_image_after`]). The video solve's trace starts
    /// after them.
    pub seconds: f64,
    /// `lambda_max` of the still operator (with the usual margin).
    pub lipschitz: f64,
    /// `||A x0 - b|| / ||b||` of the still image.
    pub residual_rel: f64,
    /// The still image (rows x cols of the video), taken or not: the fit report's still
    /// ([`crate::solve::fit`]).
    #[serde(skip)]
    pub image: Option<Vec<f32>>,
}

/// The still problem of `model`'s capture: its operator and prior (the video prior's
/// still form, [`PriorSpec::still`]).
struct StillProblem<'a> {
    op: Still<'a>,
    prior: Box<dyn Prox>,
    lipschitz: f64,
    settings: OptimizerSettings,
}

impl<'a> StillProblem<'a> {
    /// `lipschitz`: the still operator's constant when already measured (a still check
    /// of the same model), else measured here.
    fn new(model: &'a RollingShutterModel, data: &DataTerm, prior: &PriorSpec, lipschitz: Option<f64>) -> Self {
        let op = Still::new(model);
        let lipschitz = lipschitz.unwrap_or_else(|| power_iteration(&op, 100, 1e-6, 1).lambda_max * LIPSCHITZ_MARGIN);
        let atb_max = adjoint_peak(&op, data.observations()) as f64;
        let still = PriorSpec::Tv(prior.still(model.frames(), op.image_shape(), atb_max));
        let settings = OptimizerSettings::new(SolverKind::FistaRestart, lipschitz, StopRule::iterations(1));
        StillProblem { op, prior: still.build(None), lipschitz, settings }
    }

    /// `iters` more iterations from `x0`; `None` when the solve went non-finite (the
    /// video solve from zero then reports its own trouble).
    fn run(&mut self, data: &DataTerm, x0: Option<Vec<f32>>, iters: usize) -> Option<(Vec<f32>, usize)> {
        if !(self.lipschitz > 0.0 && self.lipschitz.is_finite()) {
            return None;
        }
        self.settings.stop = StopRule::iterations(iters);
        let r = run(ChannelJob { settings: &self.settings, operator: &self.op, data, prior: self.prior.as_ref(), start: x0 }, &mut NoObserver);
        (!matches!(r.termination, Termination::NonFinite { .. }) && r.x.iter().all(|v| v.is_finite())).then_some((r.x, r.iterations))
    }

    /// The first `iters` iterations from zero: the image, the iterations run and its
    /// relative residual ([`Self::residual_rel`]); `None` as [`Self::run`].
    fn first(&mut self, model: &RollingShutterModel, data: &DataTerm, iters: usize) -> Option<(Vec<f32>, usize, f64)> {
        let (image, iterations) = self.run(data, None, iters)?;
        let residual_rel = self.residual_rel(model, &image, data);
        Some((image, iterations, residual_rel))
    }

    /// `||M (A x - b)|| / ||M b||` over the pixels the data term counts (the mask `M`
    /// of `model`; a clipped pixel counts only where `A x` falls below it).
    fn residual_rel(&self, model: &RollingShutterModel, image: &[f32], data: &DataTerm) -> f64 {
        let mut ax = vec![0.0f32; self.op.output_len()];
        self.op.forward(image, &mut ax);
        residual_rel(&ax, data, model.mask())
    }
}

/// `||M (A x - b)|| / ||M b||` given `ax = A x`, over the pixels the data term counts
/// (the sensor mask `M`; a clipped pixel counts only where `A x` falls below it); 0 for
/// an all-zero `M b`.
pub(crate) fn residual_rel(ax: &[f32], data: &DataTerm, mask: Option<&[f32]>) -> f64 {
    let mut resid = vec![0.0f32; ax.len()];
    data.residual_into(ax, &mut resid);
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (i, (&r, &q)) in resid.iter().zip(data.observations()).enumerate() {
        let m = mask.map_or(1.0, |m| m[i]) as f64;
        num += (m * r as f64).powi(2);
        den += (m * q as f64).powi(2);
    }
    if den > 0.0 {
        (num / den).sqrt()
    } else {
        0.0
    }
}

/// The still image of `model`'s capture (`data`) under `start`, for a video of
/// `frames` frames whose prior is `prior`: FISTA with restart on the still problem, the
/// prior's still form ([`PriorSpec::still`]). Returns the image when the video solve starts from it, and the report
/// whenever the still problem was solved (`auto` checks the residual after
/// [`STILL_CHECK_ITERS`] and stops there above [`STILL_RESIDUAL_MAX`]).
pub fn still_image(start: Start, model: &RollingShutterModel, data: &DataTerm, prior: &PriorSpec, frames: usize) -> (Option<Vec<f32>>, Option<StillReport>) {
    still_image_after(start, model, data, prior, frames, None)
}

/// [`still_image`] after the check `checked` ([`check`] of the same model and data,
/// made to choose the scene model): its image is the first [`STILL_CHECK_ITERS`]
/// iterations, its residual `auto`'s verdict and its Lipschitz constant the step's, so
/// the still problem is not solved twice. With `auto` under the check's own prior the
/// result is the one [`still_image`] gives; under another (the static + dynamic model's weight)
/// the solve goes on from the check's image at the new weight. The report's seconds
/// include the check's.
pub fn still_image_after(
    start: Start,
    model: &RollingShutterModel,
    data: &DataTerm,
    prior: &PriorSpec,
    frames: usize,
    checked: Option<&StillReport>,
) -> (Option<Vec<f32>>, Option<StillReport>) {
    if !start.uses_still(frames) {
        return (None, None);
    }
    let clock = std::time::Instant::now();
    let mut p = StillProblem::new(model, data, prior, checked.map(|c| c.lipschitz));
    let check = if start == Start::Auto { STILL_CHECK_ITERS.min(STILL_ITERS) } else { STILL_ITERS };
    let first = match checked {
        Some(StillReport { image: Some(image), iterations, residual_rel, .. }) => Some((image.clone(), *iterations, *residual_rel)),
        _ => p.first(model, data, check),
    };
    let (mut image, mut iterations, mut residual_rel) = first.unwrap_or_else(|| {
        let zero = vec![0.0f32; p.op.input_len()];
        let r = p.residual_rel(model, &zero, data);
        (zero, 0, r)
    });
    let used = iterations > 0 && (start == Start::Still || explains(residual_rel));
    if used && iterations < STILL_ITERS {
        if let Some((more, n)) = p.run(data, Some(image.clone()), STILL_ITERS - iterations) {
            image = more;
            iterations += n;
            residual_rel = p.residual_rel(model, &image, data);
        }
    }
    let kept = (iterations > 0).then(|| image.clone());
    let seconds = clock.elapsed().as_secs_f64() + checked.map_or(0.0, |c| c.seconds);
    let report = StillReport { used, iterations, seconds, lipschitz: p.lipschitz, residual_rel, image: kept };
    if used {
        tracing::info!(iterations, seconds = report.seconds, residual_rel, "still start");
    } else {
        tracing::info!(
            iterations,
            seconds = report.seconds,
            residual_rel,
            "still start not taken: the still image leaves {residual_rel:.3} of the raw unexplained (more than {STILL_RESIDUAL_MAX}); the solve starts from zero"
        );
    }
    (used.then_some(image), Some(report))
}

/// The still image of `model`'s capture after `iters` iterations from zero, under the
/// still form of `prior` (as [`still_image`] solves it); `None` when the solve went
/// non-finite.
pub fn still_fit(model: &RollingShutterModel, data: &DataTerm, prior: &PriorSpec, iters: usize) -> Option<Vec<f32>> {
    StillProblem::new(model, data, prior, None).run(data, None, iters).map(|(image, _)| image)
}

/// `auto`'s check as a report: the still image after [`STILL_CHECK_ITERS`] iterations,
/// its residual, `used` whether `auto` would take it, the still operator's constant and
/// the seconds (the power iteration included); `None` when the still solve went
/// non-finite. [`still_image_after`] goes on from it.
pub fn check(model: &RollingShutterModel, data: &DataTerm, prior: &PriorSpec) -> Option<StillReport> {
    let clock = std::time::Instant::now();
    let mut p = StillProblem::new(model, data, prior, None);
    let (image, iterations, residual_rel) = p.first(model, data, STILL_CHECK_ITERS)?;
    let used = explains(residual_rel);
    Some(StillReport { used, iterations, seconds: clock.elapsed().as_secs_f64(), lipschitz: p.lipschitz, residual_rel, image: Some(image) })
}

/// `auto`'s rule: the still image is taken when it explains the raw to within
/// [`STILL_RESIDUAL_MAX`].
fn explains(residual_rel: f64) -> bool {
    residual_rel <= STILL_RESIDUAL_MAX
}

/// The start of a video solve whose unknowns are `to_unknowns` of `model`'s video
/// (the identity, or a scene declaration's restriction) with `frames` frames, under
/// `start` ([`still_image_after`] the check `checked`, when one was made): the still
/// image repeated in every frame (`[T]::repeat`; or `None`: from zero), and the still
/// solve's report.
pub fn video_start(
    start: Start,
    model: &RollingShutterModel,
    data: &DataTerm,
    prior: &PriorSpec,
    frames: usize,
    to_unknowns: &dyn Fn(Vec<f32>) -> Vec<f32>,
    checked: Option<&StillReport>,
) -> (Option<Vec<f32>>, Option<StillReport>) {
    let (image, report) = still_image_after(start, model, data, prior, frames, checked);
    (image.map(|i| to_unknowns(i.repeat(model.frames()))), report)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::model::capture::Fov;
    use crate::model::op::pseudo_random;
    use crate::model::shutter::{ShutterMode, Timing};
    use crate::solve::optimize::{Fista, RestartTest};
    use crate::solve::prox::prior::TvPrior;
    use crate::solve::prox::tv_dual::TvProxChoice;
    use crate::solve::prox::TotalVariation;

    /// The video prior of these tests: TV at `tau`, alpha 5, the map chosen by `auto`.
    fn prior(shape: (usize, usize, usize)) -> PriorSpec {
        PriorSpec::Tv(TvPrior::new(TotalVariation::new(shape, 1e-4, 5.0), TvProxChoice::Auto, 0.0))
    }

    /// A 12 x 10 dual-shutter model with a peaked pseudo-random PSF, and its video shape
    /// (the static + dynamic model's tests use it too).
    pub(crate) fn model() -> (RollingShutterModel, (usize, usize, usize)) {
        let (m, n) = (12, 10);
        let mut psf = pseudo_random(m * n, 3);
        psf.iter_mut().for_each(|v| *v = (*v + 0.5).powi(4));
        let weights = Timing::new(m, 10.0, 30.0, ShutterMode::Dual).weights().unwrap();
        let model = RollingShutterModel::of_psf(&psf, m, n, Fov::Sensor, weights);
        let shape = model.video_shape();
        (model, shape)
    }

    /// Light that changes in time: a still image cannot explain it, so `auto` stops
    /// after the check and starts from zero; `still` takes it anyway.
    #[test]
    fn auto_leaves_a_flashing_scene_to_the_zero_start() {
        let (model, (k, m, n)) = model();
        // One bright pixel lit in every other frame.
        let mut video = vec![0.0f32; k * m * n];
        for f in (0..k).step_by(2) {
            video[f * m * n + 5 * n + 5] = 100.0;
        }
        let mut b = vec![0.0f32; m * n];
        model.forward(&video, &mut b);
        let (data, prior) = (DataTerm::new(&b), prior((k, m, n)));
        let (image, report) = still_image(Start::Auto, &model, &data, &prior, k);
        let report = report.unwrap();
        assert!(image.is_none() && !report.used, "{report:?}");
        assert_eq!(report.iterations, STILL_CHECK_ITERS);
        assert!(report.residual_rel > STILL_RESIDUAL_MAX, "{report:?}");
        let (image, report) = still_image(Start::Still, &model, &data, &prior, k);
        assert!(image.is_some() && report.unwrap().used);
        assert_eq!(still_image(Start::Zero, &model, &data, &prior, k), (None, None));
        // The check alone says the same, with the same residual.
        let (auto_report, checked) = (still_image(Start::Auto, &model, &data, &prior, k).1.unwrap(), check(&model, &data, &prior).unwrap());
        assert_eq!((checked.residual_rel, checked.used), (auto_report.residual_rel, false));
    }

    /// The still start after the check that chose the scene model: under the check's
    /// prior, what a still start of its own gives (without solving the check's
    /// iterations again); under another weight, the solve at that weight from the
    /// check's image; after a check `auto` refuses, the check itself.
    #[test]
    fn a_still_start_goes_on_from_the_check() {
        let (model, (k, m, n)) = model();
        let scene: Vec<f32> = pseudo_random(m * n, 4).iter().map(|v| 2.0 + v).collect();
        let mut b = vec![0.0f32; m * n];
        model.forward(&scene.repeat(k), &mut b);
        let (data, prior) = (DataTerm::new(&b), prior((k, m, n)));
        let checked = check(&model, &data, &prior).unwrap();
        assert!(checked.used && checked.iterations == STILL_CHECK_ITERS && checked.image.is_some(), "{checked:?}");
        let (own, own_report) = still_image(Start::Auto, &model, &data, &prior, k);
        let (after, report) = still_image_after(Start::Auto, &model, &data, &prior, k, Some(&checked));
        let report = report.unwrap();
        assert_eq!(after, own);
        assert_eq!((report.iterations, report.residual_rel, report.lipschitz), {
            let o = own_report.unwrap();
            (o.iterations, o.residual_rel, o.lipschitz)
        });
        assert!(report.seconds >= checked.seconds);
        // Another weight: the check's image goes on at it, near the still start of its own.
        let half = PriorSpec::Tv(TvPrior::new(TotalVariation::new((k, m, n), 5e-5, 5.0), TvProxChoice::Auto, 0.0));
        let (at_half, _) = still_image(Start::Auto, &model, &data, &half, k);
        let (after_half, report) = still_image_after(Start::Auto, &model, &data, &half, k, Some(&checked));
        let (at_half, after_half) = (at_half.unwrap(), after_half.unwrap());
        assert_eq!(report.unwrap().iterations, STILL_ITERS);
        let diff = at_half.iter().zip(&after_half).map(|(p, q)| ((p - q) as f64).powi(2)).sum::<f64>().sqrt();
        let norm = at_half.iter().map(|&p| (p as f64).powi(2)).sum::<f64>().sqrt();
        assert!(diff < 1e-2 * norm, "{diff} of {norm}");
        // A check `auto` refuses: no start, the check's report (its image for the fit).
        let mut flash = vec![0.0f32; k * m * n];
        (0..k).step_by(2).for_each(|f| flash[f * m * n + 5 * n + 5] = 100.0);
        model.forward(&flash, &mut b);
        let data = DataTerm::new(&b);
        let refused = check(&model, &data, &prior).unwrap();
        let (image, report) = still_image_after(Start::Auto, &model, &data, &prior, k, Some(&refused));
        let report = report.unwrap();
        assert!(image.is_none() && !report.used && report.iterations == STILL_CHECK_ITERS);
        assert_eq!((report.residual_rel, &report.image), (refused.residual_rel, &refused.image));
        assert_eq!(still_image(Start::Auto, &model, &data, &prior, k).1.unwrap().residual_rel, refused.residual_rel);
    }

    #[test]
    fn start_names_round_trip_and_auto_skips_one_frame() {
        for s in Start::ALL {
            assert_eq!(s.name().parse::<Start>().unwrap(), s);
        }
        assert!("cold".parse::<Start>().unwrap_err().contains("auto, still or zero"));
        assert!(Start::Auto.uses_still(2) && !Start::Auto.uses_still(1));
        assert!(Start::Still.uses_still(1) && !Start::Zero.uses_still(5));
        assert!(check_for_sequence(Start::Auto).is_ok() && check_for_sequence(Start::Zero).is_ok());
        assert_eq!(check_for_sequence(Start::Still).unwrap_err().0, "start");
    }

    /// A still scene: the still image is that scene's solution, and the video solve
    /// from it starts at (and stays near) an objective a solve from zero needs many
    /// iterations for.
    #[test]
    fn still_start_of_a_still_scene_is_already_a_good_video() {
        let (model, (k, m, n)) = model();
        let scene: Vec<f32> = pseudo_random(m * n, 4).iter().map(|v| 2.0 + v).collect();
        let video = scene.repeat(k);
        let mut b = vec![0.0f32; m * n];
        model.forward(&video, &mut b);
        let tv = TotalVariation::new((k, m, n), 1e-4, 5.0);
        let (data, prior) = (DataTerm::new(&b), prior((k, m, n)));
        let (image, report) = still_image(Start::Auto, &model, &data, &prior, k);
        let (image, report) = (image.expect("a still scene takes the still start"), report.unwrap());
        let StillReport { residual_rel: residual, used: taken, .. } = check(&model, &data, &prior).unwrap();
        assert!(taken && residual <= STILL_RESIDUAL_MAX, "{residual}");
        assert!(report.used && report.seconds > 0.0 && report.lipschitz > 0.0);
        assert_eq!(report.iterations, STILL_ITERS);
        assert!(report.residual_rel < 1e-2, "still residual {}", report.residual_rel);
        let x0 = image.repeat(k);
        let l = power_iteration(&model, 100, 1e-6, 1).lambda_max * LIPSCHITZ_MARGIN;
        let objective = |x: &[f32]| {
            let mut ax = vec![0.0f32; m * n];
            model.forward(x, &mut ax);
            0.5 * ax.iter().zip(&b).map(|(p, q)| ((p - q) as f64).powi(2)).sum::<f64>() + Prox::value(&tv, x)
        };
        let fista = |x0: Option<Vec<f32>>, iters: usize| {
            Fista { lipschitz: l, stop: StopRule::iterations(iters), restart: Some(RestartTest::Objective) }.solve(&model, &data, &tv, x0, &mut NoObserver).x
        };
        let (from_still, from_zero) = (objective(&fista(Some(x0), 20)), objective(&fista(None, 20)));
        assert!(from_still < 0.1 * from_zero, "after 20 iterations: from the still start {from_still}, from zero {from_zero}");
    }
}
