//! The performance benchmark (library side of `rollcam bench`): presets, synthetic
//! inputs, FISTA iterations timed with their parts, the 2D-FFT baseline measured beside
//! them, peak memory, and time to a target PSNR.
//!
//! Every preset is a dual (outside-in) shutter with an exposure of `N_l = 3` line
//! times, frames of one line time, linear convolution with the simulator's
//! random-lenslet PSF, and a scene of a moving disc and a blinking LED (rendered
//! directly on the frame grid); `K = M/2 + N_l - 1` frames.

use crate::model::capture::Fov;
use crate::model::conv::{fft_size, Conv2d};
use crate::model::data::DataTerm;
use crate::model::op::{pseudo_random, Operator};
use crate::model::ranks::{balanced_blocks, frame_work, Ranks};
use crate::model::rolling::RollingShutterModel;
use crate::model::shutter::{ShutterMode, Timing};
use crate::model::split::{RowShare, Split};
use crate::solve::channel::RankShare;
use crate::solve::lipschitz::{power_iteration, power_iteration_from, power_start, LIPSCHITZ_MARGIN};
use crate::solve::optimize::{Fista, IterInfo, RestartTest, StopRule};
use crate::solve::problem::{SolveParams, SolveSettings, ValidSettings};
use crate::solve::prox::block::BlockTv;
use crate::solve::prox::Prox;
use crate::solve::prox::TotalVariation;
use crate::solve::split::rank_shares;
use crate::solve::tau::{Peak, FALLBACK_TAU_REL};
use crate::solve::trace::compare;
use rayon::prelude::*;
use realfft::RealFftPlanner;
use rustfft::num_complex::Complex32;
use rustfft::FftPlanner;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// Rows of exposure (exposure = `N_L` line times).
pub const N_L: usize = 3;
/// Line time of the presets, microseconds.
pub const LINE_TIME_US: f64 = crate::model::shutter::DEFAULT_LINE_TIME_US;

/// A benchmark size.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Preset {
    pub name: &'static str,
    pub rows: usize,
    pub cols: usize,
}

pub const PRESETS: [Preset; 4] = [
    Preset { name: "small", rows: 64, cols: 80 },
    Preset { name: "paper-8x", rows: 270, cols: 320 },
    Preset { name: "paper-4x", rows: 540, cols: 640 },
    Preset { name: "full", rows: 2160, cols: 2560 },
];

pub fn preset(name: &str) -> Option<Preset> {
    PRESETS.iter().copied().find(|p| p.name == name)
}

impl Preset {
    pub fn timing(&self) -> Timing {
        Timing::new(self.rows, LINE_TIME_US, N_L as f64 * LINE_TIME_US, ShutterMode::Dual)
    }
    /// `K = M/2 + N_l - 1`.
    pub fn frames(&self) -> usize {
        self.rows / 2 + N_L - 1
    }
    /// Bytes of one video volume (f32).
    pub fn volume_bytes(&self) -> usize {
        4 * self.frames() * self.rows * self.cols
    }
}

/// A sparse random PSF of `rows x cols`, normalised to sum 1: a few bright, slightly
/// blurred points per 100 x 100 pixels, like the caustics of a random lenslet diffuser.
pub fn sparse_psf(rows: usize, cols: usize, seed: u64) -> Vec<f32> {
    let points = (rows * cols / 400).max(12);
    let r = pseudo_random(3 * points, seed);
    let mut psf = vec![0.0f32; rows * cols];
    for p in 0..points {
        let (y, x, a) = ((r[3 * p] * rows as f32) as isize, (r[3 * p + 1] * cols as f32) as isize, 0.2 + r[3 * p + 2]);
        for dy in -1..=1isize {
            for dx in -1..=1isize {
                let (yy, xx) = (y + dy, x + dx);
                if yy >= 0 && xx >= 0 && (yy as usize) < rows && (xx as usize) < cols {
                    let g = (-0.8 * (dy * dy + dx * dx) as f32).exp();
                    psf[yy as usize * cols + xx as usize] += a * g;
                }
            }
        }
    }
    let s: f64 = psf.iter().map(|&v| v as f64).sum();
    psf.iter_mut().for_each(|v| *v = (*v as f64 / s) as f32);
    psf
}

/// The benchmark scene, `frames x rows x cols`: a disc (radius rows/8, value 1) moving
/// left to right across the middle half of the field (its centre from 1/4 to 3/4 of
/// the width) over a dim static background (0.1 in a band), and an LED (3 x 3, value
/// 2) blinking with a period of 16 frames.
///
/// The disc stays inside the field because an object at its left or right border
/// keeps only half of its PSF on the sensor: with the disc sweeping edge to edge, the
/// first and last frames of paper-8x stayed near 21 dB after 2000 iterations (while
/// the middle frames reached 35 dB), and that border loss, not the solver, set the
/// figure `--psnr` reports.
pub fn scene(frames: usize, rows: usize, cols: usize) -> Vec<f32> {
    scene_frames(frames, rows, cols, 0..frames)
}

/// Frames `range` of [`scene`] (a rank's block), without the others.
pub fn scene_frames(frames: usize, rows: usize, cols: usize, range: std::ops::Range<usize>) -> Vec<f32> {
    let mut v = vec![0.0f32; range.len() * rows * cols];
    let rad = (rows as f32 / 8.0).max(1.5);
    let (led_r, led_c) = (rows / 3, (3 * cols) / 4);
    let first = range.start;
    v.par_chunks_mut(rows * cols).enumerate().for_each(|(i, fr)| {
        let f = first + i;
        let t = f as f32 / frames.max(2).saturating_sub(1) as f32;
        let (cy, cx) = (rows as f32 * 0.55, cols as f32 * (0.25 + 0.5 * t));
        for r in 0..rows {
            for c in 0..cols {
                let (dy, dx) = (r as f32 - cy, c as f32 - cx);
                let mut val = if r > rows / 5 && r < rows / 4 + rows / 10 { 0.1 } else { 0.0 };
                if dy * dy + dx * dx <= rad * rad {
                    val = 1.0;
                }
                fr[r * cols + c] = val;
            }
        }
        if (f / 8) % 2 == 0 {
            for r in led_r.saturating_sub(1)..(led_r + 2).min(rows) {
                for c in led_c.saturating_sub(1)..(led_c + 2).min(cols) {
                    fr[r * cols + c] = 2.0;
                }
            }
        }
    });
    v
}

