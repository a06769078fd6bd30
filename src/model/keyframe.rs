//! Key frames: images of the scene from a second, lensed, global-shutter camera taken
//! during the rolling-shutter exposure. A key frame is one more linear measurement of the
//! video: the video integrated over the key frame's exposure window, mapped onto the key
//! camera's pixels and blurred by its lens,
//!
//! `y_j = g_j B_j R_j (sum_k w_jk v_k) + dark_j + noise`,
//!
//! with `w_jk` the fraction of frame `k`'s interval inside the window (on the capture's
//! time axis: `t = 0` when the earliest raw row starts, which is when video frame 0
//! begins), `R_j` the resampling from the video grid to the key camera's pixels (an
//! affine map, or the plain scale between the two grids), `B_j` the lens's blur and
//! `g_j` the gain between the cameras' counts. [`KeyFrameRef`] is the description
//! (`[[keyframes]]` in capture.toml); [`KeyFrameOp`] the map `v -> B R (sum_k w_k v_k)`;
//! [`Fused`] stacks the rolling-shutter operator and the key frames' maps into one
//! operator whose data term is every measurement at once. Nothing here reads files.

use crate::model::op::Operator;
use crate::model::shutter::TimingError;
use serde::{Deserialize, Serialize};

/// One `[[keyframes]]` table of a capture description.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KeyFrameRef {
    /// The key frame's image, relative to the capture description's folder (any format
    /// the tool reads).
    pub file: String,
    /// Start of the key frame's exposure on the capture's time axis, microseconds
    /// (`0`: when the earliest raw row starts, i.e. video frame 0 begins).
    pub start_us: f64,
    /// The key frame's exposure, microseconds.
    pub exposure_us: f64,
    /// The key camera's black offset (counts); estimated from the frame's darkest
    /// pixels when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dark_level: Option<f64>,
    /// Key-frame counts per unit of the raw's video (the ratio between the two cameras'
    /// counts); fitted from the data when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gain: Option<f64>,
    /// `[[a, b, t_row], [c, d, t_col]]`: the key frame's pixel (row, col) of the video
    /// grid's pixel (row, col), `p' = M [row, col, 1]`, pixel centres at integers. Absent:
    /// the two grids span the same field (a key frame of another size is resampled).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub affine: Option<[[f64; 3]; 2]>,
    /// The lens's blur as an image (relative to the capture description's folder),
    /// normalised to unit sum; absent: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub psf: Option<String>,
}

fn invalid(field: &'static str, value: String, expected: &str) -> TimingError {
    TimingError::Invalid { field, value, expected: expected.to_string() }
}

impl KeyFrameRef {
    /// The table's own checks (the window against the video is [`time_weights`]'s).
    pub fn validate(&self, index: usize) -> Result<(), TimingError> {
        let at = |v: String| format!("{v} (keyframes[{index}], {})", self.file);
        if self.file.trim().is_empty() {
            return Err(invalid("keyframes.file", at("\"\"".into()), "the key frame's image file"));
        }
        if !self.start_us.is_finite() || self.start_us.abs() > 1e15 {
            return Err(invalid("keyframes.start_us", at(self.start_us.to_string()), "a finite time in microseconds"));
        }
        if !(self.exposure_us.is_finite() && self.exposure_us > 0.0 && self.exposure_us < 1e15) {
            return Err(invalid("keyframes.exposure_us", at(self.exposure_us.to_string()), "a positive exposure in microseconds"));
        }
        if let Some(d) = self.dark_level {
            if !(d.is_finite() && d >= 0.0) {
                return Err(invalid("keyframes.dark_level", at(d.to_string()), "a non-negative count"));
            }
        }
        if let Some(g) = self.gain {
            if !(g.is_finite() && g > 0.0 && g < 1e12) {
                return Err(invalid("keyframes.gain", at(g.to_string()), "a positive ratio of counts"));
            }
        }
        if let Some(m) = self.affine {
            let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
            if m.iter().flatten().any(|v| !v.is_finite()) || det.abs() < 1e-9 {
                return Err(invalid("keyframes.affine", at(format!("{m:?}")), "an invertible 2 x 3 map of finite numbers"));
            }
        }
        Ok(())
    }

