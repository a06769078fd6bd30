//! The sources of a sparse scene: light that stays where it is and changes only in
//! brightness (LEDs, lamps, a flashing marker), fitted as such.
//!
//! The video solved on a sparse scene's [`Support`] still has every pixel of the support
//! free in every frame. Frames that few sensor rows see (a dual shutter's first ones;
//! rows where the PSF's shifted copies are dark) are weakly determined there, and TV
//! fills them with light in the wrong place or none. When the light sits in separate
//! sources that only change brightness, the video is `v_k = sum_r a_rk m_r`: each
//! source's shape `m_r` (fixed) times its brightness `a_rk` in frame `k`, a few numbers
//! per frame that the data determine even where the pixels are not.
//!
//! - **Regions** ([`Shapes::of`]): the cores of the support video's temporal mean (8-
//!   connected pixels above [`crate::solve::support::THRESHOLD_REL`] of its largest
//!   value), the rest of the support given to the nearest core; at most
//!   [`MAX_SOURCES`].
//! - **Brightness** ([`fit_brightness`]): non-negative least squares on the sources'
//!   sensor images. `A (m_r e_k) = S_k . crop(h * m_r)`, so the Gram matrix is
//!   `sum_i w_ik w_ik' <g_ri, g_r'i>` over sensor rows `i` (`g_r = crop(h * m_r)`, one
//!   convolution per source); frames share rows only within an exposure, so it is a
//!   band. Exact coordinate descent on it: the weakly seen frames get their least-
//!   squares value, not the slow mode of a gradient method. Where the rows that expose
//!   a frame barely see a source, that value is mostly noise (measured: off by up to
//!   2.4 times the LED's level); a prior then draws each source's brightness toward its
//!   mean over the frames the data see, weighted by the data's noise over the source's
//!   spread there ([`PRIOR_REL`]): the frames the data hold keep their value, the ones
//!   they do not hold go to the mean.
//! - **Shapes** ([`refine_shapes`]): at that brightness the shapes are fitted again
//!   (FISTA on the shapes, non-negative, zero outside their regions), then the
//!   brightness again: [`SOURCE_ROUNDS`] rounds of [`SHAPE_ITERS`] iterations. At a
//!   fixed brightness the sources' sensor image is `sum_r G_r . crop(h * m_r)` with a
//!   row gain `G_r(i) = sum_k w_ik a_rk` ([`ShapeMap`]): one convolution per source, not
//!   one per frame.
//!
//! The fit costs [`SOURCE_ROUNDS`] x [`SHAPE_ITERS`] passes of one convolution per
//! source and its adjoint beyond the solve's cap; none when the first brightness fit is far off ([`SOURCES_EARLY_MISFIT`]).
//! The data then decide ([`SourcesReport::kept`]): the sources' video is kept when its
//! data misfit is at most [`SOURCES_MISFIT_KEEP`] times the support video's (it has far
//! fewer unknowns and fits less noise); a moving object, or sources merged into one
//! region, fit far worse (measured: 5.7-114 times) and the support's video stands.

use crate::model::data::DataTerm;
use crate::model::op::{Operator, ShutterConvolution};
pub use crate::solve::support::{SourcesReport, SOURCES_MISFIT_KEEP, UNSEEN_REL};
use crate::solve::support::{Support, THRESHOLD_REL};
use rayon::prelude::*;
use std::collections::VecDeque;
use std::sync::Arc;

/// At most this many sources are fitted; a support with more regions keeps its video.
pub const MAX_SOURCES: usize = 64;
/// Rounds of shapes then brightness after the first brightness fit.
pub const SOURCE_ROUNDS: usize = 3;
/// FISTA iterations on the shapes per round. On the shutter-weighted convolution the
/// sources are fitted on, each costs one convolution per source
/// and its adjoint ([`refine_shapes`]), not the video's; measured on the 200 x 266 LED
/// array (4 sources, 102 frames): 3 x 40 of the video's iterations 4.9 s (rel. error
/// 0.302), 3 x 40 of the sources' 1.4 s (0.225), 3 x 200 5.0 s (0.163).
pub const SHAPE_ITERS: usize = 200;
/// Power iterations for the shapes' own Lipschitz constant ([`refine_shapes`] on a
/// shutter-weighted convolution), and the margin it is taken with.
pub const SHAPE_POWER_ITERS: usize = 30;
pub const SHAPE_LIPSCHITZ_MARGIN: f64 = 1.1;
/// No rounds are made when the first brightness fit (on the support video's mean as
/// shapes) leaves more than this many times the support video's misfit: the light
/// moves. Measured: 1.04-1.75 on the LED arrays the rounds then bring to 0.84-1.01; 5.7
/// and more for LEDs merged into one region, 114 for a moving disc.
pub const SOURCES_EARLY_MISFIT: f64 = 4.0;
/// The brightness fit's ridge, relative to the largest diagonal entry of its Gram
/// matrix: a region whose shape holds (almost) no light gets no brightness from noise.
pub const RIDGE_REL: f64 = 1e-6;
/// The weight of the brightness prior ([`fit_brightness`]) relative to the Gaussian
/// one's (the data's noise variance over the source's spread over the frames the data
/// see). Swept 0 (least squares) / 0.03 / 0.1 / 0.3 / 1 / 3 on two measured-PSF dual-
/// shutter LED captures (120 x 160, 200 x 266), the worst LED's correlation over all
/// frames 0.83 / 0.98 / 0.985 / 0.98 / 0.97 / 0.96 and 0.91 / 0.955 / 0.963 / 0.964 /
/// 0.957 / 0.951; checked on four others (docs/limits.md). The full weight pulls the
/// frames the data see partly toward the mean too (a flashing LED is not Gaussian
/// about it).
pub const PRIOR_REL: f64 = 0.1;
/// Sweeps of coordinate descent at most (it stops when no step moves the objective's
/// gradient by more than 1e-9 of its largest entry at zero).
pub const SWEEPS: usize = 2000;

