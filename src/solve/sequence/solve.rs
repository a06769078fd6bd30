//! Solving a sequence: `joint` (one FISTA solve over the whole video), `streaming`
//! (capture by capture, each over its own frames plus an overlap with the result so
//! far, warm-started from it, and stitched), `separate` (each capture alone, frames two
//! captures share averaged by their exposure weights; the baseline).
//!
//! Streaming window of capture `c`: frames `[s, o_c + K)` with
//! `s = min(o_c, e) - H`, `e` the end of the frames solved so far and `H` the overlap.
//! Every capture that reaches into the window takes part; an earlier capture that
//! starts before `s` is restricted to its frames inside the window and its
//! measurement loses the contribution of its frames before `s`, fixed at the result so
//! far. So each window solves the whole problem's objective over its own frames with
//! the rest held. The initial guess is the result so far on the frames already
//! solved (those the earlier captures saw well) and the last of them held on the rest.

use super::error::SequenceError;
use crate::model::capture::{CaptureConfig, Fov};
use crate::model::data::DataTerm;
use crate::model::noise::{median_sigma, noise_sigma};
use crate::model::op::Operator;
use crate::model::prepare::{DataMask, Plane};
use crate::model::rolling::RollingShutterModel;
use crate::model::shutter::ShutterWeights;
use crate::model::stacked::{Placed, SequenceModel};
use crate::model::time_grid::TimeGrid;
use crate::solve::job::{run, ChannelJob};
use crate::solve::lipschitz::{EigenStore, Fingerprint, LIPSCHITZ_MARGIN};
use crate::solve::optimize::{OptimizerSettings, SolverKind};
use crate::solve::problem::{adjoint_peak, fingerprint, SolveSettings};
use crate::solve::prox::tv_dual::TvProxChoice;
use crate::solve::reconstruct::ReconstructError;
use crate::solve::reconstruct::{Hooks, SolveParams, SolveStats};
use crate::solve::tau::{Noise, TauScale};
use crate::solve::trace::{compare, Error, TraceRecorder, TraceRow};
use serde::Serialize;
use std::ops::Range;
use std::sync::atomic::Ordering;
use std::sync::Arc;

/// How a sequence is solved.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Mode {
    /// One FISTA solve over the whole sequence (memory grows with the captures).
    Joint,
    /// Capture by capture with overlap and warm start; results stitched.
    Streaming,
    /// Every capture on its own (no coupling across captures): the baseline.
    Separate,
}

impl std::str::FromStr for Mode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "joint" => Ok(Mode::Joint),
            "streaming" => Ok(Mode::Streaming),
            "separate" => Ok(Mode::Separate),
            _ => Err(format!("unknown mode '{s}': expected joint, streaming or separate")),
        }
    }
}

impl std::fmt::Display for Mode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Mode::Joint => "joint",
            Mode::Streaming => "streaming",
            Mode::Separate => "separate",
        })
    }
}

/// A sequence's prior is the plain video's ([`SolveParams::prior`]: TV, and L1 where
/// `l1` is given); reweighted L1 belongs to the static + dynamic model, which a sequence
/// has not, and is refused by name. The error is (field, value, expected), as
/// [`crate::solve::start::check_for_sequence`]'s.
pub fn check_prior(settings: &SolveSettings) -> Result<(), (&'static str, String, &'static str)> {
    match settings.l1_reweight {
        Some(r) if r > 0 => Err((
            "l1_reweight",
            r.to_string(),
            "0 for consecutive captures (reweighted L1 belongs to the static + dynamic model of a single capture, [scene] static_background = true)",
        )),
        _ => Ok(()),
    }
}

/// What one FISTA solve of a sequence did.
#[derive(Clone, Debug, Serialize)]
pub struct SolveReport {
    /// Captures whose measurements took part.
    pub captures: Vec<usize>,
    /// Video frames solved, `[first, end)`.
    pub frames: [usize; 2],
    pub warm_start: bool,
    /// The solver that ran and its TV map (`auto` resolved).
    pub solver: SolverKind,
    pub tv_prox: String,
    /// The solve's figures; its `error` is against the truth on the solved frames.
    #[serde(flatten)]
    pub stats: SolveStats,
    #[serde(skip)]
    pub trace: Vec<TraceRow>,
}

