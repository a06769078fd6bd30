//! The static + dynamic scene model's solve (`[scene] static_background = true`):
//! `v_k = s + d_k` with
//!
//! `min 0.5||A (1 ⊗ s + d) - b||^2 + tau K TV_xy(s) + tau TV_w(d) + lambda ||d||_1`
//! `s.t. s >= 0, s + d_k >= 0`,
//!
//! where `K` is the number of frames (the static image's TV counts once per frame it
//! stands for, as a static scene's does, so a still video costs the same as in the
//! plain problem) and `lambda = l1 tau` ([`crate::solve::problem::default_l1`]).
//!
//! ## Steps per block
//! The static block's Lipschitz constant `L_s` (of `s -> A (1 ⊗ s)`) is far larger than
//! the dynamic block's `L_d` (of `A`): every row sees `s` over its whole exposure. One
//! step `1/L` for both would freeze `d`. The solve works on scaled unknowns
//! ([`StaticPlusDynamic`] with `c = (1/sqrt(L_s), 1/sqrt(L_d))`), where a plain step is
//! `1/L_s` on `s` and `1/L_d` on `d` times one common factor, `1/L_z`, with `L_z` the
//! measured constant of the scaled operator (at most 2). All three constants are
//! measured by power iteration and kept in the Lipschitz cache.

use crate::model::data::DataTerm;
use crate::model::keyframe::Fused;
use crate::model::op::Operator;
use crate::model::rolling::RollingShutterModel;
use crate::model::scene::{Colour, SceneSpec};
use crate::model::static_dynamic::StaticPlusDynamic;
use crate::solve::channel::{
    ChannelReport, ChannelSolve, FrameSensitivity, FullGrid, Hooks, ModelChoice, Reconstruction, StaticBackground, StaticDynamicChannel, StaticDynamicReport,
};
use crate::solve::job::{run, ChannelJob};
use crate::solve::keyframes::KeyFrameData;
use crate::solve::lipschitz::{EigenStore, LIPSCHITZ_MARGIN};
use crate::solve::optimize::fista::RestartTest;
use crate::solve::optimize::OptimizerSettings;
use crate::solve::optimize::{IterInfo, StopRule, Termination};
use crate::solve::problem::{adjoint_peak, PriorRecipe, Problem, ReconstructError, ReweightPlan, SolveParams};
use crate::solve::prox::prior::{PriorSpec, TvPrior};
use crate::solve::prox::sparse::reweight;
use crate::solve::prox::TotalVariation;
use crate::solve::start::{still_image_after, Start, StillReport};
use crate::solve::trace::motion_error;
use ndarray::{Array3, Array4, Axis};
use rayon::prelude::*;

/// The static block's share of the scaled operator's constant: `c_s = sqrt(share /
/// L_s)`, so the scaled constant `L_z` is at most `share + 1` and the dynamic part's
/// step `1 / (L_d L_z)` stays near its own `1 / L_d`. The static image starts from the
/// still (the key frames' or the raw's) and needs short steps; the moving part is what
/// converges last. Measured on the 240 x 320 x 122 disc and occluder with key frames
/// (docs/keyframes.md): share 1 (the steps of both blocks' own constants, `L_z` 1.68)
/// gave motion errors 0.585 / 0.785, 0.25 gave 0.543 / 0.739, 0.1 gave 0.521 / 0.733.
pub const STATIC_STEP_SHARE: f64 = 0.1;

/// The largest gain [`refit_dynamic_scale`] gives the dynamic part. The priors shrink
/// the moving part (L1 and TV pull it toward zero), so the data's least-squares gain is
/// at least 1 where the shape is right; measured 1.8-3.6 after the first round and
/// 1.1-1.5 after the last on the 240 x 320 discs (docs/dense-scenes.md). A larger one
/// comes from a moving part that is not the data's shape (an occluder whose motion the
/// raw does not hold: 4 and more after every round, motion error 0.92 -> 1.03 when
/// applied), so it is refused and the solve refits no more.
pub const MAX_DYNAMIC_GAIN: f64 = 4.0;

/// Reweighted L1: `eps` of the weights relative to the dynamic part's 99.9th
/// percentile magnitude ([`reweight`]).
pub const REWEIGHT_EPS: f32 = 0.1;