/// The sources of a sparse scene: regions of a [`Support`], each with its shape.
#[derive(Clone, Debug)]
pub struct Shapes {
    /// Per pixel of the video grid: 0 outside, else the region's number plus one.
    pub label: Arc<Vec<u32>>,
    /// Per pixel: the shape's value (zero outside).
    pub shape: Arc<Vec<f32>>,
}

impl Shapes {
    /// The regions of `support` split by the cores of `image` (the support video's
    /// temporal mean, `rows x cols`), with `image`'s values as shapes (negative values
    /// as zero). `None` when the image has no light on the support, or more than
    /// [`MAX_SOURCES`] regions.
    pub fn of(support: &Support, image: &[f32]) -> Option<Shapes> {
        let (rows, cols) = support.shape;
        assert_eq!(image.len(), rows * cols, "an image of the support's grid");
        let inside = |i: usize| support.keep[i] && image[i].is_finite();
        let top = (0..rows * cols).filter(|&i| inside(i)).map(|i| image[i]).fold(0.0f32, f32::max);
        if !(top > 0.0) {
            return None;
        }
        let core: Vec<bool> = (0..rows * cols).map(|i| inside(i) && image[i] > THRESHOLD_REL * top).collect();
        let neighbours = |p: usize| {
            let (r, c) = ((p / cols) as isize, (p % cols) as isize);
            (-1..=1isize)
                .flat_map(move |dr| (-1..=1isize).map(move |dc| (r + dr, c + dc)))
                .filter(move |&(q, d)| q >= 0 && d >= 0 && q < rows as isize && d < cols as isize && (q, d) != (r, c))
                .map(move |(q, d)| q as usize * cols + d as usize)
        };
        let mut label = vec![0u32; rows * cols];
        let mut regions = 0u32;
        let mut stack = Vec::new();
        for start in 0..rows * cols {
            if !core[start] || label[start] != 0 {
                continue;
            }
            regions += 1;
            label[start] = regions;
            stack.push(start);
            while let Some(p) = stack.pop() {
                for j in neighbours(p) {
                    if core[j] && label[j] == 0 {
                        label[j] = regions;
                        stack.push(j);
                    }
                }
            }
        }
        if regions as usize > MAX_SOURCES {
            return None;
        }
        // The rest of the support goes to the nearest core (breadth first, inside it).
        let mut front: VecDeque<usize> = (0..rows * cols).filter(|&i| label[i] > 0).collect();
        while let Some(p) = front.pop_front() {
            for j in neighbours(p) {
                if support.keep[j] && label[j] == 0 {
                    label[j] = label[p];
                    front.push_back(j);
                }
            }
        }
        let shape = image.iter().zip(&label).map(|(&v, &l)| if l > 0 && v.is_finite() { v.max(0.0) } else { 0.0 }).collect();
        Some(Shapes { label: Arc::new(label), shape: Arc::new(shape) })
    }

    /// Regions.
    pub fn regions(&self) -> usize {
        self.label.iter().copied().max().unwrap_or(0) as usize
    }

    /// Region `r`'s shape alone on the grid.
    fn image(&self, r: usize) -> Vec<f32> {
        self.label.iter().zip(self.shape.iter()).map(|(&l, &s)| if l as usize == r + 1 { s } else { 0.0 }).collect()
    }

    /// The video of the shapes at the brightness `a` (`a[r * frames + k]`).
    pub fn video(&self, a: &[f64], frames: usize) -> Vec<f32> {
        video_of(&self.label, &self.shape, a, frames)
    }
}

/// The video of the shapes `shape` on the regions `label` at the brightness `a`.
fn video_of(label: &[u32], shape: &[f32], a: &[f64], frames: usize) -> Vec<f32> {
    let p = label.len();
    let mut v = vec![0.0f32; frames * p];
    v.par_chunks_mut(p).enumerate().for_each(|(k, frame)| {
        for ((o, &l), &s) in frame.iter_mut().zip(label).zip(shape) {
            if l > 0 {
                *o = (a[(l as usize - 1) * frames + k] * s as f64) as f32;
            }
        }
    });
    v
}

/// Passes of the brightness fit over the clipped pixels ([`fit_brightness`]).
pub const CLIPPED_PASSES: usize = 3;

/// The sources' brightness per frame that fits the data `b` best (non-negative least
/// squares with the ridge [`RIDGE_REL`], then with the prior [`PRIOR_REL`] toward each
/// source's mean over the frames the data see), `a[r * frames + k]`: the shapes' sensor images
/// through the shutter convolution `sc`, their banded Gram matrix over each sensor row's
/// frames, and coordinate descent on it (at most `sweeps`). Pixels the mask leaves out
/// are left out of the fit. A clipped pixel (`lower`) is a lower bound, as in the data
/// term: it counts where the fit falls below it; the fit is made again with the
/// clipped pixels its prediction falls below ([`CLIPPED_PASSES`] passes at most, the
/// first with all of them).
pub fn fit_brightness(sc: &ShutterConvolution, b: &[f32], lower: Option<&[bool]>, shapes: &Shapes, sweeps: usize) -> Brightness {
    fit_brightness_with(sc, b, lower, shapes, sweeps, PRIOR_REL)
}

/// [`fit_brightness`] with the prior's weight `prior_rel` (0: least squares alone).
fn fit_brightness_with(sc: &ShutterConvolution, b: &[f32], lower: Option<&[bool]>, shapes: &Shapes, sweeps: usize, prior_rel: f64) -> Brightness {
    let (m, n) = sc.conv.sensor_shape();
    assert_eq!(b.len(), m * n, "data of the sensor's size");
    let images: Vec<Vec<f64>> = (0..shapes.regions())
        .into_par_iter()
        .map(|r| {
            let mut scratch = sc.conv.scratch();
            sc.conv.apply(&shapes.image(r), &mut scratch).iter().zip(0..m * n).map(|(&g, i)| g as f64 * sc.mask.map_or(1.0, |mk| mk[i] as f64)).collect()
        })
        .collect();
    let mut counted = vec![true; m * n];
    let mut fit = brightness_on(sc, b, &images, &counted, sweeps, prior_rel);
    let Some(lower) = lower else { return fit };
    for _ in 1..CLIPPED_PASSES {
        // The fit's sensor image: where it reaches a clipped value, that pixel says no more.
        let frames = sc.weights.frames();
        let next: Vec<bool> = (0..m * n)
            .into_par_iter()
            .map(|i| {
                if !lower[i] {
                    return true;
                }
                let row = i / n;
                let pred: f64 = (0..frames)
                    .map(|k| sc.weights.get(row, k) as f64 * images.iter().enumerate().map(|(r, g)| fit.a[r * frames + k] * g[i]).sum::<f64>())
                    .sum();
                pred < b[i] as f64
            })
            .collect();
        if next == counted {
            break;
        }
        counted = next;
        fit = brightness_on(sc, b, &images, &counted, sweeps, prior_rel);
    }
    fit
}

