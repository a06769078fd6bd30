//! One capture solved by several processes (MPI ranks), each holding a contiguous
//! block of the video's frames and only that block's volumes.
//!
//! What crosses between ranks, per FISTA iteration:
//! - the forward's sensor image, summed over the ranks ([`Split`]); the adjoint of the
//!   summed residual is local;
//! - for the temporal TV, the edge frames of the TV map's argument to both neighbours
//!   (the Haar map; the exact dual map exchanges one edge frame each way per inner
//!   iteration), and of the new iterate (for its TV value) to the previous rank
//!   ([`crate::solve::prox::block::BlockTv`]);
//! - a few scalars: the iterate's change and norm, the TV value, the loop's agreement
//!   on stopping (and, with a truth, the error's sums).
//!
//! The Lipschitz constant is read from the cache by rank 0 (one process's key) or
//! measured by all ranks together (power iteration on the same start vector as one
//! process) and stored, and broadcast from rank 0. The video is gathered on rank 0 in frame order.
//!
//! What is split: the plain video and the declarations that keep frames apart (a
//! frame window, a support box, a grey scene, TV weights), with FISTA (with or without
//! restart, MFISTA, PGD), either TV map (Haar, exact dual) and an L1 term. The rest is
//! refused with its reason: a static scene (one frame), the static + dynamic model (its
//! static image is every rank's) and ADMM.

use crate::model::capture::{CaptureConfig, Fov};
use crate::model::data::DataTerm;
use crate::model::op::Operator;
use crate::model::prepare::Prepared;
use crate::model::ranks::{balanced_blocks, frame_work, Ranks, Traffic};
use crate::model::rolling::RollingShutterModel;
use crate::model::scene::{Colour, SceneSpec};
use crate::model::shutter::ShutterWeights;
use crate::model::split::{RowShare, Split};
use crate::solve::channel::{warn_strong_haar, ChannelReport, FrameSensitivity, Hooks, RankShare, Reconstruction, SolveStats, SplitReport};
use crate::solve::job::{run, ChannelJob};
use crate::solve::lipschitz::{
    check_range, power_iteration_from, power_start, Eigen, EigenStore, Fingerprint, Lipschitz, CHECK_ITERATIONS, LIPSCHITZ_MARGIN, MEASURE_SEED,
};
use crate::solve::modes::{check_scene, scene_report};
use crate::solve::optimize::{IterInfo, OptimizerSettings, StopRule, Termination};
use crate::solve::plan::{Mode, Processes, SolveOptions, SolvePlan};
use crate::solve::problem::{adjoint_peak, build_operator, DeclaredProblem, PriorRecipe, Problem, ReconstructError, SolveParams, ValidSettings};
use crate::solve::prox::TotalVariation;
use crate::solve::reconstruct::{check_truth, truth_plane};
use crate::solve::scene::declare_on;
use crate::solve::start::{still_image_after, StillReport};
use crate::solve::trace::{motion_error, Baselines, Error, ErrorSums, TraceRow};
use ndarray::{Array4, ArrayView4, Axis};
use std::ops::Range;
use std::sync::atomic::Ordering;

/// What [`reconstruct`] gives each rank: the reconstruction on rank 0 (the gathered
/// video; `None` elsewhere) and the split's report on every rank.
pub struct SplitOutcome {
    pub reconstruction: Option<Reconstruction>,
    pub params: SolveParams,
    pub report: SplitReport,
}

/// The processes a capture is split across: the ranks, and how this process reads its
/// peak resident memory (the caller's: the solver layer reads no files).
pub struct RankContext<'a> {
    pub ranks: &'a dyn Ranks,
    pub peak_memory: &'a dyn Fn() -> Option<u64>,
    /// Told the plan once every rank has decided it, before the solve (on every rank);
    /// false declines the solve.
    pub on_plan: &'a dyn Fn(&SolvePlan) -> bool,
}