/// Peak resident memory of this process (`VmHWM`), bytes.
pub fn peak_rss_bytes() -> Option<u64> {
    proc_status_kb("VmHWM:").map(|kb| kb * 1024)
}

fn proc_status_kb(key: &str) -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    s.lines().find(|l| l.starts_with(key))?.split_whitespace().nth(1)?.parse().ok()
}

/// Memory the system reports available (`MemAvailable`), bytes.
pub fn mem_available_bytes() -> Option<u64> {
    crate::io::budget::mem_available_bytes()
}

/// CPU seconds (user + system) this process has used, from `/proc/self/stat`.
pub fn process_cpu_seconds() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which is in parentheses and may hold spaces).
    let rest = &s[s.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let (u, k): (f64, f64) = (f.get(11)?.parse().ok()?, f.get(12)?.parse().ok()?);
    Some((u + k) / 100.0) // USER_HZ is 100 on Linux
}

/// The 1-minute load average.
pub fn load_average() -> Option<f64> {
    std::fs::read_to_string("/proc/loadavg").ok()?.split_whitespace().next()?.parse().ok()
}

/// CPU model name and logical CPU count.
pub fn machine() -> (String, usize) {
    let model = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with("model name")).and_then(|l| l.split(':').nth(1)).map(|m| m.trim().to_string()))
        .unwrap_or_else(|| "unknown".into());
    (model, std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1))
}

/// Median of a list (mean of the two middle values for an even count).
pub fn median(xs: &[f64]) -> f64 {
    if xs.is_empty() {
        return f64::NAN;
    }
    let mut v = xs.to_vec();
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// An operator that adds the time of each call to counters.
pub struct TimedOp<'a, A: ?Sized> {
    pub inner: &'a A,
    pub forward_ns: AtomicU64,
    pub adjoint_ns: AtomicU64,
}

impl<'a, A: Operator + ?Sized> TimedOp<'a, A> {
    pub fn new(inner: &'a A) -> Self {
        TimedOp { inner, forward_ns: AtomicU64::new(0), adjoint_ns: AtomicU64::new(0) }
    }
}

impl<A: Operator + ?Sized> Operator for TimedOp<'_, A> {
    fn input_shape(&self) -> Vec<usize> {
        self.inner.input_shape()
    }
    fn output_shape(&self) -> Vec<usize> {
        self.inner.output_shape()
    }
    fn forward(&self, x: &[f32], y: &mut [f32]) {
        let t = Instant::now();
        self.inner.forward(x, y);
        self.forward_ns.fetch_add(t.elapsed().as_nanos() as u64, Ordering::Relaxed);
    }
    fn adjoint(&self, y: &[f32], x: &mut [f32]) {
        let t = Instant::now();
        self.inner.adjoint(y, x);
        self.adjoint_ns.fetch_add(t.elapsed().as_nanos() as u64, Ordering::Relaxed);
    }
}

/// A proximal term that adds the time of each call to counters.
pub struct TimedProx<'a, R: ?Sized> {
    pub inner: &'a R,
    pub prox_ns: AtomicU64,
    pub value_ns: AtomicU64,
}

impl<'a, R: Prox + ?Sized> TimedProx<'a, R> {
    pub fn new(inner: &'a R) -> Self {
        TimedProx { inner, prox_ns: AtomicU64::new(0), value_ns: AtomicU64::new(0) }
    }
}

impl<R: Prox + ?Sized> Prox for TimedProx<'_, R> {
    fn value(&self, x: &[f32]) -> f64 {
        let t = Instant::now();
        let v = self.inner.value(x);
        self.value_ns.fetch_add(t.elapsed().as_nanos() as u64, Ordering::Relaxed);
        v
    }
    fn prox(&self, z: &[f32], gamma: f32, out: &mut [f32]) {
        let t = Instant::now();
        self.inner.prox(z, gamma, out);
        self.prox_ns.fetch_add(t.elapsed().as_nanos() as u64, Ordering::Relaxed);
    }
}

/// Seconds of one FISTA iteration and its parts (medians over the timed iterations).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct IterationTimes {
    pub iterations: usize,
    pub s_per_iter: f64,
    pub forward_s: f64,
    pub adjoint_s: f64,
    pub tv_prox_s: f64,
    pub tv_value_s: f64,
    /// Everything else: residual, gradient step, momentum, objective.
    pub rest_s: f64,
    /// Fastest and slowest timed iteration.
    pub min_s: f64,
    pub max_s: f64,
    /// CPU seconds (all threads) per timed iteration, mean: on a shared machine,
    /// `cpu_s_per_iter / threads` is what an idle machine would need at best.
    #[serde(default)]
    pub cpu_s_per_iter: f64,
}

