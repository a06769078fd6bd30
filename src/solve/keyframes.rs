//! Key frames in the solve: each key frame a data term beside the rolling-shutter raw
//! ([`crate::model::keyframe`]), weighted by the noise measured in the key frame itself,
//! the gain between the two cameras fitted once up front, and the video started from
//! the key frames.
//!
//! In video units the key frame `j` reads `y_j / g_j = K_j v + n_j / g_j`; with the
//! raw's noise `sigma_b` and the key frame's `sigma_j` (both measured), the weighted
//! least-squares term is `0.5 ||A v - b||^2 + sum_j 0.5 lambda_j ||K_j v - y_j / g_j||^2`
//! with `lambda_j = (sigma_b g_j / sigma_j)^2`: one data term of the stacked operator
//! `[A; sqrt(lambda_j) K_j]` ([`Fused`]) over the stacked observations `[b;
//! sqrt(lambda_j) y_j / g_j]`, which every gradient solver minimises as it is.
//!
//! The gain: the key frames' still image (each back-projected onto the video grid and
//! divided by its exposure in frames, then averaged) explains the raw through the still
//! operator up to one factor, fitted by least squares over the raw's kept pixels; the
//! factor is `1 / g`. A brightness mismatch between the cameras would read as motion, so
//! it is fitted once from the whole scene and never re-fitted against a running estimate.

use crate::model::data::DataTerm;
use crate::model::keyframe::{Fused, KeyFrameOp};
use crate::model::op::Operator;
use crate::model::prepare::Prepared;
use crate::model::rolling::RollingShutterModel;
use crate::solve::lipschitz::{EigenStore, Fingerprint};
use crate::solve::problem::{PriorRecipe, Problem, ReconstructError};
use rayon::prelude::*;
use serde::Serialize;

/// How one key frame entered one channel's solve, and how the video fits it.
#[derive(Clone, Debug, Serialize)]
pub struct KeyFrameFit {
    pub file: String,
    pub start_us: f64,
    pub exposure_us: f64,
    /// Key-frame counts per video unit per frame of exposure.
    pub gain: f64,
    /// `fitted` (from the raw) or `given` (the table's `gain`).
    pub gain_from: &'static str,
    pub dark_level: f64,
    pub dark_estimated: bool,
    /// The key frame's noise, counts (measured on the frame).
    pub noise_sigma: f64,
    /// `lambda_j`: the term's weight against the raw's.
    pub weight: f64,
    /// Whether the weight was held below the noise's (`(sigma_b g / sigma_j)^2`) at the
    /// raw term's stiffness times `stiffness_cap`.
    pub weight_capped: bool,
    /// How much stiffer than the raw's term this one may be ([`STIFFNESS_CAP`] for the
    /// plain video, [`STATIC_DYNAMIC_STIFFNESS_CAP`] for the static + dynamic model).
    pub stiffness_cap: f64,
    /// Pixels of the key frame in the data term.
    pub pixels: usize,
    /// The video's misfit to the key frame per pixel over its noise (1: to the noise).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub chi2: Option<f64>,
}

/// The key frames' terms of one channel: their maps (scaled by the weights), their
/// stacked observations and their reports.
pub struct KeyFrameTerms {
    pub ops: Vec<KeyFrameOp>,
    pub obs: Vec<f32>,
    pub fits: Vec<KeyFrameFit>,
    /// The still scene the key frames show, one frame on the video grid
    /// ([`background`]: the plain video's start between the key frames, the static
    /// image's start in the static + dynamic model).
    pub background: Vec<f32>,
    /// Each key frame's still image over its gain, in video units ([`KeyFrameTerms::start`]).
    keys: Vec<Vec<f32>>,
}

/// How much stiffer than the raw's term a key frame's term may be in the plain video's
/// solve (its weight is held there when its noise would make it stiffer). Measured on
/// disc-over-texture through the measured PSF with key frames at the first and last
/// frame (docs/keyframes.md): motion error 0.81 at 1, 0.72 at 3, 0.69 at 10, 0.72 at 30
/// (600 iterations, not converged); the steps shrink by about this factor.
pub const STIFFNESS_CAP: f64 = 10.0;