    /// `w_k`: the fraction of frame `k`'s interval `[k T_f, (k+1) T_f)` inside the
    /// window `[start, start + exposure)`, for `frames` frames of `frame_time_us`. A
    /// window that misses every frame is refused (it says nothing about the video).
    pub fn time_weights(&self, frames: usize, frame_time_us: f64) -> Result<Vec<f32>, TimingError> {
        let (s, e) = (self.start_us, self.start_us + self.exposure_us);
        let w: Vec<f32> = (0..frames)
            .map(|k| {
                let (a, b) = (k as f64 * frame_time_us, (k + 1) as f64 * frame_time_us);
                ((e.min(b) - s.max(a)).max(0.0) / frame_time_us) as f32
            })
            .collect();
        if w.iter().all(|&v| v == 0.0) {
            let end = frames as f64 * frame_time_us;
            return Err(invalid(
                "keyframes.start_us",
                format!("{s} .. {e} us ({})", self.file),
                &format!("a window that overlaps the video's 0 .. {end} us ({frames} frames of {frame_time_us} us)"),
            ));
        }
        Ok(w)
    }
}

/// A blur kernel (odd sides, unit sum), applied centred with zeros outside.
#[derive(Clone, Debug, PartialEq)]
pub struct Kernel {
    pub rows: usize,
    pub cols: usize,
    pub data: Vec<f32>,
}

impl Kernel {
    /// The largest side a lens blur may have (direct convolution).
    pub const MAX_SIDE: usize = 63;

    /// A kernel from an image of `rows x cols`: cropped to odd sides around its centre
    /// of mass, normalised to unit sum. `None` when it holds no light.
    pub fn from_image(data: &[f32], rows: usize, cols: usize) -> Option<Kernel> {
        let total: f64 = data.iter().map(|&v| v.max(0.0) as f64).sum();
        if !(total > 0.0 && total.is_finite()) {
            return None;
        }
        let (mut cr, mut cc) = (0.0, 0.0);
        for (i, &v) in data.iter().enumerate() {
            let v = v.max(0.0) as f64;
            cr += v * (i / cols) as f64;
            cc += v * (i % cols) as f64;
        }
        let (cr, cc) = ((cr / total).round() as usize, (cc / total).round() as usize);
        let hr = cr.min(rows - 1 - cr).min(Self::MAX_SIDE / 2);
        let hc = cc.min(cols - 1 - cc).min(Self::MAX_SIDE / 2);
        let (kr, kc) = (2 * hr + 1, 2 * hc + 1);
        let mut k = Vec::with_capacity(kr * kc);
        for r in cr - hr..=cr + hr {
            for c in cc - hc..=cc + hc {
                k.push(data[r * cols + c].max(0.0));
            }
        }
        let s: f64 = k.iter().map(|&v| v as f64).sum();
        if s <= 0.0 {
            return None;
        }
        Some(Kernel { rows: kr, cols: kc, data: k.into_iter().map(|v| (v as f64 / s) as f32).collect() })
    }

    /// `out = k * x` (`transpose`: the correlation, the adjoint) on an `rows x cols` image.
    fn apply(&self, x: &[f32], rows: usize, cols: usize, out: &mut [f32], transpose: bool) {
        let (hr, hc) = ((self.rows / 2) as isize, (self.cols / 2) as isize);
        for r in 0..rows as isize {
            for c in 0..cols as isize {
                let mut acc = 0.0f64;
                for i in 0..self.rows as isize {
                    let sr = if transpose { r + i - hr } else { r - i + hr };
                    if sr < 0 || sr >= rows as isize {
                        continue;
                    }
                    for j in 0..self.cols as isize {
                        let sc = if transpose { c + j - hc } else { c - j + hc };
                        if sc < 0 || sc >= cols as isize {
                            continue;
                        }
                        acc += self.data[(i * self.cols as isize + j) as usize] as f64 * x[(sr * cols as isize + sc) as usize] as f64;
                    }
                }
                out[(r * cols as isize + c) as usize] = acc as f32;
            }
        }
    }
}

/// Bilinear taps of every key-frame pixel into one video frame: four (index, weight)
/// pairs; a pixel whose position falls outside the video grid has none (the map sees
/// nothing there and its measurement is left out of the data term).
#[derive(Clone, Debug)]
struct Sampler {
    taps: Vec<[(u32, f32); 4]>,
    inside: Vec<bool>,
}