/// Run `warmup + timed` FISTA iterations on `b` and time each after the warm-up.
pub fn time_iterations<A: Operator + ?Sized, R: Prox + ?Sized>(op: &A, data: &DataTerm, tv: &R, lipschitz: f64, warmup: usize, timed: usize) -> IterationTimes {
    let top = TimedOp::new(op);
    let tprox = TimedProx::new(tv);
    let fista = Fista { lipschitz, stop: StopRule::iterations(warmup + timed), restart: Some(RestartTest::Objective) };
    let mut rows: Vec<[f64; 5]> = Vec::with_capacity(warmup + timed + 1);
    let mut last = [0.0f64; 5];
    let mut cpu_start = None;
    let mut obs = |i: &IterInfo| {
        if i.iteration == warmup.max(1) {
            cpu_start = process_cpu_seconds();
        }
        let now = [
            i.seconds,
            top.forward_ns.load(Ordering::Relaxed) as f64 * 1e-9,
            top.adjoint_ns.load(Ordering::Relaxed) as f64 * 1e-9,
            tprox.prox_ns.load(Ordering::Relaxed) as f64 * 1e-9,
            tprox.value_ns.load(Ordering::Relaxed) as f64 * 1e-9,
        ];
        if i.iteration > warmup {
            rows.push([now[0] - last[0], now[1] - last[1], now[2] - last[2], now[3] - last[3], now[4] - last[4]]);
        }
        last = now;
        true
    };
    fista.solve(&top, data, &tprox, None, &mut obs);
    let cpu_end = process_cpu_seconds();
    let counted = (warmup + timed).saturating_sub(warmup.max(1)).max(1);
    let cpu_s_per_iter = match (cpu_start, cpu_end) {
        (Some(a), Some(b)) => (b - a) / counted as f64,
        _ => f64::NAN,
    };
    let col = |j: usize| rows.iter().map(|r| r[j]).collect::<Vec<_>>();
    let rest: Vec<f64> = rows.iter().map(|r| r[0] - r[1] - r[2] - r[3] - r[4]).collect();
    let total = col(0);
    IterationTimes {
        iterations: rows.len(),
        s_per_iter: median(&total),
        forward_s: median(&col(1)),
        adjoint_s: median(&col(2)),
        tv_prox_s: median(&col(3)),
        tv_value_s: median(&col(4)),
        rest_s: median(&rest),
        min_s: total.iter().cloned().fold(f64::INFINITY, f64::min),
        max_s: total.iter().cloned().fold(0.0, f64::max),
        cpu_s_per_iter,
    }
}

/// Seconds for `count` real 2D FFTs of a `p x q` grid (half forward: real FFTs of
/// the `p` rows, then complex FFTs of the `q/2+1` columns; half inverse), done the
/// straightforward way with `realfft`/`rustfft`, transforms in parallel on the rayon
/// threads. This is what one FISTA iteration costs the 2D path in FFTs alone when
/// `count = 4K`.
pub fn fft2d_seconds(p: usize, q: usize, count: usize) -> f64 {
    let qc = q / 2 + 1;
    let mut rp = RealFftPlanner::<f32>::new();
    let (r2c, c2r) = (rp.plan_fft_forward(q), rp.plan_fft_inverse(q));
    let mut cp = FftPlanner::<f32>::new();
    let (cf, ci) = (cp.plan_fft_forward(p), cp.plan_fft_inverse(p));
    let pairs = count.div_ceil(2);
    let chunks = (2 * rayon::current_num_threads()).clamp(1, pairs.max(1));
    struct Buf {
        grid: Vec<f32>,
        spec: Vec<Complex32>,
        rowc: Vec<Complex32>,
        rs: Vec<Complex32>,
        cs: Vec<Complex32>,
    }
    let mut bufs: Vec<Buf> = (0..chunks)
        .map(|c| Buf {
            grid: pseudo_random(p * q, c as u64 + 1),
            spec: vec![Complex32::new(0.0, 0.0); qc * p],
            rowc: vec![Complex32::new(0.0, 0.0); qc],
            rs: vec![Complex32::new(0.0, 0.0); r2c.get_scratch_len().max(c2r.get_scratch_len())],
            cs: vec![Complex32::new(0.0, 0.0); cf.get_inplace_scratch_len().max(ci.get_inplace_scratch_len())],
        })
        .collect();
    let per = pairs.div_ceil(chunks);
    let t = Instant::now();
    bufs.par_iter_mut().enumerate().for_each(|(c, b)| {
        for _ in c * per..((c + 1) * per).min(pairs) {
            for r in 0..p {
                r2c.process_with_scratch(&mut b.grid[r * q..(r + 1) * q], &mut b.rowc, &mut b.rs).expect("r2c");
                for (k, z) in b.rowc.iter().enumerate() {
                    b.spec[k * p + r] = *z;
                }
            }
            cf.process_with_scratch(&mut b.spec, &mut b.cs);
            ci.process_with_scratch(&mut b.spec, &mut b.cs);
            for r in 0..p {
                for (k, z) in b.rowc.iter_mut().enumerate() {
                    *z = b.spec[k * p + r];
                }
                b.rowc[0].im = 0.0;
                b.rowc[qc - 1].im = 0.0;
                c2r.process_with_scratch(&mut b.rowc, &mut b.grid[r * q..(r + 1) * q], &mut b.rs).expect("c2r");
            }
            // Keep the values bounded (the pair scales by p q).
            let s = 1.0 / (p * q) as f32;
            b.grid.iter_mut().for_each(|v| *v *= s);
        }
    });
    t.elapsed().as_secs_f64()
}

/// The benchmark's PSF: the simulator's random-lenslet PSF (default parameters, seed
/// 7), or [`sparse_psf`] should the simulator refuse the size.
pub fn psf(rows: usize, cols: usize) -> Vec<f32> {
    match crate::sim::psf::lenslet_psf(rows, cols, &crate::sim::psf::LensletParams::default(), 7) {
        Ok(a) => a.iter().copied().collect(),
        Err(e) => {
            tracing::warn!("lenslet PSF unavailable ({e}); using a sparse random PSF");
            sparse_psf(rows, cols, 7)
        }
    }
}

/// Build the benchmark's model for a preset (sensor field of view), with `frames`
/// restricted to a window when given.
pub fn build(preset: &Preset, window: Option<std::ops::Range<usize>>) -> RollingShutterModel {
    let psf = psf(preset.rows, preset.cols);
    let conv = Conv2d::sensor(&psf, preset.rows, preset.cols);
    let w = preset.timing().weights().expect("preset timing is valid");
    let w = match window {
        Some(r) => w.window(r),
        None => w,
    };
    RollingShutterModel::new(conv, w)
}

