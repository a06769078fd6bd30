//! Key frames of a simulated capture: images of the scene from a second, lensed,
//! global-shutter camera, taken during the rolling-shutter exposure.
//!
//! Key frame `j` is rendered from the truth video (`v`, in the raw's video units, the
//! units of `truth.npy`) with the map the reconstruction inverts,
//! [`crate::model::keyframe::KeyFrameOp`]: the video integrated over the key frame's
//! window (the fraction `w_jk` of each frame inside it), resampled onto the key camera's
//! pixels (the plain scale between the grids, or an affine map when the key camera is
//! shifted) and blurred by its lens (a Gaussian), then
//!
//! `y_j = round(g K_j v + dark) + noise`, clipped to `[0, 65535]`,
//!
//! with the key camera's gain `g` (counts per video unit) and black offset. The noise is
//! the simulator's readout ([`super::expose::read_out`]): shot noise on the key counts
//! at the raw sensor's conversion gain and a read noise given in counts. Rendering with
//! the solver's own map is the model, not the physics: a window that cuts a frame takes
//! that frame's mean over the part inside, where a real camera would see the scene's
//! motion within it. No files: `crate::lab::sim_output` writes the images.

use super::error::{invalid, SimError};
use super::expose::{read_out, NoiseModel};
use super::scene::derive_seed;
use crate::model::keyframe::{scale_map, Kernel, KeyFrameOp, KeyFrameRef};
use crate::model::op::Operator;
use ndarray::{Array2, ArrayView3};

/// The key cameras' lens blur, beside the key frames.
pub const KEYFRAME_PSF_FILE: &str = "keyframe_psf.tiff";

/// File name of key frame `j` (`keyframe_000.tiff`, ...).
pub fn keyframe_file(j: usize) -> String {
    format!("keyframe_{j:03}.tiff")
}

/// The key frames' ADC maximum (16 bits), counts.
pub const KEY_FULL_SCALE: f64 = 65535.0;
/// Without a gain, the brightest key pixel's expected value sits at this fraction of
/// [`KEY_FULL_SCALE`] above the dark level.
pub const DEFAULT_KEY_FILL: f64 = 0.4;
/// The most key frames one simulation writes.
pub const MAX_KEYFRAMES: usize = 1000;
/// The smallest lens blur, pixels: a narrower Gaussian is one pixel to f32 precision
/// (and its variance underflows far below).
pub const MIN_BLUR_PX: f64 = 0.1;

/// The largest lens blur, pixels: its kernel (`2 ceil(3 sigma) + 1` wide) fits
/// [`Kernel::MAX_SIDE`].
pub const MAX_BLUR_PX: f64 = 10.0;
/// The largest key frame relative to the video grid.
pub const MAX_KEY_SCALE: f64 = 8.0;
/// The random stream of the key frames' noise ([`derive_seed`]).
const STREAM_KEYFRAMES: u64 = 6;

/// When a key frame starts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum KeyTime {
    /// At the first video frame's start (`t = 0`).
    First,
    /// At the last video frame's start.
    Last,
    /// At this time on the capture's axis, microseconds.
    At(f64),
}

impl KeyTime {
    /// `first`, `last` or a number of microseconds.
    pub fn parse(s: &str) -> Result<KeyTime, SimError> {
        match s.trim() {
            "first" => Ok(KeyTime::First),
            "last" => Ok(KeyTime::Last),
            t => t.parse::<f64>().map(KeyTime::At).map_err(|_| invalid("keyframes", format!("'{s}'"), "start times in microseconds, first or last")),
        }
    }

    fn start_us(self, frames: usize, frame_time_us: f64) -> f64 {
        match self {
            KeyTime::First => 0.0,
            KeyTime::Last => (frames - 1) as f64 * frame_time_us,
            KeyTime::At(t) => t,
        }
    }

    /// The time as given (`first`, `last`, microseconds).
    pub fn label(self) -> String {
        match self {
            KeyTime::First => "first".into(),
            KeyTime::Last => "last".into(),
            KeyTime::At(t) if t.is_finite() && t != 0.0 && !(1e-3..1e9).contains(&t.abs()) => format!("{t:e}"),
            KeyTime::At(t) => t.to_string(),
        }
    }
}