/// The static + dynamic model's solve of every channel of a problem: what each
/// channel's solve reads.
pub(crate) struct StaticDynamicSolve<'a> {
    pub problem: &'a Problem<'a>,
    pub params: &'a SolveParams,
    pub spec: &'a SceneSpec,
    /// Where the scene was declared (`capture.toml` or `options`).
    pub declared_in: &'static str,
    /// Why the model is solved.
    pub chosen_by: ModelChoice,
    pub recipe: PriorRecipe,
    /// Reweighted-L1 rounds after the first solve and their budget.
    pub reweight: ReweightPlan,
    /// Per channel, the truth on the full video grid.
    pub truth_planes: Option<Vec<Vec<f32>>>,
    pub cache: &'a dyn EigenStore,
    pub hooks: &'a Hooks<'a>,
    /// The still checks that chose the model, one per channel (empty when none was
    /// made): the static image's start goes on from them.
    pub still_checks: &'a [StillReport],
    /// The data terms beside the model: the raw, or the raw and the key frames.
    pub data_terms: DataTerms,
}

/// What the static + dynamic model is fitted to.
#[derive(Clone, Copy, Debug)]
pub(crate) enum DataTerms {
    /// The raw alone.
    Raw,
    /// The raw and its key frames, weighed by the raw's noise (measured once for every
    /// channel; `None`: not measurable).
    RawAndKeyFrames { raw_sigma: Option<f32> },
}

/// One channel's result: the video, the static image, the report and the model's
/// figures.
type ChannelOut = (Vec<f32>, Vec<f32>, ChannelReport, StaticDynamicChannel);

/// One channel's data and operator on the video ([`StaticDynamicSolve::channel_data`]).
struct ChannelData<'m> {
    /// The key frames' terms, when any.
    terms: Option<crate::solve::keyframes::KeyFrameTerms>,
    /// The raw's operator, stacked with the key frames' maps.
    op: Fused<&'m RollingShutterModel>,
    /// The stacked observations and their lower bounds (the raw's clipped pixels).
    obs: Vec<f32>,
    lower: Option<Vec<bool>>,
    /// The Lipschitz cache key of `op`.
    key: crate::solve::lipschitz::Fingerprint,
    /// `op`'s Lipschitz constant (with the margin) and whether it was cached.
    lipschitz: crate::solve::lipschitz::Lipschitz,
}

/// One channel's two blocks ([`StaticDynamicSolve::blocks`]).
struct Blocks<'m> {
    model: &'m RollingShutterModel,
    data: ChannelData<'m>,
    /// `[L_s, L_d, L_z]`: the static block's, the dynamic block's and the scaled
    /// operator's constants, with the margin.
    l: [f64; 3],
    /// All three came from the cache.
    cached: bool,
    /// `[c_s, c_d]` of [`StaticPlusDynamic`].
    scale: [f32; 2],
    static_part: TvPrior,
    dynamic_part: TvPrior,
}

impl Blocks<'_> {
    /// The scaled operator on `z = [z_s; z_d]`.
    fn op(&self) -> StaticPlusDynamic<&Fused<&RollingShutterModel>> {
        StaticPlusDynamic::new(&self.data.op, self.scale)
    }

    /// The stacked data term.
    fn data(&self) -> DataTerm<'_> {
        DataTerm::new(&self.data.obs).with_lower_bounds(self.data.lower.as_deref())
    }

    /// The prior of both blocks, the dynamic part's L1 weighted by `l1_weights`.
    fn prior(&self, l1_weights: Option<Vec<f32>>) -> PriorSpec {
        let (_, m, n) = self.model.video_shape();
        PriorSpec::StaticDynamic {
            static_part: self.static_part.clone(),
            dynamic_part: TvPrior { l1_weights, ..self.dynamic_part.clone() },
            scale: self.scale,
            pixels: m * n,
        }
    }

    /// The scaled unknowns of the static image `image` with the dynamic part zero;
    /// `None` without an image.
    fn z0(&self, image: Option<Vec<f32>>) -> Option<Vec<f32>> {
        let (k, m, n) = self.model.video_shape();
        let px = m * n;
        image.map(|image| {
            let mut z = vec![0.0f32; px * (k + 1)];
            z[..px].iter_mut().zip(&image).for_each(|(z, &v)| *z = v / self.scale[0]);
            z
        })
    }
}

