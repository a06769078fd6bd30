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
//! Measured in docs/dense-scenes.md ("Faster convergence"): on the dense benchmark
//! scene the video solve from the still start passes, in its first iteration, the error
//! a solve from zero reaches after 600; on the LED scene it ends 200 iterations at a
//! relative error of 0.63 against 0.82.

use crate::model::op::Operator;
use crate::model::rolling::RollingShutterModel;
use crate::model::still::Still;
use crate::solve::lipschitz::{power_iteration, LIPSCHITZ_MARGIN};
use crate::solve::optimize::{solve, NoObserver, SolverKind, SolverSettings, StopRule, Termination};
use crate::solve::problem::InvalidSetting;
use crate::solve::prox::tv::TotalVariation;
use crate::solve::prox::tv_dual::TvProxChoice;
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
/// refused. The error is (field, value, expected), as [`crate::solve::problem::InvalidSetting`].
pub fn check_for_sequence(start: Start) -> Result<(), InvalidSetting> {
    match start {
        Start::Still => Err(InvalidSetting {
            field: "start",
            value: start.name().into(),
            expected: "auto or zero for consecutive captures: each window starts from the result so far (from zero with --cold-start); the still start is for single captures",
        }),
        Start::Auto | Start::Zero => Ok(()),
    }
}

/// Iterations of the still solve. Measured on the 240 x 320 LED and dense scenes
/// (docs/dense-scenes.md): 100 leaves the LED video 0.12 above the error 300 give; 1000
/// gain little more. At about a tenth of a video iteration each, 300 cost about 30
/// video iterations.
pub const STILL_ITERS: usize = 300;

/// What the still solve did (summary.json's `start`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StillReport {
    pub iterations: usize,
    /// Seconds of the still solve, its Lipschitz measurement included. The video
    /// solve's trace starts after them.
    pub seconds: f64,
    /// `lambda_max` of the still operator (with the usual margin).
    pub lipschitz: f64,
    /// `||A x0 - b|| / ||b||` of the start.
    pub residual_rel: f64,
}

/// The still image of `model`'s capture `b`: FISTA with restart on the still problem,
/// whose TV is the video's spatial TV (`tv`'s weights and non-negativity) with weight
/// `tv.tau` times the model's frames, the TV map chosen as the video's (`tv_prox`).
/// Returns the image (one frame of `model`'s video grid) and the report.
pub fn still_image(model: &RollingShutterModel, b: &[f32], tv: &TotalVariation, tv_prox: TvProxChoice, iters: usize) -> (Vec<f32>, StillReport) {
    let clock = std::time::Instant::now();
    let still = Still::new(model);
    let (m, n) = still.image_shape();
    let still_tv = TotalVariation { shape: (1, m, n), tau: tv.tau * model.frames() as f32, weights: tv.weights, nonneg: tv.nonneg };
    let lipschitz = power_iteration(&still, 100, 1e-6, 1).lambda_max * LIPSCHITZ_MARGIN;
    let (mut image, mut iterations) = (vec![0.0f32; m * n], 0);
    if lipschitz > 0.0 && lipschitz.is_finite() {
        let mut atb = vec![0.0f32; m * n];
        still.adjoint(b, &mut atb);
        let atb_max = atb.iter().fold(0.0f32, |a, &v| a.max(v)) as f64;
        let mut settings = SolverSettings::new(SolverKind::FistaRestart, lipschitz, StopRule::iterations(iters));
        settings.tv_prox = tv_prox.resolve(&still_tv, atb_max);
        let r = solve(&settings, &still, b, &still_tv, None, &mut NoObserver);
        // A still solve that went non-finite gives no start (the video solve from zero
        // reports its own trouble).
        if !matches!(r.termination, Termination::NonFinite { .. }) && r.x.iter().all(|v| v.is_finite()) {
            image = r.x;
        }
        iterations = r.iterations;
    }
    let mut ax = vec![0.0f32; still.output_len()];
    still.forward(&image, &mut ax);
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (&p, &q) in ax.iter().zip(b) {
        num += ((p - q) as f64).powi(2);
        den += (q as f64).powi(2);
    }
    let residual_rel = if den > 0.0 { (num / den).sqrt() } else { 0.0 };
    (image, StillReport { iterations, seconds: clock.elapsed().as_secs_f64(), lipschitz, residual_rel })
}