/// A reconstructed sequence: `(frames, rows, cols)` video and its solves.
pub struct SequenceVideo {
    pub video: Vec<f32>,
    pub shape: (usize, usize, usize),
    pub solves: Vec<SolveReport>,
    /// Of the whole video against the truth, when given.
    pub error: Option<Error>,
}

/// A sequence ready to solve: the time grid, the shared per-capture model, the
/// prepared measurements.
pub struct Sequence {
    pub grid: TimeGrid,
    pub psf: Plane,
    pub fov: Fov,
    /// The model of one capture (every capture shares timing and optics).
    pub model: Arc<RollingShutterModel>,
    /// Per capture: dark-subtracted, downsampled measurement (`rows x cols`).
    pub raws: Vec<Vec<f32>>,
    /// Per capture: the data term's mask (defects left out, clipped pixels one-sided).
    /// A masked capture gets its own operator `M_j A`.
    pub masks: Vec<DataMask>,
}

/// What one solve of a sequence covers: its frames, the captures whose measurements
/// take part, its index in the reports (the capture it is for), where it starts (zero
/// when `None`) and the Lipschitz constant (with margin; whether it was stored).
struct Part {
    frames: Range<usize>,
    captures: Vec<usize>,
    index: usize,
    x0: Option<Vec<f32>>,
    lipschitz: crate::solve::lipschitz::Lipschitz,
}

/// One streaming window: its frames, operator and measurements.
pub struct Window {
    pub capture: usize,
    pub frames: Range<usize>,
    pub captures: Vec<usize>,
    pub op: SequenceModel,
    pub b: Vec<f32>,
    /// The captures' clipped pixels in `b`'s order, when any capture has them.
    pub lower_bounds: Option<Vec<bool>>,
    key: Fingerprint,
}

impl Sequence {
    /// The sequence of `raws` (prepared planes of one size) on `grid` under `weights`,
    /// the shutter weights of `cfg`'s timing (computed once by the caller, which placed
    /// the captures on the grid with them).
    pub fn new(cfg: &CaptureConfig, weights: ShutterWeights, psf: Plane, grid: TimeGrid, raws: Vec<Plane>) -> Sequence {
        assert_eq!(raws.len(), grid.captures(), "one measurement per capture on the grid");
        let model = Arc::new(RollingShutterModel::of_psf(&psf.data, psf.rows, psf.cols, cfg.fov, weights));
        for r in &raws {
            assert_eq!((r.rows, r.cols), (psf.rows, psf.cols), "measurements must match the PSF grid");
        }
        let masks = vec![DataMask::default(); raws.len()];
        Sequence { grid, psf, fov: cfg.fov, model, raws: raws.into_iter().map(|p| p.data).collect(), masks }
    }

    /// The sequence with each capture's data-term mask (one entry per capture).
    pub fn with_masks(mut self, masks: Vec<DataMask>) -> Sequence {
        assert_eq!(masks.len(), self.raws.len(), "one mask entry per capture");
        self.masks = masks;
        self
    }

    /// Capture `j`'s operator over `weights` (the whole capture's when `None`): the
    /// shared model, or one with the capture's mask.
    fn capture_model(&self, j: usize, weights: Option<ShutterWeights>) -> Arc<RollingShutterModel> {
        let m = &self.masks[j];
        match (m.mask.is_none() && m.lower_bounds.is_none(), weights) {
            (true, None) => self.model.clone(),
            (_, w) => {
                let w = w.unwrap_or_else(|| self.model.weights().clone());
                Arc::new(RollingShutterModel::of_psf(&self.psf.data, self.psf.rows, self.psf.cols, self.fov, w).with_data_mask(m))
            }
        }
    }

    /// A key extended by capture `j`'s mask.
    fn mask_key(&self, key: Fingerprint, j: usize) -> Fingerprint {
        match &self.masks[j].mask {
            None => key,
            Some(m) => key.bytes(b"mask").usize(j).f32s(m),
        }
    }