/// The same cap in the static + dynamic model, where the static image (every frame's
/// share) is pinned by the key frames and the raw together in its own block, and the
/// dynamic block's step is set by the stacked operator's constant: a stiffer key frame
/// only shortens the step of every frame it does not see. 240 x 320 x 122 disc over
/// texture with key frames at the first and last frame (docs/keyframes.md): motion error
/// 0.658 at 0.3, 0.657 at 1, 0.658 at 3, 0.705 at 10 (not converged at 600 iterations);
/// solver seconds 38.4, 35.7, 57.5, 70.2.
pub const STATIC_DYNAMIC_STIFFNESS_CAP: f64 = 1.0;

/// How many frames of the video one frame of the coarse solve spans
/// ([`coarse_binning`]). Measured on disc-over-texture through the measured PSF at
/// 240 x 320 x 122 with key frames at the first and last frame (`tau_rel` 1e-4, each
/// solve to the stop rule, docs/keyframes.md): the coarse video, brought to the
/// capture's frames, has a motion error of 0.82 at 2 (367 iterations, 20.5 s), 0.78
/// at 4 (376, 11.5 s); the solve on the capture's own frames reached 0.78 only after
/// 1200 iterations (137 s). Each coarse frame is seen by four times the rows, so what
/// moves settles in far fewer, cheaper iterations.
pub const COARSE_BINNING: usize = 4;

/// The fewest frames a coarse solve may have: a shorter video is solved on its own
/// frames alone.
pub const COARSE_MIN_FRAMES: usize = 8;

/// The binning of the coarse solve that starts a key-frame solve of `frames` frames
/// ([`COARSE_BINNING`]), when the coarse video keeps at least [`COARSE_MIN_FRAMES`].
pub fn coarse_binning(frames: usize) -> Option<usize> {
    (frames / COARSE_BINNING >= COARSE_MIN_FRAMES).then_some(COARSE_BINNING)
}

/// The coarse solve a key-frame solve started from (summary.json:
/// `channels[].coarse`).
#[derive(Clone, Debug, Serialize)]
pub struct CoarseStart {
    /// Frames of the video per coarse frame.
    pub binning: usize,
    /// Frames of the coarse video.
    pub frames: usize,
    pub iterations: usize,
    /// Seconds of the coarse solve, its set-up included; counted in the channel's
    /// seconds and trace.
    pub seconds: f64,
}

impl CoarseStart {
    /// The terminal line.
    pub fn line(&self) -> String {
        format!(
            "started from a solve {}x coarser in time: {} frames, {} iterations in {:.2} s (counted in the run's seconds)",
            self.binning, self.frames, self.iterations, self.seconds
        )
    }
}

/// The coarse video `coarse` (`coarse_frames` frames, each spanning `binning` frames
/// of the video) on the video's `(frames, rows, cols)`: linear in time between the
/// coarse frames' centres (held past the first and last centre), divided by `binning`
/// (a coarse frame holds the light of `binning` frames).
pub fn refine_in_time(coarse: &[f32], coarse_frames: usize, binning: usize, (k, m, n): (usize, usize, usize)) -> Vec<f32> {
    let px = m * n;
    assert_eq!(coarse.len(), coarse_frames * px, "the coarse video must hold its frames");
    let b = binning.max(1) as f64;
    let last = coarse_frames.saturating_sub(1);
    let mut out = vec![0.0f32; k * px];
    out.par_chunks_mut(px).enumerate().for_each(|(f, o)| {
        // Frame f's centre in coarse frames, from the first coarse frame's centre.
        let u = ((f as f64 + 0.5) / b - 0.5).clamp(0.0, last as f64);
        let lo = (u.floor() as usize).min(last);
        let hi = (lo + 1).min(last);
        let w = (u - lo as f64) as f32;
        let (a, c) = (&coarse[lo * px..(lo + 1) * px], &coarse[hi * px..(hi + 1) * px]);
        let inv = 1.0 / b as f32;
        for ((o, &a), &c) in o.iter_mut().zip(a).zip(c) {
            *o = ((1.0 - w) * a + w * c) * inv;
        }
    });
    out
}

/// The smallest noise a term is weighted by, relative to its data's peak: a noise-free
/// frame must not make its term infinitely stiff.
const NOISE_FLOOR: f32 = 1e-4;

