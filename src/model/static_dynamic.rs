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
    /// `c_d y` of an adjoint call, the still form's data of a forward call (allocated
    /// once).
    scratch_y: Mutex<Vec<f32>>,
    /// The inner operator has a still form ([`Operator::forward_still`]).
    still: bool,
}

impl<A: Operator> StaticPlusDynamic<A> {
    /// The operator of `inner` (input `(frames, rows, cols)`) with block scales `scale`.
    pub fn new(inner: A, scale: [f32; 2]) -> Self {
        let s = inner.input_shape();
        assert_eq!(s.len(), 3, "the static + dynamic model needs a (frames, rows, cols) operator");
        let shape = (s[0], s[1], s[2]);
        let mut probe = vec![0.0f32; inner.output_len()];
        let still = inner.forward_still(&vec![0.0f32; shape.1 * shape.2], &mut probe);
        StaticPlusDynamic { inner, shape, scale, scratch: Mutex::new(Vec::new()), scratch_y: Mutex::new(probe), still }
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
    /// With the inner operator's still form ([`Operator::forward_still`]): `c_d A z_d +
    /// c_s A (1 ⊗ z_s)`, one convolution of `z_s` and no video built; otherwise `A`
    /// of the video `c_s 1 ⊗ z_s + c_d z_d`.
    fn forward(&self, z: &[f32], y: &mut [f32]) {
        let p = self.pixels();
        let [cs, cd] = self.scale;
        let (zs, zd) = z.split_at(p);
        if self.still {
            let mut ys = self.scratch_y.lock().unwrap_or_else(|e| e.into_inner());
            ys.resize(y.len(), 0.0);
            // The still form's one convolution runs beside the video's.
            let still_y: &mut [f32] = &mut ys;
            let (has_still, ()) = rayon::join(
                || self.inner.forward_still(zs, still_y),
                || {
                    if cd != 0.0 {
                        self.inner.forward(zd, y)
                    }
                },
            );
            assert!(has_still, "the still form was there when the operator was made");
            if cd != 0.0 {
                y.iter_mut().zip(ys.iter()).for_each(|(o, &s)| *o = cd * *o + cs * s);
            } else {
                y.iter_mut().zip(ys.iter()).for_each(|(o, &s)| *o = cs * s);
            }
            return;
        }
        let mut scratch = self.scratch.lock().unwrap_or_else(|e| e.into_inner());
        scratch.resize(self.shape.0 * self.pixels(), 0.0);
        self.video_into(z, &mut scratch);
        self.inner.forward(&scratch, y);
    }
    /// `(c_s sum_k (A^T y)_k, c_d A^T y)`; the static block by the still form's
    /// adjoint when the inner operator has one.
    fn adjoint(&self, y: &[f32], z: &mut [f32]) {
        let p = self.pixels();
        let [cs, cd] = self.scale;
        let (zs, zd) = z.split_at_mut(p);
        // `c_d A^T y` as `A^T (c_d y)`: the data are one image, the video a hundred
        // (scaling the video afterwards was a pass over it per call). A zero `c_d`
        // (the static block alone) leaves the dynamic block zero.
        let scaled = cd != 0.0;
        let mut ys = self.scratch_y.lock().unwrap_or_else(|e| e.into_inner());
        ys.clear();
        if scaled {
            ys.extend(y.iter().map(|&v| cd * v));
        }
        let scaled_y: &[f32] = &ys;
        if self.still {
            // The still form's one convolution runs beside the video's.
            let (has_still, ()) = rayon::join(
                || self.inner.adjoint_still(y, zs),
                || {
                    if scaled {
                        self.inner.adjoint(scaled_y, zd)
                    }
                },
            );
            assert!(has_still, "the still form was there when the operator was made");
            zs.iter_mut().for_each(|v| *v *= cs);
            if !scaled {
                zd.fill(0.0);
            }
            return;
        }
        // No still form: the static block sums the frames of `A^T y`.
        if scaled {
            self.inner.adjoint(scaled_y, zd);
        } else {
            self.inner.adjoint(y, zd);
        }
        drop(ys);
        let cs = if scaled { cs / cd } else { cs };
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
        if !scaled {
            zd.fill(0.0);
        }
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

    /// The still form (one convolution of the static image, the data scaled before the
    /// adjoint) gives what the video form gives, on a masked rolling-shutter operator
    /// stacked with a resampled, blurred key frame, and for the static block alone.
    #[test]
    fn the_still_form_matches_building_the_video() {
        use crate::model::capture::Fov;
        use crate::model::keyframe::{Fused, Kernel, KeyFrameOp};
        use crate::model::rolling::RollingShutterModel;
        use crate::model::shutter::{ShutterMode, Timing};
        use std::sync::Arc;
        /// The same operator without its still form.
        struct VideoOnly<A>(A);
        impl<A: Operator> Operator for VideoOnly<A> {
            fn input_shape(&self) -> Vec<usize> {
                self.0.input_shape()
            }
            fn output_shape(&self) -> Vec<usize> {
                self.0.output_shape()
            }
            fn forward(&self, x: &[f32], y: &mut [f32]) {
                self.0.forward(x, y)
            }
            fn adjoint(&self, y: &[f32], x: &mut [f32]) {
                self.0.adjoint(y, x)
            }
        }
        for mode in ShutterMode::ALL {
            let (m, n) = (9, 7);
            let weights = Timing::new(m, 10.0, 25.0, mode).weights().unwrap();
            let mut mask = vec![1.0f32; m * n];
            mask[n + 2] = 0.0;
            let rs = RollingShutterModel::of_psf(&pseudo_random(m * n, 7), m, n, Fov::Sensor, weights).with_mask(Some(Arc::from(mask)));
            let (k, mv, nv) = rs.video_shape();
            let mut time = vec![0.0f32; k];
            time[k / 2] = 0.7;
            time[k - 1] = 1.0;
            let blur = Kernel::from_image(&[0.0, 1.0, 0.0, 1.0, 4.0, 2.0, 0.0, 1.0, 0.0], 3, 3);
            let mut key = KeyFrameOp::new((k, mv, nv), (2 * mv, 2 * nv), time, None, blur);
            key.scale = 3.5;
            let fused = Fused::new(&rs, vec![key]);
            let mut probe = vec![0.0f32; fused.output_len()];
            assert!(fused.forward_still(&vec![1.0; mv * nv], &mut probe), "the stacked operator has a still form");
            assert!(!VideoOnly(&fused).forward_still(&vec![1.0; mv * nv], &mut probe));
            for scale in [[0.7f32, 1.3], [0.4, 0.0]] {
                let still = StaticPlusDynamic::new(&fused, scale);
                let video = StaticPlusDynamic::new(VideoOnly(&fused), scale);
                let z = pseudo_random(still.input_len(), 9);
                let (mut a, mut b) = (vec![0.0f32; still.output_len()], vec![0.0f32; still.output_len()]);
                still.forward(&z, &mut a);
                video.forward(&z, &mut b);
                let top = b.iter().fold(0.0f32, |t, v| t.max(v.abs()));
                assert!(top > 0.0);
                for (p, q) in a.iter().zip(&b) {
                    assert!((p - q).abs() <= 2e-5 * top, "{mode} {scale:?} forward: {p} vs {q}");
                }
                let y = pseudo_random(still.output_len(), 4);
                let (mut a, mut b) = (vec![0.0f32; still.input_len()], vec![0.0f32; still.input_len()]);
                still.adjoint(&y, &mut a);
                video.adjoint(&y, &mut b);
                let top = b.iter().fold(0.0f32, |t, v| t.max(v.abs()));
                for (p, q) in a.iter().zip(&b) {
                    assert!((p - q).abs() <= 2e-5 * top, "{mode} {scale:?} adjoint: {p} vs {q}");
                }
                assert!(adjoint_mismatch(&still, &z, &y) < 1e-5, "{mode} {scale:?}");
            }
        }
    }
}