/// The start of a video solve whose unknowns are `to_unknowns` of `model`'s video
/// (the identity, or a scene declaration's restriction) with `frames` frames, under
/// `start`: the still image of `model`'s problem repeated in every frame, or `None`
/// (from zero). `tv` carries the video's TV weight and axis weights.
pub fn video_start(
    start: Start,
    model: &RollingShutterModel,
    b: &[f32],
    tv: &TotalVariation,
    tv_prox: TvProxChoice,
    frames: usize,
    to_unknowns: &dyn Fn(Vec<f32>) -> Vec<f32>,
) -> Option<(Vec<f32>, StillReport)> {
    if !start.uses_still(frames) {
        return None;
    }
    let (image, report) = still_image(model, b, tv, tv_prox, STILL_ITERS);
    tracing::info!(iterations = report.iterations, seconds = report.seconds, residual_rel = report.residual_rel, "still start");
    Some((to_unknowns(Still::new(model).repeat(&image)), report))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::capture::Fov;
    use crate::model::op::pseudo_random;
    use crate::model::shutter::{ShutterMode, Timing};
    use crate::solve::optimize::Fista;
    use crate::solve::prox::tv::Prox;

    #[test]
    fn start_names_round_trip_and_auto_skips_one_frame() {
        for s in Start::ALL {
            assert_eq!(s.name().parse::<Start>().unwrap(), s);
        }
        assert!("cold".parse::<Start>().unwrap_err().contains("auto, still or zero"));
        assert!(Start::Auto.uses_still(2) && !Start::Auto.uses_still(1));
        assert!(Start::Still.uses_still(1) && !Start::Zero.uses_still(5));
        assert!(check_for_sequence(Start::Auto).is_ok() && check_for_sequence(Start::Zero).is_ok());
        assert_eq!(check_for_sequence(Start::Still).unwrap_err().field, "start");
    }

    /// A still scene: the still image is that scene's solution, and the video solve
    /// from it starts at (and stays near) an objective a solve from zero needs many
    /// iterations for.
    #[test]
    fn still_start_of_a_still_scene_is_already_a_good_video() {
        let (m, n) = (12, 10);
        let mut psf = pseudo_random(m * n, 3);
        psf.iter_mut().for_each(|v| *v = (*v + 0.5).powi(4));
        let weights = Timing::new(m, 10.0, 30.0, ShutterMode::Dual).weights().unwrap();
        let model = RollingShutterModel::of_psf(&psf, m, n, Fov::Sensor, weights);
        let (k, _, _) = model.video_shape();
        let scene: Vec<f32> = pseudo_random(m * n, 4).iter().map(|v| 2.0 + v).collect();
        let video = Still::new(&model).repeat(&scene);
        let mut b = vec![0.0f32; m * n];
        model.forward(&video, &mut b);
        let tv = TotalVariation::new((k, m, n), 1e-4, 5.0);
        let (image, report) = still_image(&model, &b, &tv, TvProxChoice::Auto, 2000);
        assert!(report.seconds > 0.0 && report.lipschitz > 0.0);
        assert_eq!(report.iterations, 2000);
        assert!(report.residual_rel < 1e-2, "still residual {}", report.residual_rel);
        let x0 = Still::new(&model).repeat(&image);
        let l = power_iteration(&model, 100, 1e-6, 1).lambda_max * LIPSCHITZ_MARGIN;
        let objective = |x: &[f32]| {
            let mut ax = vec![0.0f32; m * n];
            model.forward(x, &mut ax);
            0.5 * ax.iter().zip(&b).map(|(p, q)| ((p - q) as f64).powi(2)).sum::<f64>() + tv.value(x)
        };
        let fista = |x0: Option<Vec<f32>>, iters: usize| {
            Fista { lipschitz: l, stop: StopRule::iterations(iters), restart: true }.solve(&model, &b, &tv, x0, &mut NoObserver).x
        };
        let (from_still, from_zero) = (objective(&fista(Some(x0), 20)), objective(&fista(None, 20)));
        assert!(from_still < 0.1 * from_zero, "after 20 iterations: from the still start {from_still}, from zero {from_zero}");
    }
}