/// The still image of one key frame on the video grid, in key counts per frame of
/// exposure: its pixels back-projected through the map (`R^T y / R^T 1`), divided by the
/// window's length in frames.
fn still_of(op: &KeyFrameOp, y: &[f32], usable: &[bool]) -> Vec<f32> {
    let y: Vec<f32> = y.iter().zip(usable).map(|(&v, &u)| if u { v } else { 0.0 }).collect();
    let ones: Vec<f32> = usable.iter().map(|&u| u as u8 as f32).collect();
    let num = op.image_adjoint(&y);
    let den = op.image_adjoint(&ones);
    let e = op.exposure_frames().max(1e-12) as f32;
    num.iter().zip(&den).map(|(&n, &d)| if d > 1e-6 { n / d / e } else { 0.0 }).collect()
}

/// Each key frame's map onto `model`'s video grid and its still image there
/// ([`still_of`]), channel `ch`.
fn maps(prepared: &Prepared, ch: usize, model: &RollingShutterModel) -> Result<(Vec<KeyFrameOp>, Vec<Vec<f32>>), String> {
    let (k, mv, nv) = model.video_shape();
    let frame_us = model.weights().frame_time_us();
    let mut ops = Vec::new();
    let mut stills = Vec::new();
    for p in &prepared.keyframes {
        let w = p.spec.time_weights(k, frame_us).map_err(|e| format!("{}: {e}", p.name))?;
        let mut op = KeyFrameOp::new((k, mv, nv), (p.rows, p.cols), w, p.affine, p.blur.clone());
        op.leave_out(&p.usable);
        if !op.inside().iter().any(|&i| i) {
            return Err(format!("{}: no pixel of the key frame maps into the video grid ({mv} x {nv}): check its affine", p.name));
        }
        stills.push(still_of(&op, &p.planes[ch], op.inside()));
        ops.push(op);
    }
    Ok((ops, stills))
}

/// Each key frame's window centre (in frames, frame `f` spanning `f .. f + 1`) with
/// its index, earliest first; a window that covers no frame is left out.
fn by_centre(ops: &[KeyFrameOp]) -> Vec<(f64, usize)> {
    let mut centres: Vec<(f64, usize)> = ops
        .iter()
        .enumerate()
        .filter_map(|(j, op)| {
            let w = op.time_weights();
            let sum: f64 = w.iter().map(|&x| x as f64).sum();
            (sum > 0.0).then(|| (w.iter().enumerate().map(|(f, &x)| (f as f64 + 0.5) * x as f64).sum::<f64>() / sum, j))
        })
        .collect();
    centres.sort_by(|a, b| a.0.total_cmp(&b.0));
    centres
}

/// A pixel changes between two key frames when their values, each over its frame's
/// mean, differ by more than this (a key frame's noise above it reads as motion: the
/// departure from the interpolation is the model that assumes less).
pub const MOTION_CONTRAST: f64 = 0.1;

/// Below this share of the video grid changing between the key frames, a small part
/// moves over a still scene: the static + dynamic model's case. Above it (a camera pan,
/// a deforming region, a large moving part) the key-frame video is solved as its
/// departure from the key frames' interpolation. Measured in docs/keyframes.md, *Which
/// model*: a disc and an occluder change 1.4% of the grid; a cut-out object 9.0%, a
/// face-sized deformation 8.9%, a pan 84%.
pub const SMALL_MOTION_SHARE: f64 = 0.05;

