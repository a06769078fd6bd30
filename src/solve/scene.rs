//! Declaring a channel's problem: one channel's [`DeclaredProblem`] (or the grey
//! mean's) restricted as [`crate::model::scene::SceneSpec`] declares, with its TV term
//! and what the declaration left out ([`ScenePlan`]), in its [`Declaration`]. The operator is the undeclared
//! channel's, shared, unless the declaration changes the operator itself (a frame
//! window's shutter weights, a grey scene's mean PSF).

use crate::model::capture::Fov;
use crate::model::prepare::{Plane, Prepared};
use crate::model::rolling::RollingShutterModel;
use crate::model::scene::{invalid, Colour, SceneError, ScenePlan, SceneSpec};
use crate::model::shutter::ShutterWeights;
use crate::solve::problem::{build_operator, ChannelProblem, Declaration, DeclaredProblem, Problem};
use crate::solve::prox::TotalVariation;
use std::sync::Arc;

impl Problem<'_> {
    /// Channel `ch`'s problem (or the grey mean's) as `spec` declares it, at TV weight
    /// `tau` and temporal weight `alpha`, on the operators built once.
    pub fn declare(&self, spec: &SceneSpec, tau: f32, alpha: f32, ch: usize) -> Result<DeclaredProblem, SceneError> {
        declare(self.prepared, self.weights(), self.fov, spec, (tau, alpha), ch, Some(self.channel(ch)))
    }
}

/// [`Problem::declare`] without a [`Problem`] (a split solve's block): the operators
/// built here.
pub fn declare_on(
    prepared: &Prepared,
    weights: &ShutterWeights,
    fov: Fov,
    spec: &SceneSpec,
    tau: f32,
    alpha: f32,
    ch: usize,
) -> Result<DeclaredProblem, SceneError> {
    declare(prepared, weights, fov, spec, (tau, alpha), ch, None)
}

/// Channel `ch`'s declared problem; `undeclared`: channel `ch`'s undeclared problem,
/// whose operator is shared when the declaration leaves the operator itself as it is.
fn declare(
    prepared: &Prepared,
    weights: &ShutterWeights,
    fov: Fov,
    spec: &SceneSpec,
    (tau, alpha): (f32, f32),
    ch: usize,
    undeclared: Option<&ChannelProblem>,
) -> Result<DeclaredProblem, SceneError> {
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
    let whole = (k0, k1) == (0, k_full);
    let build = |weights: &ShutterWeights| Arc::new(RollingShutterModel::of_psf(&psf, rows, cols, fov, weights.clone()).with_data_mask(&prepared.data_mask));
    // The undeclared operator of this PSF: the channel's own (shared) unless grey.
    let full = match undeclared {
        Some(u) if !grey => Arc::clone(&u.op.inner),
        _ if !grey => Arc::new(build_operator(&prepared.psf[ch], weights, fov, &prepared.data_mask)),
        _ => build(weights),
    };
    let model = if whole { Arc::clone(&full) } else { build(&weights.window(k0..k1)) };
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
    let lower_bounds = prepared.data_mask.lower_bounds.clone();
    let channel = match undeclared {
        Some(u) if Arc::ptr_eq(&u.op.inner, &model) => u.restricted(r0..r1, c0..c1, spec.static_scene),
        _ => ChannelProblem::new(crate::model::scene::Restricted::new(model, r0..r1, c0..c1, spec.static_scene), b, lower_bounds, psf),
    };
    let shape = channel.op.shape();
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
    Ok(channel.declared(Declaration { tv, plan, full }))
}