/// Reconstruct a prepared capture (`(prepared, cfg)`) split across `processes`: every
/// rank calls this with the same inputs and decides the plan one process would
/// ([`SolvePlan::decide`]), refusing the modes a split cannot solve. `None`: the plan
/// was declined.
pub fn reconstruct(
    (prepared, cfg): (&Prepared, &CaptureConfig),
    settings: &ValidSettings,
    scene: Option<SceneSpec>,
    truth: Option<(ArrayView4<f32>, &str)>,
    cache: &dyn EigenStore,
    hooks: &Hooks,
    processes: RankContext,
) -> Result<Option<SplitOutcome>, ReconstructError> {
    let RankContext { ranks, peak_memory, on_plan } = processes;
    let fov = cfg.fov;
    let weights = cfg.timing().weights()?;
    let k_all = weights.frames();
    let captured = prepared.raw.len();
    // The video grid and the sensor's place in it (one frame's operator: no volumes).
    let probe = build_operator(&prepared.psf[0], &weights.window(0..1), fov, &prepared.data_mask);
    let ((mv, nv), offset) = (probe.conv().video_shape(), probe.conv().offset());
    drop(probe);
    let work_all = frame_work(&weights, mv);
    let too_few = |frames: usize| {
        ReconstructError::Unsupported(format!(
            "split across MPI ranks: {frames} frames cannot be split across {} ranks (at least one frame each)",
            ranks.size()
        ))
    };
    // Each channel's max(A^T b) over every frame: each rank takes a block of all the
    // frames for it (a collective). Every rank holds the whole raw, so each measures
    // the same noise and decides the same plan.
    let all = balanced_blocks(&work_all, ranks.size()).ok_or_else(|| too_few(k_all))?;
    let peaks = channel_peaks(prepared, &weights.window(all[ranks.rank()].clone()), fov, ranks);
    let whole = Problem::with_peaks(prepared, cfg, fov, &peaks)?;
    let options = SolveOptions { scene, measure_full: true };
    // A truth of another shape is refused before the plan's still checks.
    if let Some((t, name)) = &truth {
        let grey = options.declared(cfg)?.0.colour == Colour::Grey && captured > 1;
        check_truth(t, name, k_all, (mv, nv), (prepared.psf[0].rows, prepared.psf[0].cols), captured, grey)?;
    }
    // The plan one process would solve, or a refusal naming what the split cannot take.
    let plan = SolvePlan::decide(&whole, settings, &options, Processes::Split { ranks: ranks.size() }, cache, hooks.stop)?;
    if !on_plan(&plan) {
        return Ok(None);
    }
    let (spec, declared_in) = (plan.spec.clone(), plan.declared_in);
    let grey = spec.colour == Colour::Grey && captured > 1;
    let channels_out = if grey { 1 } else { captured };
    let declared = plan.mode == Mode::Declared;
    let (k0, k1) = match spec.frames {
        Some([a, b]) if b <= k_all && a < b => (a, b),
        Some([a, b]) => {
            return Err(crate::model::scene::invalid("frames", format!("[{a}, {b}]"), format!("a window inside the capture's {k_all} frames")).into())
        }
        None => (0, k_all),
    };
    let window = k1 - k0;
    // The solve's blocks: the declared window's frames.
    let work = &work_all[k0..k1];
    let blocks = balanced_blocks(work, ranks.size()).ok_or_else(|| too_few(window))?;
    let mine = blocks[ranks.rank()].clone();
    let abs = |r: &Range<usize>| k0 + r.start..k0 + r.end;
    let abs_blocks: Vec<Range<usize>> = blocks.iter().map(abs).collect();
    let params = plan.params.clone();
    let recipe = params.prior(false).for_scene(&spec, k_all);
    // One process's stop rule: a plain video's with each channel's noise floor.
    let stops: Vec<StopRule> = (0..channels_out)
        .map(|ch| match plan.mode {
            Mode::WholeGrid => params.stop.clone().with_noise_floor(crate::solve::fit::noise_floor(&whole, ch)),
            _ => params.stop.clone(),
        })
        .collect();

    let mut block_spec = spec.clone();
    block_spec.frames = Some([k0 + mine.start, k0 + mine.end]);
    let channels = SplitChannels {
        prepared,
        weights: &weights,
        fov,
        spec: &spec,
        block_spec: &block_spec,
        recipe,
        params: &params,
        mine: mine.clone(),
        blocks: &blocks,
        abs_blocks: &abs_blocks,
        frames: (k0, k1, k_all),
        grid: ((mv, nv), offset),
        grey,
        truth: truth.as_ref().map(|(t, _)| t.view()),
        stops: &stops,
        still_checks: &plan.still_checks,
        cache,
        hooks,
        ranks,
    };
    drop(whole);
    let mut traffic = Traffic::default();
    let mut iterations = 0usize;
    let mut summed_rows = 0usize;
    let mut results: Vec<(Vec<f32>, ChannelReport)> = Vec::new();
    let mut globals: Vec<DeclaredProblem> = Vec::new();
    for ch in 0..channels_out {
        let done = channels.solve(ch)?;
        traffic = traffic + done.traffic;
        iterations += done.iterations;
        summed_rows = done.summed_rows;
        results.push((done.video, done.report));
        globals.push(done.whole);
    }
    let report = split_report(&channels, work, (traffic, iterations), peak_memory(), window * mv * nv * 4, (summed_rows, weights.rows()));
    if ranks.rank() != 0 {
        return Ok(Some(SplitOutcome { reconstruction: None, params, report }));
    }

    let mut video = Array4::<f32>::zeros((k_all, mv, nv, channels_out));
    let mut reports = Vec::new();
    let mut checks = Vec::new();
    for (ch, (x, mut rep)) in results.into_iter().enumerate() {
        rep.motion_error = channels.truth.as_ref().and_then(|t| motion_error(&x, &truth_plane(t, ch, channels.grey, 0..k_all, (mv, nv), offset), k_all));
        if declared {
            checks.push(check_scene(&globals[ch], &x, &params, true));
        }
        let plane = ndarray::ArrayView3::from_shape((k_all, mv, nv), &x).unwrap();
        video.index_axis_mut(Axis(3), ch).assign(&plane);
        reports.push(rep);
    }
    let scene = declared.then(|| scene_report(globals[0].plan().clone(), declared_in, &reports, &checks));
    let models: Vec<_> = prepared.psf.iter().map(|psf| build_operator(psf, &weights, fov, &prepared.data_mask)).collect();
    let models: Vec<&RollingShutterModel> = models.iter().collect();
    let frame_sensitivity = FrameSensitivity::of(&models, prepared).with_video(&video);
    let reconstruction = Reconstruction {
        video,
        frame_time_us: cfg.timing().frame_time_us(),
        sensor_offset: offset,
        channels: reports,
        scene,
        frame_sensitivity,
        static_background: None,
        split: Some(report.clone()),
        tau_search: None,
        fit: None,
        estimated_seconds: None,
        plan: Some(plan.report()),
    };
    Ok(Some(SplitOutcome { reconstruction: Some(reconstruction), params, report }))
}

