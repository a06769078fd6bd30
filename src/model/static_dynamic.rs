//! The static + dynamic scene model: every frame is one static image plus a dynamic
//! part, `v_k = s + d_k`.
//!
//! A bench scene is mostly still (the bench, the target, the background) with a few
//! things that move. The static image `s` is seen by every sensor row over its whole
//! exposure, so it is constrained like a global-shutter image: `A (1 ⊗ s) = (sum_k W_k)
//! . crop(h * s)`. The dynamic part `d` carries what changes.
//!
//! [`StaticPlusDynamic`] is the operator of the unknowns `z = [z_s; z_d]` (one image,
//! then a video) under a per-block scale `x = (c_s z_s, c_d z_d)`:
//!
//! `B z = A (c_s 1 ⊗ z_s + c_d z_d)`, `B^T y = (c_s sum_k (A^T y)_k, c_d A^T y)`,
//!
//! one application of the video operator `A` either way. The scale is how a gradient
//! method takes a step per block: plain steps on `z` are steps `c^2` on `x`, so with
//! `c_s = 1/sqrt(L_s)`, `c_d = 1/sqrt(L_d)` (each block's own Lipschitz constant) the
//! static block, whose constant is far larger than the dynamic block's, no longer holds
//! the dynamic block's step down.

use crate::model::op::Operator;
use rayon::prelude::*;
use std::sync::Mutex;

/// `z = [z_s; z_d] -> A (c_s 1 ⊗ z_s + c_d z_d)` for a video operator `A` on
/// `(frames, rows, cols)`.
pub struct StaticPlusDynamic<A> {
    pub inner: A,
    /// (frames, rows, cols) of the inner operator's input.
    pub shape: (usize, usize, usize),
    /// `[c_s, c_d]`: the scale of the static and the dynamic unknowns.
    pub scale: [f32; 2],
    /// The video `c_s 1 ⊗ z_s + c_d z_d` of a forward call (allocated once).
    scratch: Mutex<Vec<f32>>,
}

impl<A: Operator> StaticPlusDynamic<A> {
    /// The operator of `inner` (input `(frames, rows, cols)`) with block scales `scale`.
    pub fn new(inner: A, scale: [f32; 2]) -> Self {
        let s = inner.input_shape();
        assert_eq!(s.len(), 3, "the static + dynamic model needs a (frames, rows, cols) operator");
        let shape = (s[0], s[1], s[2]);
        StaticPlusDynamic { inner, shape, scale, scratch: Mutex::new(Vec::new()) }
    }

    /// Pixels of one frame.
    pub fn pixels(&self) -> usize {
        self.shape.1 * self.shape.2
    }

    /// The static image `s = c_s z_s` of `z`.
    pub fn static_image(&self, z: &[f32]) -> Vec<f32> {
        z[..self.pixels()].iter().map(|&v| self.scale[0] * v).collect()
    }

    /// The video `v_k = s + d_k` of `z`.
    pub fn video(&self, z: &[f32]) -> Vec<f32> {
        let mut v = vec![0.0f32; self.shape.0 * self.pixels()];
        self.video_into(z, &mut v);
        v
    }

    /// [`video`](Self::video) into `out`.
    pub fn video_into(&self, z: &[f32], out: &mut [f32]) {
        let p = self.pixels();
        let [cs, cd] = self.scale;
        let (zs, zd) = z.split_at(p);
        out.par_chunks_mut(p).zip(zd.par_chunks(p)).for_each(|(o, d)| {
            for ((o, &d), &s) in o.iter_mut().zip(d).zip(zs) {
                *o = cs * s + cd * d;
            }
        });
    }
}