/// The sources' brightness per frame and how much of it the data see.
#[derive(Clone, Debug)]
pub struct Brightness {
    /// `a[r * frames + k]`: source `r`'s brightness in frame `k`.
    pub a: Vec<f64>,
    /// The same layout: the curvature of the data misfit in `a_rk` (the light of the
    /// source's sensor image in the rows that expose frame `k`, weighted by their
    /// exposure), before the ridge.
    pub light: Vec<f64>,
}

impl Brightness {
    /// The frames in which some source's light is under [`UNSEEN_REL`] of its best
    /// frame's, as runs `[first, end)`: there its brightness is not in the data.
    pub fn unseen(&self, frames: usize) -> Vec<[usize; 2]> {
        let best: Vec<f64> = self.light.chunks(frames.max(1)).map(|c| c.iter().copied().fold(0.0f64, f64::max)).collect();
        crate::solve::frames::frame_runs((0..frames).map(|k| best.iter().enumerate().any(|(r, &top)| self.light[r * frames + k] < UNSEEN_REL * top)))
    }
}

/// [`fit_brightness`] on the sensor pixels `counted`, the sources' sensor images
/// `images` (masked).
fn brightness_on(sc: &ShutterConvolution, b: &[f32], images: &[Vec<f64>], counted: &[bool], sweeps: usize, prior_rel: f64) -> Brightness {
    let (m, n) = sc.conv.sensor_shape();
    let frames = sc.weights.frames();
    let nr = images.len();
    let images: Vec<Vec<f64>> = images.iter().map(|g| g.iter().zip(counted).map(|(&v, &c)| if c { v } else { 0.0 }).collect()).collect();
    // Each sensor row's frames and weights; the band's half width.
    let row_frames: Vec<Vec<(usize, f64)>> =
        (0..m).map(|i| (0..frames).filter_map(|k| Some(sc.weights.get(i, k)).filter(|&w| w != 0.0).map(|w| (k, w as f64))).collect()).collect();
    let span = row_frames.iter().filter_map(|f| Some(f.last()?.0 - f.first()?.0)).max().unwrap_or(0);
    let band = 2 * span + 1;
    let idx = band_index(span, nr);
    let mut g = vec![0.0f64; frames * band * nr * nr];
    let mut c = vec![0.0f64; nr * frames];
    let (mut bb, mut pixels) = (0.0f64, 0.0f64);
    for (i, seen) in row_frames.iter().enumerate().filter(|(_, f)| !f.is_empty()) {
        let row = |r: usize| &images[r][i * n..(i + 1) * n];
        for j in i * n..(i + 1) * n {
            if counted[j] && sc.mask.map_or(true, |mk| mk[j] != 0.0) {
                bb += (b[j] as f64).powi(2);
                pixels += 1.0;
            }
        }
        let mut p = vec![0.0f64; nr * nr];
        for r in 0..nr {
            for s in r..nr {
                let v: f64 = row(r).iter().zip(row(s)).map(|(x, y)| x * y).sum();
                p[r * nr + s] = v;
                p[s * nr + r] = v;
            }
        }
        let q: Vec<f64> = (0..nr).map(|r| row(r).iter().zip(&b[i * n..(i + 1) * n]).map(|(x, &y)| x * y as f64).sum()).collect();
        for &(k, wk) in seen {
            for r in 0..nr {
                c[r * frames + k] += wk * q[r];
            }
            for &(k2, wk2) in seen {
                let base = idx(k, k2, 0, 0);
                for (e, &v) in g[base..base + nr * nr].iter_mut().zip(&p) {
                    *e += wk * wk2 * v;
                }
            }
        }
    }
    let light: Vec<f64> = (0..nr * frames).map(|j| g[idx(j % frames, j % frames, j / frames, j / frames)]).collect();
    let top = light.iter().copied().fold(0.0f64, f64::max);
    for k in 0..frames {
        for r in 0..nr {
            g[idx(k, k, r, r)] += RIDGE_REL * top;
        }
    }
    let mut a = vec![0.0f64; nr * frames];
    descend(&g, &c, &mut a, frames, nr, span, sweeps);
    if prior_rel > 0.0 {
        // Each source's brightness about its mean over the frames the data see, with the
        // spread it has there; the data's noise from the fit's residual.
        let residual = (bb - 2.0 * c.iter().zip(&a).map(|(x, y)| x * y).sum::<f64>() + quadratic(&g, &a, frames, nr, span)).max(0.0) / pixels.max(1.0);
        let mut changed = false;
        for r in 0..nr {
            let best = (0..frames).map(|k| light[r * frames + k]).fold(0.0f64, f64::max);
            let seen: Vec<f64> = (0..frames).filter(|&k| light[r * frames + k] >= UNSEEN_REL * best).map(|k| a[r * frames + k]).collect();
            if seen.len() < 2 {
                continue;
            }
            let mean = seen.iter().sum::<f64>() / seen.len() as f64;
            let spread = seen.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (seen.len() - 1) as f64;
            let weight = prior_rel * residual / spread;
            if !(weight.is_finite() && weight > 0.0) {
                continue;
            }
            for k in 0..frames {
                g[idx(k, k, r, r)] += weight;
                c[r * frames + k] += weight * mean;
            }
            changed = true;
        }
        if changed {
            descend(&g, &c, &mut a, frames, nr, span, sweeps);
        }
    }
    Brightness { a, light }
}