/// One preset's figures (one JSON line of `rollcam bench`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PresetReport {
    pub preset: String,
    pub rows: usize,
    pub cols: usize,
    pub frames: usize,
    /// Padded grid of the 2D path (P, Q).
    pub fft_grid: (usize, usize),
    pub threads: usize,
    #[serde(flatten)]
    pub times: IterationTimes,
    /// Seconds for 4K real 2D FFTs of the padded grid, measured in the same run.
    pub fft_4k_s: f64,
    /// `s_per_iter / fft_4k_s` (target: at most 0.5).
    pub iter_over_fft_4k: f64,
    /// Forward + adjoint by the 2D-FFT reference path, and by the row path (medians).
    pub reference_fwd_adj_s: Option<f64>,
    pub fast_fwd_adj_s: Option<f64>,
    pub volume_bytes: usize,
    /// Peak resident memory of the process (VmHWM) after the timed iterations.
    pub peak_rss_bytes: Option<u64>,
    pub peak_over_volume: Option<f64>,
    /// Set when the figures are extrapolated from a window of frames (and why).
    pub extrapolated: Option<String>,
    /// Memory a full solve needs (4 volumes + model buffers), bytes.
    pub solve_needs_bytes: usize,
    pub load_before: Option<f64>,
    pub load_after: Option<f64>,
}

/// Options of a preset run.
#[derive(Clone, Debug)]
pub struct RunOptions {
    pub warmup: usize,
    pub timed: usize,
    /// Repetitions of the forward + adjoint comparison (0: skip it).
    pub reference_reps: usize,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions { warmup: 2, timed: 10, reference_reps: 3 }
    }
}

/// Time one preset. The `full` preset, when four volumes do not fit in the memory
/// available, is timed on a window of 32 frames from the middle of the capture and
/// extrapolated to all frames (the report says so).
pub fn run_preset(preset: &Preset, opts: &RunOptions) -> PresetReport {
    let load_before = load_average();
    let threads = rayon::current_num_threads();
    let k = preset.frames();
    let full_model_bytes = {
        let m = build_probe_bytes(preset, threads);
        4 * preset.volume_bytes() + m + 3 * 4 * preset.rows * preset.cols
    };
    let available = mem_available_bytes().unwrap_or(u64::MAX) as usize;
    let window = if full_model_bytes > available * 9 / 10 {
        // Frames from the middle: their rows (about M/4 and 3M/4) have the average
        // number of PSF rows overlapping the sensor. Per-call costs that do not grow
        // with the frames (one FFT per sensor row and direction) are scaled too, an
        // overestimate of about 1/window of the operator time.
        let w = 32.min(k);
        Some((k / 2 - w / 2)..(k / 2 - w / 2 + w))
    } else {
        None
    };
    let model = build(preset, window.clone());
    let (kw, m, n) = model.video_shape();
    // Measurements through the model's own forward operator.
    let truth = scene(kw, m, n);
    let mut b = vec![0.0f32; m * n];
    model.forward(&truth, &mut b);
    drop(truth);
    let eig = power_iteration(&model, 20, 1e-3, 0x5eed);
    let lipschitz = eig.lambda_max * LIPSCHITZ_MARGIN;
    let params = timing_settings().resolve(&Peak::of(&model, &b), Fov::Sensor);
    let tv = TotalVariation::new((kw, m, n), params.tau, params.alpha);
    let mut times = time_iterations(&model, &DataTerm::new(&b), &tv, lipschitz, opts.warmup, opts.timed);
    let peak = peak_rss_bytes();
    let (reference, fast) = if opts.reference_reps > 0 {
        let x = scene(kw, m, n);
        let (mut y, mut g) = (vec![0.0f32; m * n], vec![0.0f32; x.len()]);
        let mut rt = Vec::new();
        let mut ft = Vec::new();
        for _ in 0..opts.reference_reps {
            let t = Instant::now();
            model.forward_reference(&x, &mut y);
            model.adjoint_reference(&y, &mut g);
            rt.push(t.elapsed().as_secs_f64());
            let t = Instant::now();
            model.forward(&x, &mut y);
            model.adjoint(&y, &mut g);
            ft.push(t.elapsed().as_secs_f64());
        }
        (Some(median(&rt)), Some(median(&ft)))
    } else {
        (None, None)
    };
    let (p, q) = model.conv().fft_shape();
    let scale = k as f64 / kw as f64;
    // 4K 2D FFTs (a sample of them, scaled, when the run is windowed).
    let sample = if window.is_some() { (4 * kw).min(16) } else { 4 * k };
    let fft_4k_s = fft2d_seconds(p, q, sample) * (4 * k) as f64 / sample as f64;
    let extrapolated = window.as_ref().map(|w| {
        format!(
            "a full solve needs {:.1} GB, {:.1} GB available: timed on frames {}..{} of {k} and scaled by {scale:.1}; FFT baseline from {sample} transforms",
            full_model_bytes as f64 / 1e9,
            available as f64 / 1e9,
            w.start,
            w.end
        )
    });
    if window.is_some() {
        for v in [
            &mut times.cpu_s_per_iter,
            &mut times.s_per_iter,
            &mut times.forward_s,
            &mut times.adjoint_s,
            &mut times.tv_prox_s,
            &mut times.tv_value_s,
            &mut times.rest_s,
            &mut times.min_s,
            &mut times.max_s,
        ] {
            *v *= scale;
        }
    }
    let reference = reference.map(|v| v * scale);
    let fast = fast.map(|v| v * scale);
    PresetReport {
        preset: preset.name.into(),
        rows: preset.rows,
        cols: preset.cols,
        frames: k,
        fft_grid: (p, q),
        threads,
        iter_over_fft_4k: times.s_per_iter / fft_4k_s,
        times,
        fft_4k_s,
        reference_fwd_adj_s: reference,
        fast_fwd_adj_s: fast,
        volume_bytes: preset.volume_bytes(),
        peak_rss_bytes: peak,
        peak_over_volume: if window.is_some() { None } else { peak.map(|p| p as f64 / preset.volume_bytes() as f64) },
        extrapolated,
        solve_needs_bytes: full_model_bytes,
        load_before,
        load_after: load_average(),
    }
}

