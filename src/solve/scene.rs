//! A scene declaration's problem: the restricted operator, the data and the TV term of
//! one channel (or of the grey mean) as [`crate::model::scene::SceneSpec`] declares it.

use crate::model::capture::{CaptureConfig, Fov};
use crate::model::data::DataTerm;
use crate::model::prepare::{Plane, Prepared};
use crate::model::rolling::RollingShutterModel;
use crate::model::scene::{invalid, Colour, Restricted, SceneError, ScenePlan, SceneSpec};
use crate::model::shutter::ShutterWeights;
use crate::solve::lipschitz::{EigenStore, Fingerprint, LIPSCHITZ_MARGIN};
use crate::solve::metric::{FrameMetric, FrameScaled};
use crate::solve::problem::adjoint_peak;
use crate::solve::prox::TotalVariation;

/// One channel's problem as the scene declares it.
pub struct SceneProblem {
    pub op: Restricted<RollingShutterModel>,
    pub b: Vec<f32>,
    /// The capture's clipped pixels (lower bounds of the data term), when any.
    pub lower_bounds: Option<Vec<bool>>,
    /// PSF the operator convolves with (summed over channels for a grey scene).
    pub psf: Vec<f32>,
    pub tv: TotalVariation,
    pub plan: ScenePlan,
}

impl SceneProblem {
    /// The Lipschitz cache key of the declared operator.
    pub fn fingerprint(&self) -> Fingerprint {
        let model = &self.op.inner;
        let (k, mv, nv) = model.video_shape();
        let (m, n) = model.conv().sensor_shape();
        let (ks, ms, ns) = self.plan.solved_shape;
        let key = Fingerprint::default()
            .bytes(b"rolling-shutter-restricted-v1")
            .f32s(&self.psf)
            .f32s(model.weights().as_slice())
            .usize(k)
            .usize(mv)
            .usize(nv)
            .usize(m)
            .usize(n)
            .usize(self.op.rows.start)
            .usize(self.op.cols.start)
            .usize(ks)
            .usize(ms)
            .usize(ns)
            .usize(self.op.static_scene as usize);
        crate::solve::problem::with_mask_key(key, model)
    }

    /// The Lipschitz constant (with margin) from `store`, or measured, and whether it
    /// came from the store.
    pub fn lipschitz(&self, store: &dyn EigenStore) -> (f64, bool) {
        let (e, cached) = store.get_or_measure(self.fingerprint(), &self.op);
        (e.lambda_max * LIPSCHITZ_MARGIN, cached)
    }

    /// The per-frame metric of the preconditioned gradient methods: each solved frame's
    /// sensitivity ([`RollingShutterModel::frame_sensitivity`] of the frames the
    /// operator holds; one frame of weight 1 for a static scene).
    pub fn frame_metric(&self) -> FrameMetric {
        let (k, m, n) = self.plan.solved_shape;
        let s = self.op.inner.frame_sensitivity(&self.psf);
        if self.op.static_scene || s.len() != k {
            return FrameMetric::identity(k, m * n);
        }
        FrameMetric::from_sensitivity(&s, m * n)
    }

    /// The Lipschitz constant (with margin) in `metric`, `lambda_max(P^{-1/2} A^T A
    /// P^{-1/2})`, from `store` (keyed by the operator and the metric's weights, never
    /// the plain constant) or measured, and whether it came from the store.
    pub fn lipschitz_in(&self, metric: &FrameMetric, store: &dyn EigenStore) -> (f64, bool) {
        let key = self.fingerprint().bytes(b"frame-metric-v1").f32s(metric.weights());
        let (e, cached) = store.get_or_measure(key, &FrameScaled { op: &self.op, metric });
        (e.lambda_max * LIPSCHITZ_MARGIN, cached)
    }

    /// The Lipschitz constant measured again (and stored), for a solve that went
    /// non-finite on a stored one.
    pub fn remeasure_lipschitz(&self, store: &dyn EigenStore) -> f64 {
        store.measure(self.fingerprint(), &self.op).lambda_max * LIPSCHITZ_MARGIN
    }

    /// The data term: `b`, one-sided at the clipped pixels.
    pub fn data(&self) -> DataTerm<'_> {
        DataTerm::new(&self.b).with_lower_bounds(self.lower_bounds.as_deref())
    }

    /// The largest finite entry of `A^T b` of the declared operator.
    pub fn atb_max(&self) -> f32 {
        adjoint_peak(&self.op, &self.b)
    }

    /// The reduced unknowns of a truth given on the full (frames, rows, cols) grid.
    pub fn restrict_truth(&self, full: &[f32]) -> Vec<f32> {
        let (k, m, n) = self.plan.full_shape;
        let (k0, k1) = self.plan.frames;
        let window = &full[k0 * m * n..k1 * m * n];
        debug_assert_eq!(full.len(), k * m * n);
        self.op.restrict(window, false)
    }
}