/// The index of `G[(k, r), (k2, s)]` in the banded Gram matrix of [`brightness_on`]
/// (half width `span` frames, `nr` sources): frame, offset in the band, then the pair.
fn band_index(span: usize, nr: usize) -> impl Fn(usize, usize, usize, usize) -> usize {
    let band = 2 * span + 1;
    move |k, k2, r, s| ((k * band + (k2 + span - k)) * nr + r) * nr + s
}

/// Coordinate descent on `0.5 a^T G a - c^T a`, `a >= 0`, from `a` (the banded `g` of
/// [`brightness_on`]; at most `sweeps`).
fn descend(g: &[f64], c: &[f64], a: &mut [f64], frames: usize, nr: usize, span: usize, sweeps: usize) {
    let idx = band_index(span, nr);
    let mut grad: Vec<f64> = c.iter().map(|v| -v).collect();
    for (j, &aj) in a.iter().enumerate().filter(|(_, v)| **v != 0.0) {
        let (r, k) = (j / frames, j % frames);
        for k2 in k.saturating_sub(span)..(k + span + 1).min(frames) {
            for s in 0..nr {
                grad[s * frames + k2] += g[idx(k2, k, s, r)] * aj;
            }
        }
    }
    let scale = c.iter().fold(0.0f64, |acc, v| acc.max(v.abs())).max(f64::MIN_POSITIVE);
    for _ in 0..sweeps {
        let mut biggest = 0.0f64;
        for k in 0..frames {
            for r in 0..nr {
                let d = g[idx(k, k, r, r)];
                if !(d > 0.0) {
                    continue;
                }
                let j = r * frames + k;
                let new = (a[j] - grad[j] / d).max(0.0);
                let delta = new - a[j];
                if delta == 0.0 {
                    continue;
                }
                a[j] = new;
                biggest = biggest.max((delta * d).abs());
                for k2 in k.saturating_sub(span)..(k + span + 1).min(frames) {
                    for s in 0..nr {
                        grad[s * frames + k2] += g[idx(k2, k, s, r)] * delta;
                    }
                }
            }
        }
        if biggest < 1e-9 * scale {
            break;
        }
    }
}

/// `a^T G a` on the banded matrix `g` ([`brightness_on`]'s layout).
fn quadratic(g: &[f64], a: &[f64], frames: usize, nr: usize, span: usize) -> f64 {
    let idx = band_index(span, nr);
    let mut total = 0.0;
    for k in 0..frames {
        for k2 in k.saturating_sub(span)..(k + span + 1).min(frames) {
            for r in 0..nr {
                for s in 0..nr {
                    total += a[r * frames + k] * g[idx(k, k2, r, s)] * a[s * frames + k2];
                }
            }
        }
    }
    total
}

/// The shapes that fit the data best at the brightness `a`: `iters` steps of FISTA on
/// the shapes (non-negative, zero outside their regions), from the present shapes. On
/// a shutter-weighted convolution through the sources' [`ShapeMap`] (one convolution
/// per source, its own measured Lipschitz constant); else through the video operator
/// `op` (Lipschitz constant `lipschitz`): the video is linear in the shapes with a norm
/// at most `sqrt(max_r sum_k a_rk^2)` times the shapes' (the regions are disjoint), so
/// the step is `1 / (lipschitz max_r sum_k a_rk^2)`.
pub fn refine_shapes<A: Operator + ?Sized>(op: &A, data: &DataTerm, lipschitz: f64, shapes: &Shapes, a: &[f64], iters: usize) -> Shapes {
    if let Some(sc) = op.shutter_convolution() {
        return refine_shapes_convolved(&sc, data, shapes, a, iters);
    }
    let p = shapes.label.len();
    let nr = shapes.regions();
    let frames = a.len() / nr.max(1);
    let energy = (0..nr).map(|r| a[r * frames..(r + 1) * frames].iter().map(|v| v * v).sum::<f64>()).fold(0.0f64, f64::max);
    if !(energy > 0.0 && lipschitz > 0.0) {
        return shapes.clone();
    }
    let step = 1.0 / (lipschitz * energy);
    let label = &shapes.label;
    let mut x: Vec<f32> = shapes.shape.to_vec();
    let mut y = x.clone();
    let mut t = 1.0f64;
    let (mut ax, mut resid, mut g) = (vec![0.0f32; op.output_len()], vec![0.0f32; op.output_len()], vec![0.0f32; op.input_len()]);
    for _ in 0..iters {
        op.forward(&video_of(label, &y, a, frames), &mut ax);
        data.residual_into(&ax, &mut resid);
        op.adjoint(&resid, &mut g);
        let next: Vec<f32> = (0..p)
            .into_par_iter()
            .map(|i| match label[i] as usize {
                0 => 0.0,
                l => {
                    let grad: f64 = (0..frames).map(|k| a[(l - 1) * frames + k] * g[k * p + i] as f64).sum();
                    (y[i] as f64 - step * grad).max(0.0) as f32
                }
            })
            .collect();
        fista_step(next, &mut x, &mut y, &mut t);
    }
    Shapes { label: shapes.label.clone(), shape: Arc::new(x) }
}

/// FISTA's move from the projected step `next`: `x` becomes it, `y` the non-negative
/// extrapolation past it, `t` the next momentum parameter.
fn fista_step(next: Vec<f32>, x: &mut Vec<f32>, y: &mut Vec<f32>, t: &mut f64) {
    let t1 = 0.5 * (1.0 + (1.0 + 4.0 * *t * *t).sqrt());
    let beta = ((*t - 1.0) / t1) as f32;
    *y = next.iter().zip(x.iter()).map(|(&nw, &old)| (nw + beta * (nw - old)).max(0.0)).collect();
    *x = next;
    *t = t1;
}