/// The share of channel `ch`'s video grid that changes between consecutive key frames
/// (the largest over the pairs; [`MOTION_CONTRAST`]); `None` with fewer than two key
/// frames or when they do not map onto the grid.
pub fn moving_share(prepared: &Prepared, ch: usize, model: &RollingShutterModel) -> Option<f64> {
    let (ops, stills) = maps(prepared, ch, model).ok()?;
    let order: Vec<usize> = by_centre(&ops).into_iter().map(|(_, j)| j).collect();
    // Each key frame over its mean on the pixels it sees (NaN where it sees none).
    let scaled: Vec<Vec<f64>> = order
        .iter()
        .map(|&j| {
            let (op, still) = (&ops[j], &stills[j]);
            let ones: Vec<f32> = op.inside().iter().map(|&u| u as u8 as f32).collect();
            let den = op.image_adjoint(&ones);
            let seen: Vec<f64> = still.iter().zip(&den).filter(|(_, &d)| d > 1e-6).map(|(&v, _)| v as f64).collect();
            let mean = (seen.iter().sum::<f64>() / seen.len().max(1) as f64).max(f64::MIN_POSITIVE);
            still.iter().zip(&den).map(|(&v, &d)| if d > 1e-6 { v as f64 / mean } else { f64::NAN }).collect()
        })
        .collect();
    scaled
        .windows(2)
        .map(|pair| {
            let (mut both, mut moving) = (0usize, 0usize);
            for (&x, &y) in pair[0].iter().zip(&pair[1]) {
                if x.is_finite() && y.is_finite() {
                    both += 1;
                    moving += ((x - y).abs() > MOTION_CONTRAST) as usize;
                }
            }
            moving as f64 / both.max(1) as f64
        })
        .reduce(f64::max)
}

/// The key frames' terms of channel `ch` for `model` (the raw's operator) and the raw
/// `b` with its noise `raw_sigma` (counts; `None`: unmeasured, the terms weigh as the
/// key frames' own noise says against a raw noise of one count).
pub fn terms(
    prepared: &Prepared,
    ch: usize,
    model: &RollingShutterModel,
    raw_sigma: Option<f32>,
    raw_lipschitz: f64,
    raw_still: Option<&[f32]>,
    stiffness_cap: f64,
) -> Result<KeyFrameTerms, String> {
    let (_, mv, nv) = model.video_shape();
    let (mut ops, stills) = maps(prepared, ch, model)?;
    let gains = gains(prepared, ch, model, &ops, &stills)?;
    let raw_sigma = raw_sigma.filter(|s| s.is_finite() && *s > 0.0).unwrap_or(1.0);
    let mut obs = Vec::new();
    let mut fits = Vec::new();
    for ((p, op), &(g, from)) in prepared.keyframes.iter().zip(ops.iter_mut()).zip(&gains) {
        let y = &p.planes[ch];
        let peak = y.iter().fold(0.0f32, |m, &v| m.max(v.abs())).max(1e-12);
        let sigma = p.sigma[ch].filter(|s| s.is_finite()).unwrap_or(0.0).max(NOISE_FLOOR * peak);
        let noise_scale = raw_sigma as f64 * g / sigma as f64;
        // A term far stiffer than the raw's would set every step: its weight is held at
        // `stiffness_cap` times the raw term's Lipschitz constant over its map's.
        op.scale = 1.0;
        let norm = op.lipschitz_upper_bound().unwrap_or(1.0).max(1e-30);
        let scale = noise_scale.min((stiffness_cap * raw_lipschitz / norm).sqrt());
        op.scale = scale as f32;
        let f = scale / g;
        obs.extend(y.iter().zip(op.inside()).map(|(&v, &i)| if i { (f * v as f64) as f32 } else { 0.0 }));
        fits.push(KeyFrameFit {
            file: p.name.clone(),
            start_us: p.spec.start_us,
            exposure_us: p.spec.exposure_us,
            gain: g,
            gain_from: from,
            dark_level: p.dark,
            dark_estimated: p.dark_estimated,
            noise_sigma: sigma as f64,
            weight: scale * scale,
            weight_capped: scale < noise_scale,
            stiffness_cap,
            pixels: op.inside().iter().filter(|&&i| i).count(),
            chi2: None,
        });
    }
    let (keys, background) = background(&stills, &gains, raw_still, mv * nv);
    Ok(KeyFrameTerms { ops, obs, fits, background, keys })
}