/// One preset timed with its frames split across ranks (one JSON line of `rollcam
/// bench` under `mpirun`, from rank 0).
#[derive(Clone, Debug, Serialize)]
pub struct SplitPresetReport {
    pub preset: String,
    pub rows: usize,
    pub cols: usize,
    pub frames: usize,
    /// Worker threads of each rank.
    pub threads: usize,
    pub ranks: usize,
    /// Rank 0's iterations (every iteration waits for all ranks at the forward's sum).
    #[serde(flatten)]
    pub times: IterationTimes,
    /// Bytes of one video-sized vector of the whole problem.
    pub volume_bytes: usize,
    /// What one process needs for the whole solve (4 volumes + model buffers), bytes.
    pub single_process_needs_bytes: usize,
    /// Sensor rows the forward sums across the ranks (those two blocks' frames touch;
    /// of `rows`).
    pub sensor_rows_summed: usize,
    /// Each rank's frames, share of the work, peak memory and traffic per iteration.
    pub per_rank: Vec<RankShare>,
}

/// Time one preset split across `ranks` (every rank calls this): each rank builds the
/// model of its block of frames ([`balanced_blocks`] by [`frame_work`]) and the block
/// of the benchmark scene, and FISTA runs on the split problem. `Err` when the preset
/// has fewer frames than ranks, or when this machine's ranks would need more memory
/// than it has (`ranks_here`: the ranks on this machine).
pub fn run_preset_split(preset: &Preset, opts: &RunOptions, ranks: &dyn Ranks, ranks_here: usize) -> Result<SplitPresetReport, String> {
    let threads = rayon::current_num_threads();
    let k = preset.frames();
    let (m, n) = (preset.rows, preset.cols);
    let w = preset.timing().weights().expect("preset timing is valid");
    let work = frame_work(&w, m);
    let blocks = balanced_blocks(&work, ranks.size()).ok_or_else(|| format!("{}: {k} frames cannot be split across {} ranks", preset.name, ranks.size()))?;
    let mine = blocks[ranks.rank()].clone();
    let frame_bytes = 4 * m * n;
    let largest = blocks.iter().map(|b| b.len()).max().unwrap_or(0);
    let per_rank_needs = 4 * largest * frame_bytes + build_probe_bytes(preset, threads) + 3 * frame_bytes;
    let available = mem_available_bytes().unwrap_or(u64::MAX) as usize;
    let mut over = [(per_rank_needs.saturating_mul(ranks_here.max(1)) > available * 9 / 10) as u8 as f64];
    ranks.max_f64(&mut over);
    if over[0] > 0.0 {
        return Err(format!(
            "{}: each rank needs {:.1} GB for its block of at most {largest} frames; {} ranks on one machine with {:.1} GB available do not fit (use more machines or ranks)",
            preset.name,
            per_rank_needs as f64 / 1e9,
            ranks_here,
            available as f64 / 1e9
        ));
    }
    let op = Split::new(build(preset, Some(mine.clone())), ranks, mine.clone(), k, RowShare::new(&w, &blocks, ranks.rank()));
    let truth = scene_frames(k, m, n, mine.clone());
    let mut b = vec![0.0f32; m * n];
    op.forward(&truth, &mut b);
    drop(truth);
    let start = power_start(k * m * n, 0x5eed, op.offset()..op.offset() + op.input_len());
    let mut lambda = [power_iteration_from(&op, op.partition(), start, 20, 1e-3).lambda_max];
    ranks.broadcast_f64(&mut lambda);
    let lipschitz = lambda[0] * LIPSCHITZ_MARGIN;
    let params = timing_settings().resolve(&Peak::across_ranks(Peak::of(&op, &b).0, ranks), Fov::Sensor);
    let tv = BlockTv::new(TotalVariation::new((k, m, n), params.tau, params.alpha), ranks);
    let before = ranks.traffic();
    let times = time_iterations(&op, &DataTerm::new(&b).on(op.partition()), &tv, lipschitz, opts.warmup, opts.timed);
    let traffic = ranks.traffic().since(before);
    let shares = rank_shares(&blocks, 0, &work, traffic, opts.warmup + opts.timed, peak_rss_bytes(), ranks);
    Ok(SplitPresetReport {
        preset: preset.name.into(),
        rows: m,
        cols: n,
        frames: k,
        threads,
        ranks: ranks.size(),
        times,
        volume_bytes: preset.volume_bytes(),
        single_process_needs_bytes: 4 * preset.volume_bytes() + build_probe_bytes(preset, threads) + 3 * frame_bytes,
        sensor_rows_summed: op.summed_rows(),
        per_rank: shares,
    })
}

/// Bytes of the model's own buffers for a preset, without building it.
fn build_probe_bytes(preset: &Preset, threads: usize) -> usize {
    let (m, n) = (preset.rows, preset.cols);
    let q = fft_size(2 * n - 1, true);
    let w = (q / 2 + 1).div_ceil(8) * 8;
    let chunks = (4 * threads).min(preset.frames());
    // PSF row spectra, per-chunk partial sums (M x w complex), sensor-row spectra.
    8 * m * w + chunks * 8 * m * w + 8 * m * w + m * n * 4
}

