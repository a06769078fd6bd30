//! [`Mode::Declared`](crate::solve::plan::Mode::Declared): the video as `[scene]`
//! declares it, each output channel on its restricted operator, checked against the
//! undeclared one (the residual, and whether the data want light where the declaration
//! allows none).

use super::shared::{retry_on_non_finite, ChannelVideos, ModeRun};
use crate::model::op::Operator;
use crate::model::scene::{Colour, ScenePlan};
use crate::solve::channel::{ChannelReport, FullGrid, SceneReport};
use crate::solve::problem::{DeclaredProblem, ReconstructError, SolveParams};
use rayon::prelude::*;
use std::time::Instant;

/// Above this [`SceneReport::outside_optimality_ratio`] the declaration is reported as
/// contradicted by the data (see `tests/solve/scene_reconstruct.rs` for measured values).
pub const CONTRADICTION_RATIO: f64 = 3.0;

impl ModeRun<'_> {
    /// The video as `spec` declares it: each output channel on its restricted
    /// operator, checked against the undeclared one.
    pub(super) fn declared(&self) -> Result<(ChannelVideos, SceneReport), ReconstructError> {
        let (spec, declared_in, measure_full) = (&self.plan.spec, self.plan.declared_in, self.plan.measure_full);
        let (problem, params, cache) = (self.problem, self.params, self.cache);
        let (prepared, kind) = (problem.prepared, params.solver);
        let captured = prepared.raw.len();
        let channels_out = if spec.colour == Colour::Grey && captured > 1 { 1 } else { captured };
        let (k, mv, nv) = problem.channel(0).model().video_shape();
        let recipe = self.recipe.for_scene(spec, k);
        let problems: Vec<DeclaredProblem> = (0..channels_out).map(|ch| problem.declare(spec, recipe.tau, params.alpha, ch)).collect::<Result<_, _>>()?;
        kind.check_operator(&problems[0].op).map_err(ReconstructError::Unsupported)?;
        let p0 = recipe.of_tv(problems[0].tv().clone(), problems[0].atb_max() as f64).build(None);
        kind.check_on_device(params.device, &problems[0].op, &problems[0].data(), p0.as_ref(), false)
            .and_then(|()| kind.check_device_memory(params.device, &problems[0].op, problems.len()))
            .map_err(ReconstructError::Unsupported)?;
        let plan = problems[0].plan().clone();
        for l in &plan.left_out {
            tracing::info!("left out: {l}");
        }
        let out: Vec<(Vec<f32>, ChannelReport, SceneCheck)> = problems
            .par_iter()
            .enumerate()
            .map(|(ch, p)| {
                let lipschitz = p.lipschitz(cache);
                let (k0, _) = p.plan().frames;
                let to_full = |x: &[f32]| {
                    let mut v = vec![0.0f32; k * mv * nv];
                    let w = p.op.embed(x);
                    v[k0 * mv * nv..k0 * mv * nv + w.len()].copy_from_slice(&w);
                    v
                };
                let prior = recipe.of_tv(p.tv().clone(), p.atb_max() as f64);
                let restrict = |v: Vec<f32>| p.op.restrict(&v, false);
                let full = FullGrid { truth: self.truth(ch), to_full: &to_full };
                let run = |l| self.job(ch).run(&p.op, &p.data(), &prior, l, full, (p.model(), &restrict));
                let (full, rep) =
                    retry_on_non_finite(run(lipschitz), lipschitz.cached, || run(crate::solve::lipschitz::Lipschitz::measured(p.remeasure_lipschitz(cache))));
                let check = check_scene(p, &full, params, measure_full);
                (full, rep, check)
            })
            .collect();
        let (reports, checks): (Vec<&ChannelReport>, Vec<&SceneCheck>) = out.iter().map(|(_, r, c)| (r, c)).unzip();
        let report = scene_report(plan, declared_in, &reports, &checks);
        for w in &report.warnings {
            tracing::warn!("{w}");
        }
        Ok((out.into_iter().map(|(v, r, _)| (v, r)).collect(), report))
    }
}