impl<'a> StaticDynamicSolve<'a> {
    /// Solve every channel with the static + dynamic model.
    pub(crate) fn reconstruct(&self) -> Result<Reconstruction, ReconstructError> {
        let (problem, params, spec) = (self.problem, self.params, self.spec);
        let (prepared, cfg) = (problem.prepared, problem.cfg);
        debug_assert!(!params.solver.shrinks_tv_itself(), "the caller refuses the ADMMs");
        debug_assert!(spec.colour != Colour::Grey && spec.support.is_none() && spec.frames.is_none() && !spec.static_scene);
        let models = problem.models();
        let (k, mv, nv) = models[0].video_shape();
        let offset = models[0].conv().offset();
        let pixels = mv * nv;
        tracing::info!(declared_in = self.declared_in, "static + dynamic scene model: one static image and a dynamic video, v_k = s + d_k");
        let out: Vec<ChannelOut> = (0..models.len()).into_par_iter().map(|ch| self.channel(ch)).collect::<Result<_, _>>()?;

        let channels = out.len();
        let mut video = Array4::<f32>::zeros((k, mv, nv, channels));
        let mut static_image = Array3::<f32>::zeros((mv, nv, channels));
        let mut reports = Vec::new();
        let mut infos = Vec::new();
        for (ch, (v, s, mut rep, info)) in out.into_iter().enumerate() {
            rep.motion_error = self.truth_planes.as_ref().and_then(|t| motion_error(&v, &t[ch], k));
            video.index_axis_mut(Axis(3), ch).assign(&ndarray::ArrayView3::from_shape((k, mv, nv), &v).expect("video shape"));
            static_image.index_axis_mut(Axis(2), ch).assign(&ndarray::ArrayView2::from_shape((mv, nv), &s).expect("image shape"));
            reports.push(rep);
            infos.push(info);
        }
        let frame_sensitivity = FrameSensitivity::of(&models, prepared).with_video(&video);
        Ok(Reconstruction {
            video,
            frame_time_us: cfg.timing().frame_time_us(),
            sensor_offset: offset,
            channels: reports,
            scene: None,
            frame_sensitivity,
            static_background: Some(StaticBackground {
                image: static_image,
                report: StaticDynamicReport { chosen_by: self.chosen_by, unknowns_plain: k * pixels, unknowns_solved: (k + 1) * pixels, channels: infos },
            }),
            split: None,
            tau_search: None,
            fit: None,
            estimated_seconds: None,
            plan: None,
        })
    }