/// Each channel's `max(A^T b)` over every frame, from this rank's block of them
/// (`block`) and the other ranks' (a collective).
fn channel_peaks(prepared: &Prepared, block: &ShutterWeights, fov: Fov, ranks: &dyn Ranks) -> Vec<f32> {
    let mut peaks: Vec<f64> = prepared
        .psf
        .iter()
        .zip(&prepared.raw)
        .map(|(psf, raw)| adjoint_peak(&build_operator(psf, block, fov, &prepared.data_mask), &raw.data) as f64)
        .collect();
    ranks.max_f64(&mut peaks);
    peaks.iter().map(|&p| p as f32).collect()
}

/// What every channel's split solve shares: the capture, the prior, the frame blocks
/// and this rank's, the video grid, the truth, the cache and the hooks.
struct SplitChannels<'a> {
    prepared: &'a Prepared,
    weights: &'a ShutterWeights,
    fov: Fov,
    spec: &'a SceneSpec,
    /// The declaration restricted to this rank's frames.
    block_spec: &'a SceneSpec,
    recipe: PriorRecipe,
    params: &'a SolveParams,
    /// This rank's block of the window's frames (relative to the window).
    mine: Range<usize>,
    blocks: &'a [Range<usize>],
    abs_blocks: &'a [Range<usize>],
    /// The window's first and end frames, and the capture's frames.
    frames: (usize, usize, usize),
    /// The video grid `(rows, cols)` and the sensor's place in it.
    grid: ((usize, usize), (usize, usize)),
    grey: bool,
    truth: Option<ArrayView4<'a, f32>>,
    /// Each output channel's stop rule (the plan's, as one process runs it).
    stops: &'a [StopRule],
    /// The plan's still checks, one per channel (empty when none was made): the still
    /// start goes on from them, as in one process.
    still_checks: &'a [StillReport],
    cache: &'a dyn EigenStore,
    hooks: &'a Hooks<'a>,
    ranks: &'a dyn Ranks,
}

