//! Metrics of a dense scene's video: a moving object over a static background (the
//! `disc-over-texture` benchmark of `rollcam simulate`), judged against the truth.
//!
//! A video here is one channel, `frames x rows x cols` (`f32`), on one pixel grid with
//! its truth. The static part of a video is estimated by the per-pixel temporal median
//! ([`static_estimate`]); it is judged by its Pearson correlation with the truth's
//! ([`correlation`]). The moving object is located in each frame by the centroid of
//! the frame's excess over a static image near the excess's maximum, or of its deficit
//! for an object darker than what it covers ([`object_track`], [`Contrast`]); [`track_errors`] compares the tracks of a video and of its truth
//! over the middle 70% of the frames (the first and last frames of a reconstruction
//! are the least constrained).
//!
//! Positions are `(row, col)` in continuous pixel coordinates of the video's grid:
//! pixel `(i, j)` covers `[i, i+1) x [j, j+1)`, its centre is `(i + 0.5, j + 0.5)`, as
//! for the simulator's scenes (`crate::sim::scene`); on a grid downsampled by `d` a
//! raw position is `d` times it. Data stay `f32`; sums are accumulated in `f64`.

use ndarray::{Array2, ArrayView2, ArrayView3, Axis};
use rayon::prelude::*;
use serde::Serialize;

/// The per-pixel temporal median of `video` (`frames x rows x cols`): its static
/// image (`rows x cols`), where a moving object covers each pixel in fewer than half
/// the frames. With an even number of frames the median is the mean of the two middle
/// values. Non-finite values are left out; a pixel with no finite value (or a video of
/// no frames) gets 0.
pub fn static_estimate(video: ArrayView3<f32>) -> Array2<f32> {
    let (k, rows, cols) = video.dim();
    let values: Vec<f32> = (0..rows * cols)
        .into_par_iter()
        .map_init(
            || Vec::with_capacity(k),
            |buf, p| {
                buf.clear();
                buf.extend(video.slice(ndarray::s![.., p / cols, p % cols]).iter().cloned().filter(|v| v.is_finite()));
                median_f32(buf)
            },
        )
        .collect();
    Array2::from_shape_vec((rows, cols), values).expect("rows x cols")
}

/// Median of `v` (reordered in place): the mean of the two middle values for an even
/// count, 0 for none.
fn median_f32(v: &mut [f32]) -> f32 {
    let n = v.len();
    if n == 0 {
        return 0.0;
    }
    let (_, &mut hi, _) = v.select_nth_unstable_by(n / 2, |a, b| a.total_cmp(b));
    if n % 2 == 1 {
        return hi;
    }
    let lo = v[..n / 2].iter().cloned().fold(f32::NEG_INFINITY, f32::max);
    ((lo as f64 + hi as f64) / 2.0) as f32
}

/// The object's position in each frame of `video` (`frames x rows x cols`) over the
/// static image `background` (`rows x cols`): the intensity-weighted centroid of the
/// positive part of `c (frame - background)` (`c` 1 for a [`Contrast::Brighter`]
/// object, -1 for a darker one) over the pixels within `window_radius_px` (a
/// disc, Euclidean distance between pixel centres) of the maximum of
/// `frame - background` after a 3 x 3 box smoothing (the mean of the neighbours inside
/// the frame; it keeps a single noisy pixel from taking the window). `(row, col)` in
/// continuous pixel coordinates (see the module documentation); `None` for a frame
/// with no positive (finite) excess in the window. Non-finite pixels are left out.
///
/// Panics if `background` is not `rows x cols`.
pub fn object_track(video: ArrayView3<f32>, background: ArrayView2<f32>, window_radius_px: f64, contrast: Contrast) -> Vec<Option<(f64, f64)>> {
    let (_, rows, cols) = video.dim();
    assert_eq!(background.dim(), (rows, cols), "the background must be rows x cols of the video");
    let r = window_radius_px.max(0.0);
    video.axis_iter(Axis(0)).into_par_iter().map(|frame| frame_position(frame, background, r, contrast.sign())).collect()
}