impl Sampler {
    /// `to_key`: the video (row, col) -> key frame (row, col) map; the taps sample its
    /// inverse.
    fn new(video: (usize, usize), key: (usize, usize), to_key: [[f64; 3]; 2]) -> Sampler {
        let m = to_key;
        let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
        let inv = [[m[1][1] / det, -m[0][1] / det], [-m[1][0] / det, m[0][0] / det]];
        let (mv, nv) = video;
        let mut taps = Vec::with_capacity(key.0 * key.1);
        let mut inside = Vec::with_capacity(key.0 * key.1);
        for r in 0..key.0 {
            for c in 0..key.1 {
                let (dr, dc) = (r as f64 - m[0][2], c as f64 - m[1][2]);
                let (vr, vc) = (inv[0][0] * dr + inv[0][1] * dc, inv[1][0] * dr + inv[1][1] * dc);
                let ok = vr >= -0.5 && vc >= -0.5 && vr <= mv as f64 - 0.5 && vc <= nv as f64 - 0.5;
                let (vr, vc) = (vr.clamp(0.0, (mv - 1) as f64), vc.clamp(0.0, (nv - 1) as f64));
                let (r0, c0) = (vr.floor() as usize, vc.floor() as usize);
                let (r1, c1) = ((r0 + 1).min(mv - 1), (c0 + 1).min(nv - 1));
                let (fr, fc) = ((vr - r0 as f64) as f32, (vc - c0 as f64) as f32);
                let idx = |r: usize, c: usize| (r * nv + c) as u32;
                let t = if ok {
                    [(idx(r0, c0), (1.0 - fr) * (1.0 - fc)), (idx(r0, c1), (1.0 - fr) * fc), (idx(r1, c0), fr * (1.0 - fc)), (idx(r1, c1), fr * fc)]
                } else {
                    [(0, 0.0); 4]
                };
                taps.push(t);
                inside.push(ok);
            }
        }
        Sampler { taps, inside }
    }
}

/// The map of one key frame: `v -> B R (sum_k w_k v_k)` from the video `(frames, rows,
/// cols)` to the key frame's `(rows, cols)`, scaled by `scale` (the term's weight).
#[derive(Clone, Debug)]
pub struct KeyFrameOp {
    video: (usize, usize, usize),
    key: (usize, usize),
    time: Vec<f32>,
    sampler: Sampler,
    blur: Option<Kernel>,
    /// The video -> key frame map the sampler inverts.
    map: [[f64; 3]; 2],
    pub scale: f32,
}

impl KeyFrameOp {
    /// The map for `time` weights over the video `(frames, rows, cols)` onto a key frame
    /// of `key` pixels; `to_key` the affine map (`None`: the grids span the same field).
    pub fn new(video: (usize, usize, usize), key: (usize, usize), time: Vec<f32>, to_key: Option<[[f64; 3]; 2]>, blur: Option<Kernel>) -> KeyFrameOp {
        assert_eq!(time.len(), video.0, "one time weight per video frame");
        let m = to_key.unwrap_or_else(|| scale_map((video.1, video.2), key));
        KeyFrameOp { video, key, time, sampler: Sampler::new((video.1, video.2), key, m), blur, map: m, scale: 1.0 }
    }

    /// The key frame's pixels in the data term: those the video grid covers and not
    /// left out ([`Self::leave_out`]); the map reads zero elsewhere.
    pub fn inside(&self) -> &[bool] {
        &self.sampler.inside
    }

    /// Leave out the pixels where `usable` is false (clipped, defective).
    pub fn leave_out(&mut self, usable: &[bool]) {
        assert_eq!(usable.len(), self.sampler.inside.len(), "one flag per key-frame pixel");
        self.sampler.inside.iter_mut().zip(usable).for_each(|(i, &u)| *i &= u);
    }

    /// (rows, cols) of the key frame.
    pub fn key_shape(&self) -> (usize, usize) {
        self.key
    }

    /// The video -> key frame map in use (the given affine, or the scale map).
    pub fn map(&self) -> [[f64; 3]; 2] {
        self.map
    }

    pub fn blur(&self) -> Option<&Kernel> {
        self.blur.as_ref()
    }

    pub fn time_weights(&self) -> &[f32] {
        &self.time
    }

    /// The weight of a still scene: `sum_k w_k` (the window's length in frames).
    pub fn exposure_frames(&self) -> f64 {
        self.time.iter().map(|&w| w as f64).sum()
    }