/// One channel's split solve: the video gathered on rank 0 (empty elsewhere), its
/// report, the whole problem's description, and what the solve cost.
struct SplitChannel {
    video: Vec<f32>,
    report: ChannelReport,
    whole: DeclaredProblem,
    traffic: Traffic,
    iterations: usize,
    summed_rows: usize,
}

impl SplitChannels<'_> {
    /// Channel `ch` solved on this rank's block, gathered on rank 0.
    fn solve(&self, ch: usize) -> Result<SplitChannel, ReconstructError> {
        let (prepared, weights, fov, spec, block_spec, recipe, params) =
            (self.prepared, self.weights, self.fov, self.spec, self.block_spec, self.recipe, self.params);
        let (mine, blocks, abs_blocks, ranks, cache, hooks, truth, grey) =
            (&self.mine, self.blocks, self.abs_blocks, self.ranks, self.cache, self.hooks, self.truth.as_ref(), self.grey);
        let (k0, k1, k_all) = self.frames;
        let ((mv, nv), offset) = self.grid;
        let window = k1 - k0;
        let abs = |r: &Range<usize>| k0 + r.start..k0 + r.end;
        // The whole problem's description (no volumes): its cache key, bound and plan.
        let whole = declare_on(prepared, weights, fov, spec, recipe.tau, params.alpha, ch)?;
        let block = declare_on(prepared, weights, fov, block_spec, recipe.tau, params.alpha, ch)?;
        let (_, ms, ns) = block.plan().solved_shape;
        let tv = TotalVariation { shape: (window, ms, ns), ..block.tv().clone() };
        let DeclaredProblem { problem: block, .. } = block;
        let op = Split::new(block.op, ranks, mine.clone(), window, RowShare::new(weights, abs_blocks, ranks.rank()));
        let summed_rows = op.summed_rows();
        let mut atb = [adjoint_peak(&op, &block.b) as f64];
        ranks.max_f64(&mut atb);
        let prior = recipe.of_tv(tv, atb[0]);
        let strength = prior.haar_strength();
        warn_strong_haar(ch, params.solver, params.tv_prox, strength);
        let data = DataTerm::new(&block.b).with_lower_bounds(block.lower_bounds.as_deref()).on(op.partition());
        // The truth of this block on its grid, and rank 0's share of the frames outside
        // the window (where the estimate is zero).
        let truth_block = truth.map(|t| truth_plane(t, ch, grey, abs(mine), (mv, nv), offset));
        let outside = truth.filter(|_| ranks.rank() == 0).map(|t| {
            let mut s = ErrorSums::default();
            for f in (0..k0).chain(k1..k_all) {
                let plane = truth_plane(t, ch, grey, f..f + 1, (mv, nv), offset);
                s.add(&vec![0.0; plane.len()], &plane);
            }
            s
        });
        let error_of = |x: &[f32]| -> Option<Error> {
            let t = truth_block.as_ref()?;
            let full = op.inner.embed(x);
            split_error(&full, t, outside.unwrap_or_default(), k_all * mv * nv, ranks)
        };
        // The still start of one process: every rank solves the whole still problem
        // (one image; the same bits on every rank and in one process), then keeps its
        // block's frames.
        let whole_prior = recipe.of_tv(whole.tv().clone(), atb[0]);
        let (image, start) = still_image_after(params.start, whole.model(), &whole.data(), &whole_prior, whole.tv().shape.0, self.still_checks.get(ch));
        let x0 = image.map(|image| op.inner.restrict(&image.repeat(op.inner.inner.frames()), false));
        let start_s = start.as_ref().map_or(0.0, |s| s.seconds);
        // One solve with the constant `lipschitz`: fresh TV map (and warm start), its
        // trace.
        let solve_with = |lipschitz: f64| {
            let reg = prior.build(Some(ranks));
            let solver = OptimizerSettings::new(params.solver, lipschitz, self.stops[ch].clone());
            let mut rows: Vec<TraceRow> = Vec::new();
            let mut observer = |i: &IterInfo| {
                let row = TraceRow::from_info(&IterInfo { seconds: i.seconds + start_s, ..*i }, error_of(i.x));
                (hooks.on_row)(ch, &row);
                rows.push(row);
                !hooks.stop.load(Ordering::Relaxed)
            };
            let mut r = run(ChannelJob { settings: &solver, operator: &op, data: &data, prior: reg.as_ref(), start: x0.clone() }, &mut observer);
            r.seconds += start_s;
            (r, rows)
        };
        let span = tracing::info_span!("solve", channel = ch, rank = ranks.rank(), frames = ?abs(mine), solver = %params.solver);
        let _g = span.enter();
        // The keys one process uses (the declared operator's for a declaration), so the
        // cache serves both, checked against the whole operator's bound.
        let key = whole.key();
        let stored = stored_lipschitz(key, whole.op.lipschitz_upper_bound(), &op, cache, ranks);
        let mut lipschitz = match stored {
            Some(value) => Lipschitz { value, cached: true },
            None => Lipschitz::measured(measure_lipschitz(key, &op, cache, ranks)),
        };
        let before = ranks.traffic();
        let (mut r, mut rows) = solve_with(lipschitz.value);
        // As one process does: a solve that went non-finite (on every rank: the loop
        // agrees) with a stored constant runs again with the constant measured anew.
        if lipschitz.cached && matches!(r.termination, Termination::NonFinite { .. }) {
            tracing::warn!(channel = ch, "the solve went non-finite with the stored Lipschitz constant: measuring it again and solving anew");
            lipschitz = Lipschitz::measured(measure_lipschitz(key, &op, cache, ranks));
            (r, rows) = solve_with(lipschitz.value);
        }
        let traffic = ranks.traffic().since(before);
        tracing::info!(iterations = r.iterations, seconds = r.seconds, termination = ?r.termination, "channel solved");
        let iterations = r.iterations;
        let error = error_of(&r.x);
        let report = ChannelReport {
            channel: ch,
            stats: SolveStats::new(&r, lipschitz, error),
            baseline: truth.and_then(|t| Baselines::of(&truth_plane(t, ch, grey, 0..k_all, (mv, nv), offset), k_all)),
            // Filled on rank 0 from the gathered video.
            motion_error: None,
            solver: params.solver,
            tv_prox: prior.tv_map_name(),
            haar_strength: strength,
            start,
            keyframes: Vec::new(),
            coarse: None,
            interpolation: None,
            support: None,
            trace: rows,
        };
        // The block on the full grid, gathered on rank 0 into the whole video.
        let local = op.inner.embed(&r.x);
        drop(r);
        let fl = mv * nv;
        let mut video = (ranks.rank() == 0).then(|| vec![0.0f32; k_all * fl]);
        ranks.gather_frames(&local, blocks, fl, video.as_mut().map(|v| &mut v[k0 * fl..k1 * fl]));
        Ok(SplitChannel { video: video.unwrap_or_default(), report, whole, traffic, iterations, summed_rows })
    }
}