/// What `rollcam simulate --keyframes` asks for: when the key frames start and how the
/// key camera sees (times in microseconds, sizes in key-frame pixels).
#[derive(Clone, Debug, PartialEq)]
pub struct KeyFrameParams {
    pub times: Vec<KeyTime>,
    /// Every key frame's exposure; `None`: one video frame time.
    pub exposure_us: Option<f64>,
    /// Key counts per video unit; `None`: the brightest key pixel at
    /// [`DEFAULT_KEY_FILL`] of full scale.
    pub gain: Option<f64>,
    pub dark_level_adu: f64,
    /// Read noise, counts; 0: no noise at all (quantisation remains).
    pub read_noise_adu: f64,
    /// Noise on (`--no-noise` turns it off for the key frames too).
    pub noise: bool,
    /// Gaussian sigma of the lens blur; 0: none.
    pub blur_px: f64,
    /// Shift of the key camera: the video pixel `(r, c)` lands on key pixel
    /// `(r, c) + offset` (after the scale).
    pub offset_px: (f64, f64),
    /// The key frame's size over the video grid's.
    pub scale: f64,
    /// Write the gain into each `[[keyframes]]` table (else it is provenance only).
    pub write_gain: bool,
}

impl Default for KeyFrameParams {
    /// No key frames; a key camera with dark level 64 and 2 counts of read noise, no
    /// blur, no shift, the video's size.
    fn default() -> Self {
        KeyFrameParams {
            times: Vec::new(),
            exposure_us: None,
            gain: None,
            dark_level_adu: 64.0,
            read_noise_adu: 2.0,
            noise: true,
            blur_px: 0.0,
            offset_px: (0.0, 0.0),
            scale: 1.0,
            write_gain: false,
        }
    }
}

/// Key frames checked against a video, ready to render.
#[derive(Clone, Debug)]
pub struct KeyFramePlan {
    params: KeyFrameParams,
    /// The video `(frames, rows, cols)` and its frame time.
    video: (usize, usize, usize),
    frame_time_us: f64,
    /// Start times and exposure, microseconds.
    pub starts_us: Vec<f64>,
    pub exposure_us: f64,
    /// The key frames' size.
    pub key: (usize, usize),
    /// The affine map written to capture.toml (`None`: the plain scale between grids).
    pub affine: Option<[[f64; 3]; 2]>,
    /// The lens blur (unit sum) as written to [`KEYFRAME_PSF_FILE`].
    pub psf: Option<Array2<f32>>,
    kernel: Option<Kernel>,
}

fn check(ok: bool, field: &'static str, value: impl std::fmt::Display, expected: &str) -> Result<(), SimError> {
    if ok {
        Ok(())
    } else {
        Err(invalid(field, value, expected))
    }
}