    /// The map of a still image `s` (one frame): `B R s` (unscaled, no time weights).
    pub fn image(&self, s: &[f32]) -> Vec<f32> {
        let mut y = vec![0.0f32; self.key.0 * self.key.1];
        for (o, t) in y.iter_mut().zip(&self.sampler.taps) {
            *o = t.iter().map(|&(i, w)| w * s[i as usize]).sum();
        }
        let mut y = match &self.blur {
            None => y,
            Some(k) => {
                let mut out = vec![0.0f32; y.len()];
                k.apply(&y, self.key.0, self.key.1, &mut out, false);
                out
            }
        };
        y.iter_mut().zip(&self.sampler.inside).filter(|(_, &i)| !i).for_each(|(v, _)| *v = 0.0);
        y
    }

    /// `R^T B^T y` on one frame (unscaled).
    pub fn image_adjoint(&self, y: &[f32]) -> Vec<f32> {
        let masked: Vec<f32> = y.iter().zip(&self.sampler.inside).map(|(&v, &i)| if i { v } else { 0.0 }).collect();
        let y = match &self.blur {
            None => masked,
            Some(k) => {
                let mut out = vec![0.0f32; masked.len()];
                k.apply(&masked, self.key.0, self.key.1, &mut out, true);
                out
            }
        };
        let mut s = vec![0.0f32; self.video.1 * self.video.2];
        for (&v, t) in y.iter().zip(&self.sampler.taps) {
            for &(i, w) in t {
                s[i as usize] += w * v;
            }
        }
        s
    }
}

/// The map between two grids spanning the same field: pixel centres matched.
pub fn scale_map(video: (usize, usize), key: (usize, usize)) -> [[f64; 3]; 2] {
    let (sr, sc) = (key.0 as f64 / video.0 as f64, key.1 as f64 / video.1 as f64);
    [[sr, 0.0, 0.5 * sr - 0.5], [0.0, sc, 0.5 * sc - 0.5]]
}

impl KeyFrameOp {
    /// `s += scale (sum_k w_k) R^T B^T y`: the still form's adjoint
    /// ([`Operator::adjoint_still`]) added into `s`, as the stacked operator sums it.
    pub fn still_adjoint_add(&self, y: &[f32], s: &mut [f32]) {
        let f = (self.scale as f64 * self.exposure_frames()) as f32;
        for (o, v) in s.iter_mut().zip(self.image_adjoint(y)) {
            *o += f * v;
        }
    }

    /// `x += K^T y`, touching only the frames inside the window: the stacked
    /// operator's adjoint ([`Fused`]), which would otherwise write and add a whole
    /// video per key frame (at 240 x 320 x 122 with two key frames that made an
    /// iteration 1.8 times a plain one).
    pub fn adjoint_add(&self, y: &[f32], x: &mut [f32]) {
        let px = self.video.1 * self.video.2;
        let s = self.image_adjoint(y);
        for (k, &w) in self.time.iter().enumerate() {
            if w != 0.0 {
                let f = self.scale * w;
                for (o, &v) in x[k * px..(k + 1) * px].iter_mut().zip(&s) {
                    *o += f * v;
                }
            }
        }
    }
}