/// The stored Lipschitz constant (with margin) of the whole problem under `key` (the
/// same key as one process's), when rank 0 finds one and it lies in the range one
/// process checks ([`crate::solve::lipschitz::lambda_range`]: at most `upper`, at least
/// a few power iterations of all ranks together); every rank learns it.
fn stored_lipschitz<A: Operator>(key: Fingerprint, upper: Option<f64>, op: &Split<'_, A>, cache: &dyn EigenStore, ranks: &dyn Ranks) -> Option<f64> {
    let mut found = [0.0f64, 0.0];
    if ranks.rank() == 0 {
        if let Some(e) = cache.load(&key).filter(|e| e.lambda_max.is_finite() && e.lambda_max > 0.0) {
            found = [1.0, e.lambda_max];
        }
    }
    ranks.broadcast_f64(&mut found);
    if found[0] == 0.0 {
        return None;
    }
    // A collective: the norms are summed over the ranks, so every rank sees one value.
    let lower = power_iteration_from(op, op.partition(), split_start(op), CHECK_ITERATIONS, 0.0).lambda_max;
    match check_range(found[1], lower, upper) {
        Ok(()) => Some(found[1] * LIPSCHITZ_MARGIN),
        Err(why) => {
            if ranks.rank() == 0 {
                tracing::warn!(key = %key.hex(), lambda = found[1], "stored Lipschitz constant ignored and measured again: {why}");
            }
            None
        }
    }
}

