//! The imaging operator of a sequence of captures: capture `c`'s rolling-shutter
//! model applied to its slice of one long video,
//! `y_c = A_c v[o_c .. o_c + K_c]`, the measurements stacked capture after capture.
//! The adjoint adds every capture's `A_c^T y_c` into its slice, so frames two captures
//! share (continuous rolling readout) receive both contributions, and frames no
//! capture covers receive none.

use crate::model::op::Operator;
use crate::model::rolling::RollingShutterModel;
use std::sync::{Arc, Mutex};

/// One capture inside the sequence operator.
#[derive(Clone)]
pub struct Placed {
    /// First video frame the capture's model sees.
    pub offset: usize,
    pub model: Arc<RollingShutterModel>,
}

/// `A` of a sequence: per-capture models on slices of one `(frames, rows, cols)` video.
pub struct SequenceModel {
    frames: usize,
    video: (usize, usize),
    sensor: (usize, usize),
    parts: Vec<Placed>,
    /// Adjoint buffer for captures that overlap an earlier one.
    scratch: Mutex<Vec<f32>>,
}

impl SequenceModel {
    /// `parts` sorted by offset is not required; every part must fit in `frames` and all
    /// must share the video and sensor grids.
    pub fn new(frames: usize, parts: Vec<Placed>) -> SequenceModel {
        assert!(!parts.is_empty(), "a sequence operator needs at least one capture");
        let (_, mv, nv) = parts[0].model.video_shape();
        let sensor = parts[0].model.conv().sensor_shape();
        for p in &parts {
            let (k, pm, pn) = p.model.video_shape();
            assert!(p.offset + k <= frames, "capture frames {}..{} outside the {frames}-frame video", p.offset, p.offset + k);
            assert_eq!((pm, pn), (mv, nv), "captures must share the video grid");
            assert_eq!(p.model.conv().sensor_shape(), sensor, "captures must share the sensor size");
        }
        SequenceModel { frames, video: (mv, nv), sensor, parts, scratch: Mutex::new(Vec::new()) }
    }

    pub fn frames(&self) -> usize {
        self.frames
    }
    pub fn parts(&self) -> &[Placed] {
        &self.parts
    }
    /// (frames, rows, cols) of the video.
    pub fn video_shape(&self) -> (usize, usize, usize) {
        (self.frames, self.video.0, self.video.1)
    }
    fn frame_len(&self) -> usize {
        self.video.0 * self.video.1
    }
    fn sensor_len(&self) -> usize {
        self.sensor.0 * self.sensor.1
    }
}

impl Operator for SequenceModel {
    fn input_shape(&self) -> Vec<usize> {
        vec![self.frames, self.video.0, self.video.1]
    }
    fn output_shape(&self) -> Vec<usize> {
        vec![self.parts.len(), self.sensor.0, self.sensor.1]
    }
    /// `||A v||^2 = sum_c ||A_c v_c||^2 <= sum_c U_c ||v_c||^2`, so the largest sum of
    /// the captures' bounds `U_c` over the captures that see one frame.
    fn lipschitz_upper_bound(&self) -> Option<f64> {
        let mut per_frame = vec![0.0f64; self.frames];
        for p in &self.parts {
            let u = p.model.lipschitz_upper_bound()?;
            per_frame[p.offset..p.offset + p.model.frames()].iter_mut().for_each(|f| *f += u);
        }
        Some(per_frame.into_iter().fold(0.0, f64::max))
    }

    fn forward(&self, x: &[f32], y: &mut [f32]) {
        let (fl, sl) = (self.frame_len(), self.sensor_len());
        assert_eq!(x.len(), self.frames * fl);
        assert_eq!(y.len(), self.parts.len() * sl);
        for (p, yc) in self.parts.iter().zip(y.chunks_mut(sl)) {
            let k = p.model.frames();
            p.model.forward(&x[p.offset * fl..(p.offset + k) * fl], yc);
        }
    }

    fn adjoint(&self, y: &[f32], x: &mut [f32]) {
        let (fl, sl) = (self.frame_len(), self.sensor_len());
        assert_eq!(x.len(), self.frames * fl);
        assert_eq!(y.len(), self.parts.len() * sl);
        x.fill(0.0);
        // Frames [0, written) may already hold an earlier capture's contribution.
        let mut written = vec![false; self.frames];
        let mut local = Vec::new();
        let mut guard = self.scratch.try_lock().ok();
        let scratch: &mut Vec<f32> = match guard.as_deref_mut() {
            Some(s) => s,
            None => &mut local,
        };
        for (p, yc) in self.parts.iter().zip(y.chunks(sl)) {
            let k = p.model.frames();
            let range = p.offset..p.offset + k;
            let slice = &mut x[range.start * fl..range.end * fl];
            if !written[range.clone()].iter().any(|&w| w) {
                p.model.adjoint(yc, slice);
            } else {
                scratch.resize(k * fl, 0.0);
                p.model.adjoint(yc, &mut scratch[..k * fl]);
                for (a, &b) in slice.iter_mut().zip(scratch.iter()) {
                    *a += b;
                }
            }
            written[range].iter_mut().for_each(|w| *w = true);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::conv::Conv2d;
    use crate::model::op::{adjoint_mismatch, pseudo_random};
    use crate::model::shutter::{ShutterMode, Timing};

    #[test]
    fn single_capture_equals_its_model() {
        let (m, n) = (8, 6);
        let psf = pseudo_random(m * n, 2);
        let w = Timing::new(m, 10.0, 30.0, ShutterMode::Dual).weights().unwrap();
        let model = Arc::new(RollingShutterModel::new(Conv2d::sensor(&psf, m, n), w));
        let k = model.frames();
        let seq = SequenceModel::new(k, vec![Placed { offset: 0, model: model.clone() }]);
        let x = pseudo_random(seq.input_len(), 3);
        let (mut a, mut b) = (vec![0.0; m * n], vec![0.0; m * n]);
        seq.forward(&x, &mut a);
        model.forward(&x, &mut b);
        assert_eq!(a, b);
        assert!(adjoint_mismatch(&seq, &x, &pseudo_random(m * n, 4)) < 1e-6);
    }

    #[test]
    fn masked_captures_keep_their_own_pixels() {
        let (m, n) = (8, 6);
        let psf = pseudo_random(m * n, 2);
        let w = Timing::new(m, 10.0, 30.0, ShutterMode::Dual).weights().unwrap();
        let k = w.frames();
        let plain = Arc::new(RollingShutterModel::new(Conv2d::sensor(&psf, m, n), w.clone()));
        let mask: Vec<f32> = (0..m * n).map(|i| if i % 5 == 0 { 0.0 } else { 1.0 }).collect();
        let masked = Arc::new(RollingShutterModel::new(Conv2d::sensor(&psf, m, n), w).with_mask(Some(mask.clone().into())));
        let seq = SequenceModel::new(k + 2, vec![Placed { offset: 0, model: plain.clone() }, Placed { offset: 2, model: masked.clone() }]);
        // The second capture's masked pixels read 0; the adjoint still holds.
        let x = pseudo_random(seq.input_len(), 5);
        let mut y = vec![0.0; 2 * m * n];
        seq.forward(&x, &mut y);
        for (i, &v) in y[m * n..].iter().enumerate() {
            if mask[i] == 0.0 {
                assert_eq!(v, 0.0);
            }
        }
        assert!(adjoint_mismatch(&seq, &x, &pseudo_random(2 * m * n, 6)) < 1e-5);
    }
}