impl KeyFrameParams {
    /// The plan for a video of `(frames, rows, cols)` frames of `frame_time_us`: every
    /// value checked, each window inside the video's `0 .. frames T_f`.
    pub fn plan(&self, video: (usize, usize, usize), frame_time_us: f64) -> Result<KeyFramePlan, SimError> {
        let (frames, rows, cols) = video;
        let duration = frames as f64 * frame_time_us;
        check(!self.times.is_empty() && self.times.len() <= MAX_KEYFRAMES, "keyframes", self.times.len(), &format!("1 to {MAX_KEYFRAMES} key frames"))?;
        let exposure_us = self.exposure_us.unwrap_or(frame_time_us);
        let ok = exposure_us.is_finite() && exposure_us > 0.0 && exposure_us <= duration * (1.0 + 1e-12);
        check(
            ok,
            "keyframe_exposure_us",
            exposure_us,
            &format!("a positive exposure no longer than the video's {duration} us ({frames} frames of {frame_time_us} us)"),
        )?;
        let mut starts_us = Vec::with_capacity(self.times.len());
        for &t in &self.times {
            let s = t.start_us(frames, frame_time_us);
            check(s.is_finite(), "keyframes", t.label(), "finite start times in microseconds, first or last")?;
            let tol = 1e-9 * duration;
            let inside = s >= -tol && s + exposure_us <= duration + tol;
            let latest = duration - exposure_us;
            let expected = format!(
                "a key frame inside the video's 0 .. {duration} us ({frames} frames of {frame_time_us} us): with an exposure of {exposure_us} us, a start from 0 to {latest} us, first or last"
            );
            check(inside, "keyframes", t.label(), &expected)?;
            starts_us.push(s.max(0.0));
        }
        if let Some(g) = self.gain {
            check(g.is_finite() && g > 0.0 && g < 1e12, "keyframe_gain", g, "a positive gain in key counts per video unit")?;
        }
        let d = self.dark_level_adu;
        check(d.is_finite() && (0.0..KEY_FULL_SCALE).contains(&d), "keyframe_dark_level_adu", d, "an offset from 0 to below the 16-bit full scale (65535)")?;
        let r = self.read_noise_adu;
        check(r.is_finite() && (0.0..=KEY_FULL_SCALE).contains(&r), "keyframe_noise", r, "a non-negative read noise in counts")?;
        let b = self.blur_px;
        let ok = b == 0.0 || (MIN_BLUR_PX..=MAX_BLUR_PX).contains(&b);
        let shown = if b != 0.0 && b.abs() < 1e-3 { format!("{b:e}") } else { b.to_string() };
        check(ok, "keyframe_blur_px", shown, &format!("a Gaussian sigma of 0 (none) or from {MIN_BLUR_PX} to {MAX_BLUR_PX} pixels"))?;
        let f = self.scale;
        check(f.is_finite() && f > 0.0 && f <= MAX_KEY_SCALE, "keyframe_scale", f, &format!("a size ratio above 0, at most {MAX_KEY_SCALE}"))?;
        let key = ((f * rows as f64).round() as usize, (f * cols as f64).round() as usize);
        check(key.0 >= 1 && key.1 >= 1, "keyframe_scale", f, &format!("a ratio that leaves the {rows} x {cols} video grid at least one pixel a side"))?;
        let (or, oc) = self.offset_px;
        let ok = or.is_finite() && oc.is_finite() && or.abs() < key.0 as f64 && oc.abs() < key.1 as f64;
        check(ok, "keyframe_offset_px", format!("{or},{oc}"), &format!("a shift (rows, cols) smaller than the {} x {} key frame", key.0, key.1))?;
        let affine = (self.offset_px != (0.0, 0.0)).then(|| {
            let mut m = scale_map((rows, cols), key);
            m[0][2] += or;
            m[1][2] += oc;
            m
        });
        let kernel = (b > 0.0).then(|| gaussian_kernel(b));
        let psf = kernel.as_ref().map(|k| Array2::from_shape_vec((k.rows, k.cols), k.data.clone()).expect("rows x cols"));
        Ok(KeyFramePlan { params: self.clone(), video, frame_time_us, starts_us, exposure_us, key, affine, psf, kernel })
    }
}

/// A unit-sum Gaussian of `sigma_px`, `2 ceil(3 sigma) + 1` pixels a side.
fn gaussian_kernel(sigma_px: f64) -> Kernel {
    let h = (3.0 * sigma_px).ceil().max(1.0) as usize;
    let side = 2 * h + 1;
    let data: Vec<f32> = (0..side * side)
        .map(|i| {
            let (r, c) = ((i / side) as f64 - h as f64, (i % side) as f64 - h as f64);
            (-(r * r + c * c) / (2.0 * sigma_px * sigma_px)).exp() as f32
        })
        .collect();
    Kernel::from_image(&data, side, side).expect("a Gaussian holds light")
}

/// Rendered key frames and what capture.toml says of them.
#[derive(Clone, Debug)]
pub struct KeyFrames {
    /// The images, counts (dark level included, quantised, clipped), key size.
    pub images: Vec<Array2<f32>>,
    /// The `[[keyframes]]` tables (file, start, exposure, dark level, the affine map
    /// and lens blur where there are; the gain only when asked).
    pub refs: Vec<KeyFrameRef>,
    /// The lens blur to write as [`KEYFRAME_PSF_FILE`].
    pub psf: Option<Array2<f32>>,
    /// The true gain, key counts per video unit.
    pub gain: f64,
    /// Key pixels clipped at full scale, over every key frame.
    pub saturated_pixels: usize,
    /// Provenance: `[simulation.keyframes]`.
    pub table: toml::Table,
}

/// `g` rounded to three significant digits.
fn round3(g: f64) -> f64 {
    let e = g.log10().floor() as i32 - 2;
    if e >= 0 {
        (g / 10f64.powi(e)).round() * 10f64.powi(e)
    } else {
        (g * 10f64.powi(-e)).round() / 10f64.powi(-e)
    }
}

impl KeyFramePlan {
    /// Frames of the video the plan was checked against.
    pub fn video_frames(&self) -> usize {
        self.video.0
    }