impl Operator for KeyFrameOp {
    fn input_shape(&self) -> Vec<usize> {
        vec![self.video.0, self.video.1, self.video.2]
    }
    fn output_shape(&self) -> Vec<usize> {
        vec![self.key.0, self.key.1]
    }
    fn forward(&self, x: &[f32], y: &mut [f32]) {
        let px = self.video.1 * self.video.2;
        let mut s = vec![0.0f64; px];
        for (k, &w) in self.time.iter().enumerate() {
            if w != 0.0 {
                for (a, &v) in s.iter_mut().zip(&x[k * px..(k + 1) * px]) {
                    *a += w as f64 * v as f64;
                }
            }
        }
        let s: Vec<f32> = s.into_iter().map(|v| v as f32).collect();
        for (o, v) in y.iter_mut().zip(self.image(&s)) {
            *o = self.scale * v;
        }
    }
    fn adjoint(&self, y: &[f32], x: &mut [f32]) {
        let px = self.video.1 * self.video.2;
        let s = self.image_adjoint(y);
        for (k, &w) in self.time.iter().enumerate() {
            let f = self.scale * w;
            for (o, &v) in x[k * px..(k + 1) * px].iter_mut().zip(&s) {
                *o = f * v;
            }
        }
    }
    /// A still video's key frame: `scale (sum_k w_k) B R s`.
    fn forward_still(&self, s: &[f32], y: &mut [f32]) -> bool {
        let f = (self.scale as f64 * self.exposure_frames()) as f32;
        for (o, v) in y.iter_mut().zip(self.image(s)) {
            *o = f * v;
        }
        true
    }
    fn adjoint_still(&self, y: &[f32], s: &mut [f32]) -> bool {
        s.fill(0.0);
        self.still_adjoint_add(y, s);
        true
    }
    /// `||K||^2 <= scale^2 (sum_k w_k^2) ||R||^2 ||B||^2` (Cauchy-Schwarz over the
    /// frames); a unit-sum kernel has `||B|| <= 1`, and `||R||^2 <= ||R||_1 ||R||_inf`:
    /// the taps of one key pixel sum to one, so the largest tap sum over a video pixel.
    fn lipschitz_upper_bound(&self) -> Option<f64> {
        let mut per_video = vec![0.0f64; self.video.1 * self.video.2];
        for t in &self.sampler.taps {
            for &(i, w) in t {
                per_video[i as usize] += w as f64;
            }
        }
        let col = per_video.into_iter().fold(0.0, f64::max).max(1.0);
        let time: f64 = self.time.iter().map(|&w| (w as f64) * (w as f64)).sum();
        Some((self.scale as f64).powi(2) * time * col)
    }
}

/// The rolling-shutter operator and the key frames' maps stacked: `v -> [A v; K_1 v;
/// ...]`; the adjoint sums every part's.
pub struct Fused<A> {
    pub inner: A,
    pub keys: Vec<KeyFrameOp>,
    out_len: usize,
}

impl<A: Operator> Fused<A> {
    pub fn new(inner: A, keys: Vec<KeyFrameOp>) -> Fused<A> {
        let input = inner.input_shape();
        for k in &keys {
            assert_eq!(k.input_shape(), input, "a key frame's map must take the video of the rolling-shutter operator");
        }
        let out_len = inner.output_len() + keys.iter().map(|k| k.output_len()).sum::<usize>();
        Fused { inner, keys, out_len }
    }

    /// Where each part's measurements sit in the stacked output: the rolling-shutter
    /// data first, then each key frame's.
    pub fn ranges(&self) -> Vec<std::ops::Range<usize>> {
        let mut at = self.inner.output_len();
        let mut r = Vec::with_capacity(1 + self.keys.len());
        r.push(0..at);
        for k in &self.keys {
            r.push(at..at + k.output_len());
            at += k.output_len();
        }
        r
    }
}

