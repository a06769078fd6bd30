//! One capture to one video: the plan decided ([`crate::solve::plan`]) and solved in
//! its mode ([`crate::solve::modes`]), the truth brought to the video grid, the error
//! against run time counting the plan's own seconds.

use crate::model::scene::Colour;
pub use crate::solve::channel::{ChannelReport, FrameSensitivity, Hooks, ModelChoice, Reconstruction, SceneReport, SolveStats, WEAK_FRAME};
use crate::solve::lipschitz::EigenStore;
use crate::solve::plan::{Processes, SolvePlan};
use crate::solve::problem::{Problem, ValidSettings};
pub use crate::solve::problem::{ReconstructError, SolveParams};
use ndarray::ArrayView4;

pub use crate::solve::plan::SolveOptions;

pub use crate::solve::modes::CONTRADICTION_RATIO;

/// Decide the plan ([`SolvePlan::decide`], one process) and solve it.
pub fn reconstruct(
    problem: &Problem,
    settings: &ValidSettings,
    opts: &SolveOptions,
    truth: Option<(ArrayView4<f32>, &str)>,
    cache: &dyn EigenStore,
    hooks: &Hooks,
) -> Result<(Reconstruction, SolveParams), ReconstructError> {
    let plan = SolvePlan::decide(problem, settings, opts, Processes::One, cache, hooks.stop)?;
    let rec = solve(problem, &plan, truth, cache, hooks)?;
    Ok((rec, plan.params))
}

/// Solve `problem` as `plan` says (decided on this problem) in its mode
/// ([`crate::solve::modes::run`]): every channel, the error against run time counting
/// the plan's still checks and weight search.
pub fn solve(
    problem: &Problem,
    plan: &SolvePlan,
    truth: Option<(ArrayView4<f32>, &str)>,
    cache: &dyn EigenStore,
    hooks: &Hooks,
) -> Result<Reconstruction, ReconstructError> {
    if problem.fov != plan.params.fov {
        return Err(ReconstructError::Fov { problem: problem.fov, params: plan.params.fov });
    }
    let grey = plan.spec.colour == Colour::Grey && problem.prepared.raw.len() > 1;
    let truth_planes = truth_planes(problem, truth, grey)?;
    let mut rec = crate::solve::modes::run(problem, plan, truth_planes, cache, hooks)?;
    if !plan.params.start.uses_still(plan.frames) {
        // Error against run time: a still start goes on from the checks and counts
        // their seconds; a solve from zero did not use them.
        rec.add_prior_seconds(plan.check_seconds());
    }
    if let Some(s) = &plan.tau_search {
        rec.add_prior_seconds(s.seconds);
    }
    rec.tau_search = plan.tau_search.clone();
    rec.plan = Some(plan.report());
    Ok(rec)
}

/// Truth per output channel, on the full video grid (zero outside the sensor for
/// --fov full; the channel mean for a grey scene).
fn truth_planes(problem: &Problem, truth: Option<(ArrayView4<f32>, &str)>, grey: bool) -> Result<Option<Vec<Vec<f32>>>, ReconstructError> {
    let Some((t, name)) = truth else {
        return Ok(None);
    };
    let model = problem.channel(0).model();
    let (k, mv, nv) = model.video_shape();
    let captured = problem.prepared.raw.len();
    check_truth(&t, name, k, (mv, nv), model.conv().sensor_shape(), captured, grey)?;
    if t.iter().all(|&v| v == 0.0) {
        tracing::warn!("{name}: {}; the error figures are left out", crate::solve::trace::ZERO_TRUTH);
    }
    let channels_out = if grey { 1 } else { captured };
    Ok(Some((0..channels_out).map(|ch| truth_plane(&t, ch, grey, 0..k, (mv, nv), model.conv().offset())).collect()))
}

/// Whether a truth `t` (frames, rows, cols, channels) fits a video of `k` frames on
/// the `(mv, nv)` grid of a `(m, n)` sensor (either grid) with `captured` channels (one
/// for a grey scene).
pub(crate) fn check_truth(
    t: &ArrayView4<f32>,
    name: &str,
    k: usize,
    (mv, nv): (usize, usize),
    (m, n): (usize, usize),
    captured: usize,
    grey: bool,
) -> Result<(), ReconstructError> {
    let (tk, tm, tn, tc) = t.dim();
    let ok_grid = (tm, tn) == (mv, nv) || (tm, tn) == (m, n);
    let ok_channels = tc == captured || (grey && tc == 1);
    if tk != k || !ok_grid || !ok_channels {
        return Err(ReconstructError::TruthShape { what: name.into(), got: vec![tk, tm, tn, tc], expected: vec![k, mv, nv, captured] });
    }
    Ok(())
}

/// Frames `frames` of channel `ch` of the truth (or the channel mean for a grey scene)
/// on the video grid (`offset`: the sensor's place in it when the truth is given on the
/// sensor's grid).
pub(crate) fn truth_plane(
    t: &ArrayView4<f32>,
    ch: usize,
    grey: bool,
    frames: std::ops::Range<usize>,
    (mv, nv): (usize, usize),
    offset: (usize, usize),
) -> Vec<f32> {
    let (_, tm, tn, tc) = t.dim();
    let (or, oc) = if (tm, tn) == (mv, nv) { (0, 0) } else { offset };
    let srcs: Vec<usize> = if grey { (0..tc).collect() } else { vec![ch] };
    let inv = 1.0 / srcs.len() as f64;
    let mut v = vec![0.0f32; frames.len() * mv * nv];
    for (i, f) in frames.enumerate() {
        for r in 0..tm {
            for c in 0..tn {
                let s: f64 = srcs.iter().map(|&sc| t[[f, r, c, sc]] as f64).sum();
                v[(i * mv + r + or) * nv + c + oc] = (s * inv) as f32;
            }
        }
    }
    v
}