/// [`object_track`] of one frame.
fn frame_position(frame: ArrayView2<f32>, background: ArrayView2<f32>, radius: f64, sign: f64) -> Option<(f64, f64)> {
    let (rows, cols) = frame.dim();
    let excess = Array2::from_shape_fn((rows, cols), |(i, j)| {
        let d = sign * (frame[[i, j]] as f64 - background[[i, j]] as f64);
        if d.is_finite() {
            d
        } else {
            f64::NAN
        }
    });
    if !excess.iter().any(|&d| d > 0.0) {
        return None;
    }
    // The maximum of the 3 x 3 box-smoothed excess.
    let mut peak: Option<(usize, usize, f64)> = None;
    for i in 0..rows {
        for j in 0..cols {
            let (mut s, mut n) = (0.0, 0usize);
            for y in i.saturating_sub(1)..(i + 2).min(rows) {
                for x in j.saturating_sub(1)..(j + 2).min(cols) {
                    let d = excess[[y, x]];
                    if d.is_finite() {
                        s += d;
                        n += 1;
                    }
                }
            }
            if n > 0 {
                let m = s / n as f64;
                if peak.map_or(true, |(_, _, best)| m > best) {
                    peak = Some((i, j, m));
                }
            }
        }
    }
    let (pi, pj, _) = peak?;
    let reach = radius.floor() as usize;
    let (mut w, mut wr, mut wc) = (0.0, 0.0, 0.0);
    for i in pi.saturating_sub(reach)..(pi + reach + 1).min(rows) {
        for j in pj.saturating_sub(reach)..(pj + reach + 1).min(cols) {
            let (dy, dx) = (i as f64 - pi as f64, j as f64 - pj as f64);
            let d = excess[[i, j]];
            if dy * dy + dx * dx <= radius * radius && d > 0.0 {
                w += d;
                wr += d * (i as f64 + 0.5);
                wc += d * (j as f64 + 0.5);
            }
        }
    }
    (w > 0.0).then(|| (wr / w, wc / w))
}

/// The frames judged of a video of `frames` frames: the middle 70%,
/// `floor(0.15 frames)..ceil(0.85 frames)` (end exclusive).
pub fn judged_frames(frames: usize) -> std::ops::Range<usize> {
    (15 * frames / 100)..(85 * frames).div_ceil(100)
}

/// How well a video tracks the truth's moving object ([`track_errors`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TrackReport {
    /// Radius of the centroid window, pixels.
    pub window_radius_px: f64,
    /// The truth's object is brighter or darker than what it covers ([`Contrast::of`]);
    /// both tracks follow that sign.
    pub contrast: Contrast,
    /// Frames of the video.
    pub frames: usize,
    /// First frame judged ([`judged_frames`]).
    pub first_frame: usize,
    /// One past the last frame judged.
    pub end_frame: usize,
    /// Distance between the video's and the truth's object positions, pixels, for
    /// frames `first_frame..end_frame` (entry `k` is frame `first_frame + k`); `None`
    /// where either has no position.
    pub per_frame: Vec<Option<f64>>,
    /// The video's object positions over the judged frames, `(row, col)` pixels.
    pub estimate_px: Vec<Option<(f64, f64)>>,
    /// The truth's object positions over the judged frames, `(row, col)` pixels.
    pub truth_px: Vec<Option<(f64, f64)>>,
    /// Median of the distances of the frames used, pixels (`None` if none).
    pub median_px: Option<f64>,
    /// 90th percentile (linear interpolation) of the distances, pixels (`None` if none).
    pub p90_px: Option<f64>,
    /// 90th percentile with the lost frames counted as misses (an infinite distance):
    /// `None` when it falls on a lost frame. The figure to quote: a tracker that loses
    /// the object is not better for it.
    pub p90_px_with_lost: Option<f64>,
    /// Judged frames where both have a position (those with a distance).
    pub frames_used: usize,
    /// Judged frames where the truth has a position and the video none.
    pub frames_lost: usize,
    /// Judged frames where the truth has no position (left out).
    pub frames_without_truth: usize,
}

