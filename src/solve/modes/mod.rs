//! One file per mode of a solve ([`crate::solve::plan::Mode`]): each turns the plan and
//! the problem into its channels' solves and never tests the mode again; [`run`] is the
//! one dispatch on the mode. A new mode is a file here and an arm in
//! [`crate::solve::plan::SolvePlan::decide`] and [`run`].

mod declared;
mod keyframes;
mod shared;
mod sparse;
pub mod static_dynamic;
mod whole_grid;

pub use declared::CONTRADICTION_RATIO;
pub(crate) use declared::{check_scene, scene_report};

use crate::solve::channel::{Hooks, Reconstruction};
use crate::solve::lipschitz::EigenStore;
use crate::solve::plan::{Mode, SolvePlan};
use crate::solve::problem::{reweight_plan, Problem, ReconstructError};
use shared::ModeRun;
use std::sync::OnceLock;

/// Solve `problem` in the mode `plan` chose: the one place the mode is matched.
pub(crate) fn run(
    problem: &Problem,
    plan: &SolvePlan,
    truth_planes: Option<Vec<Vec<f32>>>,
    cache: &dyn EigenStore,
    hooks: &Hooks,
) -> Result<Reconstruction, ReconstructError> {
    let params = &plan.params;
    let recipe = params.prior(plan.static_dynamic());
    if let Mode::StaticDynamic(chosen_by) = plan.mode {
        return static_dynamic::StaticDynamicSolve {
            problem,
            params,
            spec: &plan.spec,
            declared_in: plan.declared_in,
            chosen_by,
            recipe,
            reweight: reweight_plan(params.l1_reweight),
            truth_planes,
            cache,
            hooks,
            still_checks: &plan.still_checks,
            data_terms: match plan.keyframes {
                0 => static_dynamic::DataTerms::Raw,
                _ => static_dynamic::DataTerms::RawAndKeyFrames {
                    raw_sigma: crate::solve::problem::prepared_noise(problem.prepared, plan.frames).map(|n| n.sigma),
                },
            },
        }
        .reconstruct();
    }
    let run = ModeRun { problem, plan, params, recipe, truth_planes: truth_planes.as_deref(), cache, hooks, plain_stops: OnceLock::new() };
    let (results, scene) = match (plan.mode, plan.support.as_ref()) {
        (Mode::SparseSources, Some(support)) => (run.sparse(support)?, None),
        (Mode::KeyFrames, _) => (run.with_keyframes()?, None),
        (Mode::Declared, _) => run.declared().map(|(r, s)| (r, Some(s)))?,
        // The plan gives a sparse scene its support.
        (Mode::WholeGrid | Mode::SparseSources, _) => (run.whole_grid()?, None),
        (Mode::StaticDynamic(_), _) => unreachable!("solved above"),
    };
    Ok(run.assemble(results, scene))
}