    /// (frames, rows, cols) of the whole video.
    pub fn video_shape(&self) -> (usize, usize, usize) {
        let (_, mv, nv) = self.model.video_shape();
        (self.grid.frames, mv, nv)
    }

    fn frame_len(&self) -> usize {
        let (_, mv, nv) = self.model.video_shape();
        mv * nv
    }

    /// The operator of the whole sequence.
    pub fn operator(&self) -> SequenceModel {
        let parts = self.grid.offsets.iter().enumerate().map(|(j, &o)| Placed { offset: o, model: self.capture_model(j, None) }).collect();
        SequenceModel::new(self.grid.frames, parts)
    }

    /// The clipped pixels (lower bounds of the data term) of `captures`, capture after
    /// capture as their measurements are stacked; `None` when none has any.
    fn lower_bounds(&self, captures: &[usize]) -> Option<Vec<bool>> {
        let n = self.raws.first().map_or(0, Vec::len);
        captures
            .iter()
            .any(|&j| self.masks[j].lower_bounds.is_some())
            .then(|| captures.iter().flat_map(|&j| self.masks[j].lower_bounds.clone().unwrap_or_else(|| vec![false; n])).collect())
    }

    /// All measurements, capture after capture.
    pub fn measurements(&self) -> Vec<f32> {
        self.raws.concat()
    }

    /// Bytes a joint solve needs: four video volumes of FISTA, the output, an adjoint
    /// buffer of one capture, the measurement-sized vectors and the model's buffers.
    pub fn joint_bytes(&self) -> usize {
        let (f, mv, nv) = self.video_shape();
        let vol = 4 * f * mv * nv;
        let (m, n) = self.model.conv().sensor_shape();
        let meas = 4 * self.raws.len() * m * n;
        5 * vol + 4 * self.grid.capture_frames * mv * nv + 6 * meas + self.model.work_bytes(rayon::current_num_threads())
    }

    fn fingerprint(&self, tag: &[u8]) -> Fingerprint {
        let base = fingerprint(&self.psf.data, &self.model);
        Fingerprint::default().bytes(tag).bytes(base.hex().as_bytes())
    }

    fn check_truth(&self, truth: Option<(&[f32], &str)>) -> Result<(), SequenceError> {
        let (f, mv, nv) = self.video_shape();
        if let Some((t, name)) = truth {
            if t.len() != f * mv * nv {
                return Err(SequenceError::TruthShape { what: name.into(), got: vec![t.len() / (mv * nv).max(1), mv, nv], expected: vec![f, mv, nv] });
            }
        }
        Ok(())
    }

    /// Solve `part` of the sequence: `data` on `op` with `params`' prior, its trace
    /// against `truth` (the whole video's) through `hooks`.
    fn run<A: Operator + ?Sized>(
        &self,
        op: &A,
        data: &DataTerm,
        part: Part,
        params: &SolveParams,
        truth: Option<&[f32]>,
        hooks: &Hooks,
    ) -> Result<(Vec<f32>, SolveReport), SequenceError> {
        let Part { frames, captures, index, x0, lipschitz: crate::solve::lipschitz::Lipschitz { value: lipschitz, cached } } = part;
        params
            .solver
            .check_data(data)
            .and_then(|()| params.solver.check_operator(op))
            .and_then(|()| match params.device {
                crate::solve::optimize::Device::Cpu => Ok(()),
                d => Err(format!(
                    "consecutive captures are solved on the CPU: their windows are not one capture's convolution (--device {d} is for reconstruct)"
                )),
            })
            .map_err(|e| SequenceError::Reconstruct(ReconstructError::Unsupported(e)))?;
        let (_, mv, nv) = self.model.video_shape();
        let fl = mv * nv;
        let truth_w = truth.map(|t| &t[frames.start * fl..frames.end * fl]);
        let mut rec = TraceRecorder::new(truth_w).with_callback(|row| {
            (hooks.on_row)(index, row);
            !hooks.stop.load(Ordering::Relaxed)
        });
        let warm = x0.is_some();
        // The TV map the parameters ask for; `auto` is judged on this window's A^T b
        // (one adjoint, taken only then).
        let settings = OptimizerSettings::new(params.solver, lipschitz, params.stop.clone());
        let scale = match params.tv_prox {
            TvProxChoice::Fixed(_) => 0.0,
            TvProxChoice::Auto => adjoint_peak(op, data.observations()) as f64,
        };
        let prior = params.prior(false).video((frames.len(), mv, nv), scale);
        let tv_prox = params.solver.tv_map_label(&prior);
        let span = tracing::info_span!("sequence_solve", index, first = frames.start, end = frames.end, solver = %params.solver, tv_prox = %tv_prox);
        let _g = span.enter();
        let r = run(ChannelJob { settings: &settings, operator: op, data, prior: prior.build(None).as_ref(), start: x0 }, &mut rec);
        tracing::info!(iterations = r.iterations, seconds = r.seconds, termination = ?r.termination, "solved");
        let error = truth_w.and_then(|t| compare(&r.x, t));
        let report = SolveReport {
            captures,
            frames: [frames.start, frames.end],
            warm_start: warm,
            solver: params.solver,
            tv_prox,
            stats: SolveStats::new(&r, crate::solve::lipschitz::Lipschitz { value: lipschitz, cached }, error),
            trace: rec.rows,
        };
        Ok((r.x, report))
    }