/// The still scene the key frames show: at each pixel the key frame (over its gain)
/// nearest the raw's still image `raw_still` (the time average, which a moving object
/// barely changes) is taken as the background (without a still image: the key frames'
/// mean). Returns each key frame over its gain, and the background.
fn background(stills: &[Vec<f32>], gains: &[(f64, &'static str)], raw_still: Option<&[f32]>, px: usize) -> (Vec<Vec<f32>>, Vec<f32>) {
    let keys: Vec<Vec<f32>> = stills.iter().zip(gains).map(|(s, &(g, _))| s.iter().map(|&v| (v as f64 / g).max(0.0) as f32).collect()).collect();
    let mean = |p: usize| keys.iter().map(|key| key[p]).sum::<f32>() / keys.len().max(1) as f32;
    let background: Vec<f32> = (0..px)
        .map(|p| {
            let near = raw_still.map_or_else(|| mean(p), |s| s[p]);
            keys.iter().map(|key| key[p]).min_by(|a, b| (a - near).abs().total_cmp(&(b - near).abs())).unwrap_or(near)
        })
        .collect();
    (keys, background)
}

/// The gain of each key frame: the table's, else the one factor by which the key
/// frames' mean still image (the frames without a given gain) explains the raw.
fn gains(prepared: &Prepared, ch: usize, model: &RollingShutterModel, ops: &[KeyFrameOp], stills: &[Vec<f32>]) -> Result<Vec<(f64, &'static str)>, String> {
    let unknown: Vec<usize> = (0..ops.len()).filter(|&j| prepared.keyframes[j].spec.gain.is_none()).collect();
    let fitted = if unknown.is_empty() {
        None
    } else {
        let (k, mv, nv) = model.video_shape();
        let px = mv * nv;
        let mut s = vec![0.0f32; px];
        for &j in &unknown {
            s.iter_mut().zip(&stills[j]).for_each(|(a, &v)| *a += v / unknown.len() as f32);
        }
        let video: Vec<f32> = s.repeat(k);
        let mut a_s = vec![0.0f32; model.output_len()];
        model.forward(&video, &mut a_s);
        let b = &prepared.raw[ch].data;
        let mask = prepared.data_mask.mask.as_deref();
        let (mut ab, mut aa) = (0.0f64, 0.0f64);
        for (i, (&x, &y)) in a_s.iter().zip(b).enumerate() {
            if mask.is_some_and(|m| m[i] == 0.0) {
                continue;
            }
            ab += x as f64 * y as f64;
            aa += x as f64 * x as f64;
        }
        if !(aa > 0.0) {
            let names: Vec<&str> = unknown.iter().map(|&j| prepared.keyframes[j].name.as_str()).collect();
            return Err(format!(
                "{}: no light above the key frames' dark level ({}): nothing to fit their gain to; check the key camera's exposure and trigger, its dark_level, or give `gain` in the [[keyframes]] tables",
                names.join(", "),
                unknown.iter().map(|&j| format!("{:.1}", prepared.keyframes[j].dark)).collect::<Vec<_>>().join(", ")
            ));
        }
        let c = ab / aa;
        if !(c.is_finite() && c > 0.0) {
            return Err(format!(
                "{}: the key frames' still image does not explain the raw with a positive gain (fitted {c:.3e}); give `gain` in the [[keyframes]] tables, or check the key frames' dark level and files",
                prepared.keyframes[unknown[0]].name
            ));
        }
        Some(1.0 / c)
    };
    Ok(prepared.keyframes.iter().map(|p| p.spec.gain.map_or_else(|| (fitted.unwrap_or(1.0), "fitted"), |g| (g, "given"))).collect())
}

impl KeyFrameTerms {
    /// The plain video's start from the still scene the key frames show: every frame
    /// holds the [`background`], and each frame inside a key frame's window holds that
    /// key frame, weighted by its overlap. Made only when a solve starts from it.
    /// Against the key frames interpolated in time, this start leaves no ghost of the
    /// moving object in the frames between them: on disc-over-texture at 240 x 320 x 122
    /// the track's p90 went from 34.6 to 6.2 px and the run from 501 to 317 iterations,
    /// the motion error from 0.858 to 0.891 (docs/keyframes.md).
    pub fn start(&self) -> Vec<f32> {
        let px = self.background.len();
        let k = self.ops.first().map_or(0, |op| op.time_weights().len());
        let mut video = vec![0.0f32; k * px];
        for (f, frame) in video.chunks_mut(px.max(1)).enumerate() {
            let w: Vec<f32> = self.ops.iter().map(|op| op.time_weights()[f]).collect();
            let rest = (1.0 - w.iter().sum::<f32>()).clamp(0.0, 1.0);
            for (p, o) in frame.iter_mut().enumerate() {
                *o = rest * self.background[p] + w.iter().zip(&self.keys).map(|(&wj, key)| wj * key[p]).sum::<f32>();
            }
        }
        video
    }

    /// The key frames interpolated in time on the video grid: each frame linear
    /// between the two key frames whose windows' centres bracket it, the first (last)
    /// key frame held before (after) its centre; one key frame: that key frame in every
    /// frame.
    pub fn interpolation(&self) -> Vec<f32> {
        let px = self.background.len();
        let k = self.ops.first().map_or(0, |op| op.time_weights().len());
        let centres = by_centre(&self.ops);
        let mut video = vec![0.0f32; k * px];
        if centres.is_empty() {
            video.chunks_mut(px.max(1)).for_each(|f| f.copy_from_slice(&self.background));
            return video;
        }
        video.par_chunks_mut(px.max(1)).enumerate().for_each(|(f, frame)| {
            let t = f as f64 + 0.5;
            let hi = centres.iter().position(|&(c, _)| c >= t).unwrap_or(centres.len() - 1);
            let lo = hi.saturating_sub(1);
            let ((c0, j0), (c1, j1)) = (centres[lo], centres[hi]);
            let w = if c1 > c0 { ((t - c0) / (c1 - c0)).clamp(0.0, 1.0) as f32 } else { 1.0 };
            for ((o, &a), &b) in frame.iter_mut().zip(&self.keys[j0]).zip(&self.keys[j1]) {
                *o = (1.0 - w) * a + w * b;
            }
        });
        video
    }

    /// The stacked operator `[A; K_1; ...]` on `model`.
    pub fn fused<'m>(&self, model: &'m RollingShutterModel) -> Fused<&'m RollingShutterModel> {
        Fused::new(model, self.ops.clone())
    }

    /// The stacked observations `[b; y_1; ...]` and their lower bounds (the raw's
    /// clipped pixels; none in the key frames), when the raw has any.
    pub fn observations(&self, b: &[f32], lower: Option<&[bool]>) -> (Vec<f32>, Option<Vec<bool>>) {
        let mut obs = b.to_vec();
        obs.extend_from_slice(&self.obs);
        let lower = lower.map(|l| {
            let mut v = l.to_vec();
            v.resize(obs.len(), false);
            v
        });
        (obs, lower)
    }

    /// The Lipschitz cache key of the stacked operator: the raw operator's key, then each
    /// key frame's map.
    pub fn key(&self, raw_key: Fingerprint) -> Fingerprint {
        self.ops.iter().fold(raw_key.bytes(b"keyframes-v1"), |key, op| {
            let (r, c) = op.key_shape();
            let map: Vec<f32> = op.map().iter().flatten().map(|&v| v as f32).collect();
            let inside: Vec<u8> = op.inside().iter().map(|&i| i as u8).collect();
            let key = key.usize(r).usize(c).f32s(op.time_weights()).f32s(&map).f32s(&[op.scale]).bytes(&inside);
            match op.blur() {
                None => key,
                Some(k) => key.usize(k.rows).usize(k.cols).f32s(&k.data),
            }
        })
    }

    /// Each key frame's misfit per pixel over its noise for the video `v`.
    pub fn add_fit(&mut self, v: &[f32]) {
        let mut at = 0;
        for (op, fit) in self.ops.iter().zip(self.fits.iter_mut()) {
            let n = op.output_len();
            let mut y = vec![0.0f32; n];
            op.forward(v, &mut y);
            let obs = &self.obs[at..at + n];
            // The scaled residual is `(scale / g) (g K v - y)`: over `scale sigma_j / g`
            // it is the residual in counts over the key frame's noise.
            let unit = (op.scale as f64) * fit.noise_sigma / fit.gain;
            let ss: f64 = y.iter().zip(obs).zip(op.inside()).filter(|(_, &i)| i).map(|((&p, &q), _)| ((p - q) as f64 / unit).powi(2)).sum();
            fit.chi2 = Some(ss / fit.pixels.max(1) as f64);
            at += n;
        }
    }
}