/// Time to reach a PSNR on a preset's scene.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PsnrReport {
    pub preset: String,
    pub target_db: f64,
    /// Solver seconds (observer excluded) until the target was first reached.
    pub seconds: Option<f64>,
    pub iterations: Option<usize>,
    pub best_db: f64,
    pub iterations_run: usize,
    pub solver_seconds: f64,
    pub lipschitz_seconds: f64,
    pub tau: f32,
    pub alpha: f32,
    /// First (seconds, iteration) at which each milestone PSNR was reached.
    pub milestones: Vec<Milestone>,
    /// Per-frame PSNR at the last iterate (against the whole video's peak): the
    /// worst frame, the median frame, and how many frames are below the target.
    pub frame_db_min: f64,
    pub frame_db_median: f64,
    pub frames_below_target: usize,
    /// Index of the worst frame, and the number of frames.
    pub worst_frame: usize,
    pub frames: usize,
    pub final_db: f64,
    pub measurement: String,
    pub threads: usize,
    pub load_before: Option<f64>,
    pub load_after: Option<f64>,
}

/// A PSNR milestone on the way to the target.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Milestone {
    pub db: f64,
    pub seconds: Option<f64>,
    pub iterations: Option<usize>,
}

/// Per-frame PSNR of `x` against `truth` (`frames` equal frames), with the peak of
/// the whole truth video as the reference, so that dark frames are not flattered.
pub fn frame_psnr_db(x: &[f32], truth: &[f32], frames: usize) -> Vec<f64> {
    let peak = truth.iter().fold(f32::NEG_INFINITY, |a, &v| a.max(v)) as f64;
    let len = truth.len() / frames.max(1);
    (0..frames)
        .map(|f| {
            let se: f64 = x[f * len..(f + 1) * len].iter().zip(&truth[f * len..(f + 1) * len]).map(|(&a, &b)| (a as f64 - b as f64).powi(2)).sum();
            let mse = se / len.max(1) as f64;
            if mse > 0.0 {
                10.0 * (peak * peak / mse).log10()
            } else {
                f64::INFINITY
            }
        })
        .collect()
}

/// FISTA with TV on the preset's scene until `target_db` PSNR (or `max_iters`),
/// noting when 20 dB, 25 dB and the target were first reached.
pub fn time_to_psnr(preset: &Preset, target_db: f64, max_iters: usize, settings: &ValidSettings) -> PsnrReport {
    let load_before = load_average();
    let model = build(preset, None);
    let (k, m, n) = model.video_shape();
    let truth = scene(k, m, n);
    let mut b = vec![0.0f32; m * n];
    model.forward(&truth, &mut b);
    let t = Instant::now();
    let eig = power_iteration(&model, 300, 1e-5, 0x5eed);
    let lipschitz_seconds = t.elapsed().as_secs_f64();
    let SolveParams { tau, alpha, .. } = settings.resolve(&Peak::of(&model, &b), Fov::Sensor);
    let tv = TotalVariation::new((k, m, n), tau, alpha);
    let fista = Fista { lipschitz: eig.lambda_max * LIPSCHITZ_MARGIN, stop: StopRule::iterations(max_iters), restart: Some(RestartTest::Objective) };
    let mut levels: Vec<f64> = [20.0, 25.0].into_iter().filter(|&d| d < target_db).collect();
    levels.push(target_db);
    let mut milestones: Vec<Milestone> = levels.iter().map(|&db| Milestone { db, seconds: None, iterations: None }).collect();
    let (mut reached, mut best, mut last_db) = (None, f64::NEG_INFINITY, f64::NEG_INFINITY);
    let mut obs = |i: &IterInfo| {
        // A simulated scene has light: a zero truth (no figures) ends the run.
        let Some(e) = compare(i.x, &truth) else { return false };
        best = best.max(e.psnr_db);
        last_db = e.psnr_db;
        for m in milestones.iter_mut().filter(|m| m.seconds.is_none() && e.psnr_db >= m.db) {
            (m.seconds, m.iterations) = (Some(i.seconds), Some(i.iteration));
        }
        if e.psnr_db >= target_db {
            reached = Some((i.seconds, i.iteration));
            return false;
        }
        true
    };
    let r = fista.solve(&model, &DataTerm::new(&b), &tv, None, &mut obs);
    let mut per_frame = frame_psnr_db(&r.x, &truth, k);
    let worst_frame = (0..k).min_by(|&a, &b| per_frame[a].total_cmp(&per_frame[b])).unwrap_or(0);
    let frames_below_target = per_frame.iter().filter(|&&d| d < target_db).count();
    per_frame.sort_by(|a, b| a.total_cmp(b));
    PsnrReport {
        preset: preset.name.into(),
        target_db,
        seconds: reached.map(|r| r.0),
        iterations: reached.map(|r| r.1),
        best_db: best,
        iterations_run: r.iterations,
        solver_seconds: r.seconds,
        lipschitz_seconds,
        tau,
        alpha,
        milestones,
        frame_db_min: per_frame.first().copied().unwrap_or(f64::NAN),
        frame_db_median: per_frame.get(per_frame.len() / 2).copied().unwrap_or(f64::NAN),
        frames_below_target,
        worst_frame,
        frames: k,
        final_db: last_db,
        measurement: "noise-free, made by the model's own forward operator from the benchmark scene (a disc crossing the middle half of the field, a dim static band, a blinking LED) and the random-lenslet PSF".into(),
        threads: rayon::current_num_threads(),
        load_before,
        load_after: load_average(),
    }
}

/// Marks of the generated block in a Markdown file.
pub const MD_BEGIN: &str = "<!-- bench:begin (generated by `rollcam bench --all --markdown`; edits inside are overwritten) -->";
pub const MD_END: &str = "<!-- bench:end -->";

/// `YYYY-MM-DD HH:MM UTC` of the system clock.
pub fn utc_now() -> String {
    crate::io::utc::utc_minutes_now()
}