/// Build the problem of channel `ch` (or of the grey sum) from a prepared capture.
pub fn build_problem(
    prepared: &Prepared,
    cfg: &CaptureConfig,
    fov: Fov,
    spec: &SceneSpec,
    tau: f32,
    alpha: f32,
    ch: usize,
) -> Result<SceneProblem, SceneError> {
    build_problem_with(prepared, &cfg.timing().weights()?, fov, spec, tau, alpha, ch)
}

/// [`build_problem`] with the capture's shutter weights already computed (a
/// [`crate::solve::problem::Problem`] computes them once for every channel).
pub fn build_problem_with(
    prepared: &Prepared,
    weights: &ShutterWeights,
    fov: Fov,
    spec: &SceneSpec,
    tau: f32,
    alpha: f32,
    ch: usize,
) -> Result<SceneProblem, SceneError> {
    let captured = prepared.raw.len();
    let grey = spec.colour == Colour::Grey && captured > 1;
    let (rows, cols) = (prepared.psf[0].rows, prepared.psf[0].cols);
    // The mean over channels: with unit-sum PSFs, a grey scene (the same video in every
    // channel) explains the mean raw through the mean PSF, and one channel alone is the
    // same problem as the combined one.
    let mean = |planes: &[Plane]| -> Vec<f32> {
        let mut s = vec![0.0f64; rows * cols];
        for p in planes {
            for (a, &v) in s.iter_mut().zip(&p.data) {
                *a += v as f64;
            }
        }
        let inv = 1.0 / planes.len() as f64;
        s.into_iter().map(|v| (v * inv) as f32).collect()
    };
    let (b, psf) = if grey { (mean(&prepared.raw), mean(&prepared.psf)) } else { (prepared.raw[ch].data.clone(), prepared.psf[ch].data.clone()) };
    let k_full = weights.frames();
    let (k0, k1) = match spec.frames {
        None => (0, k_full),
        Some([k0, k1]) => {
            if k1 > k_full {
                return Err(invalid("frames", format!("[{k0}, {k1}]"), format!("a window inside the capture's {k_full} frames")));
            }
            (k0, k1)
        }
    };
    let weights = if (k0, k1) == (0, k_full) { weights.clone() } else { weights.window(k0..k1) };
    let model = RollingShutterModel::of_psf(&psf, rows, cols, fov, weights).with_data_mask(&prepared.data_mask);
    let (_, mv, nv) = model.video_shape();
    let (r0, r1, c0, c1) = match spec.support {
        None => (0, mv, 0, nv),
        Some([r0, r1, c0, c1]) => {
            if r1 > mv || c1 > nv {
                return Err(invalid("support", format!("[{r0}, {r1}, {c0}, {c1}]"), format!("a box inside the {mv} x {nv} video grid")));
            }
            (r0, r1, c0, c1)
        }
    };
    let op = Restricted::new(model, r0..r1, c0..c1, spec.static_scene);
    let shape = op.shape();
    let weights3 = spec.tv_weights.unwrap_or([alpha, 1.0, 1.0]);
    let tv = TotalVariation { shape, tau, weights: weights3, nonneg: true };
    let names = ["t", "y", "x"];
    let tv_axes: Vec<&'static str> = tv.active_axes().into_iter().map(|a| names[a]).collect();
    let mut left_out = Vec::new();
    if grey {
        left_out.push(format!("colour: grey scene, {captured} channels averaged and solved once"));
    }
    if (k0, k1) != (0, k_full) {
        left_out.push(format!("frames: {} of {k_full} frames outside the window {k0}..{k1}", k_full - (k1 - k0)));
    }
    if spec.static_scene {
        left_out.push(format!("static: {} frames solved as one", k1 - k0));
    }
    if (r0, r1, c0, c1) != (0, mv, 0, nv) {
        left_out.push(format!("support: {} of {} pixels per frame outside rows {r0}..{r1}, cols {c0}..{c1}", mv * nv - (r1 - r0) * (c1 - c0), mv * nv));
    }
    for (a, name) in names.iter().enumerate() {
        if !tv.active_axes().contains(&a) && [shape.0, shape.1, shape.2][a] > 1 {
            left_out.push(format!("tv: axis {name} left out of the TV term (weight 0)"));
        }
    }
    let plan = ScenePlan {
        spec: spec.clone(),
        channels_captured: captured,
        channels_solved: if grey { 1 } else { captured },
        full_shape: (k_full, mv, nv),
        solved_shape: shape,
        frames: (k0, k1),
        tv_axes,
        left_out,
    };
    Ok(SceneProblem { op, b, lower_bounds: prepared.data_mask.lower_bounds.clone(), psf, tv, plan })
}