/// How far a key-frame video departs from the key frames' interpolation, and whether
/// the raw supports the departure (summary.json: `channels[].interpolation`).
#[derive(Clone, Debug, Serialize)]
pub struct InterpolationReport {
    /// `||v - r|| / ||r||`: the video's departure from the interpolation `r`.
    pub departure_rel: f64,
    /// `||M (A r - b)|| / ||M b||`: the raw's residual under the interpolation (the data
    /// term's pixels, as the still check's residual).
    pub raw_residual_interpolation: f64,
    /// `||M (A v - b)|| / ||M b||`: the raw's residual under the video.
    pub raw_residual_video: f64,
    /// The interpolation's relative error (after the best scale) against the truth,
    /// when one was given: the baseline the video must beat.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub interpolation_rel_error_scaled: Option<f64>,
    /// The interpolation's motion error against the truth, when one was given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub interpolation_motion_error: Option<f64>,
}

impl InterpolationReport {
    /// The report of the video `v` against the interpolation `r` on the raw operator
    /// `model` and the raw's data term `data` (and the truth, when given).
    pub fn of(model: &RollingShutterModel, data: &DataTerm, v: &[f32], r: &[f32], truth: Option<&[f32]>) -> InterpolationReport {
        let residual = |x: &[f32]| {
            let mut ax = vec![0.0f32; model.output_len()];
            model.forward(x, &mut ax);
            crate::solve::start::residual_rel(&ax, data, model.mask())
        };
        let frames = model.video_shape().0;
        InterpolationReport {
            // An all-dark interpolation is refused before any solve (no light to fit the gain to).
            departure_rel: crate::solve::trace::compare(v, r).map_or(f64::INFINITY, |e| e.rel_error),
            raw_residual_interpolation: residual(r),
            raw_residual_video: residual(v),
            interpolation_rel_error_scaled: truth.and_then(|t| crate::solve::trace::compare(r, t)).map(|e| e.rel_error_scaled),
            interpolation_motion_error: truth.and_then(|t| crate::solve::trace::motion_error(r, t, frames)),
        }
    }