/// The report of a declared solve from its channels' reports and checks (the plain
/// and the split solves').
pub(crate) fn scene_report(
    plan: ScenePlan,
    declared_in: &'static str,
    reports: &[impl std::borrow::Borrow<ChannelReport>],
    checks: &[impl std::borrow::Borrow<SceneCheck>],
) -> SceneReport {
    let per_iteration = |r: &ChannelReport| r.stats.seconds / r.stats.iterations.max(1) as f64;
    let (fu, su) = plan.unknowns();
    let solved_s: f64 = reports.iter().map(|r| per_iteration(r.borrow())).sum();
    let merged = (plan.channels_captured / plan.channels_solved) as f64;
    let full_est = reports.iter().zip(checks).map(|(r, c)| c.borrow().cost_ratio.map(|q| q * per_iteration(r.borrow()) * merged)).sum::<Option<f64>>();
    let ratio = checks.iter().filter_map(|c| c.borrow().outside_ratio).reduce(f64::max);
    let residual_rel = checks.iter().map(|c| c.borrow().residual_rel).fold(0.0, f64::max);
    let mut warnings = Vec::new();
    if let Some(q) = ratio.filter(|&q| q > CONTRADICTION_RATIO) {
        warnings.push(format!(
            "the data contradict the scene declaration: light is wanted where it declares none (A^T residual there is {q:.1} x the largest TV subgradient); the declared solve leaves that light unexplained (residual {residual_rel:.3} of the data)"
        ));
    }
    SceneReport {
        declared_in,
        plan,
        unknowns_full: fu,
        unknowns_solved: su,
        vector_bytes_full: fu * 4,
        vector_bytes_solved: su * 4,
        seconds_per_iteration_solved: solved_s,
        seconds_per_iteration_full_estimate: full_est,
        outside_optimality_ratio: ratio,
        residual_rel,
        warnings,
    }
}

/// What the undeclared operator says about a declared solution.
pub(crate) struct SceneCheck {
    /// Cost of one forward + adjoint, full over declared.
    cost_ratio: Option<f64>,
    outside_ratio: Option<f64>,
    residual_rel: f64,
}

/// Apply the undeclared operator (all frames, the whole grid; the declared problem's
/// PSF) to the declared solution `full` (on the full grid): the residual, the
/// optimality of the imposed zeros, and the cost of one forward + adjoint against the
/// declared operator's.
pub(crate) fn check_scene(p: &DeclaredProblem, full: &[f32], params: &SolveParams, measure: bool) -> SceneCheck {
    let model = &*p.declaration.full;
    let (k, mv, nv) = model.video_shape();
    let t0 = Instant::now();
    let mut ax = vec![0.0f32; model.output_len()];
    model.forward(full, &mut ax);
    let resid: Vec<f32> = p.b.iter().zip(&ax).map(|(&b, &a)| b - a).collect();
    let mut g = vec![0.0f32; model.input_len()];
    model.adjoint(&resid, &mut g);
    let t_full = t0.elapsed().as_secs_f64();
    let nb: f64 = p.b.iter().map(|&v| (v as f64).powi(2)).sum::<f64>().sqrt();
    let nr: f64 = resid.iter().map(|&v| (v as f64).powi(2)).sum::<f64>().sqrt();
    let residual_rel = nr / nb.max(1e-300);
    // Pixels the declaration sets to zero: outside the support box or the frame window.
    let (k0, k1) = p.plan().frames;
    let (rr, cr) = (p.op.rows.clone(), p.op.cols.clone());
    let restricted_space = (k0, k1) != (0, k) || rr != (0..mv) || cr != (0..nv);
    let outside_ratio = restricted_space.then(|| {
        let mut worst = f32::NEG_INFINITY;
        for f in 0..k {
            for r in 0..mv {
                let row = &g[(f * mv + r) * nv..(f * mv + r + 1) * nv];
                for (c, &v) in row.iter().enumerate() {
                    let inside = (k0..k1).contains(&f) && rr.contains(&r) && cr.contains(&c);
                    if !inside && v.is_finite() {
                        worst = worst.max(v);
                    }
                }
            }
        }
        let w = p.plan().spec.tv_weights.unwrap_or([params.alpha, 1.0, 1.0]);
        let dims = [k, mv, nv];
        let bound = 2.0 * params.tau as f64 * (0..3).filter(|&a| dims[a] > 1).map(|a| w[a] as f64).sum::<f64>();
        worst.max(0.0) as f64 / bound.max(1e-30)
    });
    let cost_ratio = measure.then(|| {
        let x = vec![0.0f32; p.op.input_len()];
        let mut y = vec![0.0f32; p.op.output_len()];
        let mut xa = vec![0.0f32; p.op.input_len()];
        let t0 = Instant::now();
        p.op.forward(&x, &mut y);
        p.op.adjoint(&y, &mut xa);
        t_full / t0.elapsed().as_secs_f64().max(1e-9)
    });
    SceneCheck { cost_ratio, outside_ratio, residual_rel }
}