/// A rank's block of one process's power-iteration start.
fn split_start<A: Operator>(op: &Split<'_, A>) -> Vec<f32> {
    power_start(op.total_frames * op.frame_len(), MEASURE_SEED, op.offset()..op.offset() + op.input_len())
}

/// The Lipschitz constant (with margin) measured by all ranks together (power
/// iteration from one process's start vector, the norms summed over the ranks), rank
/// 0's value broadcast; rank 0 stores it under `key`.
fn measure_lipschitz<A: Operator>(key: Fingerprint, op: &Split<'_, A>, cache: &dyn EigenStore, ranks: &dyn Ranks) -> f64 {
    let e = power_iteration_from(op, op.partition(), split_start(op), 300, 1e-5);
    let mut lambda = [e.lambda_max];
    ranks.broadcast_f64(&mut lambda);
    tracing::info!(lambda = lambda[0], iterations = e.iterations, "measured the Lipschitz constant by power iteration across the ranks");
    if ranks.rank() == 0 {
        cache.store(&key, &Eigen { lambda_max: lambda[0], ..e });
    }
    lambda[0] * LIPSCHITZ_MARGIN
}

/// [`crate::solve::trace::compare`] of the whole video from its blocks: the sums over
/// the ranks, the truth's peak over the ranks (`outside`: rank 0's sums over the frames
/// no block holds, where the estimate is zero).
fn split_error(x: &[f32], truth: &[f32], outside: ErrorSums, len: usize, ranks: &dyn Ranks) -> Option<Error> {
    let mut sums = outside;
    sums.add(x, truth);
    let mut s = sums.to_array();
    let mut peak = [sums.peak];
    ranks.sum_f64(&mut s);
    ranks.max_f64(&mut peak);
    ErrorSums::from_array(s, peak[0]).error(len)
}

/// The split's report, gathered on every rank (a collective): the ranks' blocks of
/// `channels`, each frame's `work`, the `(traffic, iterations)` of every channel's
/// solve, this process's `peak` memory, the whole video's bytes and the sensor rows
/// `(summed, all)`.
fn split_report(
    channels: &SplitChannels,
    work: &[f64],
    (traffic, iterations): (Traffic, usize),
    peak: Option<u64>,
    vector_whole: usize,
    rows: (usize, usize),
) -> SplitReport {
    let (blocks, k0, ranks) = (channels.blocks, channels.frames.0, channels.ranks);
    let per_frame = vector_whole / work.len().max(1);
    SplitReport {
        ranks: ranks.size(),
        per_rank: rank_shares(blocks, k0, work, traffic, iterations, peak, ranks),
        vector_bytes_whole: vector_whole,
        vector_bytes_largest_block: blocks.iter().map(|b| b.len()).max().unwrap_or(0) * per_frame,
        sensor_rows_summed: rows.0,
        sensor_rows: rows.1,
    }
}