    /// The terminal line.
    pub fn line(&self) -> String {
        let supported = if self.raw_residual_video < self.raw_residual_interpolation { "the raw supports it" } else { "the raw does not support it" };
        let mut line = format!(
            "departs {:.3} (relative) from the key frames' interpolation; the raw's residual {:.4} under the video, {:.4} under the interpolation: {supported}",
            self.departure_rel, self.raw_residual_video, self.raw_residual_interpolation
        );
        if let (Some(e), Some(m)) = (self.interpolation_rel_error_scaled, self.interpolation_motion_error) {
            line.push_str(&format!(" (the interpolation alone: relative error {e:.4}, motion error {m:.4})"));
        }
        line
    }
}

/// A key frame's misfit above which the fit report warns: the video cannot be brought
/// to it, which a wrong window (the cameras' clocks), map or dark level does.
pub const CHI2_WARNING: f64 = 50.0;

/// The terminal line of one channel's key frames, and the warnings of those the video
/// does not fit.
pub fn report_lines(fits: &[KeyFrameFit]) -> (Option<String>, Vec<String>) {
    let Some(first) = fits.first() else {
        return (None, Vec::new());
    };
    let chi2: Vec<String> = fits.iter().map(|f| f.chi2.map_or("-".into(), |c| format!("{c:.2}"))).collect();
    let gains: Vec<f64> = fits.iter().map(|f| f.gain).collect();
    let same = gains.iter().all(|&g| (g - gains[0]).abs() <= 1e-9 * g.abs());
    let gain = if same { format!("gain {:.4} ({})", first.gain, first.gain_from) } else { format!("gains {gains:.4?}") };
    let capped = fits.iter().filter(|f| f.weight_capped).count();
    let cap =
        if capped > 0 { format!(", {capped} weighted at {}x the raw's stiffness (below their noise's weight)", first.stiffness_cap) } else { String::new() };
    let line = format!("key frames: {}, {gain}{cap}; chi2 per pixel over their noise {}", fits.len(), chi2.join(", "));
    let warnings = fits
        .iter()
        .filter(|f| f.chi2.is_some_and(|c| c > CHI2_WARNING))
        .map(|f| {
            format!(
                "{}: the video misfits this key frame by chi2 {:.1} per pixel: check its start_us/exposure_us (the two cameras' clocks must agree to about one line time), its affine map and dark level",
                f.file,
                f.chi2.unwrap_or(f64::NAN)
            )
        })
        .collect();
    (Some(line), warnings)
}