impl<A: Operator> Operator for StaticPlusDynamic<A> {
    fn input_shape(&self) -> Vec<usize> {
        let (k, m, n) = self.shape;
        vec![(k + 1) * m * n]
    }
    fn output_shape(&self) -> Vec<usize> {
        self.inner.output_shape()
    }
    /// `||B z|| <= c_s ||A (1 ⊗ z_s)|| + c_d ||A z_d||`, so by Cauchy-Schwarz
    /// `lambda_max(B^T B) <= c_s^2 U_s + c_d^2 U_d` with the static image's and the
    /// video's bounds of a shutter convolution `A`.
    fn lipschitz_upper_bound(&self) -> Option<f64> {
        let s = self.inner.shutter_convolution()?;
        let [cs, cd] = self.scale.map(|c| c as f64);
        Some(cs * cs * s.static_lambda_upper_bound() + cd * cd * s.lambda_upper_bound())
    }
    fn forward(&self, z: &[f32], y: &mut [f32]) {
        let mut scratch = self.scratch.lock().unwrap_or_else(|e| e.into_inner());
        scratch.resize(self.shape.0 * self.pixels(), 0.0);
        self.video_into(z, &mut scratch);
        self.inner.forward(&scratch, y);
    }
    fn adjoint(&self, y: &[f32], z: &mut [f32]) {
        let p = self.pixels();
        let [cs, cd] = self.scale;
        let (zs, zd) = z.split_at_mut(p);
        self.inner.adjoint(y, zd);
        // Static block: c_s times the sum over frames, in parallel over pixels: f32
        // sums over runs of FRAMES_F32 frames (a few ulps, as FISTA's momentum sums),
        // added in f64 (widening every term to f64 was this adjoint's largest cost);
        // the sums on the stack (no allocation per call).
        const CHUNK: usize = 1024;
        const FRAMES_F32: usize = 8;
        zs.par_chunks_mut(CHUNK).enumerate().for_each(|(ci, out)| {
            let (p0, len) = (ci * CHUNK, out.len());
            let mut acc = [0.0f64; CHUNK];
            let mut run = [0.0f32; CHUNK];
            let (acc, run) = (&mut acc[..len], &mut run[..len]);
            for frames in zd.chunks(p * FRAMES_F32) {
                run.fill(0.0);
                for frame in frames.chunks(p) {
                    for (a, &g) in run.iter_mut().zip(&frame[p0..p0 + len]) {
                        *a += g;
                    }
                }
                for (a, &r) in acc.iter_mut().zip(run.iter()) {
                    *a += r as f64;
                }
            }
            for (o, &a) in out.iter_mut().zip(acc.iter()) {
                *o = cs * a as f32;
            }
        });
        zd.par_chunks_mut(p).for_each(|f| f.iter_mut().for_each(|v| *v *= cd));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::op::{adjoint_mismatch, pseudo_random, Dense};

    #[test]
    fn adjoint_and_forward_match_the_definition() {
        // A dense "video" operator on (3 frames, 2 x 2) -> 5 outputs.
        let (k, m, n) = (3, 2, 2);
        let dense = Dense { rows: 5, cols: k * m * n, a: pseudo_random(5 * k * m * n, 7) };
        struct Video(Dense, (usize, usize, usize));
        impl Operator for Video {
            fn input_shape(&self) -> Vec<usize> {
                vec![self.1 .0, self.1 .1, self.1 .2]
            }
            fn output_shape(&self) -> Vec<usize> {
                vec![self.0.rows]
            }
            fn forward(&self, x: &[f32], y: &mut [f32]) {
                self.0.forward(x, y)
            }
            fn adjoint(&self, y: &[f32], x: &mut [f32]) {
                self.0.adjoint(y, x)
            }
        }
        let op = StaticPlusDynamic::new(Video(dense, (k, m, n)), [0.7, 1.3]);
        assert!(adjoint_mismatch(&op, &pseudo_random(op.input_len(), 3), &pseudo_random(5, 4)) < 1e-5);
        // Forward of z equals the video operator applied to s + d_k.
        let z = pseudo_random(op.input_len(), 9);
        let mut y = vec![0.0; 5];
        op.forward(&z, &mut y);
        let s = op.static_image(&z);
        let v: Vec<f32> = z[m * n..].iter().enumerate().map(|(i, &zd)| 1.3 * zd + s[i % (m * n)]).collect();
        let mut y2 = vec![0.0; 5];
        op.inner.forward(&v, &mut y2);
        for (a, b) in y.iter().zip(&y2) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
        for (a, b) in op.video(&z).iter().zip(&v) {
            assert!((a - b).abs() < 1e-6, "{a} vs {b}");
        }
    }
}