fn fmt_s(v: f64) -> String {
    if v >= 10.0 {
        format!("{v:.1}")
    } else if v >= 0.1 {
        format!("{v:.3}")
    } else {
        format!("{v:.4}")
    }
}

fn fmt_gb(b: f64) -> String {
    if b >= 1e9 {
        format!("{:.2} GB", b / 1e9)
    } else {
        format!("{:.0} MB", b / 1e6)
    }
}

/// The generated Markdown block: machine, one table of presets, time to PSNR.
pub fn markdown_block(reports: &[PresetReport], psnr: Option<&PsnrReport>, command: &str) -> String {
    let (cpu, cores) = machine();
    let mut s = String::new();
    s.push_str(&format!("Measured {} on {cpu}, {cores} logical CPUs, with `{command}`.\n", utc_now()));
    if let (Some(a), Some(b)) = (reports.first().and_then(|r| r.load_before), reports.last().and_then(|r| r.load_after)) {
        s.push_str(&format!("Load average (1 min) {a:.2} at the start, {b:.2} at the end (other work on the machine makes the figures noisy; medians over the timed iterations).\n"));
    }
    s.push_str("\n| preset | M x N | K | threads | s / iteration (median) | forward | adjoint | TV prox | TV value | rest | CPU s / iteration | 4K 2D FFTs (s) | iteration / 4K FFTs | peak memory | peak / volume |\n");
    s.push_str("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for r in reports {
        let t = &r.times;
        s.push_str(&format!(
            "| {}{} | {} x {} | {} | {} | {} (min {}, max {}, n = {}) | {} | {} | {} | {} | {} | {} | {} | {:.3} | {} | {} |\n",
            r.preset,
            if r.extrapolated.is_some() { " *" } else { "" },
            r.rows,
            r.cols,
            r.frames,
            r.threads,
            fmt_s(t.s_per_iter),
            fmt_s(t.min_s),
            fmt_s(t.max_s),
            t.iterations,
            fmt_s(t.forward_s),
            fmt_s(t.adjoint_s),
            fmt_s(t.tv_prox_s),
            fmt_s(t.tv_value_s),
            fmt_s(t.rest_s),
            fmt_s(t.cpu_s_per_iter),
            fmt_s(r.fft_4k_s),
            r.iter_over_fft_4k,
            r.peak_rss_bytes.map(|b| fmt_gb(b as f64)).unwrap_or_else(|| "-".into()),
            r.peak_over_volume.map(|v| format!("{v:.2}")).unwrap_or_else(|| "-".into()),
        ));
    }
    s.push_str("\nTimes in seconds. Parts are medians of each part, so they need not add up to the median total exactly. ");
    s.push_str("\"4K 2D FFTs\": 4K real 2D FFTs of the padded P x Q grid, the transforms alone of one iteration of the straightforward path, measured in the same run on the same threads. ");
    s.push_str("CPU s / iteration: CPU time of all threads per iteration (mean); on a shared machine, CPU time / threads bounds what an idle one would take. Peak memory is the process's VmHWM (one process per preset), including the measurement, the model and the solver's four video volumes.\n");
    let cmp: Vec<&PresetReport> = reports.iter().filter(|r| r.reference_fwd_adj_s.is_some()).collect();
    if !cmp.is_empty() {
        s.push_str("\n| preset | forward + adjoint, 2D-FFT reference (s) | forward + adjoint, row path (s) | speed-up |\n|---|---|---|---|\n");
        for r in cmp {
            let (a, b) = (r.reference_fwd_adj_s.unwrap(), r.fast_fwd_adj_s.unwrap_or(f64::NAN));
            s.push_str(&format!("| {} | {} | {} | {:.1}x |\n", r.preset, fmt_s(a), fmt_s(b), a / b));
        }
    }
    for r in reports.iter().filter(|r| r.extrapolated.is_some()) {
        s.push_str(&format!(
            "\n\\* `{}`: not solved whole: {}. A whole solve would need about {} (4 video volumes of {} each, plus buffers).\n",
            r.preset,
            r.extrapolated.as_deref().unwrap_or(""),
            fmt_gb(r.solve_needs_bytes as f64),
            fmt_gb(r.volume_bytes as f64)
        ));
    }
    if let Some(p) = psnr {
        s.push('\n');
        s.push_str(&psnr_markdown(p, command));
    }
    s
}

/// The generated Markdown of a time-to-PSNR run (its own block, so that it can be
/// regenerated alone with `rollcam bench --psnr --markdown FILE`).
pub fn psnr_markdown(p: &PsnrReport, command: &str) -> String {
    let mut s = format!("Measured {} with `{command}`", utc_now());
    if let (Some(a), Some(b)) = (p.load_before, p.load_after) {
        s.push_str(&format!(" (load average {a:.2} at the start, {b:.2} at the end)"));
    }
    s.push_str(&format!(
        ".\n\nTime to {:.0} dB PSNR on `{}` ({} threads; measurement {}; FISTA with restart, tau = {:.3e}, alpha = {}): ",
        p.target_db, p.preset, p.threads, p.measurement, p.tau, p.alpha
    ));
    match (p.seconds, p.iterations) {
        (Some(sec), Some(it)) => s.push_str(&format!("**{} s** ({it} iterations)", fmt_s(sec))),
        _ => s.push_str(&format!("not reached in {} iterations ({} s); best {:.2} dB", p.iterations_run, fmt_s(p.solver_seconds), p.best_db)),
    }
    s.push_str(&format!(
        ", plus {} s for the Lipschitz constant by power iteration (cached on disk per PSF and timing in normal use).\n\n",
        fmt_s(p.lipschitz_seconds)
    ));
    s.push_str("| PSNR | seconds | iterations |\n|---|---|---|\n");
    for m in &p.milestones {
        match (m.seconds, m.iterations) {
            (Some(sec), Some(it)) => s.push_str(&format!("| {:.0} dB | {} | {it} |\n", m.db, fmt_s(sec))),
            _ => s.push_str(&format!("| {:.0} dB | not reached | - |\n", m.db)),
        }
    }
    s.push_str(&format!(
        "\nAt the last iterate ({:.2} dB over the whole video): per-frame PSNR (peak of the whole video as reference) from {:.1} dB (worst: frame {} of {}) to a median of {:.1} dB; {} of the {} frames below {:.0} dB.",
        p.final_db, p.frame_db_min, p.worst_frame, p.frames, p.frame_db_median, p.frames_below_target, p.frames, p.target_db
    ));
    if p.worst_frame < p.frames / 4 {
        s.push_str(" The worst frame is an early one: early frames are exposed by the outermost rows of a dual (outside-in) shutter, which receive the least PSF energy (the time-varying field of view).");
    }
    s.push('\n');
    s
}

