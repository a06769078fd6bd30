//! The per-frame diagonal metric of the preconditioned gradient methods
//! ([`FrameMetric`]: `||x||_P^2 = sum_k d_k ||x_k||^2`, one weight per frame), the
//! choice of it ([`Precondition`]), and the operator `A P^{-1/2}` ([`FrameScaled`])
//! whose largest squared singular value is the step's Lipschitz constant in that
//! metric.
//!
//! FISTA in a fixed metric `P` converges at its usual rate when the gradient step is
//! `P^{-1} grad / L_P`, `L_P` the largest eigenvalue of `P^{-1/2} A^T A P^{-1/2}`, and
//! the prox is taken in the same metric: `argmin_x gamma R(x) + 0.5 sum_k d_k ||x_k -
//! z_k||^2` ([`crate::solve::prox::MetricProx`]). The weights come from each frame's
//! sensitivity `||A P_k||_F^2` (the Jacobi weight of a frame, averaged over its
//! pixels): frames that only the outer sensor rows see get the longer steps their
//! weaker constraint allows.

use crate::model::op::Operator;
use serde::Serialize;

/// Whether the gradient methods step in the per-frame metric.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Precondition {
    /// Plain steps (the identity metric).
    #[default]
    None,
    /// The per-frame metric from each frame's sensitivity ([`FrameMetric::from_sensitivity`]).
    Frames,
}

impl Precondition {
    pub fn name(self) -> &'static str {
        match self {
            Precondition::None => "none",
            Precondition::Frames => "frames",
        }
    }
}

impl std::str::FromStr for Precondition {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "none" => Ok(Precondition::None),
            "frames" => Ok(Precondition::Frames),
            _ => Err(format!("unknown preconditioner '{s}': expected none or frames")),
        }
    }
}

impl std::fmt::Display for Precondition {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The smallest frame weight relative to the largest: a frame the data barely see
/// (sensitivity ~0) is held at this, so that its step stays finite and the TV dual
/// map's step (bounded by the largest `1/d_k`) stays within a factor of ten of the
/// plain one. Outer-row frames of a rolling shutter (0.2 to 0.6) are above it.
pub const MIN_FRAME_WEIGHT: f32 = 0.1;

/// A diagonal metric constant on each frame of `frame_len` values: weights `d_k > 0`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FrameMetric {
    frame_len: usize,
    d: Vec<f32>,
    inv: Vec<f32>,
}

impl FrameMetric {
    /// The metric with weights `d` (finite, positive) on frames of `frame_len` values.
    pub fn new(d: Vec<f32>, frame_len: usize) -> Result<Self, String> {
        if frame_len == 0 || d.is_empty() {
            return Err("a frame metric needs at least one frame of at least one value".into());
        }
        if let Some((k, v)) = d.iter().enumerate().find(|(_, v)| !(v.is_finite() && **v > 0.0)) {
            return Err(format!("frame {k}: weight {v}: expected a positive finite number"));
        }
        let inv = d.iter().map(|&v| 1.0 / v).collect();
        Ok(FrameMetric { frame_len, d, inv })
    }

    /// The identity metric on `frames` frames.
    pub fn identity(frames: usize, frame_len: usize) -> Self {
        FrameMetric::new(vec![1.0; frames.max(1)], frame_len.max(1)).expect("ones are positive")
    }

    /// The metric of each frame's sensitivity `s_k` (`||A P_k||_F^2`, any common scale):
    /// `d_k = max(s_k / max_j s_j, MIN_FRAME_WEIGHT)`. Non-finite or negative
    /// sensitivities count as zero; all zero (no data): the identity.
    pub fn from_sensitivity(s: &[f64], frame_len: usize) -> Self {
        let clean = |v: f64| if v.is_finite() { v.max(0.0) } else { 0.0 };
        let top = s.iter().map(|&v| clean(v)).fold(0.0f64, f64::max);
        if top <= 0.0 {
            return FrameMetric::identity(s.len(), frame_len);
        }
        let d = s.iter().map(|&v| ((clean(v) / top) as f32).max(MIN_FRAME_WEIGHT)).collect();
        FrameMetric::new(d, frame_len).expect("weights are at least MIN_FRAME_WEIGHT")
    }

    pub fn frame_len(&self) -> usize {
        self.frame_len
    }

    pub fn frames(&self) -> usize {
        self.d.len()
    }

    /// The weights `d_k`.
    pub fn weights(&self) -> &[f32] {
        &self.d
    }

    /// `1 / d_k`.
    pub fn inverse(&self) -> &[f32] {
        &self.inv
    }

    /// `max_k 1 / d_k`.
    pub fn max_inverse(&self) -> f32 {
        self.inv.iter().fold(0.0f32, |a, &b| a.max(b))
    }

    /// `x_k *= s(k)` for every frame of `x`.
    fn scale(&self, x: &mut [f32], s: impl Fn(usize) -> f32 + Sync) {
        use rayon::prelude::*;
        x.par_chunks_mut(self.frame_len).enumerate().for_each(|(k, f)| {
            let s = s(k);
            f.iter_mut().for_each(|v| *v *= s);
        });
    }
}

/// `A P^{-1/2}`: the operator whose `lambda_max` of the normal operator is the
/// Lipschitz constant of the data term's gradient in the metric `P`.
pub struct FrameScaled<'a, A: ?Sized> {
    pub op: &'a A,
    pub metric: &'a FrameMetric,
}

impl<A: Operator + ?Sized> Operator for FrameScaled<'_, A> {
    fn input_shape(&self) -> Vec<usize> {
        self.op.input_shape()
    }
    fn output_shape(&self) -> Vec<usize> {
        self.op.output_shape()
    }
    fn forward(&self, x: &[f32], y: &mut [f32]) {
        let mut xs = x.to_vec();
        self.metric.scale(&mut xs, |k| self.metric.inv[k].sqrt());
        self.op.forward(&xs, y);
    }
    fn adjoint(&self, y: &[f32], x: &mut [f32]) {
        self.op.adjoint(y, x);
        self.metric.scale(x, |k| self.metric.inv[k].sqrt());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::op::{adjoint_mismatch, pseudo_random, Dense};

    #[test]
    fn weights_from_sensitivity_are_relative_to_the_largest_and_floored() {
        let m = FrameMetric::from_sensitivity(&[2.0, 4.0, 1e-9, f64::NAN], 3);
        assert_eq!(m.weights(), &[0.5, 1.0, MIN_FRAME_WEIGHT, MIN_FRAME_WEIGHT]);
        assert_eq!(m.max_inverse(), 1.0 / MIN_FRAME_WEIGHT);
        assert_eq!(FrameMetric::from_sensitivity(&[0.0, 0.0], 3), FrameMetric::identity(2, 3));
        assert!(FrameMetric::new(vec![1.0, 0.0], 2).unwrap_err().contains("frame 1"));
        assert_eq!("frames".parse::<Precondition>(), Ok(Precondition::Frames));
        assert!("diag".parse::<Precondition>().unwrap_err().contains("none or frames"));
    }

    #[test]
    fn the_scaled_operator_has_its_adjoint() {
        let a = Dense { rows: 5, cols: 6, a: pseudo_random(30, 2) };
        let metric = FrameMetric::new(vec![0.3, 1.0, 2.0], 2).unwrap();
        let s = FrameScaled { op: &a, metric: &metric };
        assert!(adjoint_mismatch(&s, &pseudo_random(6, 3), &pseudo_random(5, 4)) < 1e-5);
    }
}
