//! One capture to one video: build the imaging operator per colour channel, measure
//! (or recall) its Lipschitz constant, run FISTA with TV, record the trace. Channels
//! are solved in parallel, each with its own PSF.

use crate::capture::{CaptureConfig, Fov};
use crate::conv::Conv2d;
use crate::fista::{Fista, StopRule, Termination};
use crate::lipschitz::{Fingerprint, LipschitzCache, LIPSCHITZ_MARGIN};
use crate::model::RollingShutterModel;
use crate::op::Operator;
use crate::prepare::Prepared;
use crate::shutter::TimingError;
use crate::trace::{compare, Error, TraceRecorder, TraceRow};
use crate::tv::TotalVariation;
use ndarray::{Array4, ArrayView4, Axis};
use rayon::prelude::*;
use serde::Serialize;
use std::sync::atomic::{AtomicBool, Ordering};

/// Reconstruction parameters.
#[derive(Clone, Debug, Serialize)]
pub struct Params {
    /// TV weight tau (>= 0), in the units of the data (counts per frame interval).
    pub tau: f32,
    /// Weight of the temporal gradient relative to the spatial ones.
    pub alpha: f32,
    pub stop: StopRule,
    pub fov: Fov,
    /// FISTA with adaptive (function-value) restart.
    pub restart: bool,
}