    /// Channel `ch`'s data and the operator on the video: the raw alone, or with key
    /// frames the stacked operator of the raw and the key frames
    /// ([`crate::solve::keyframes`]; they see `s + d_k` over their windows, so the static
    /// image is pinned by them and the raw), with its Lipschitz constant and cache key.
    fn channel_data<'m>(&self, ch: usize, model: &'m RollingShutterModel) -> Result<ChannelData<'m>, ReconstructError>
    where
        'a: 'm,
    {
        let (problem, cache) = (self.problem, self.cache);
        let prepared = problem.prepared;
        match self.data_terms {
            DataTerms::Raw => {
                let (b, lower) = (&prepared.raw[ch].data, prepared.data_mask.lower_bounds.as_deref());
                Ok(ChannelData {
                    terms: None,
                    op: Fused::new(model, Vec::new()),
                    obs: b.to_vec(),
                    lower: lower.map(<[bool]>::to_vec),
                    key: problem.channel(ch).key(),
                    lipschitz: problem.channel(ch).lipschitz(cache),
                })
            }
            DataTerms::RawAndKeyFrames { raw_sigma } => {
                let d =
                    KeyFrameData::of(problem, ch, raw_sigma, &self.recipe, crate::solve::keyframes::STATIC_DYNAMIC_STIFFNESS_CAP, self.params.solver, cache)?;
                Ok(ChannelData { terms: Some(d.terms), op: d.op, obs: d.obs, lower: d.lower, key: d.key, lipschitz: d.lipschitz })
            }
        }
    }

    /// Channel `ch`'s blocks: its data and operator ([`Self::channel_data`]), the
    /// three Lipschitz constants, the scale of the unknowns and the two blocks' priors.
    fn blocks(&self, ch: usize) -> Result<Blocks<'_>, ReconstructError> {
        let (problem, params, recipe, cache) = (self.problem, self.params, self.recipe, self.cache);
        let model: &RollingShutterModel = problem.channel(ch).model();
        let (k, mv, nv) = model.video_shape();
        let [wt, wy, wx] = self.spec.tv_weights.unwrap_or([params.alpha, 1.0, 1.0]);
        let data = self.channel_data(ch, model)?;
        let static_only = StaticPlusDynamic::new(&data.op, [1.0, 0.0]);
        let (e_s, cached_s) = cache.get_or_measure(data.key.bytes(b"static-sum-v1"), &static_only);
        let l_s = e_s.lambda_max * LIPSCHITZ_MARGIN;
        let l_d = data.lipschitz.value;
        let scale = [(STATIC_STEP_SHARE / l_s).sqrt() as f32, (1.0 / l_d.sqrt()) as f32];
        let (e_z, cached_z) = cache.get_or_measure(data.key.bytes(b"static-dynamic-scaled-v1").f32s(&scale), &StaticPlusDynamic::new(&data.op, scale));
        let l_z = e_z.lambda_max * LIPSCHITZ_MARGIN;
        let tv_s = TotalVariation { shape: (1, mv, nv), tau: recipe.static_tau(k, data.terms.is_some()), weights: [0.0, wy, wx], nonneg: false };
        let tv_d = TotalVariation { shape: (k, mv, nv), tau: recipe.tau, weights: [wt, wy, wx], nonneg: false };
        // The TV maps' choice (auto: the exact dual map at strong TV) per block, on
        // each block's own scale of A^T b.
        let atb_s = adjoint_peak(&static_only, &data.obs) as f64;
        let atb_d = problem.channel(ch).atb_max() as f64;
        Ok(Blocks {
            model,
            cached: data.lipschitz.cached && cached_s && cached_z,
            static_part: TvPrior::new(tv_s, recipe.tv_prox, atb_s),
            dynamic_part: TvPrior::new(tv_d, recipe.tv_prox, atb_d).with_l1(recipe.l1(recipe.tau)),
            data,
            l: [l_s, l_d, l_z],
            scale,
        })
    }

    /// Channel `ch`'s solve: the blocks, the still start, the rounds of reweighted L1
    /// ([`round_stop`]), and the model's figures.
    fn channel(&self, ch: usize) -> Result<ChannelOut, ReconstructError> {
        let (problem, params, hooks) = (self.problem, self.params, self.hooks);
        let b = &problem.prepared.raw[ch].data;
        let raw_data = DataTerm::new(b).with_lower_bounds(problem.prepared.data_mask.lower_bounds.as_deref());
        let blocks = self.blocks(ch)?;
        let (model, l1) = (blocks.model, blocks.dynamic_part.l1);
        let [l_s, l_d, l_z] = blocks.l;
        let (k, mv, nv) = model.video_shape();
        let pixels = mv * nv;
        let truth_planes = &self.truth_planes;
        let (data, op) = (blocks.data(), blocks.op());
        let plan = if l1 > 0.0 { self.reweight } else { ReweightPlan { rounds: 0, budget_iters: None, min_round_iters: 0 } };
        let rounds = plan.rounds;
        let label = format!(
            "{}{}",
            blocks.prior(None).tv_map_name(),
            match (l1 > 0.0, rounds) {
                (false, _) => String::new(),
                (true, 0) => " + L1".into(),
                (true, r) => match plan.budget_iters {
                    Some(b) => format!(" + L1 reweighted in rounds within {b} iterations"),
                    None => format!(" + L1 reweighted {r}x"),
                },
            }
        );
        let strength = blocks.prior(None).haar_strength();

        // The gradient test for restarts: at a reweighted round's start the objective
        // rises under the Haar map while the iterate makes progress, and the objective
        // test reset the momentum every iteration there (an ISTA crawl of ~120
        // iterations on the 240 x 320 occluder).
        let settings = OptimizerSettings { restart_test: RestartTest::Gradient, ..OptimizerSettings::new(params.solver, l_z, params.stop.clone()) };
        let job = ChannelSolve { ch, kind: params.solver, device: params.device, start: params.start, stop: &params.stop, hooks, still_check: None };
        // The still start is the static image's (the dynamic part from zero); with key
        // frames, the still scene they show.
        let (image, start) = match &blocks.data.terms {
            Some(t) if params.start != Start::Zero => (Some(t.background.clone()), None),
            Some(_) => (None, None),
            None => still_image_after(params.start, model, &raw_data, &blocks.prior(None), k, self.still_checks.get(ch)),
        };
        let z0 = blocks.z0(image);
        let truth_ch = truth_planes.as_ref().map(|t| t[ch].as_slice());
        let to_full = |z: &[f32]| op.video(z);
        // The report's Lipschitz figure is the scaled operator's (the step's).
        let mut s = Vec::new();
        let mut rounds_run = Vec::new();
        let mut gains = Vec::new();
        let mut refits = true;
        let (video, mut report) = job.observed(
            (k, mv, nv),
            (&label, strength),
            crate::solve::lipschitz::Lipschitz { value: l_z, cached: blocks.cached },
            FullGrid { truth: truth_ch, to_full: &to_full },
            start,
            |obs| {
                // Round 0 with uniform L1; each further round re-weights the dynamic
                // part's L1 from the last estimate and starts from it ([`round_stop`]).
                // The trace runs on across rounds (iterations and seconds added up).
                let (mut done_iters, mut done_s) = (0usize, 0.0f64);
                let mut weights = None;
                let mut x0 = z0;
                let mut first: Option<(usize, Termination)> = None;
                let mut r = loop {
                    let reg = blocks.prior(weights.take()).build(None);
                    let mut stopped = false;
                    let mut shifted = |i: &IterInfo| {
                        let go = obs.observe(&IterInfo { iteration: i.iteration + done_iters, seconds: i.seconds + done_s, ..*i });
                        stopped |= !go;
                        go
                    };
                    let mut stop = round_stop(&params.stop, plan, first.map(|(n, _)| n), done_iters);
                    // A reweighted round has what the earlier rounds left of the run's
                    // time budget.
                    stop.time_budget_s = stop.time_budget_s.map(|t| (t - done_s).max(0.0));
                    let round = OptimizerSettings { stop, ..settings.clone() };
                    let round = ChannelJob { settings: &round, operator: &op, data: &data, prior: reg.as_ref(), start: x0.take() };
                    let mut r = run(round, &mut shifted);
                    done_iters += r.iterations;
                    done_s += r.seconds;
                    rounds_run.push(r.iterations);
                    match first {
                        None => first = Some((r.iterations, r.termination)),
                        // A reweighted round that ran its length after a first round that
                        // settled has converged as the rule means it.
                        Some((_, Termination::Converged)) if r.termination == Termination::MaxIterations && !stopped => r.termination = Termination::Converged,
                        Some(_) => {}
                    }
                    // The moving part's scale refitted after each round, so that the
                    // next round's weights and start have it; not after a stop asked
                    // for, the time budget or a non-finite iterate. A gain past the
                    // bound ends the refits of this solve.
                    if refits && !stopped && matches!(r.termination, Termination::Converged | Termination::MaxIterations) {
                        match refit_dynamic_scale(&blocks.data.op, blocks.scale, pixels, &data, &mut r.x) {
                            Some(g) => gains.push(g),
                            None => refits = false,
                        }
                    }
                    let nothing_left = first.is_some_and(|(n, _)| round_stop(&params.stop, plan, Some(n), done_iters).max_iters == 0);
                    let out_of_time = r.termination == Termination::TimeBudget;
                    if stopped || out_of_time || matches!(r.termination, Termination::NonFinite { .. }) || rounds_run.len() > rounds || nothing_left {
                        break r;
                    }
                    // The next round starts from this one's iterate.
                    weights = Some(reweight(&r.x[pixels..], REWEIGHT_EPS));
                    x0 = Some(r.x);
                };
                r.iterations = done_iters;
                r.seconds = done_s;
                s = op.static_image(&r.x);
                r
            },
        );
        let mut terms = blocks.data.terms;
        let light_v: f64 = video.iter().map(|&v| v as f64).sum();
        let light_s: f64 = k as f64 * s.iter().map(|&v| v as f64).sum::<f64>();
        let mut av = vec![0.0f32; model.output_len()];
        model.forward(&video, &mut av);
        let nb = b.iter().map(|&v| (v as f64).powi(2)).sum::<f64>().sqrt();
        let nr = av.iter().zip(b.iter()).map(|(&a, &q)| ((a - q) as f64).powi(2)).sum::<f64>().sqrt();
        let info = StaticDynamicChannel {
            channel: ch,
            lipschitz_static: l_s,
            lipschitz_dynamic: l_d,
            lipschitz_scaled: l_z,
            step_static: (blocks.scale[0] as f64).powi(2) / l_z,
            step_dynamic: 1.0 / (l_d * l_z),
            tau_static: blocks.static_part.tv.tau,
            tau_dynamic: self.recipe.tau,
            l1_dynamic: l1,
            static_share: if light_v > 0.0 { light_s / light_v } else { 0.0 },
            residual_rel: nr / nb.max(1e-300),
            round_iterations: rounds_run,
            dynamic_gains: gains,
        };
        tracing::info!(
            channel = ch,
            l_static = l_s,
            l_dynamic = l_d,
            l_scaled = l_z,
            static_share = info.static_share,
            residual_rel = info.residual_rel,
            "static + dynamic solve"
        );
        if let Some(t) = terms.as_mut() {
            t.add_fit(&video);
            report.keyframes = std::mem::take(&mut t.fits);
        }
        Ok((video, s, report, info))
    }
}