    /// One FISTA solve over the whole sequence; refused when it needs more than
    /// `memory_limit_bytes`.
    pub fn solve_joint(
        &self,
        params: &SolveParams,
        truth: Option<(&[f32], &str)>,
        cache: &dyn EigenStore,
        hooks: &Hooks,
        memory_limit_bytes: u64,
    ) -> Result<SequenceVideo, SequenceError> {
        self.check_truth(truth)?;
        let need = self.joint_bytes();
        let shape = self.video_shape();
        if need as u64 > memory_limit_bytes {
            return Err(SequenceError::Memory {
                captures: self.raws.len(),
                frames: shape.0,
                rows: shape.1,
                cols: shape.2,
                needed_bytes: need as u64,
                limit_bytes: memory_limit_bytes,
            });
        }
        let op = self.operator();
        let mut key = self.fingerprint(b"sequence-joint-v1").usize(shape.0);
        for (j, &o) in self.grid.offsets.iter().enumerate() {
            key = self.mask_key(key.usize(o), j);
        }
        let (eig, cached) = cache.get_or_measure(key, &op);
        let l = eig.lambda_max * LIPSCHITZ_MARGIN;
        let t = truth.map(|t| t.0);
        let (b, captures): (Vec<f32>, Vec<usize>) = (self.measurements(), (0..self.raws.len()).collect());
        let lower = self.lower_bounds(&captures);
        let data = DataTerm::new(&b).with_lower_bounds(lower.as_deref());
        let part = Part { frames: 0..shape.0, captures, index: 0, x0: None, lipschitz: crate::solve::lipschitz::Lipschitz { value: l, cached } };
        let (x, rep) = self.run(&op, &data, part, params, t, hooks)?;
        let error = t.and_then(|t| compare(&x, t));
        Ok(SequenceVideo { video: x, shape, solves: vec![rep], error })
    }