impl<A: Operator> Operator for Fused<A> {
    fn input_shape(&self) -> Vec<usize> {
        self.inner.input_shape()
    }
    fn output_shape(&self) -> Vec<usize> {
        vec![self.out_len]
    }
    fn forward(&self, x: &[f32], y: &mut [f32]) {
        let r = self.ranges();
        self.inner.forward(x, &mut y[r[0].clone()]);
        for (k, range) in self.keys.iter().zip(&r[1..]) {
            k.forward(x, &mut y[range.clone()]);
        }
    }
    fn adjoint(&self, y: &[f32], x: &mut [f32]) {
        let r = self.ranges();
        self.inner.adjoint(&y[r[0].clone()], x);
        for (k, range) in self.keys.iter().zip(&r[1..]) {
            k.adjoint_add(&y[range.clone()], x);
        }
    }
    fn forward_still(&self, s: &[f32], y: &mut [f32]) -> bool {
        let r = self.ranges();
        if !self.inner.forward_still(s, &mut y[r[0].clone()]) {
            return false;
        }
        self.keys.iter().zip(&r[1..]).all(|(k, range)| k.forward_still(s, &mut y[range.clone()]))
    }
    fn adjoint_still(&self, y: &[f32], s: &mut [f32]) -> bool {
        let r = self.ranges();
        if !self.inner.adjoint_still(&y[r[0].clone()], s) {
            return false;
        }
        for (k, range) in self.keys.iter().zip(&r[1..]) {
            k.still_adjoint_add(&y[range.clone()], s);
        }
        true
    }
    fn lipschitz_upper_bound(&self) -> Option<f64> {
        let mut total = self.inner.lipschitz_upper_bound()?;
        for k in &self.keys {
            total += k.lipschitz_upper_bound()?;
        }
        Some(total)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::op::{adjoint_mismatch, pseudo_random, Dense};

    fn window(start_us: f64, exposure_us: f64) -> KeyFrameRef {
        KeyFrameRef { file: "k.tiff".into(), start_us, exposure_us, dark_level: None, gain: None, affine: None, psf: None }
    }

    #[test]
    fn time_weights_are_the_overlap_of_the_window_with_each_frame() {
        // Frames of 10 us; a window from 5 to 25 us covers half of frame 0, all of
        // frame 1 and half of frame 2.
        let w = window(5.0, 20.0).time_weights(4, 10.0).unwrap();
        assert_eq!(w, vec![0.5, 1.0, 0.5, 0.0]);
        let e = window(50.0, 5.0).time_weights(4, 10.0).unwrap_err().to_string();
        assert!(e.contains("overlaps the video's 0 .. 40 us"), "{e}");
    }

    #[test]
    fn the_table_is_checked_by_name() {
        let mut k = window(0.0, 0.0);
        assert!(k.validate(2).unwrap_err().to_string().contains("keyframes.exposure_us"));
        k.exposure_us = 1.0;
        k.affine = Some([[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]);
        let e = k.validate(2).unwrap_err().to_string();
        assert!(e.contains("keyframes.affine") && e.contains("keyframes[2]"), "{e}");
        k.affine = None;
        k.gain = Some(-1.0);
        assert!(k.validate(0).unwrap_err().to_string().contains("keyframes.gain"));
    }

    #[test]
    fn the_map_and_its_adjoint_agree_with_resampling_blur_and_affine() {
        let blur = Kernel::from_image(&[0.0, 1.0, 0.0, 1.0, 4.0, 2.0, 0.0, 1.0, 0.0], 3, 3).unwrap();
        for (key, affine, blur) in [((6, 8), None, None), ((12, 16), None, Some(blur.clone())), ((5, 7), Some([[0.9, 0.1, 0.5], [-0.1, 1.1, 0.3]]), Some(blur))]
        {
            let op = KeyFrameOp::new((3, 6, 8), key, vec![0.25, 1.0, 0.0], affine, blur);
            let x = pseudo_random(3 * 48, 7);
            let y = pseudo_random(key.0 * key.1, 9);
            assert!(adjoint_mismatch(&op, &x, &y) < 1e-5, "{key:?}");
            // The stored bound holds.
            let lmax = Dense::from_operator(&op).gram_lambda_max();
            assert!(lmax <= op.lipschitz_upper_bound().unwrap() * 1.0001, "{lmax}");
        }
    }

    #[test]
    fn the_same_grid_without_a_map_is_the_time_integral() {
        let op = KeyFrameOp::new((2, 3, 4), (3, 4), vec![0.5, 1.0], None, None);
        let x: Vec<f32> = (0..24).map(|i| i as f32).collect();
        let mut y = vec![0.0; 12];
        op.forward(&x, &mut y);
        for (p, got) in y.iter().enumerate() {
            assert!((got - (0.5 * p as f32 + (12 + p) as f32)).abs() < 1e-5);
        }
        assert!(op.inside().iter().all(|&i| i));
    }

    #[test]
    fn the_fused_operator_stacks_and_sums() {
        let a = KeyFrameOp::new((2, 4, 4), (4, 4), vec![1.0, 0.0], None, None);
        let b = KeyFrameOp::new((2, 4, 4), (8, 8), vec![0.0, 1.0], None, None);
        let f = Fused::new(a.clone(), vec![b]);
        assert_eq!(f.output_len(), 16 + 64);
        let x = pseudo_random(32, 3);
        let y = pseudo_random(80, 4);
        assert!(adjoint_mismatch(&f, &x, &y) < 1e-5);
        // A key frame's adjoint adds into its window's frames and leaves the rest.
        let (start, yk) = (pseudo_random(32, 5), pseudo_random(64, 6));
        let (mut added, mut alone) = (start.clone(), vec![0.0; 32]);
        f.keys[0].adjoint_add(&yk, &mut added);
        f.keys[0].adjoint(&yk, &mut alone);
        assert_eq!(&added[..16], &start[..16]);
        for i in 16..32 {
            assert!((added[i] - (start[i] + alone[i])).abs() < 1e-6, "{i}");
        }
    }
}