/// The sources' sensor images at the brightness `a` as one map of the shapes: source `r`
/// lit in frame `k` is `w_ik a_rk crop(h * m_r)` in sensor row `i`, so the video's
/// image is `sum_r G_r . crop(h * m_r)` with the row gain `G_r(i) = sum_k w_ik a_rk`
/// (times the mask): one convolution per source instead of one per frame.
struct ShapeMap<'a> {
    sc: &'a ShutterConvolution<'a>,
    label: &'a [u32],
    /// Per source, per sensor pixel: the row gain times the mask.
    gain: Vec<Vec<f32>>,
}

impl<'a> ShapeMap<'a> {
    fn new(sc: &'a ShutterConvolution<'a>, label: &'a [u32], regions: usize, a: &[f64]) -> ShapeMap<'a> {
        let (m, n) = sc.conv.sensor_shape();
        let frames = sc.weights.frames();
        let gain = (0..regions)
            .into_par_iter()
            .map(|r| {
                let rows: Vec<f64> = (0..m).map(|i| (0..frames).map(|k| a[r * frames + k] * sc.weights.get(i, k) as f64).sum()).collect();
                (0..m * n).map(|j| (rows[j / n] * sc.mask.map_or(1.0, |mk| mk[j] as f64)) as f32).collect()
            })
            .collect();
        ShapeMap { sc, label, gain }
    }

    fn forward(&self, x: &[f32], y: &mut [f32]) {
        let images: Vec<Vec<f32>> = (0..self.gain.len())
            .into_par_iter()
            .map(|r| {
                let one: Vec<f32> = x.iter().zip(self.label).map(|(&v, &l)| if l as usize == r + 1 { v } else { 0.0 }).collect();
                let mut scratch = self.sc.conv.scratch();
                let mut out = self.sc.conv.apply(&one, &mut scratch);
                for (o, &g) in out.iter_mut().zip(&self.gain[r]) {
                    *o *= g;
                }
                out
            })
            .collect();
        y.par_iter_mut().enumerate().for_each(|(j, o)| *o = images.iter().map(|im| im[j]).sum());
    }

    fn adjoint(&self, y: &[f32], x: &mut [f32]) {
        let (m, n) = self.sc.conv.sensor_shape();
        let parts: Vec<Vec<f32>> = (0..self.gain.len())
            .into_par_iter()
            .map(|r| {
                let mut scratch = self.sc.conv.scratch();
                let mut out = vec![0.0f32; self.label.len()];
                let gain = &self.gain[r];
                self.sc.conv.adjoint_rows(
                    std::slice::from_ref(&(0..m)),
                    &mut scratch,
                    |i, row| {
                        for ((o, &v), &g) in row.iter_mut().zip(&y[i * n..(i + 1) * n]).zip(&gain[i * n..(i + 1) * n]) {
                            *o = v * g;
                        }
                    },
                    &mut out,
                );
                out
            })
            .collect();
        x.par_iter_mut().zip(self.label.par_iter()).enumerate().for_each(|(i, (o, &l))| *o = if l > 0 { parts[l as usize - 1][i] } else { 0.0 });
    }

    /// `lambda_max` of the map's normal operator on the regions, by power iteration
    /// from `start` (non-negative: the top eigenvector of a non-negative map's normal
    /// operator is near it).
    fn lipschitz(&self, start: &[f32], iters: usize, out_len: usize) -> f64 {
        let norm = |v: &[f32]| v.iter().map(|&x| x as f64 * x as f64).sum::<f64>().sqrt();
        let mut x: Vec<f32> = start.iter().zip(self.label).map(|(&v, &l)| if l > 0 { v.max(0.0) + 1e-3 } else { 0.0 }).collect();
        let (mut y, mut z) = (vec![0.0f32; out_len], vec![0.0f32; x.len()]);
        let mut lambda = 0.0;
        for _ in 0..iters {
            let nx = norm(&x);
            if !(nx > 0.0) {
                return 0.0;
            }
            x.iter_mut().for_each(|v| *v = (*v as f64 / nx) as f32);
            self.forward(&x, &mut y);
            self.adjoint(&y, &mut z);
            lambda = norm(&z);
            std::mem::swap(&mut x, &mut z);
        }
        lambda
    }
}

/// [`refine_shapes`] through the [`ShapeMap`] of a shutter-weighted convolution: the
/// same problem at one convolution per source, its step from the map's own measured
/// Lipschitz constant.
fn refine_shapes_convolved(sc: &ShutterConvolution, data: &DataTerm, shapes: &Shapes, a: &[f64], iters: usize) -> Shapes {
    let nr = shapes.regions();
    let map = ShapeMap::new(sc, &shapes.label, nr, a);
    let (m, n) = sc.conv.sensor_shape();
    let lipschitz = map.lipschitz(&shapes.shape, SHAPE_POWER_ITERS, m * n) * SHAPE_LIPSCHITZ_MARGIN;
    if !(lipschitz > 0.0 && lipschitz.is_finite()) {
        return shapes.clone();
    }
    let step = (1.0 / lipschitz) as f32;
    let label = &shapes.label;
    let mut x: Vec<f32> = shapes.shape.to_vec();
    let mut y = x.clone();
    let mut t = 1.0f64;
    let (mut ax, mut resid, mut g) = (vec![0.0f32; m * n], vec![0.0f32; m * n], vec![0.0f32; label.len()]);
    for _ in 0..iters {
        map.forward(&y, &mut ax);
        data.residual_into(&ax, &mut resid);
        map.adjoint(&resid, &mut g);
        let next: Vec<f32> =
            y.par_iter().zip(g.par_iter()).zip(label.par_iter()).map(|((&v, &d), &l)| if l > 0 { (v - step * d).max(0.0) } else { 0.0 }).collect();
        fista_step(next, &mut x, &mut y, &mut t);
    }
    Shapes { label: shapes.label.clone(), shape: Arc::new(x) }
}

/// The sources' fit of a support video: its video and report. `None` when the video's
/// temporal mean gives no sources ([`Shapes::of`]).
pub struct SourcesFit {
    pub video: Vec<f32>,
    pub regions: usize,
    /// Rounds of shapes and brightness made (0: the first fit was far off).
    pub rounds: usize,
    /// Data misfit (the data term) of the sources' video.
    pub misfit: f64,
    /// Frames where some source is not seen ([`Brightness::unseen`]).
    pub unseen: Vec<[usize; 2]>,
    pub frames: usize,
    pub seconds: f64,
}

/// Fit the sources of `video` (`frames` frames of `support`'s grid, solved on it, with
/// the data misfit `on_support`) to the data: regions and shapes from its temporal
/// mean, then the brightness and [`SOURCE_ROUNDS`] rounds of shapes and brightness
/// (none when the first fit leaves more than [`SOURCES_EARLY_MISFIT`] times
/// `on_support`).
pub fn fit_sources<A: Operator + ?Sized>(
    op: &A,
    data: &DataTerm,
    lipschitz: f64,
    (support, video, on_support): (&Support, &[f32], f64),
    frames: usize,
) -> Option<SourcesFit> {
    let t0 = std::time::Instant::now();
    let sc = op.shutter_convolution()?;
    let mean: Vec<f32> = crate::solve::trace::temporal_mean(video, frames).iter().map(|&m| m as f32).collect();
    let mut shapes = Shapes::of(support, &mean)?;
    let (b, lower) = (data.observations(), data.lower_bounds());
    let mut ax = vec![0.0f32; op.output_len()];
    let mut misfit_of = |video: &[f32]| {
        op.forward(video, &mut ax);
        data.value(&ax)
    };
    let mut fit = fit_brightness(&sc, b, lower, &shapes, SWEEPS);
    let mut video = shapes.video(&fit.a, frames);
    let mut misfit = misfit_of(&video);
    let rounds = if misfit <= SOURCES_EARLY_MISFIT * on_support { SOURCE_ROUNDS } else { 0 };
    for _ in 0..rounds {
        shapes = refine_shapes(op, data, lipschitz, &shapes, &fit.a, SHAPE_ITERS);
        fit = fit_brightness(&sc, b, lower, &shapes, SWEEPS);
    }
    if rounds > 0 {
        video = shapes.video(&fit.a, frames);
        misfit = misfit_of(&video);
    }
    Some(SourcesFit { video, regions: shapes.regions(), rounds, misfit, unseen: fit.unseen(frames), frames, seconds: t0.elapsed().as_secs_f64() })
}

impl SourcesFit {
    /// The report of this fit against a support video of misfit `on_support`.
    pub fn report(&self, on_support: f64) -> SourcesReport {
        SourcesReport {
            unseen_frames: self.unseen.clone(),
            frames: self.frames,
            ..SourcesReport::new(self.regions, self.rounds, (self.misfit, on_support), self.seconds)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::capture::Fov;
    use crate::model::op::pseudo_random;
    use crate::model::rolling::RollingShutterModel;
    use crate::model::shutter::{ShutterMode, Timing};

    /// Two sources side by side, closer than the support's margin (one support region,
    /// two cores), in the grid's middle rows: every sensor row sees them through the
    /// PSF, so every frame's brightness is in the data.
    fn two_sources(rows: usize, cols: usize) -> (Support, Vec<f32>) {
        let mut img = vec![0.0f32; rows * cols];
        for (r, c, v) in [(11, 12, 2.0), (11, 13, 1.0), (12, 12, 1.5), (11, 17, 3.0), (12, 17, 1.0)] {
            img[r * cols + c] = v;
        }
        (Support::from_still(&[&img], (rows, cols)).expect("sparse"), img)
    }

    /// A rolling shutter through a PSF whose light lies in rows 4-7: each source's
    /// sensor image is a band of rows, and the frames exposed by the other rows miss it.
    fn band_model(rows: usize, cols: usize) -> RollingShutterModel {
        let psf: Vec<f32> =
            pseudo_random(rows * cols, 9).iter().enumerate().map(|(i, &v)| if (4..8).contains(&(i / cols)) && v > 0.5 { v } else { 0.0 }).collect();
        let weights = Timing::new(rows, 10.0, 30.0, ShutterMode::Rolling).weights().unwrap();
        RollingShutterModel::of_psf(&psf, rows, cols, Fov::Sensor, weights)
    }

    #[test]
    fn the_support_is_split_at_its_cores_and_every_pixel_of_it_goes_to_one_source() {
        let (rows, cols) = (24, 32);
        let (support, img) = two_sources(rows, cols);
        let shapes = Shapes::of(&support, &img).expect("light on the support");
        assert_eq!(shapes.regions(), 2);
        assert_ne!(shapes.label[11 * cols + 12], shapes.label[11 * cols + 17]);
        // Every support pixel has a source, none outside; the shape is the image's.
        for (i, &v) in img.iter().enumerate() {
            assert_eq!(shapes.label[i] > 0, support.keep[i], "pixel {i}");
            assert_eq!(shapes.shape[i], if support.keep[i] { v } else { 0.0 });
        }
        // The pixel between them goes to the nearer core.
        assert_eq!(shapes.label[11 * cols + 14], shapes.label[11 * cols + 13]);
        assert_eq!(shapes.label[11 * cols + 16], shapes.label[11 * cols + 17]);
        assert!(Shapes::of(&support, &vec![0.0; rows * cols]).is_none(), "no light");
    }

    #[test]
    fn the_brightness_of_known_shapes_is_recovered_from_noise_free_data_in_every_shutter_mode() {
        let (rows, cols) = (24, 32);
        let (support, img) = two_sources(rows, cols);
        let shapes = Shapes::of(&support, &img).unwrap();
        for mode in [ShutterMode::Rolling, ShutterMode::Dual] {
            let weights = Timing::new(rows, 10.0, 30.0, mode).weights().unwrap();
            // A caustic-like PSF: sparse bright points (a smooth one makes the two
            // sources' images nearly alike).
            let psf: Vec<f32> = pseudo_random(rows * cols, 5).iter().map(|&v| if v > 0.6 { v } else { 0.0 }).collect();
            let model = RollingShutterModel::of_psf(&psf, rows, cols, Fov::Sensor, weights);
            let frames = model.video_shape().0;
            // Flashing: each source on and off with its own period; a dim frame too.
            let a: Vec<f64> = (0..2 * frames).map(|j| if (j % frames) / (2 + j / frames) % 2 == 0 { 1.0 + 0.1 * (j % 3) as f64 } else { 0.0 }).collect();
            let mut b = vec![0.0f32; model.output_len()];
            model.forward(&shapes.video(&a, frames), &mut b);
            let got = fit_brightness(&model.shutter_convolution().unwrap(), &b, None, &shapes, SWEEPS).a;
            let rel = |got: &[f64]| got.iter().zip(&a).map(|(g, w)| (g - w).powi(2)).sum::<f64>().sqrt() / a.iter().map(|w| w * w).sum::<f64>().sqrt();
            let err = rel(&got);
            assert!(err < 1e-3, "{mode:?}: brightness error {err}");
            // The brightest tenth of the pixels clipped: as lower bounds they still
            // give the brightness; taken as exact values they do not.
            let mut sorted = b.clone();
            sorted.sort_by(f32::total_cmp);
            let level = sorted[sorted.len() * 9 / 10];
            let clipped: Vec<f32> = b.iter().map(|&v| v.min(level)).collect();
            let lower: Vec<bool> = b.iter().map(|&v| v >= level).collect();
            let sc = model.shutter_convolution().unwrap();
            let (bounded, exact) =
                (rel(&fit_brightness(&sc, &clipped, Some(&lower), &shapes, SWEEPS).a), rel(&fit_brightness(&sc, &clipped, None, &shapes, SWEEPS).a));
            assert!(bounded < 0.02 && bounded < exact, "{mode:?}: clipped as lower bounds {bounded}, as values {exact}");
            // The fit of the sources from a video that holds them: the data fitted.
            let data = DataTerm::new(&b);
            let l = crate::solve::lipschitz::power_iteration(&model, 200, 1e-7, 1).lambda_max * 1.05;
            let fit = fit_sources(&model, &data, l, (&support, &shapes.video(&a, frames), 1.0), frames).unwrap();
            assert_eq!((fit.regions, fit.rounds), (2, SOURCE_ROUNDS));
            assert!(fit.misfit < 1e-6 * data.value(&vec![0.0; b.len()]), "{mode:?}: misfit {}", fit.misfit);
        }
    }

    #[test]
    fn frames_whose_rows_miss_a_source_are_reported_unseen() {
        let (rows, cols) = (24, 32);
        let (support, img) = two_sources(rows, cols);
        let shapes = Shapes::of(&support, &img).unwrap();
        // A PSF whose light lies in a few rows: each source's sensor image is a band of
        // rows, and the rolling shutter's frames exposed by the other rows miss it.
        let model = band_model(rows, cols);
        let frames = model.video_shape().0;
        let a: Vec<f64> = (0..2 * frames).map(|j| 1.0 + ((j * 7) % 5) as f64).collect();
        let mut b = vec![0.0f32; model.output_len()];
        model.forward(&shapes.video(&a, frames), &mut b);
        let fit = fit_brightness(&model.shutter_convolution().unwrap(), &b, None, &shapes, SWEEPS);
        // The light of a source in a frame is the energy of its sensor image lit in that
        // frame alone.
        let mut lit = vec![0.0f32; model.output_len()];
        let top = fit.light.iter().copied().fold(0.0f64, f64::max);
        for r in 0..2 {
            for k in 0..frames {
                let one: Vec<f64> = (0..2 * frames).map(|j| if j == r * frames + k { 1.0 } else { 0.0 }).collect();
                model.forward(&shapes.video(&one, frames), &mut lit);
                let energy: f64 = lit.iter().map(|&v| v as f64 * v as f64).sum();
                let got = fit.light[r * frames + k];
                assert!((got - energy).abs() <= 1e-4 * energy + 1e-9 * top, "source {r} frame {k}: {got} vs {energy}");
            }
        }
        let unseen = fit.unseen(frames);
        let flagged = |k: usize| unseen.iter().any(|&[s, e]| (s..e).contains(&k));
        let count = (0..frames).filter(|&k| flagged(k)).count();
        assert!(count > 0 && count < frames, "some frames unseen, not all: {unseen:?}");
        for k in 0..frames {
            let best = |r: usize| (0..frames).map(|f| fit.light[r * frames + f]).fold(0.0f64, f64::max);
            let weak = (0..2).any(|r| fit.light[r * frames + k] < UNSEEN_REL * best(r));
            assert_eq!(flagged(k), weak, "frame {k}");
        }
    }

    #[test]
    fn the_frames_the_data_barely_see_go_to_the_sources_mean_and_the_others_keep_their_fit() {
        let (rows, cols) = (24, 32);
        let (support, img) = two_sources(rows, cols);
        let shapes = Shapes::of(&support, &img).unwrap();
        // The band PSF of the test above: the frames whose rows miss it are unseen.
        let model = band_model(rows, cols);
        let sc = model.shutter_convolution().unwrap();
        let frames = model.video_shape().0;
        // Flashing between 0.5 and 1.5; noise of 2% of the data's largest value.
        let a: Vec<f64> = (0..2 * frames).map(|j| if (j % frames) / (2 + j / frames) % 2 == 0 { 1.5 } else { 0.5 }).collect();
        let mut b = vec![0.0f32; model.output_len()];
        model.forward(&shapes.video(&a, frames), &mut b);
        let peak = b.iter().copied().fold(0.0f32, f32::max);
        for (v, n) in b.iter_mut().zip(pseudo_random(rows * cols, 4)) {
            *v += 0.02 * peak * (2.0 * n - 1.0) * 3f32.sqrt();
        }
        let plain = fit_brightness_with(&sc, &b, None, &shapes, SWEEPS, 0.0);
        let fit = fit_brightness(&sc, &b, None, &shapes, SWEEPS);
        assert_eq!(plain.light, fit.light, "the light is the data's, before any prior");
        let best = |r: usize| (0..frames).map(|k| fit.light[r * frames + k]).fold(0.0f64, f64::max);
        let (mut unseen, mut seen) = (Vec::new(), Vec::new());
        for j in 0..2 * frames {
            (if fit.light[j] < UNSEEN_REL * best(j / frames) { &mut unseen } else { &mut seen }).push(j);
        }
        assert!(unseen.len() >= 4 && seen.len() >= 4, "unseen {} seen {}", unseen.len(), seen.len());
        let rms = |got: &[f64], at: &[usize]| (at.iter().map(|&j| (got[j] - a[j]).powi(2)).sum::<f64>() / at.len() as f64).sqrt();
        let (before, after) = (rms(&plain.a, &unseen), rms(&fit.a, &unseen));
        // The mean's error is the flashing's half swing (0.5); least squares there is
        // noise.
        assert!(after < 0.7 * before && after < 0.7, "unseen frames: rms error {after} with the prior, {before} without");
        let (before, after) = (rms(&plain.a, &seen), rms(&fit.a, &seen));
        assert!(after <= 1.1 * before + 0.01, "seen frames: rms error {after} with the prior, {before} without");
        // Where the data hold (almost) none of it, the brightness is its source's mean over
        // the seen frames.
        let dark: Vec<usize> = unseen.iter().copied().filter(|&j| fit.light[j] < 1e-3 * best(j / frames)).collect();
        assert!(!dark.is_empty(), "some frames dark to a source");
        for &j in &dark {
            let r = j / frames;
            let at: Vec<f64> = seen.iter().filter(|&&i| i / frames == r).map(|&i| fit.a[i]).collect();
            let mean = at.iter().sum::<f64>() / at.len() as f64;
            assert!((fit.a[j] - mean).abs() < 0.05, "source {r} frame {}: {} against the mean {mean}", j % frames, fit.a[j]);
        }
        assert!(fit.a.iter().all(|v| v.is_finite() && *v >= 0.0));
    }

    #[test]
    fn the_shape_map_is_the_video_operator_on_the_sources_and_its_adjoint_and_it_refits_shapes() {
        let (rows, cols) = (24, 32);
        let (support, img) = two_sources(rows, cols);
        let shapes = Shapes::of(&support, &img).unwrap();
        let weights = Timing::new(rows, 10.0, 30.0, ShutterMode::Dual).weights().unwrap();
        let psf: Vec<f32> = pseudo_random(rows * cols, 5).iter().map(|&v| if v > 0.6 { v } else { 0.0 }).collect();
        let model = RollingShutterModel::of_psf(&psf, rows, cols, Fov::Sensor, weights);
        let sc = model.shutter_convolution().unwrap();
        let frames = model.video_shape().0;
        let a: Vec<f64> = (0..2 * frames).map(|j| 0.5 + ((j * 5) % 7) as f64 / 4.0).collect();
        let map = ShapeMap::new(&sc, &shapes.label, 2, &a);
        // Forward: the video operator on the shapes' video.
        let (mut want, mut got) = (vec![0.0f32; model.output_len()], vec![0.0f32; model.output_len()]);
        model.forward(&shapes.video(&a, frames), &mut want);
        map.forward(&shapes.shape, &mut got);
        let norm = want.iter().map(|&v| v as f64 * v as f64).sum::<f64>().sqrt();
        let diff = want.iter().zip(&got).map(|(&x, &y)| (x as f64 - y as f64).powi(2)).sum::<f64>().sqrt();
        assert!(diff < 1e-5 * norm, "forward: {diff} of {norm}");
        // Adjoint: <F x, y> = <x, F^T y> for shapes on the regions.
        let x: Vec<f32> = pseudo_random(rows * cols, 7).iter().zip(shapes.label.iter()).map(|(&v, &l)| if l > 0 { v } else { 0.0 }).collect();
        let y = pseudo_random(model.output_len(), 8);
        let (mut fx, mut fty) = (vec![0.0f32; model.output_len()], vec![0.0f32; rows * cols]);
        map.forward(&x, &mut fx);
        map.adjoint(&y, &mut fty);
        let (lhs, rhs): (f64, f64) =
            (fx.iter().zip(&y).map(|(&p, &q)| p as f64 * q as f64).sum(), x.iter().zip(&fty).map(|(&p, &q)| p as f64 * q as f64).sum());
        assert!((lhs - rhs).abs() < 1e-5 * lhs.abs().max(rhs.abs()), "adjoint: {lhs} vs {rhs}");
        assert!(fty.iter().zip(shapes.label.iter()).all(|(&v, &l)| l > 0 || v == 0.0), "nothing outside the regions");
        // Its Lipschitz constant bounds the map on random shapes.
        let l = map.lipschitz(&shapes.shape, SHAPE_POWER_ITERS, model.output_len());
        let gain = fx.iter().map(|&v| v as f64 * v as f64).sum::<f64>() / x.iter().map(|&v| v as f64 * v as f64).sum::<f64>();
        assert!(l >= gain * 0.999, "lambda {l} under a Rayleigh quotient {gain}");
        // From flat shapes, noise-free data of the true ones: the misfit falls far.
        let data = DataTerm::new(&want);
        let flat = Shapes { label: shapes.label.clone(), shape: Arc::new(shapes.label.iter().map(|&l| if l > 0 { 1.0 } else { 0.0 }).collect()) };
        let misfit = |s: &Shapes| {
            let mut ax = vec![0.0f32; model.output_len()];
            model.forward(&s.video(&a, frames), &mut ax);
            data.value(&ax)
        };
        let fitted = refine_shapes(&model, &data, 0.0, &flat, &a, SHAPE_ITERS);
        assert!(misfit(&fitted) < 1e-3 * misfit(&flat), "misfit {} from {}", misfit(&fitted), misfit(&flat));
        assert!(fitted.shape.iter().all(|v| v.is_finite() && *v >= 0.0));
    }
}
