//! The imaging model `A v = sum_k W[:, k] . crop(h * v_k)`: a video of `K` frames
//! seen through the diffuser and gated row by row by the shutter. `A` is never formed:
//! each frame is convolved through FFTs and only the rows its shutter weights touch
//! are evaluated.

use crate::conv::{Conv2d, ConvScratch};
use crate::op::Operator;
use crate::shutter::ShutterWeights;
use rayon::prelude::*;
use std::sync::Mutex;

/// `A` for one colour channel.
pub struct RollingShutterModel {
    conv: Conv2d,
    weights: ShutterWeights,
    /// Reusable per-thread FFT buffers (taken and returned around each frame).
    pool: Mutex<Vec<ConvScratch>>,
}

impl RollingShutterModel {
    /// `conv` fixes the PSF and the video grid; `weights` must have the sensor's rows.
    pub fn new(conv: Conv2d, weights: ShutterWeights) -> Self {
        assert_eq!(conv.sensor_shape().0, weights.rows(), "shutter weights must have one row per sensor row");
        RollingShutterModel { conv, weights, pool: Mutex::new(Vec::new()) }
    }

    pub fn frames(&self) -> usize {
        self.weights.frames()
    }
    pub fn weights(&self) -> &ShutterWeights {
        &self.weights
    }
    pub fn conv(&self) -> &Conv2d {
        &self.conv
    }
    /// (frames, rows, cols) of the video.
    pub fn video_shape(&self) -> (usize, usize, usize) {
        let (mv, nv) = self.conv.video_shape();
        (self.weights.frames(), mv, nv)
    }

    fn with_scratch<R>(&self, f: impl FnOnce(&mut ConvScratch) -> R) -> R {
        let mut s = self.pool.lock().unwrap().pop().unwrap_or_else(|| self.conv.scratch());
        let r = f(&mut s);
        self.pool.lock().unwrap().push(s);
        r
    }
}

impl Operator for RollingShutterModel {
    fn input_shape(&self) -> Vec<usize> {
        let (k, mv, nv) = self.video_shape();
        vec![k, mv, nv]
    }
    fn output_shape(&self) -> Vec<usize> {
        let (m, n) = self.conv.sensor_shape();
        vec![m, n]
    }

    fn forward(&self, x: &[f32], y: &mut [f32]) {
        let (k, mv, nv) = self.video_shape();
        let (_, n) = self.conv.sensor_shape();
        let frame_len = mv * nv;
        assert_eq!(x.len(), k * frame_len);
        // Frames are split into fixed chunks, each summed into its own image, then the
        // images are added in order: the result does not depend on thread timing.
        let chunks = rayon::current_num_threads().clamp(1, k);
        let per = k.div_ceil(chunks);
        let partials: Vec<Vec<f32>> = (0..chunks)
            .into_par_iter()
            .map(|c| {
                let mut acc = vec![0.0f32; y.len()];
                self.with_scratch(|s| {
                    for f in c * per..((c + 1) * per).min(k) {
                        let rows = self.weights.rows_of_frame(f);
                        if rows.is_empty() {
                            continue;
                        }
                        self.conv.forward_rows(&x[f * frame_len..(f + 1) * frame_len], rows, s, |i, row| {
                            let w = self.weights.get(i, f);
                            for (a, &v) in acc[i * n..(i + 1) * n].iter_mut().zip(row) {
                                *a += w * v;
                            }
                        });
                    }
                });
                acc
            })
            .collect();
        y.fill(0.0);
        for p in &partials {
            for (a, b) in y.iter_mut().zip(p) {
                *a += b;
            }
        }
    }

    fn adjoint(&self, y: &[f32], x: &mut [f32]) {
        let (k, mv, nv) = self.video_shape();
        let (_, n) = self.conv.sensor_shape();
        assert_eq!(x.len(), k * mv * nv);
        x.par_chunks_mut(mv * nv).enumerate().for_each(|(f, xf)| {
            let rows = self.weights.rows_of_frame(f);
            if rows.is_empty() {
                xf.fill(0.0);
                return;
            }
            self.with_scratch(|s| {
                self.conv.adjoint_rows(
                    rows,
                    s,
                    |i, row| {
                        let w = self.weights.get(i, f);
                        for (r, &v) in row.iter_mut().zip(&y[i * n..(i + 1) * n]) {
                            *r = w * v;
                        }
                    },
                    xf,
                );
            });
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::op::{adjoint_mismatch, pseudo_random, Dense};
    use crate::shutter::{ShutterMode, Timing};

    fn model(m: usize, n: usize, mode: ShutterMode, full: bool) -> RollingShutterModel {
        let psf = pseudo_random(m * n, 11);
        let t = Timing::new(m, 10.0, 25.0, mode);
        let conv = if full { Conv2d::full(&psf, m, n) } else { Conv2d::sensor(&psf, m, n) };
        RollingShutterModel::new(conv, t.weights().unwrap())
    }

    #[test]
    fn adjoint_dot_product_every_mode_odd_and_even_sizes() {
        for mode in ShutterMode::ALL {
            for (m, n) in [(8, 6), (7, 9), (1, 4), (2, 3)] {
                for full in [false, true] {
                    let a = model(m, n, mode, full);
                    let x = pseudo_random(a.input_len(), 1);
                    let y = pseudo_random(a.output_len(), 2);
                    let e = adjoint_mismatch(&a, &x, &y);
                    assert!(e < 1e-5, "{mode} {m}x{n} full={full}: {e}");
                }
            }
        }
    }

    #[test]
    fn static_scene_gives_exposure_ratio_times_convolution() {
        let (m, n) = (6, 5);
        let a = model(m, n, ShutterMode::Dual, false);
        let (k, _, _) = a.video_shape();
        let frame = pseudo_random(m * n, 3);
        let x: Vec<f32> = (0..k).flat_map(|_| frame.iter().cloned()).collect();
        let mut y = vec![0.0; m * n];
        a.forward(&x, &mut y);
        let c = a.conv().apply(&frame, &mut a.conv().scratch());
        for (yi, ci) in y.iter().zip(&c) {
            assert!((yi - 2.5 * ci).abs() < 1e-4 * ci.abs().max(1.0), "{yi} vs {}", 2.5 * ci);
        }
    }

    #[test]
    fn forward_matches_dense_reference_built_from_weights() {
        // Build A from its definition: sum_k W[:,k] . conv(v_k), column by column.
        let (m, n) = (4, 3);
        let a = model(m, n, ShutterMode::Rolling, false);
        let dense = Dense::from_operator(&a);
        let psf = pseudo_random(m * n, 11);
        let w = a.weights();
        let (k, _, _) = a.video_shape();
        for f in 0..k {
            for p in 0..m * n {
                let mut v = vec![0.0; m * n];
                v[p] = 1.0;
                let c = crate::conv::conv_direct(&psf, m, n, &v, m, n, (0, 0));
                for i in 0..m {
                    for j in 0..n {
                        let expect = w.get(i, f) * c[i * n + j];
                        let got = dense.a[(i * n + j) * dense.cols + f * m * n + p];
                        assert!((got - expect).abs() < 1e-5, "frame {f} pixel {p} -> ({i},{j})");
                    }
                }
            }
        }
    }
}