/// The object track of `video` over its static image `background_est` (e.g.
/// [`static_estimate`] of the video) against that of `truth` over `background_truth`
/// (the truth's own static image: [`static_estimate`] of the truth), both by
/// [`object_track`] with `window_radius_px` and the truth's [`Contrast`], over the middle 70% of the frames
/// ([`judged_frames`]).
///
/// Panics if `video` and `truth` differ in shape or a background is not their
/// `rows x cols`.
pub fn track_errors(
    video: ArrayView3<f32>,
    truth: ArrayView3<f32>,
    background_est: ArrayView2<f32>,
    background_truth: ArrayView2<f32>,
    window_radius_px: f64,
) -> TrackReport {
    assert_eq!(video.dim(), truth.dim(), "the video and the truth must have the same frames x rows x cols");
    let frames = video.dim().0;
    let range = judged_frames(frames);
    let judged = ndarray::s![range.clone(), .., ..];
    let contrast = Contrast::of(truth.slice(judged), background_truth);
    let estimate_px = object_track(video.slice_move(judged), background_est, window_radius_px, contrast);
    let truth_px = object_track(truth.slice_move(judged), background_truth, window_radius_px, contrast);
    let per_frame: Vec<Option<f64>> = estimate_px
        .iter()
        .zip(&truth_px)
        .map(|(e, t)| match (e, t) {
            (Some(e), Some(t)) => Some((e.0 - t.0).hypot(e.1 - t.1)),
            _ => None,
        })
        .collect();
    let mut used: Vec<f64> = per_frame.iter().flatten().cloned().collect();
    used.sort_by(|a, b| a.total_cmp(b));
    let lost = estimate_px.iter().zip(&truth_px).filter(|(e, t)| e.is_none() && t.is_some()).count();
    // The lost frames as misses: an infinite distance, after every found one.
    let mut with_lost = used.clone();
    with_lost.extend(std::iter::repeat(f64::INFINITY).take(lost));
    TrackReport {
        window_radius_px,
        contrast,
        frames,
        first_frame: range.start,
        end_frame: range.end,
        median_px: quantile_sorted(&used, 0.5),
        p90_px: quantile_sorted(&used, 0.9),
        p90_px_with_lost: quantile_sorted(&with_lost, 0.9).filter(|v| v.is_finite()),
        frames_used: used.len(),
        frames_lost: lost,
        frames_without_truth: truth_px.iter().filter(|t| t.is_none()).count(),
        per_frame,
        estimate_px,
        truth_px,
    }
}

/// `q`-quantile of sorted values by linear interpolation between order statistics
/// (position `q (n - 1)`); `None` for no values.
fn quantile_sorted(v: &[f64], q: f64) -> Option<f64> {
    let n = v.len();
    if n == 0 {
        return None;
    }
    let pos = q.clamp(0.0, 1.0) * (n - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, (pos.ceil() as usize).min(n - 1));
    Some(v[lo] + (v[hi] - v[lo]) * (pos - lo as f64))
}

/// Whether the moving object is brighter or darker than what it covers: which sign of
/// `frame - background` the tracker follows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Contrast {
    Brighter,
    Darker,
}

impl Contrast {
    fn sign(self) -> f64 {
        match self {
            Contrast::Brighter => 1.0,
            Contrast::Darker => -1.0,
        }
    }