/// Each rank's share (`blocks` of frames from `k0`; `work`: each frame's), peak memory
/// and traffic per iteration (over `iterations`), gathered on every rank (a
/// collective).
pub fn rank_shares(
    blocks: &[Range<usize>],
    k0: usize,
    work: &[f64],
    traffic: Traffic,
    iterations: usize,
    peak: Option<u64>,
    ranks: &dyn Ranks,
) -> Vec<RankShare> {
    const F: usize = 4;
    let n = ranks.size();
    let mut figures = vec![0.0f64; F * n];
    let it = iterations.max(1) as f64;
    let mine = &mut figures[F * ranks.rank()..F * (ranks.rank() + 1)];
    mine[0] = peak.map(|p| p as f64).unwrap_or(-1.0);
    mine[1] = traffic.sent_bytes as f64 / it;
    mine[2] = traffic.received_bytes as f64 / it;
    mine[3] = rayon::current_num_threads() as f64;
    ranks.sum_f64(&mut figures);
    let total: f64 = work.iter().sum();
    blocks
        .iter()
        .enumerate()
        .map(|(r, b)| RankShare {
            rank: r,
            frames: [k0 + b.start, k0 + b.end],
            work_share: work[b.clone()].iter().sum::<f64>() / total.max(1e-300),
            peak_memory_bytes: (figures[F * r] >= 0.0).then_some(figures[F * r] as u64),
            sent_bytes_per_iteration: figures[F * r + 1],
            received_bytes_per_iteration: figures[F * r + 2],
            threads: figures[F * r + 3] as usize,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::capture::Fov;
    use crate::model::op::pseudo_random;
    use crate::model::ranks::threads::ThreadRanks;
    use crate::model::rolling::RollingShutterModel;
    use crate::model::shutter::{ShutterMode, ShutterWeights, Timing};
    use crate::solve::optimize::SolverKind;
    use crate::solve::optimize::{solve, NoObserver, StopRule};
    use crate::solve::prox::block::BlockTv;

    /// FISTA on the blocks of 3 ranks (threads): every exchange of the split (the
    /// forward's shared rows, halo frames, sums, the agreed stop, the gather) gives the
    /// whole problem's video.
    #[test]
    fn fista_on_blocks_of_thread_ranks_gives_the_whole_video() {
        let (m, n) = (24, 20);
        let psf: Vec<f32> = pseudo_random(m * n, 5).iter().map(|v| v.powi(4)).collect();
        let w = Timing::new(m, 10.0, 30.0, ShutterMode::Dual).weights().unwrap();
        let model = |w: ShutterWeights| RollingShutterModel::of_psf(&psf, m, n, Fov::Sensor, w);
        let whole = model(w.clone());
        let k = w.frames();
        let truth: Vec<f32> = pseudo_random(k * m * n, 9);
        let mut b = vec![0.0f32; m * n];
        whole.forward(&truth, &mut b);
        let tv = TotalVariation::new((k, m, n), 1e-3, 5.0);
        let settings = OptimizerSettings::new(
            SolverKind::FistaRestart,
            1.01 * crate::solve::lipschitz::power_iteration(&whole, 200, 1e-9, 1).lambda_max,
            StopRule::iterations(25),
        );
        let expected = solve(&settings, &whole, &DataTerm::new(&b), &tv, None, &mut NoObserver).x;
        let blocks = balanced_blocks(&frame_work(&w, m), 3).unwrap();
        let ranks = ThreadRanks::chain(3);
        let video = std::thread::scope(|s| {
            let handles: Vec<_> = ranks
                .iter()
                .map(|r| {
                    let (blocks, w, b, tv, settings) = (&blocks, &w, &b, &tv, &settings);
                    let model = &model;
                    s.spawn(move || {
                        let mine = blocks[r.rank()].clone();
                        let op = Split::new(model(w.window(mine.clone())), r, mine, k, RowShare::new(w, blocks, r.rank()));
                        let data = DataTerm::new(b).on(op.partition());
                        let x = solve(settings, &op, &data, &BlockTv::new(tv.clone(), r), None, &mut NoObserver).x;
                        let mut out = (r.rank() == 0).then(|| vec![0.0f32; k * m * n]);
                        r.gather_frames(&x, blocks, m * n, out.as_deref_mut());
                        out
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).next().flatten().unwrap()
        });
        let d: f64 = video.iter().zip(&expected).map(|(&a, &e)| (a as f64 - e as f64).powi(2)).sum::<f64>().sqrt();
        let e: f64 = expected.iter().map(|&v| (v as f64).powi(2)).sum::<f64>().sqrt();
        assert!(d / e < 1e-5, "relative difference {}", d / e);
    }
}