/// One channel's raw and key frames as one data term ([`KeyFrameData::of`]): the key
/// frames' terms, the raw's operator fused with their maps, the stacked observations
/// with their lower bounds, the fused operator's cache key and Lipschitz constant (with
/// the margin; whether it was stored).
pub(crate) struct KeyFrameData<'m> {
    pub terms: KeyFrameTerms,
    pub op: Fused<&'m RollingShutterModel>,
    pub obs: Vec<f32>,
    pub lower: Option<Vec<bool>>,
    pub key: Fingerprint,
    pub lipschitz: crate::solve::lipschitz::Lipschitz,
}

impl<'m> KeyFrameData<'m> {
    /// Channel `ch` of `problem` with its key frames: their terms weighed by the raw's
    /// noise `raw_sigma`, matched to a still fitted to the raw under `recipe`'s video
    /// prior, each term's stiffness capped at `stiffness_cap` of the raw's; `solver`
    /// checked against the fused operator before its constant is measured.
    pub(crate) fn of(
        problem: &'m Problem,
        ch: usize,
        raw_sigma: Option<f32>,
        recipe: &PriorRecipe,
        stiffness_cap: f64,
        solver: crate::solve::optimize::SolverKind,
        cache: &dyn EigenStore,
    ) -> Result<KeyFrameData<'m>, ReconstructError> {
        let (prepared, channel) = (problem.prepared, problem.channel(ch));
        let model = channel.model();
        let (b, lower) = (&prepared.raw[ch].data, prepared.data_mask.lower_bounds.as_deref());
        let raw_data = DataTerm::new(b).with_lower_bounds(lower);
        let prior = recipe.video(model.video_shape(), channel.atb_max() as f64);
        let still = crate::solve::start::still_fit(model, &raw_data, &prior, 150);
        let terms =
            terms(prepared, ch, model, raw_sigma, channel.lipschitz(cache).value, still.as_deref(), stiffness_cap).map_err(ReconstructError::Unsupported)?;
        let op = terms.fused(model);
        solver.check_operator(&op).map_err(ReconstructError::Unsupported)?;
        let (obs, lower) = terms.observations(b, lower);
        let key = terms.key(channel.key());
        let (e, cached) = cache.get_or_measure(key, &op);
        Ok(KeyFrameData {
            terms,
            op,
            obs,
            lower,
            key,
            lipschitz: crate::solve::lipschitz::Lipschitz { value: e.lambda_max * crate::solve::lipschitz::LIPSCHITZ_MARGIN, cached },
        })
    }

    /// The stacked data term.
    pub(crate) fn data(&self) -> DataTerm<'_> {
        DataTerm::new(&self.obs).with_lower_bounds(self.lower.as_deref())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_coarse_video_is_brought_to_the_frames_linear_between_centres() {
        // Two coarse frames of one pixel (values 8 and 16), each spanning 4 frames:
        // centres at frames 1.5 and 5.5; each frame holds a quarter of the light.
        let fine = refine_in_time(&[8.0, 16.0], 2, 4, (8, 1, 1));
        let expect = [2.0, 2.0, 2.25, 2.75, 3.25, 3.75, 4.0, 4.0];
        for (f, (&a, &b)) in fine.iter().zip(&expect).enumerate() {
            assert!((a - b).abs() < 1e-6, "frame {f}: {a} against {b}");
        }
        // A still coarse video stays still, at its light per frame; extra frames past
        // the coarse video's end hold its last frame.
        let still = refine_in_time(&[4.0, 6.0, 4.0, 6.0], 2, 2, (5, 1, 2));
        assert!(still.chunks(2).all(|f| f == [2.0, 3.0]), "{still:?}");
    }

    #[test]
    fn only_a_video_long_enough_gets_a_coarse_solve() {
        assert_eq!(coarse_binning(COARSE_BINNING * COARSE_MIN_FRAMES), Some(COARSE_BINNING));
        assert_eq!(coarse_binning(COARSE_BINNING * COARSE_MIN_FRAMES - 1), None);
        assert_eq!(coarse_binning(1), None);
        let line = CoarseStart { binning: 4, frames: 31, iterations: 280, seconds: 10.28 }.line();
        assert!(line.contains("4x coarser in time: 31 frames, 280 iterations in 10.28 s"), "{line}");
    }
}