/// Replace the generated block of `existing` (or append one) with `block`.
pub fn splice_markdown(existing: &str, block: &str) -> String {
    splice_between(existing, MD_BEGIN, MD_END, block)
}

/// Marks of the generated time-to-PSNR block.
pub const PSNR_MD_BEGIN: &str = "<!-- bench-psnr:begin (generated by `rollcam bench --psnr --markdown`; edits inside are overwritten) -->";
pub const PSNR_MD_END: &str = "<!-- bench-psnr:end -->";

/// Replace the generated time-to-PSNR block of `existing` (or append one).
pub fn splice_psnr_markdown(existing: &str, block: &str) -> String {
    splice_between(existing, PSNR_MD_BEGIN, PSNR_MD_END, block)
}

fn splice_between(existing: &str, begin: &str, end: &str, block: &str) -> String {
    let wrapped = format!("{begin}\n{block}{end}");
    match (existing.find(begin), existing.find(end)) {
        (Some(a), Some(b)) if b > a => format!("{}{}{}", &existing[..a], wrapped, &existing[b + end.len()..]),
        _ => format!("{existing}\n{wrapped}\n"),
    }
}

/// `existing` (a Markdown file's text) with each block replaced only by a run that
/// measured it: the presets' table when `reports` is not empty, the time-to-PSNR block
/// when `psnr` is given. `command` is the command line the blocks cite.
pub fn update_markdown(existing: &str, reports: &[PresetReport], psnr: Option<&PsnrReport>, command: &str) -> String {
    let mut text = existing.to_string();
    if !reports.is_empty() {
        text = splice_markdown(&text, &markdown_block(reports, None, command));
    }
    if let Some(p) = psnr {
        text = splice_psnr_markdown(&text, &psnr_markdown(p, command));
    }
    text
}

/// The text of the Markdown file `bench --markdown` may write: a file that holds the
/// bench's markers, or a new `# Performance` page where none exists. Any other file
/// (one of the user's, a system file) is refused: it is never edited.
pub fn markdown_target(path: &std::path::Path) -> std::io::Result<String> {
    match std::fs::symlink_metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok("# Performance\n".into()),
        Err(e) => return Err(e),
        Ok(m) if !m.is_file() => return Err(std::io::Error::other("not a regular file: bench writes only into a file that holds its markers, or a new file")),
        Ok(_) => {}
    }
    let text = crate::io::input::read_text(path)?;
    let marker = |m: &str| m.split(" (").next().map(|head| text.contains(head)).unwrap_or(false);
    if [MD_BEGIN, MD_END, PSNR_MD_BEGIN, PSNR_MD_END].iter().any(|m| marker(m)) {
        Ok(text)
    } else {
        Err(std::io::Error::other(format!(
            "holds none of the bench's markers ({} ... {}): bench writes only into a file that holds them, or a new file",
            MD_BEGIN.split(" (").next().unwrap_or(MD_BEGIN),
            MD_END
        )))
    }
}

/// [`update_markdown`] on the file at `path` ([`markdown_target`]: a file holding the
/// bench markers, or a new page), written back in place.
pub fn update_markdown_file(path: &std::path::Path, reports: &[PresetReport], psnr: Option<&PsnrReport>, command: &str) -> std::io::Result<()> {
    let text = markdown_target(path)?;
    std::fs::write(path, update_markdown(&text, reports, psnr, command))
}

impl RunOptions {
    /// The options of `preset` from the requested ones: the 2D path costs seconds per
    /// call at paper-4x (one repetition there) and minutes at full size (skipped; the
    /// FFT baseline stands for it).
    pub fn for_preset(preset: &Preset, warmup: usize, timed: usize, reference_reps: usize) -> RunOptions {
        let reference_reps = match preset.rows {
            r if r > 1000 => 0,
            r if r > 300 => reference_reps.min(1),
            _ => reference_reps,
        };
        RunOptions { warmup, timed, reference_reps }
    }
}

/// The settings the per-iteration timings solve with: the defaults at the fixed
/// [`FALLBACK_TAU_REL`] (a simulated noiseless raw has no noise for the default rule to
/// read, and a timing's weight should not move with it).
fn timing_settings() -> ValidSettings {
    SolveSettings { tau: crate::solve::tau::Tau::Relative(FALLBACK_TAU_REL), ..SolveSettings::default() }
        .validate()
        .expect("the defaults at a fixed weight are valid")
}

#[cfg(test)]
mod markdown_update_tests {
    use super::*;

    #[test]
    fn reference_repetitions_shrink_with_the_preset() {
        let reps = |name: &str| RunOptions::for_preset(&preset(name).unwrap(), 1, 2, 3).reference_reps;
        assert_eq!(reps("small"), 3);
        assert!(reps("full") == 0 && reps("paper-4x") <= 1);
    }

    #[test]
    fn a_markdown_update_without_results_keeps_the_text() {
        assert_eq!(update_markdown("# Performance\n", &[], None, "rollcam bench"), "# Performance\n");
    }
}
