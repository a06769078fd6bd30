//! The imaging model of a scene that does not change during the exposure.
//!
//! When every frame is the same image `s`, `A (1 ⊗ s) = sum_k W[:, k] . crop(h * s) =
//! g . crop(h * s)` with the row gains `g_i = sum_k W[i, k]` (the fraction of the frame
//! interval each row integrates, summed: `T_e / T_f` for a fully exposed row). That is
//! one convolution of one image, where `A` convolves every frame. [`Still`] is that
//! operator, with the data mask and the clipped pixels of the model it comes from, so
//! its problem is the video problem restricted to videos constant in time.
//!
//! A still solve is cheap (one `M x N` image, one convolution per call) and explains
//! what does not move, which is most of a dense bench scene. It is the warm start of
//! the video solve ([`crate::solve::start`]).

use crate::model::op::Operator;
use crate::model::rolling::RollingShutterModel;

/// `s -> M (g . crop(h * s))` for one `Mv x Nv` image, `g` the row gains of `model`'s
/// shutter weights, `M` its data mask: the model's own still form
/// ([`Operator::forward_still`]) as an operator on one image.
pub struct Still<'a> {
    model: &'a RollingShutterModel,
}

impl<'a> Still<'a> {
    pub fn new(model: &'a RollingShutterModel) -> Self {
        Still { model }
    }

    /// `(rows, cols)` of the image.
    pub fn image_shape(&self) -> (usize, usize) {
        self.model.conv().video_shape()
    }
}

impl Operator for Still<'_> {
    fn input_shape(&self) -> Vec<usize> {
        let (mv, nv) = self.image_shape();
        vec![1, mv, nv]
    }
    fn output_shape(&self) -> Vec<usize> {
        let (m, n) = self.model.conv().sensor_shape();
        vec![m, n]
    }
    fn forward(&self, x: &[f32], y: &mut [f32]) {
        let done = self.model.forward_still(x, y);
        debug_assert!(done, "a shutter convolution has a still form");
    }
    fn adjoint(&self, y: &[f32], x: &mut [f32]) {
        let done = self.model.adjoint_still(y, x);
        debug_assert!(done, "a shutter convolution has a still form");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::capture::Fov;
    use crate::model::op::{adjoint_mismatch, pseudo_random};
    use crate::model::shutter::{ShutterMode, Timing};
    use std::sync::Arc;

    fn model(m: usize, n: usize, mode: ShutterMode, fov: Fov) -> RollingShutterModel {
        let psf = pseudo_random(m * n, 7);
        let weights = Timing::new(m, 10.0, 25.0, mode).weights().unwrap();
        RollingShutterModel::of_psf(&psf, m, n, fov, weights)
    }

    #[test]
    fn still_operator_equals_the_video_operator_on_a_repeated_image() {
        for mode in ShutterMode::ALL {
            for (m, n) in [(8, 6), (7, 9), (1, 4)] {
                for fov in [Fov::Sensor, Fov::Full] {
                    let mut a = model(m, n, mode, fov);
                    // A mask with a hole: it carries over.
                    let mut mask = vec![1.0f32; m * n];
                    mask[n / 2] = 0.0;
                    a = a.with_mask(Some(Arc::from(mask)));
                    let still = Still::new(&a);
                    let image = pseudo_random(still.input_len(), 3);
                    let (mut y1, mut y2) = (vec![0.0; a.output_len()], vec![0.0; a.output_len()]);
                    still.forward(&image, &mut y1);
                    a.forward(&image.repeat(a.frames()), &mut y2);
                    let scale = y2.iter().fold(0.0f32, |s, v| s.max(v.abs()));
                    for (p, q) in y1.iter().zip(&y2) {
                        assert!((p - q).abs() <= 1e-5 * scale, "{mode} {m}x{n} {fov:?}: {p} vs {q}");
                    }
                    let e = adjoint_mismatch(&still, &pseudo_random(still.input_len(), 4), &pseudo_random(still.output_len(), 5));
                    assert!(e < 1e-5, "{mode} {m}x{n} {fov:?}: adjoint mismatch {e}");
                }
            }
        }
    }
}