/// The dynamic part's scale refitted to the data, the debiasing step of sparse
/// recovery: at the solve's static image `s` and moving part `d`, the least-squares
/// gain `g = <A d, b - A (1 ⊗ s)> / ||A d||^2` over the observations that are
/// equalities (a clipped pixel's lower bound is left out), and `d <- g d` where `s +
/// g d_k >= 0` (elsewhere `d_k = -s`: the video stays non-negative). The L1 and TV
/// terms shrink the moving part's amplitude; the data hold its scale once its shape is
/// found. Costs two forward maps (the moving part's, `A d`, and the still's one
/// convolution, `A (1 ⊗ s)`), each taken alone rather than `A d` as a difference of
/// the whole video's data and the still's (which cancel to 0.1-1% on a dense scene).
/// Returns the gain applied: 1 (nothing changed) for a gain under 1; `None` (nothing
/// changed) for one over [`MAX_DYNAMIC_GAIN`].
///
/// Run after every round of [`StaticDynamicSolve`], so that a reweighted round's
/// weights and start have the refitted part. 240 x 320 x 122 discs over texture
/// (docs/dense-scenes.md): motion error 0.782 -> 0.718 refitted after the last round,
/// 0.654 after every round (seed 44).
///
/// `op` is the operator on the video, `z` the scaled unknowns of
/// [`StaticPlusDynamic::new`]`(op, scale)` with `pixels` pixels per frame.
fn refit_dynamic_scale<A: Operator>(op: &A, scale: [f32; 2], pixels: usize, data: &DataTerm, z: &mut [f32]) -> Option<f64> {
    let [cs, cd] = scale;
    let b = data.observations();
    let mut y_d = vec![0.0f32; b.len()];
    StaticPlusDynamic::new(op, [0.0, cd]).forward(z, &mut y_d);
    let mut y_s = vec![0.0f32; b.len()];
    StaticPlusDynamic::new(op, [cs, 0.0]).forward(z, &mut y_s);
    let lower = data.lower_bounds();
    let (num, den) = (0..b.len())
        .into_par_iter()
        .filter(|&i| !lower.is_some_and(|l| l[i]))
        .map(|i| {
            let ad = y_d[i] as f64;
            (ad * (b[i] - y_s[i]) as f64, ad * ad)
        })
        .reduce(|| (0.0, 0.0), |a, c| (a.0 + c.0, a.1 + c.1));
    let g = num / den;
    if !(den > 0.0 && g.is_finite()) || g <= 1.0 {
        return Some(1.0);
    }
    if g > MAX_DYNAMIC_GAIN {
        return None;
    }
    let (zs, zd) = z.split_at_mut(pixels);
    zd.par_chunks_mut(pixels).for_each(|d| {
        for (d, &s) in d.iter_mut().zip(zs.iter()) {
            // z_d >= -c_s z_s / c_d keeps s + d >= 0.
            *d = (g as f32 * *d).max(-cs * s / cd);
        }
    });
    Some(g)
}