impl Default for Params {
    fn default() -> Self {
        Params { tau: 1e-3, alpha: 10.0, stop: StopRule::iterations(200), fov: Fov::Sensor, restart: true }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ReconstructError {
    #[error("{0}")]
    Timing(#[from] TimingError),
    #[error("tau = {0}: expected a non-negative, finite TV weight")]
    Tau(f32),
    #[error("alpha = {0}: expected a non-negative, finite temporal weight")]
    Alpha(f32),
    #[error("{what}: shape {got:?} does not match the video's (frames, rows, cols, channels) = {expected:?}")]
    TruthShape { what: String, got: Vec<usize>, expected: Vec<usize> },
    #[error("the capture's downsampled grid {cfg:?} does not match the prepared data {data:?}")]
    Grid { cfg: (usize, usize), data: (usize, usize) },
}

/// What one channel's solve produced.
#[derive(Clone, Debug, Serialize)]
pub struct ChannelReport {
    pub channel: usize,
    pub iterations: usize,
    pub seconds: f64,
    pub termination: Termination,
    pub lipschitz: f64,
    pub lipschitz_cached: bool,
    pub objective: f64,
    pub data_term: f64,
    pub tv_term: f64,
    pub error: Option<Error>,
    #[serde(skip)]
    pub trace: Vec<TraceRow>,
}

/// A reconstructed video (frame, row, col, channel) and how it was obtained.
pub struct Reconstruction {
    pub video: Array4<f32>,
    pub frame_time_us: f64,
    /// Offset of the sensor inside the video grid (non-zero for `--fov full`).
    pub sensor_offset: (usize, usize),
    pub channels: Vec<ChannelReport>,
}

/// Progress hooks: `on_row(channel, row)` after every iteration; `stop` aborts cleanly.
pub struct Hooks<'a> {
    pub on_row: &'a (dyn Fn(usize, &TraceRow) + Sync),
    pub stop: &'a AtomicBool,
}

/// Build channel `ch`'s operator.
pub fn build_model(prepared: &Prepared, ch: usize, cfg: &CaptureConfig, fov: Fov) -> Result<RollingShutterModel, ReconstructError> {
    let weights = cfg.timing().weights()?;
    let psf = &prepared.psf[ch];
    if (psf.rows, psf.cols) != cfg.grid() {
        return Err(ReconstructError::Grid { cfg: cfg.grid(), data: (psf.rows, psf.cols) });
    }
    let conv = match fov {
        Fov::Sensor => Conv2d::sensor(&psf.data, psf.rows, psf.cols),
        Fov::Full => Conv2d::full(&psf.data, psf.rows, psf.cols),
    };
    Ok(RollingShutterModel::new(conv, weights))
}

/// Fingerprint of an operator for the Lipschitz cache.
pub fn model_fingerprint(psf: &[f32], model: &RollingShutterModel) -> Fingerprint {
    let (k, mv, nv) = model.video_shape();
    let (m, n) = model.conv().sensor_shape();
    Fingerprint::default().bytes(b"rolling-shutter-v1").f32s(psf).f32s(model.weights().as_slice()).usize(k).usize(mv).usize(nv).usize(m).usize(n)
}

/// Reconstruct every channel of a prepared capture.
pub fn reconstruct(
    prepared: &Prepared,
    cfg: &CaptureConfig,
    params: &Params,
    truth: Option<(ArrayView4<f32>, &str)>,
    cache: &LipschitzCache,
    hooks: &Hooks,
) -> Result<Reconstruction, ReconstructError> {
    if !(params.tau.is_finite() && params.tau >= 0.0) {
        return Err(ReconstructError::Tau(params.tau));
    }
    if !(params.alpha.is_finite() && params.alpha >= 0.0) {
        return Err(ReconstructError::Alpha(params.alpha));
    }
    let channels = prepared.raw.len();
    let models: Vec<RollingShutterModel> =
        (0..channels).map(|ch| build_model(prepared, ch, cfg, params.fov)).collect::<Result<_, _>>()?;
    let (k, mv, nv) = models[0].video_shape();
    let offset = models[0].conv().offset();
    let (m, n) = models[0].conv().sensor_shape();

    // Truth per channel, on the video grid (zero outside the sensor for --fov full).
    let truth_planes: Option<Vec<Vec<f32>>> = match truth {
        None => None,
        Some((t, name)) => {
            let (tk, tm, tn, tc) = t.dim();
            let ok_grid = (tm, tn) == (mv, nv) || (tm, tn) == (m, n);
            if tk != k || !ok_grid || tc != channels {
                return Err(ReconstructError::TruthShape {
                    what: name.into(),
                    got: vec![tk, tm, tn, tc],
                    expected: vec![k, mv, nv, channels],
                });
            }
            let (or, oc) = if (tm, tn) == (mv, nv) { (0, 0) } else { offset };
            Some(
                (0..channels)
                    .map(|ch| {
                        let mut v = vec![0.0f32; k * mv * nv];
                        let tch = t.index_axis(Axis(3), ch);
                        for f in 0..k {
                            for r in 0..tm {
                                for c in 0..tn {
                                    v[(f * mv + r + or) * nv + c + oc] = tch[[f, r, c]];
                                }
                            }
                        }
                        v
                    })
                    .collect(),
            )
        }
    };

    let results: Vec<(Vec<f32>, ChannelReport)> = (0..channels)
        .into_par_iter()
        .map(|ch| {
            let model = &models[ch];
            let (eig, cached) = cache.get_or_measure(model_fingerprint(&prepared.psf[ch].data, model), model);
            let lipschitz = eig.lambda_max * LIPSCHITZ_MARGIN;
            let tv = TotalVariation::new((k, mv, nv), params.tau, params.alpha);
            let fista = Fista { lipschitz, stop: params.stop.clone(), restart: params.restart };
            let truth_ch = truth_planes.as_ref().map(|t| t[ch].as_slice());
            let mut rec = TraceRecorder::new(truth_ch).with_callback(|row| {
                (hooks.on_row)(ch, row);
                !hooks.stop.load(Ordering::Relaxed)
            });
            let span = tracing::info_span!("solve", channel = ch, frames = k, rows = mv, cols = nv);
            let _g = span.enter();
            let r = fista.solve(model, &prepared.raw[ch].data, &tv, None, &mut rec);
            tracing::info!(iterations = r.iterations, seconds = r.seconds, termination = ?r.termination, "channel solved");
            let error = truth_ch.map(|t| compare(&r.x, t));
            let report = ChannelReport {
                channel: ch,
                iterations: r.iterations,
                seconds: r.seconds,
                termination: r.termination,
                lipschitz,
                lipschitz_cached: cached,
                objective: r.data_term + r.reg_term,
                data_term: r.data_term,
                tv_term: r.reg_term,
                error,
                trace: rec.rows,
            };
            (r.x, report)
        })
        .collect();

    let mut video = Array4::<f32>::zeros((k, mv, nv, channels));
    let mut reports = Vec::new();
    for (ch, (x, rep)) in results.into_iter().enumerate() {
        let plane = ndarray::ArrayView3::from_shape((k, mv, nv), &x).unwrap();
        video.index_axis_mut(Axis(3), ch).assign(&plane);
        reports.push(rep);
    }
    debug_assert_eq!(models[0].input_len(), k * mv * nv);
    Ok(Reconstruction { video, frame_time_us: cfg.timing().frame_time_us(), sensor_offset: offset, channels: reports })
}

/// The scale of the TV weight for a capture: the largest entry of `A^T b` over the
/// channels (a TV weight of this order flattens the video). Default weights are a
/// small fraction of it, so they follow the data's physical scale without rescaling
/// the data itself.
pub fn tau_scale(prepared: &Prepared, cfg: &CaptureConfig, fov: Fov) -> Result<f32, ReconstructError> {
    let mut scale = 0.0f32;
    for ch in 0..prepared.raw.len() {
        let model = build_model(prepared, ch, cfg, fov)?;
        let mut atb = vec![0.0f32; model.input_len()];
        model.adjoint(&prepared.raw[ch].data, &mut atb);
        scale = atb.iter().fold(scale, |m, &v| if v.is_finite() { m.max(v) } else { m });
    }
    Ok(scale)
}