    /// The contrast of the truth's moving object: darker when the light missing from
    /// `truth` below its static image `background` outweighs the light above it.
    pub fn of(truth: ArrayView3<f32>, background: ArrayView2<f32>) -> Contrast {
        let (mut above, mut below) = (0.0f64, 0.0f64);
        for frame in truth.axis_iter(Axis(0)) {
            for (&v, &b) in frame.iter().zip(background.iter()) {
                let d = v as f64 - b as f64;
                if d > 0.0 {
                    above += d;
                } else if d < 0.0 {
                    below -= d;
                }
            }
        }
        if below > above {
            Contrast::Darker
        } else {
            Contrast::Brighter
        }
    }
}

/// Pearson correlation of two images of the same shape (e.g. a static estimate and
/// the truth's static image), accumulated in `f64`; pixels where either is not finite
/// are left out; 0 when either is constant (or there are no pixels).
///
/// Panics if the shapes differ.
pub fn correlation(a: ArrayView2<f32>, b: ArrayView2<f32>) -> f64 {
    assert_eq!(a.dim(), b.dim(), "images must have the same shape");
    let (x, y): (Vec<f64>, Vec<f64>) = a.iter().zip(b.iter()).filter(|(x, y)| x.is_finite() && y.is_finite()).map(|(&x, &y)| (x as f64, y as f64)).unzip();
    super::course::correlation(&x, &y).clamp(-1.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;

    const K: usize = 24;
    const ROWS: usize = 40;
    const COLS: usize = 56;
    const SIDE: f64 = 5.0;
    const SQUARE: f32 = 12.0;

    fn texture() -> Array2<f32> {
        Array2::from_shape_fn((ROWS, COLS), |(i, j)| {
            1.0 + 0.5 * (((i * 7 + j * 13) % 11) as f32 / 10.0) + 0.3 * ((i as f32 * 0.4).sin() * (j as f32 * 0.3).cos())
        })
    }

    /// Centre of the square in frame `f`, (row, col) pixels.
    fn centre(f: usize) -> (f64, f64) {
        (12.3 + 0.6 * f as f64, 10.7 + 1.3 * f as f64)
    }

    /// Overlap of `[a, b)` with pixel `[i, i+1)`.
    fn overlap(i: usize, a: f64, b: f64) -> f64 {
        ((i as f64 + 1.0).min(b) - (i as f64).max(a)).max(0.0)
    }

    /// A square of radiance `SQUARE` (anti-aliased by its exact area coverage) moving
    /// over the texture and occluding it.
    fn video() -> Array3<f32> {
        let tex = texture();
        Array3::from_shape_fn((K, ROWS, COLS), |(f, i, j)| {
            let (cr, cc) = centre(f);
            let h = SIDE / 2.0;
            let cov = overlap(i, cr - h, cr + h) * overlap(j, cc - h, cc + h);
            (tex[[i, j]] as f64 * (1.0 - cov) + SQUARE as f64 * cov) as f32
        })
    }

    #[test]
    fn static_estimate_is_the_temporal_median() {
        let v = Array3::from_shape_vec((3, 1, 2), vec![3.0, 1.0, 1.0, f32::NAN, 2.0, 10.0]).unwrap();
        assert_eq!(static_estimate(v.view()), Array2::from_shape_vec((1, 2), vec![2.0, 5.5]).unwrap());
        let v = Array3::from_shape_vec((4, 1, 1), vec![1.0, 10.0, 3.0, 2.0]).unwrap();
        assert_eq!(static_estimate(v.view())[[0, 0]], 2.5);
        // The moving square covers each pixel in fewer than half the frames.
        let bg = static_estimate(video().view());
        assert_eq!(bg, texture());
    }

    #[test]
    fn the_truth_tracks_the_moving_square() {
        let v = video();
        let bg = static_estimate(v.view());
        let track = object_track(v.view(), bg.view(), 6.0, Contrast::Brighter);
        assert_eq!(track.len(), K);
        for (f, p) in track.iter().enumerate() {
            let (r, c) = p.expect("a position in every frame");
            let (tr, tc) = centre(f);
            let e = (r - tr).hypot(c - tc);
            assert!(e < 0.5, "frame {f}: ({r:.3}, {c:.3}) vs ({tr:.3}, {tc:.3})");
        }
        // Against itself: no error, every judged frame used.
        let rep = track_errors(v.view(), v.view(), bg.view(), bg.view(), 6.0);
        assert_eq!((rep.first_frame, rep.end_frame), (3, 21));
        assert_eq!((rep.frames_used, rep.frames_lost, rep.frames_without_truth), (18, 0, 0));
        assert_eq!(rep.median_px, Some(0.0));
        assert_eq!(rep.p90_px, Some(0.0));
    }

    #[test]
    fn a_shifted_estimate_is_off_by_the_shift() {
        let v = video();
        // The estimate is the truth moved 2 px to the right (the left edge repeated).
        let est = Array3::from_shape_fn((K, ROWS, COLS), |(f, i, j)| v[[f, i, j.saturating_sub(2)]]);
        let bg_est = static_estimate(est.view());
        let bg_truth = static_estimate(v.view());
        let rep = track_errors(est.view(), v.view(), bg_est.view(), bg_truth.view(), 6.0);
        assert_eq!(rep.frames_used, rep.end_frame - rep.first_frame);
        for e in rep.per_frame.iter() {
            assert!((e.unwrap() - 2.0).abs() < 1e-9, "{e:?}");
        }
        assert!((rep.median_px.unwrap() - 2.0).abs() < 1e-9 && (rep.p90_px.unwrap() - 2.0).abs() < 1e-9);
        for (e, t) in rep.estimate_px.iter().zip(&rep.truth_px) {
            let (e, t) = (e.unwrap(), t.unwrap());
            assert!((e.0 - t.0).abs() < 1e-9 && (e.1 - t.1 - 2.0).abs() < 1e-9);
        }
        let json = serde_json::to_string(&rep).unwrap();
        assert!(json.contains("\"median_px\":2"), "{json}");
    }

    #[test]
    fn a_hot_pixel_does_not_take_the_window_and_lost_frames_are_counted() {
        let v = video();
        let bg = static_estimate(v.view());
        let mut est = v.clone();
        // A single pixel far brighter than the square, far from it.
        est[[10, 35, 50]] += 40.0;
        let (r, c) = object_track(est.view(), bg.view(), 6.0, Contrast::Brighter)[10].unwrap();
        let (tr, tc) = centre(10);
        assert!((r - tr).hypot(c - tc) < 0.5, "({r}, {c})");
        // Frames without any excess have no position: lost where the truth has one.
        for f in [5, 6, 20] {
            est.slice_mut(ndarray::s![f, .., ..]).assign(&bg);
        }
        assert_eq!(object_track(est.view(), bg.view(), 6.0, Contrast::Brighter)[5], None);
        let rep = track_errors(est.view(), v.view(), bg.view(), bg.view(), 6.0);
        assert_eq!((rep.frames_used, rep.frames_lost), (15, 3));
        assert_eq!(rep.p90_px_with_lost, None, "the 90th percentile falls on a lost frame");
        assert_eq!(rep.per_frame[5 - rep.first_frame], None);
    }

    #[test]
    fn the_simulated_disc_over_texture_is_tracked() {
        use crate::sim::scene::{DiscOverTexture, Scene};
        use crate::sim::BackgroundTexture;
        let (k, rows, cols, dt) = (30, 48, 64, 25.0);
        let tex = BackgroundTexture { e_per_us: 1.0, seed: 3 }.radiance(rows, cols);
        let scene = DiscOverTexture::new(tex.clone(), 4.0, (20.0, 12.0), (0.01, 0.04), 4.0).unwrap();
        let mut truth = Array3::zeros((k, rows, cols));
        for (f, mut frame) in truth.axis_iter_mut(Axis(0)).enumerate() {
            scene.integrate(f as f64 * dt, (f + 1) as f64 * dt, frame.as_slice_mut().unwrap());
        }
        let bg = static_estimate(truth.view());
        assert!(correlation(bg.view(), tex.view()) > 0.999);
        let mut worst = 0.0f64;
        for (f, p) in object_track(truth.view(), bg.view(), 7.0, Contrast::Brighter).iter().enumerate() {
            let (r, c) = p.unwrap();
            let (tr, tc) = scene.centre_px((f as f64 + 0.5) * dt);
            worst = worst.max((r - tr).hypot(c - tc));
        }
        assert!(worst < 0.5, "{worst}");
        let rep = track_errors(truth.view(), truth.view(), bg.view(), bg.view(), 7.0);
        assert_eq!((rep.frames_used, rep.frames_lost, rep.median_px), (22, 0, Some(0.0)));
    }

    #[test]
    fn a_dark_square_is_tracked_by_its_deficit() {
        // The same square at a tenth of the texture's light: the tracker must follow
        // the light it hides, and a shifted estimate be off by the shift.
        let tex = texture();
        let v = Array3::from_shape_fn((K, ROWS, COLS), |(f, i, j)| {
            let (cr, cc) = centre(f);
            let h = SIDE / 2.0;
            let cov = overlap(i, cr - h, cr + h) * overlap(j, cc - h, cc + h);
            (tex[[i, j]] as f64 * (1.0 - 0.9 * cov)) as f32
        });
        let bg = static_estimate(v.view());
        assert_eq!(Contrast::of(v.view(), bg.view()), Contrast::Darker);
        assert_eq!(Contrast::of(video().view(), static_estimate(video().view()).view()), Contrast::Brighter);
        for (f, p) in object_track(v.view(), bg.view(), 6.0, Contrast::Darker).iter().enumerate() {
            let (r, c) = p.expect("a position in every frame");
            let (tr, tc) = centre(f);
            assert!((r - tr).hypot(c - tc) < 0.6, "frame {f}: ({r:.3}, {c:.3}) vs ({tr:.3}, {tc:.3})");
        }
        let est = Array3::from_shape_fn((K, ROWS, COLS), |(f, i, j)| v[[f, i.saturating_sub(3), j]]);
        let rep = track_errors(est.view(), v.view(), static_estimate(est.view()).view(), bg.view(), 6.0);
        assert_eq!(rep.contrast, Contrast::Darker);
        assert_eq!(rep.frames_lost, 0);
        assert!((rep.median_px.unwrap() - 3.0).abs() < 0.3, "{:?}", rep.median_px);
    }

    #[test]
    fn judged_frames_are_the_middle_seventy_percent() {
        assert_eq!(judged_frames(100), 15..85);
        assert_eq!(judged_frames(7), 1..6);
        assert_eq!(judged_frames(20), 3..17);
        assert_eq!(judged_frames(0), 0..0);
        assert_eq!(quantile_sorted(&[1.0, 2.0, 3.0, 4.0], 0.5), Some(2.5));
        assert_eq!(quantile_sorted(&[0.0, 10.0], 0.9), Some(9.0));
        assert_eq!(quantile_sorted(&[], 0.5), None);
    }

    #[test]
    fn correlation_of_an_image_with_itself_and_its_negative() {
        let t = texture();
        assert!((correlation(t.view(), t.view()) - 1.0).abs() < 1e-12);
        let neg = t.mapv(|v| -v);
        assert!((correlation(t.view(), neg.view()) + 1.0).abs() < 1e-12);
        let scaled = t.mapv(|v| 3.0 * v + 7.0);
        assert!((correlation(t.view(), scaled.view()) - 1.0).abs() < 1e-6);
        let flat = Array2::from_elem((ROWS, COLS), 2.0f32);
        assert_eq!(correlation(t.view(), flat.view()), 0.0);
    }
}