    /// Each capture alone over its `K` frames; frames two captures share get the
    /// average of their estimates weighted by each capture's exposure weight there;
    /// gap frames stay 0.
    pub fn solve_separate(
        &self,
        params: &SolveParams,
        truth: Option<(&[f32], &str)>,
        cache: &dyn EigenStore,
        hooks: &Hooks,
    ) -> Result<SequenceVideo, SequenceError> {
        self.check_truth(truth)?;
        let shape = self.video_shape();
        let fl = self.frame_len();
        let k = self.grid.capture_frames;
        let (eig, cached) = cache.get_or_measure(fingerprint(&self.psf.data, &self.model), self.model.as_ref());
        let l = eig.lambda_max * LIPSCHITZ_MARGIN;
        let w = self.model.weights();
        let column: Vec<f64> = (0..k).map(|f| (0..w.rows()).map(|r| w.get(r, f) as f64).sum()).collect();
        let mut acc = vec![0.0f64; shape.0 * fl];
        let mut wsum = vec![0.0f64; shape.0];
        let mut solves = Vec::new();
        let t = truth.map(|t| t.0);
        for c in 0..self.raws.len() {
            let frames = self.grid.frames_of(c);
            let data = DataTerm::new(&self.raws[c]);
            let part =
                Part { frames: frames.clone(), captures: vec![c], index: c, x0: None, lipschitz: crate::solve::lipschitz::Lipschitz { value: l, cached } };
            let (x, rep) = self.run(self.model.as_ref(), &data, part, params, t, hooks)?;
            for (kf, f) in frames.enumerate() {
                wsum[f] += column[kf];
                for (a, &v) in acc[f * fl..(f + 1) * fl].iter_mut().zip(&x[kf * fl..(kf + 1) * fl]) {
                    *a += column[kf] * v as f64;
                }
            }
            solves.push(rep);
            if hooks.stop.load(Ordering::Relaxed) {
                break;
            }
        }
        let mut video = vec![0.0f32; shape.0 * fl];
        for f in 0..shape.0 {
            if wsum[f] > 0.0 {
                for (v, &a) in video[f * fl..(f + 1) * fl].iter_mut().zip(&acc[f * fl..(f + 1) * fl]) {
                    *v = (a / wsum[f]) as f32;
                }
            }
        }
        let error = t.and_then(|t| compare(&video, t));
        Ok(SequenceVideo { video, shape, solves, error })
    }

    /// Where capture `c`'s streaming window starts, given the frames solved so far
    /// (`solved_end`, 0 before the first) and the overlap `h`.
    pub fn window_start(&self, c: usize, solved_end: usize, h: usize) -> usize {
        let o = self.grid.offsets[c];
        if solved_end == 0 {
            o
        } else {
            o.min(solved_end).saturating_sub(h)
        }
    }

    /// Capture `c`'s streaming window over the result so far `x` (the whole video;
    /// frames before the window are held fixed).
    pub fn window(&self, c: usize, solved_end: usize, h: usize, x: &[f32]) -> Window {
        let fl = self.frame_len();
        let start = self.window_start(c, solved_end, h);
        let end = self.grid.offsets[c] + self.grid.capture_frames;
        let (m, n) = self.model.conv().sensor_shape();
        let mut parts = Vec::new();
        let mut b = Vec::new();
        let mut captures = Vec::new();
        let mut key = self.fingerprint(b"sequence-window-v1").usize(end - start);
        for j in 0..=c {
            let r = self.grid.frames_of(j);
            if r.end <= start {
                continue;
            }
            captures.push(j);
            if r.start >= start {
                parts.push(Placed { offset: r.start - start, model: self.capture_model(j, None) });
                b.extend_from_slice(&self.raws[j]);
                key = self.mask_key(key.usize(r.start - start).usize(0), j);
            } else {
                // Frames before the window are fixed: take their contribution out.
                let local = (start - r.start)..r.len();
                let mut fixed = x[r.start * fl..r.end * fl].to_vec();
                fixed[local.start * fl..].fill(0.0);
                let mut ax = vec![0.0f32; m * n];
                self.model.forward(&fixed, &mut ax);
                b.extend(self.raws[j].iter().zip(&ax).map(|(&y, &a)| y - a));
                parts.push(Placed { offset: 0, model: self.capture_model(j, Some(self.model.weights().window(local.clone()))) });
                key = self.mask_key(key.usize(0).usize(local.start + 1), j);
            }
        }
        let lower_bounds = self.lower_bounds(&captures);
        Window { capture: c, frames: start..end, captures, op: SequenceModel::new(end - start, parts), b, lower_bounds, key }
    }