    /// The video's frame time, microseconds.
    pub fn frame_time_us(&self) -> f64 {
        self.frame_time_us
    }

    /// The `[[keyframes]]` tables of the plan (without the gain).
    fn refs(&self) -> Vec<KeyFrameRef> {
        let p = &self.params;
        (0..self.starts_us.len())
            .map(|j| KeyFrameRef {
                file: keyframe_file(j),
                start_us: self.starts_us[j],
                exposure_us: self.exposure_us,
                dark_level: Some(p.dark_level_adu),
                gain: None,
                affine: self.affine,
                psf: self.kernel.as_ref().map(|_| KEYFRAME_PSF_FILE.to_string()),
            })
            .collect()
    }

    /// `K_j v` of every key frame for the video `truth` (`(frames, rows, cols)`, the
    /// plan's), video units.
    pub fn expected(&self, truth: ArrayView3<f32>) -> Result<Vec<Vec<f32>>, SimError> {
        let (frames, rows, cols) = self.video;
        if truth.dim() != self.video {
            return Err(invalid("truth", format!("{:?}", truth.dim()), format!("the video the key frames were planned for, {frames} x {rows} x {cols}")));
        }
        let x: Vec<f32> = truth.iter().copied().collect();
        self.refs()
            .iter()
            .map(|r| {
                let w = r.time_weights(frames, self.frame_time_us)?;
                let op = KeyFrameOp::new(self.video, self.key, w, self.affine, self.kernel.clone());
                let mut y = vec![0.0f32; self.key.0 * self.key.1];
                op.forward(&x, &mut y);
                Ok(y)
            })
            .collect()
    }

    /// The key frames of the video `truth`, their noise drawn from `seed` (one stream per
    /// key frame), shot noise at `conversion_gain_adu_per_e` (the raw sensor's).
    pub fn render(&self, truth: ArrayView3<f32>, conversion_gain_adu_per_e: f64, seed: u64) -> Result<KeyFrames, SimError> {
        let p = &self.params;
        let c = conversion_gain_adu_per_e;
        check(c.is_finite() && c > 0.0, "gain_adu_per_e", c, "a positive conversion gain in ADU per photo-electron")?;
        let signals = self.expected(truth)?;
        let brightest = signals.iter().flatten().fold(0.0f32, |m, &v| m.max(v)) as f64;
        let gain = match p.gain {
            Some(g) => g,
            None if brightest > 0.0 => round3(DEFAULT_KEY_FILL * KEY_FULL_SCALE / brightest),
            None => 1.0,
        };
        let noisy = p.noise && p.read_noise_adu > 0.0;
        let readout = NoiseModel {
            gain_adu_per_e: c,
            read_noise_e: p.read_noise_adu / c,
            dark_level_adu: p.dark_level_adu,
            full_well_e: 4.0 * KEY_FULL_SCALE / c,
            bits: 16,
            poisson: noisy,
            gaussian: noisy,
        };
        let mut saturated_pixels = 0;
        let mut images = Vec::with_capacity(signals.len());
        for (j, y) in signals.iter().enumerate() {
            let electrons: Vec<f64> = y.iter().map(|&v| gain * v as f64 / c).collect();
            let (raw, sat) = read_out(&electrons, &readout, derive_seed(seed, STREAM_KEYFRAMES, j as u64));
            saturated_pixels += sat;
            images.push(Array2::from_shape_vec(self.key, raw).expect("key rows x cols"));
        }
        if saturated_pixels > 0 {
            tracing::warn!(pixels = saturated_pixels, "saturated pixels in the simulated key frames");
        }
        let mut refs = self.refs();
        if p.write_gain {
            refs.iter_mut().for_each(|r| r.gain = Some(gain));
        }
        let table = self.describe(gain, noisy, c, saturated_pixels);
        Ok(KeyFrames { images, refs, psf: self.psf.clone(), gain, saturated_pixels, table })
    }