/// The stop rule of one round of a solve with `plan`'s reweighted-L1 rounds after the
/// first, from the run's rule `stop`; `first` is the first round's iterations once it
/// has run.
///
/// - The first round, when reweighted rounds follow, stops when the objective and the
///   data term have settled, without waiting for the iterate: the reweighting moves it
///   further than the rest of that round would.
/// - A reweighted round runs as many iterations as the first (at least the plan's
///   shortest round; at most the cap, and at most what the rounds so far, `done`
///   iterations, left of the plan's budget; 0: none runs): its
///   objective is flat from its start (the weights change the problem, not its value)
///   while the moving part grows, so no change-based rule can judge it.
///
/// 240 x 320 x 122 occluder with key frames at the first and last frame (docs/keyframes.md):
/// motion error 0.837 (246 + 5 iterations) -> 0.785 (133 + 133).
pub(crate) fn round_stop(stop: &StopRule, plan: ReweightPlan, first: Option<usize>, done: usize) -> StopRule {
    match first {
        None if plan.rounds > 0 => StopRule { wait_for_iterate: false, ..stop.clone() },
        None => stop.clone(),
        Some(n) => {
            let n = n.max(plan.min_round_iters);
            let left = plan.budget_iters.map_or(n, |b| b.saturating_sub(done));
            StopRule { max_iters: n.min(left).min(stop.max_iters), obj_tol: 0.0, ..stop.clone() }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::op::pseudo_random;

    /// A static image with a bright spot moving one pixel per frame, through a 12 x 10
    /// dual-shutter model: the data of the truth, and `z` holding the truth's static
    /// image and its moving part times `shrink`.
    fn shrunk_motion(shrink: f32) -> (RollingShutterModel, [f32; 2], Vec<f32>, Vec<f32>, Vec<f32>) {
        let (model, (k, m, n)) = crate::solve::start::tests::model();
        let s: Vec<f32> = pseudo_random(m * n, 5).iter().map(|v| 10.0 + 5.0 * v).collect();
        let mut d = vec![0.0f32; k * m * n];
        for f in 0..k {
            d[f * m * n + (f % m) * n + 4] = 40.0;
        }
        let truth: Vec<f32> = d.chunks(m * n).flat_map(|f| f.iter().zip(&s).map(|(d, s)| s + d)).collect();
        let mut b = vec![0.0f32; model.output_len()];
        model.forward(&truth, &mut b);
        let scale = [0.5f32, 2.0];
        let z: Vec<f32> = s.iter().map(|v| v / scale[0]).chain(d.iter().map(|v| shrink * v / scale[1])).collect();
        (model, scale, z, b, truth)
    }

    #[test]
    fn the_moving_part_shrunk_by_the_priors_gets_its_scale_back_from_the_data() {
        // Shrunk to 0.4: the gain is 1 / 0.4 and the video the truth.
        let (model, scale, mut z, b, truth) = shrunk_motion(0.4);
        let (_, m, n) = model.video_shape();
        let g = refit_dynamic_scale(&model, scale, m * n, &DataTerm::new(&b), &mut z).unwrap();
        assert!((g - 2.5).abs() < 1e-3, "gain {g}");
        let video = StaticPlusDynamic::new(&model, scale).video(&z);
        let err = video.iter().zip(&truth).map(|(v, t)| (v - t).abs()).fold(0.0f32, f32::max);
        assert!(err < 1e-2, "largest error {err}");
        // Shrunk to 0.1: a gain of 10, past the bound: refused, nothing changes.
        let (_, _, mut z, ..) = shrunk_motion(0.1);
        let before = z.clone();
        assert_eq!(refit_dynamic_scale(&model, scale, m * n, &DataTerm::new(&b), &mut z), None);
        assert_eq!(z, before);
        // Twice too strong: the data ask for 0.5, under 1: nothing changes.
        let (_, _, mut z, ..) = shrunk_motion(2.0);
        let before = z.clone();
        assert_eq!(refit_dynamic_scale(&model, scale, m * n, &DataTerm::new(&b), &mut z), Some(1.0));
        assert_eq!(z, before);
    }

    #[test]
    fn the_refitted_moving_part_never_takes_the_video_below_zero() {
        // A dark moving spot (d = -s there) shrunk to half: scaled by 2 it would go to
        // -s; it stops at -s, every frame non-negative.
        let (model, scale, mut z, _, _) = shrunk_motion(0.5);
        let (k, m, n) = model.video_shape();
        let p = m * n;
        let s: Vec<f32> = z[..p].iter().map(|v| v * scale[0]).collect();
        for f in 0..k {
            let i = p + f * p + (f % m) * n + 4;
            z[i] = -0.5 * s[(f % m) * n + 4] / scale[1];
        }
        let video = StaticPlusDynamic::new(&model, scale).video(&z);
        let mut b = vec![0.0f32; model.output_len()];
        // The data of a spot three times as deep (below zero): the gain is 3, and the
        // spot stops at zero.
        let deeper: Vec<f32> = video.chunks(p).flat_map(|f| f.iter().zip(&s).map(|(v, s)| s - 3.0 * (s - v))).collect();
        model.forward(&deeper, &mut b);
        let g = refit_dynamic_scale(&model, scale, p, &DataTerm::new(&b), &mut z).unwrap();
        assert!((g - 3.0).abs() < 1e-3, "gain {g}");
        let video = StaticPlusDynamic::new(&model, scale).video(&z);
        assert!(video.iter().all(|&v| v >= -1e-4), "lowest {}", video.iter().fold(f32::MAX, |a, &b| a.min(b)));
        let zeros = video.iter().filter(|&&v| v.abs() < 1e-4).count();
        assert_eq!(zeros, k, "the spot at zero in each of the {k} frames");
    }

    #[test]
    fn the_first_round_does_not_wait_for_the_iterate_and_a_reweighted_round_runs_its_length() {
        let stop = StopRule { max_iters: 600, rel_tol: 0.0, time_budget_s: Some(9.0), obj_tol: 1e-4, noise_floor: Some(3.0), wait_for_iterate: true };
        let asked = |rounds| ReweightPlan { rounds, budget_iters: None, min_round_iters: 0 };
        // No reweighted round: the run's rule as it is.
        let only = round_stop(&stop, asked(0), None, 0);
        assert!(only.wait_for_iterate && only.obj_tol == 1e-4 && only.max_iters == 600);
        // The first of two rounds: the objective and the data term only.
        let first = round_stop(&stop, asked(1), None, 0);
        assert!(!first.wait_for_iterate && first.obj_tol == 1e-4 && first.max_iters == 600 && first.noise_floor == Some(3.0));
        // A reweighted round asked for: the first round's length, no change-based
        // rule, the cap and the time budget kept; no budget of iterations.
        let again = round_stop(&stop, asked(1), Some(133), 133);
        assert!(again.obj_tol == 0.0 && again.max_iters == 133 && again.time_budget_s == Some(9.0));
        assert_eq!(round_stop(&stop, asked(2), Some(900), 900).max_iters, 600);
        assert_eq!(round_stop(&stop, asked(9), Some(100), 800).max_iters, 100);
        // The default plan: rounds of the first round's length until its budget is
        // spent, the last one shorter; nothing left, no round.
        let b = crate::solve::problem::REWEIGHT_BUDGET_ITERS;
        let plan = crate::solve::problem::reweight_plan(None);
        let min = crate::solve::problem::MIN_ROUND_ITERS;
        assert_eq!(plan, ReweightPlan { rounds: crate::solve::problem::MAX_L1_REWEIGHT, budget_iters: Some(b), min_round_iters: min });
        assert!(!round_stop(&stop, plan, None, 0).wait_for_iterate);
        // The lengths a default run gets: 100 + 100 + 100 + 100 of 400; 172 + 172 + 56;
        // a short first round, rounds of the shortest length; 400 alone.
        let lengths = |first: usize| {
            let mut done = first;
            let mut out = vec![first];
            while out.len() <= plan.rounds {
                let n = round_stop(&stop, plan, Some(first), done).max_iters;
                if n == 0 {
                    break;
                }
                done += n;
                out.push(n);
            }
            out
        };
        assert_eq!((b, min), (400, 100), "the lengths below are for a budget of 400 and rounds of at least 100");
        assert_eq!(lengths(100), vec![100; 4]);
        assert_eq!(lengths(172), vec![172, 172, 56]);
        assert_eq!(lengths(44), vec![44, 100, 100, 100, 56]);
        assert_eq!(lengths(27), vec![27, 100, 100, 100, 73]);
        // Without a budget the shortest round holds too: a first round of 4, rounds of 10.
        let short = ReweightPlan { rounds: 10, budget_iters: None, min_round_iters: 10 };
        assert_eq!(round_stop(&stop, short, Some(4), 4).max_iters, 10);
        assert_eq!(lengths(400), vec![400]);
        assert_eq!(lengths(550), vec![550]);
    }
}