    /// The warm start of a window: the result so far on the frames already solved
    /// that the earlier captures saw well (at least half the exposure weight of a
    /// capture's best-covered frame), and the last such frame held on the others (new
    /// frames, and the edge frames a capture's outermost rows alone saw).
    pub fn warm_start(&self, w: &Window, solved_end: usize, x: &[f32]) -> Vec<f32> {
        let fl = self.frame_len();
        let g = &self.grid;
        let col: Vec<f64> = {
            let wt = self.model.weights();
            (0..g.capture_frames).map(|k| (0..wt.rows()).map(|r| wt.get(r, k) as f64).sum()).collect()
        };
        let full = col.iter().cloned().fold(0.0f64, f64::max);
        // Coverage by the captures that ended before this window's capture.
        let mut seen = vec![0.0f64; solved_end];
        for c in (0..g.captures()).filter(|&c| c < w.capture) {
            for (k, f) in g.frames_of(c).enumerate() {
                if f < solved_end {
                    seen[f] += col[k];
                }
            }
        }
        let good = |f: usize| f < solved_end && seen[f] >= 0.5 * full;
        let held = (0..solved_end).rev().find(|&f| good(f)).unwrap_or(solved_end.saturating_sub(1));
        let mut x0 = Vec::with_capacity(w.frames.len() * fl);
        for f in w.frames.clone() {
            let src = if good(f) && f <= held { f } else { held };
            x0.extend_from_slice(&x[src * fl..(src + 1) * fl]);
        }
        x0
    }

    /// Solve window `w` from `x0` (None: from zero).
    pub fn solve_window(
        &self,
        w: &Window,
        x0: Option<Vec<f32>>,
        params: &SolveParams,
        truth: Option<&[f32]>,
        cache: &dyn EigenStore,
        hooks: &Hooks,
    ) -> Result<(Vec<f32>, SolveReport), SequenceError> {
        let (eig, cached) = cache.get_or_measure(w.key, &w.op);
        let l = eig.lambda_max * LIPSCHITZ_MARGIN;
        let data = DataTerm::new(&w.b).with_lower_bounds(w.lower_bounds.as_deref());
        let part = Part {
            frames: w.frames.clone(),
            captures: w.captures.clone(),
            index: w.capture,
            x0,
            lipschitz: crate::solve::lipschitz::Lipschitz { value: l, cached },
        };
        self.run(&w.op, &data, part, params, truth, hooks)
    }

    /// Capture by capture, each window warm-started from the result so far (from zero
    /// when `warm` is false), overlap `h` frames; the later window's result replaces the
    /// earlier on shared frames.
    pub fn solve_streaming(
        &self,
        params: &SolveParams,
        h: usize,
        warm: bool,
        truth: Option<(&[f32], &str)>,
        cache: &dyn EigenStore,
        hooks: &Hooks,
    ) -> Result<SequenceVideo, SequenceError> {
        self.check_truth(truth)?;
        let shape = self.video_shape();
        let fl = self.frame_len();
        let t = truth.map(|t| t.0);
        let mut x = vec![0.0f32; shape.0 * fl];
        let mut solved_end = 0usize;
        let mut solves = Vec::new();
        for c in 0..self.raws.len() {
            let w = self.window(c, solved_end, h, &x);
            let x0 = (warm && solved_end > 0).then(|| self.warm_start(&w, solved_end, &x));
            let (xw, rep) = self.solve_window(&w, x0, params, t, cache, hooks)?;
            x[w.frames.start * fl..w.frames.end * fl].copy_from_slice(&xw);
            solved_end = solved_end.max(w.frames.end);
            solves.push(rep);
            if hooks.stop.load(Ordering::Relaxed) {
                break;
            }
        }
        let error = t.and_then(|t| compare(&x, t));
        Ok(SequenceVideo { video: x, shape, solves, error })
    }
}

/// The TV weight's scale of a sequence: the largest entry of `A^T b` over all its
/// captures, as for one capture; the noise rule's input: the median of the captures'
/// raw noise and the frames of one capture (each capture adds its frames and its data
/// alike).
impl TauScale for Sequence {
    fn tau_scale(&self) -> f32 {
        adjoint_peak(&self.operator(), &self.measurements())
    }
    fn noise(&self) -> Option<Noise> {
        let (m, n) = self.model.conv().sensor_shape();
        let sigma = median_sigma(self.raws.iter().zip(&self.masks).map(|(raw, mask)| noise_sigma(raw, m, n, mask)))?;
        Some(Noise { sigma, frames: self.grid.capture_frames, keyframes: 0, static_dynamic: false })
    }
}