    fn describe(&self, gain: f64, noisy: bool, c: f64, saturated_pixels: usize) -> toml::Table {
        let p = &self.params;
        let mut t = toml::Table::new();
        t.insert("gain".into(), gain.into());
        t.insert("gain_in_tables".into(), p.write_gain.into());
        if p.gain.is_none() {
            t.insert("gain_rule".into(), format!("brightest expected key pixel at {DEFAULT_KEY_FILL} of {KEY_FULL_SCALE} counts above the dark level").into());
        }
        t.insert("times".into(), p.times.iter().map(|k| k.label()).collect::<Vec<_>>().into());
        t.insert("exposure_us".into(), self.exposure_us.into());
        t.insert("dark_level_adu".into(), p.dark_level_adu.into());
        t.insert("read_noise_adu".into(), if noisy { p.read_noise_adu } else { 0.0 }.into());
        t.insert("shot_noise".into(), noisy.into());
        t.insert("conversion_gain_adu_per_e".into(), c.into());
        t.insert("blur_sigma_px".into(), p.blur_px.into());
        t.insert("offset_px".into(), vec![p.offset_px.0, p.offset_px.1].into());
        t.insert("scale".into(), p.scale.into());
        t.insert("rows".into(), (self.key.0 as i64).into());
        t.insert("cols".into(), (self.key.1 as i64).into());
        t.insert("bits".into(), 16i64.into());
        t.insert("saturated_pixels".into(), (saturated_pixels as i64).into());
        t.insert(
            "renderer".into(),
            "the reconstruction's key-frame map (time window, resampling, lens blur) of truth.npy, times gain, plus the dark level and noise, rounded and clipped to 16 bits".into(),
        );
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;

    fn video() -> Array3<f32> {
        Array3::from_shape_fn((6, 8, 10), |(k, r, c)| 1.0 + k as f32 + 0.1 * r as f32 + 0.01 * c as f32)
    }

    fn params(times: &[&str]) -> KeyFrameParams {
        KeyFrameParams { times: times.iter().map(|s| KeyTime::parse(s).unwrap()).collect(), ..KeyFrameParams::default() }
    }

    #[test]
    fn first_and_last_are_the_first_and_last_frames() {
        let v = video();
        let plan = params(&["first", "last", "150"]).plan(v.dim(), 100.0).unwrap();
        assert_eq!(plan.starts_us, vec![0.0, 500.0, 150.0]);
        assert_eq!((plan.exposure_us, plan.key, plan.affine), (100.0, (8, 10), None));
        let y = plan.expected(v.view()).unwrap();
        // One frame each: the first and the last frame exactly, the third half of
        // frames 1 and 2.
        for (i, &val) in y[0].iter().enumerate() {
            assert!((val - v[[0, i / 10, i % 10]]).abs() < 1e-5);
            assert!((y[1][i] - v[[5, i / 10, i % 10]]).abs() < 1e-5);
            assert!((y[2][i] - 0.5 * (v[[1, i / 10, i % 10]] + v[[2, i / 10, i % 10]])).abs() < 1e-5);
        }
    }

    #[test]
    fn noise_free_frames_are_gain_times_the_map_plus_dark() {
        let v = video();
        let p = KeyFrameParams { read_noise_adu: 0.0, gain: Some(1000.0), ..params(&["first", "last"]) };
        let plan = p.plan(v.dim(), 100.0).unwrap();
        let k = plan.render(v.view(), 0.5, 1).unwrap();
        let y = plan.expected(v.view()).unwrap();
        for (img, y) in k.images.iter().zip(&y) {
            for (&got, &e) in img.iter().zip(y) {
                assert_eq!(got, (1000.0 * e as f64 + 64.0).round() as f32);
            }
        }
        assert!(k.refs.iter().all(|r| r.gain.is_none() && r.dark_level == Some(64.0)));
        assert_eq!(k.table["gain"].as_float(), Some(1000.0));
        // With noise: same mean, a spread of shot plus read noise.
        let noisy = KeyFrameParams { read_noise_adu: 3.0, write_gain: true, ..p }.plan(v.dim(), 100.0).unwrap().render(v.view(), 0.5, 1).unwrap();
        let d: Vec<f64> = noisy.images[0].iter().zip(k.images[0].iter()).map(|(&a, &b)| (a - b) as f64).collect();
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        let rms = (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt();
        // ~1500 counts at 0.5 ADU/e-: shot noise sqrt(0.5 * 1500) ~ 27 counts.
        assert!(mean.abs() < 10.0 && rms > 15.0 && rms < 45.0, "mean {mean}, rms {rms}");
        assert!(noisy.refs.iter().all(|r| r.gain == Some(1000.0)));
    }

    #[test]
    fn default_gain_fills_forty_percent_of_full_scale() {
        let v = video();
        let k = params(&["last"]).plan(v.dim(), 100.0).unwrap().render(v.view(), 0.5, 3).unwrap();
        let peak = k.images[0].iter().fold(0.0f32, |m, &x| m.max(x)) as f64 - 64.0;
        assert!((peak / KEY_FULL_SCALE - DEFAULT_KEY_FILL).abs() < 0.01, "{peak}");
        assert_eq!(round3(k.gain), k.gain);
        assert_eq!(round3(1234.5), 1230.0);
        assert_eq!(round3(0.012345), 0.0123);
    }

    #[test]
    fn offset_scale_and_blur_shape_the_key_frame() {
        let v = Array3::from_shape_fn((2, 16, 16), |(_, r, c)| if (r, c) == (8, 8) { 1.0 } else { 0.0 });
        let p = KeyFrameParams { offset_px: (2.0, -3.0), read_noise_adu: 0.0, gain: Some(100.0), ..params(&["first"]) };
        let plan = p.plan(v.dim(), 10.0).unwrap();
        assert_eq!(plan.affine, Some([[1.0, 0.0, 2.0], [0.0, 1.0, -3.0]]));
        let k = plan.render(v.view(), 0.5, 0).unwrap();
        assert_eq!(k.images[0][[10, 5]], 164.0);
        assert_eq!(k.images[0].iter().filter(|&&x| x != 64.0).count(), 1);
        let blurred = KeyFrameParams { blur_px: 1.0, ..p.clone() }.plan(v.dim(), 10.0).unwrap();
        let psf = blurred.psf.as_ref().unwrap();
        assert_eq!(psf.dim(), (7, 7));
        assert!((psf.sum() - 1.0).abs() < 1e-5 && psf[[3, 3]] > psf[[3, 4]]);
        let y = &blurred.expected(v.view()).unwrap()[0];
        assert!((y[10 * 16 + 5] - psf[[3, 3]]).abs() < 1e-6 && (y[10 * 16 + 6] - psf[[3, 4]]).abs() < 1e-6);
        let half = KeyFrameParams { scale: 0.5, ..params(&["first"]) }.plan(v.dim(), 10.0).unwrap();
        assert_eq!((half.key, half.affine), ((8, 8), None));
        let shifted = KeyFrameParams { scale: 0.5, offset_px: (1.0, 0.0), ..params(&["first"]) }.plan(v.dim(), 10.0).unwrap();
        assert_eq!(shifted.affine, Some([[0.5, 0.0, 0.75], [0.0, 0.5, -0.25]]));
    }

    #[test]
    fn bad_values_are_refused_by_name() {
        let dim = (6, 8, 10);
        let e = |p: KeyFrameParams| p.plan(dim, 100.0).unwrap_err().to_string();
        let msg = e(params(&["1e30"]));
        assert!(msg.starts_with("keyframes = 1e30") && msg.contains("0 .. 600 us") && msg.contains("6 frames of 100 us"), "{msg}");
        assert!(e(params(&["nan"])).contains("finite"));
        assert!(e(params(&["-5"])).contains("0 .. 600 us"));
        assert!(e(params(&["550"])).contains("from 0 to 500 us"));
        assert!(KeyTime::parse("soon").unwrap_err().to_string().contains("'soon'"));
        assert!(e(KeyFrameParams { exposure_us: Some(700.0), ..params(&["first"]) }).starts_with("keyframe_exposure_us = 700"));
        assert!(e(KeyFrameParams { exposure_us: Some(200.0), ..params(&["last"]) }).contains("from 0 to 400 us"));
        assert!(e(KeyFrameParams { gain: Some(-1.0), ..params(&["first"]) }).starts_with("keyframe_gain"));
        assert!(e(KeyFrameParams { blur_px: 11.0, ..params(&["first"]) }).starts_with("keyframe_blur_px"));
        for tiny in [1e-300, 5e-324, 0.05, -0.0001] {
            assert!(e(KeyFrameParams { blur_px: tiny, ..params(&["first"]) }).starts_with("keyframe_blur_px"), "{tiny}");
        }
        assert!(e(KeyFrameParams { scale: 0.0, ..params(&["first"]) }).starts_with("keyframe_scale"));
        assert!(e(KeyFrameParams { offset_px: (8.0, 0.0), ..params(&["first"]) }).starts_with("keyframe_offset_px"));
        assert!(e(KeyFrameParams { dark_level_adu: 70000.0, ..params(&["first"]) }).starts_with("keyframe_dark_level_adu"));
        assert!(e(params(&[])).starts_with("keyframes"));
    }
}
