//! The support of a sparse scene, found from its still image, and the solve restricted
//! to it.
//!
//! A scene whose light sits in a few places (LEDs, a small object on black) leaves a
//! dual-shutter capture's first and last frames weakly determined: the rows that expose
//! them see the scene through the PSF's edge, where sources a few pixels apart look
//! alike, and TV fills those frames with light in the wrong places. The still image of
//! the same data (the still check's, [`crate::solve::start::check`]) shows where light
//! ever is: every pixel above [`THRESHOLD_REL`] of its maximum, widened by
//! [`MARGIN_PX`]. When that covers at most [`MAX_FRACTION`] of the grid, the video is
//! solved with zero light outside it ([`Supported`]: the prior's map, then the
//! pixels outside set to zero in every frame; a convex set, like non-negativity).
//!
//! The data then say whether the support left light out (the probe): from the video
//! solved on the support (for the cap less [`PROBE_ITERS`]), the solve goes on for
//! [`PROBE_ITERS`] both on the support and on the whole grid. A source left out is
//! found by the whole grid's iterations and lowers its data misfit (the data term at the video each returns) far
//! below the support's, which gains only what going on gives; when it falls below
//! [`PROBE_MISFIT_KEEP`] of the support's, the support is dropped and the whole grid
//! solved on from its probe for what is left of the cap. Otherwise the support's video
//! is kept (the whole grid's probe seconds count in the run's).
//!
//! The data term's gradient outside the support is not the test: on the demo's LEDs it
//! is far above what noise gives (the continuous-time capture's mismatch with the
//! frames, gathered by `A^T` in the weakly seen frames) while the support's video fits
//! the data better than the whole grid's (chi2 2.06 against 2.20 per pixel).

use crate::solve::prox::Prox;
use rayon::prelude::*;
use serde::Serialize;
use std::sync::Arc;

/// A pixel belongs to the support where the still image exceeds this share of its
/// largest value (before the margin).
pub const THRESHOLD_REL: f32 = 0.2;
/// The support is widened by this many pixels in every direction (a square margin).
pub const MARGIN_PX: usize = 3;
/// A support covering more than this share of the grid is not used: the scene is not
/// sparse, and the whole grid is solved.
pub const MAX_FRACTION: f64 = 0.2;
/// Iterations of the probe from the video solved on the support (at most half the
/// cap, [`probe_iters`]).
pub const PROBE_ITERS: usize = 50;

/// Iterations of the solve on the support before the probe and the sources' fit
/// ([`crate::solve::sources`]); the rest of the cap goes on only when the sources are
/// refused (their fit refits the shapes and the brightness, so the support's video
/// need not settle). Measured with `--iters 250` against 600 (200 + 50 of the probe):
/// the 200 x 266 LED array rel. error 0.165 / 0.163 in 20.4 / 40.5 s, led-measured
/// 0.117 / 0.116, the demo 0.078 / 0.077, a 150 x 200 rolling capture 0.235 / 0.234,
/// led-synthetic 0.125 / 0.110.
pub const FIRST_ITERS: usize = 200;
/// The probe's iterations under an iteration cap of `max_iters`: [`PROBE_ITERS`], at
/// most half the cap.
pub fn probe_iters(max_iters: usize) -> usize {
    PROBE_ITERS.min(max_iters / 2)
}
/// The support is dropped when the whole grid's probe brings the data misfit below this
/// share of the support's: the data hold light outside it. Measured: 0.85-0.99 on LED
/// arrays and a disc on black that the support kept (the whole grid fits noise too),
/// 0.35 for a faint background left out and 0.44 for a faint light away from the others
/// (docs/usage.md, *A sparse scene's support*).
pub const PROBE_MISFIT_KEEP: f64 = 0.6;

/// Pixels of a video grid where light may be, the same in every frame.
#[derive(Clone, Debug)]
pub struct Support {
    /// `rows x cols`, row-major: `true` where light may be.
    pub keep: Arc<Vec<bool>>,
    pub shape: (usize, usize),
}

impl Support {
    /// The support of still images (one per channel, `rows x cols` each): pixels above
    /// [`THRESHOLD_REL`] of an image's largest value in any channel, widened by
    /// [`MARGIN_PX`]. `None` when an image has no positive finite value, or the support
    /// covers more than [`MAX_FRACTION`] of the grid.
    pub fn from_still(images: &[&[f32]], shape: (usize, usize)) -> Option<Support> {
        let (rows, cols) = shape;
        let mut seed = vec![false; rows * cols];
        for img in images {
            assert_eq!(img.len(), rows * cols, "a still image of the video grid");
            let top = img.iter().copied().filter(|v| v.is_finite()).fold(0.0f32, f32::max);
            if !(top > 0.0) {
                return None;
            }
            let t = THRESHOLD_REL * top;
            for (s, &v) in seed.iter_mut().zip(img.iter()) {
                *s |= v.is_finite() && v > t;
            }
        }
        let support = Support { keep: Arc::new(dilate(&seed, shape, MARGIN_PX)), shape };
        (support.fraction() <= MAX_FRACTION).then_some(support)
    }

    /// Pixels inside.
    pub fn pixels(&self) -> usize {
        self.keep.iter().filter(|&&k| k).count()
    }

    /// Share of the grid inside.
    pub fn fraction(&self) -> f64 {
        self.pixels() as f64 / self.keep.len().max(1) as f64
    }

    /// Set every frame of `x` (whole frames of the grid) to zero outside.
    pub fn apply(&self, x: &mut [f32]) {
        let p = self.keep.len();
        assert!(p > 0 && x.len() % p == 0, "whole frames of the support's grid");
        x.par_chunks_mut(p).for_each(|frame| {
            for (v, &k) in frame.iter_mut().zip(self.keep.iter()) {
                if !k {
                    *v = 0.0;
                }
            }
        });
    }
}

/// `seed` widened by `margin` pixels (the square of side `2 margin + 1`): rows then
/// columns, each a running window.
fn dilate(seed: &[bool], (rows, cols): (usize, usize), margin: usize) -> Vec<bool> {
    let mut across = vec![false; rows * cols];
    for r in 0..rows {
        for c in 0..cols {
            let (c0, c1) = (c.saturating_sub(margin), (c + margin + 1).min(cols));
            across[r * cols + c] = seed[r * cols + c0..r * cols + c1].iter().any(|&s| s);
        }
    }
    let mut out = vec![false; rows * cols];
    for r in 0..rows {
        let (r0, r1) = (r.saturating_sub(margin), (r + margin + 1).min(rows));
        for c in 0..cols {
            out[r * cols + c] = (r0..r1).any(|q| across[q * cols + c]);
        }
    }
    out
}

/// A prior restricted to a [`Support`]: its value, and its map followed by zero outside
/// (the projection onto the support, composed like non-negativity after TV).
pub struct Supported<'a> {
    pub inner: Box<dyn Prox + 'a>,
    pub support: Support,
}

impl Prox for Supported<'_> {
    fn value(&self, x: &[f32]) -> f64 {
        self.inner.value(x)
    }
    fn prox(&self, z: &[f32], gamma: f32, out: &mut [f32]) {
        self.inner.prox(z, gamma, out);
        self.support.apply(out);
    }
}

/// How the support was found and whether the data kept it (`summary.json`).
#[derive(Clone, Debug, Serialize)]
pub struct SupportReport {
    /// Pixels inside, and their share of the grid.
    pub pixels: usize,
    pub fraction: f64,
    pub threshold_rel: f32,
    pub margin_px: usize,
    /// Data misfit after the whole grid's probe over the support's after as many
    /// iterations.
    pub probe_misfit_ratio: f64,
    pub probe_iterations: usize,
    /// Whether the video is the one solved on the support (`false`: the data held
    /// light outside it and the whole grid was solved).
    pub kept: bool,
    /// Seconds of the probe, inside the channel's.
    pub probe_seconds: f64,
    /// The sources' fit of the kept support's video ([`crate::solve::sources`]);
    /// `None` when none was made.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sources: Option<SourcesReport>,
}

impl SupportReport {
    /// The report of `support` whose video had the misfit `on_support`, and of the
    /// probe from it: `probe_iterations` in `probe_seconds` to the misfit `probe`.
    pub fn new(support: &Support, on_support: f64, (probe, probe_iterations, probe_seconds): (f64, usize, f64)) -> Self {
        let ratio = probe / on_support.max(f64::MIN_POSITIVE);
        SupportReport {
            pixels: support.pixels(),
            fraction: support.fraction(),
            threshold_rel: THRESHOLD_REL,
            margin_px: MARGIN_PX,
            probe_misfit_ratio: ratio,
            probe_iterations,
            kept: ratio.is_finite() && ratio >= PROBE_MISFIT_KEEP,
            probe_seconds,
            sources: None,
        }
    }

    /// The report of `support` when no probe ran (the solve on it was stopped, went
    /// non-finite, or had a cap under two iterations): kept, its ratio unknown (`null`
    /// in summary.json).
    pub fn unprobed(support: &Support) -> Self {
        SupportReport { probe_misfit_ratio: f64::NAN, probe_iterations: 0, kept: true, probe_seconds: 0.0, ..SupportReport::new(support, 1.0, (1.0, 0, 0.0)) }
    }

    /// Whether the video is the sources' (the support kept, its sources fitted and kept).
    pub fn sources_kept(&self) -> bool {
        self.kept && self.sources.as_ref().is_some_and(|f| f.kept)
    }

    /// The terminal's line (and the sources' below it, when they were fitted).
    pub fn line(&self, ch: usize) -> String {
        match &self.sources {
            Some(s) => format!("{}\n{}", self.support_line(ch), s.line(ch)),
            None => self.support_line(ch),
        }
    }

    fn support_line(&self, ch: usize) -> String {
        let (share, px) = (100.0 * self.fraction, self.pixels);
        if self.probe_iterations == 0 {
            format!("channel {ch}: a sparse scene: solved with light only where the still image shows it ({px} pixels, {share:.1}% of the grid); not probed (the solve was stopped, went non-finite, or ran under 2 iterations)")
        } else if self.kept {
            format!(
                "channel {ch}: a sparse scene: solved with light only where the still image shows it ({px} pixels, {share:.1}% of the grid); the data hold no light outside ({} iterations on the whole grid left {:.2} of the support's misfit; --full-grid solves the whole grid)",
                self.probe_iterations, self.probe_misfit_ratio
            )
        } else {
            format!(
                "channel {ch}: the still image's support ({px} pixels, {share:.1}% of the grid) left light out ({} iterations on the whole grid brought the misfit to {:.2} of the support's, under {PROBE_MISFIT_KEEP}): solved on the whole grid",
                self.probe_iterations, self.probe_misfit_ratio
            )
        }
    }
}

/// The sources' video is kept when its data misfit is at most this many times the
/// support video's ([`crate::solve::sources`]). Measured (docs/usage.md, *The sources of
/// a sparse scene*): 1.01-1.07 on LED arrays, 5.7-19 when LEDs merged into one region,
/// 207 for a moving disc.
pub const SOURCES_MISFIT_KEEP: f64 = 1.25;

/// A frame's light from a source under this share of the source's best frame's
/// ([`crate::solve::sources::Brightness::unseen`]): the rows that expose the frame lie (almost) outside the
/// source's image through the PSF. Measured on a 120 x 160 outside-in dual-shutter
/// capture through the measured PSF (four LEDs mid-scene): the first 6 frames under
/// 0.005, frames 6-8 0.01-0.04, frame 9 on 0.08 and more; the fitted brightness was
/// off by up to 2.4x the LED's level in frames 0-5, within 0.11 from frame 9 and 0.05
/// from frame 12.
pub const UNSEEN_REL: f64 = 0.05;

/// The sources' fit of a kept support's video ([`crate::solve::sources`]) as
/// `summary.json` reports it (`channels[].support.sources`).
#[derive(Clone, Debug, Serialize)]
pub struct SourcesReport {
    pub regions: usize,
    /// The sources' data misfit over the support video's.
    pub misfit_ratio: f64,
    /// Whether the video is the sources' (`false`: the support's video was kept).
    pub kept: bool,
    pub rounds: usize,
    /// Seconds of the fit, inside the channel's.
    pub seconds: f64,
    /// Runs `[first, end)` of the frames in which some source's light is under
    /// `unseen_below` of its best frame's: its brightness there is not in the data
    /// ([`crate::solve::sources::Brightness::unseen`]).
    pub unseen_frames: Vec<[usize; 2]>,
    pub unseen_below: f64,
    /// The video's frames.
    #[serde(skip)]
    pub frames: usize,
}

impl SourcesReport {
    /// The report of a fit of `regions` sources in `rounds` rounds and `seconds` whose
    /// video has the data misfit `misfit`, against a support video of misfit
    /// `on_support`.
    pub fn new(regions: usize, rounds: usize, (misfit, on_support): (f64, f64), seconds: f64) -> Self {
        let ratio = misfit / on_support.max(f64::MIN_POSITIVE);
        SourcesReport {
            regions,
            misfit_ratio: ratio,
            kept: ratio.is_finite() && ratio <= SOURCES_MISFIT_KEEP,
            rounds,
            seconds,
            unseen_frames: Vec::new(),
            unseen_below: UNSEEN_REL,
            frames: 0,
        }
    }

    /// The terminal's line.
    pub fn line(&self, ch: usize) -> String {
        let (sources, fit) =
            if self.regions == 1 { ("1 source that changes".to_string(), "fits") } else { (format!("{} sources that change", self.regions), "fit") };
        if self.kept {
            let unseen = if self.unseen_frames.is_empty() {
                String::new()
            } else {
                format!(
                    "; in {} a source's light is under {} of its best frame's (the rows that expose them barely see it through the PSF): its brightness there is not in the data: a guess, drawn to the source's mean over the frames they see (summary.json: support.sources.unseen_frames)",
                    crate::solve::frames::runs_text(&self.unseen_frames, self.frames),
                    self.unseen_below
                )
            };
            format!(
                "channel {ch}: {sources} only in brightness {fit} the data ({:.2} of the support video's misfit): the video is theirs{unseen}",
                self.misfit_ratio
            )
        } else {
            format!(
                "channel {ch}: {sources} only in brightness {fit} the data badly ({:.2} of the support video's misfit, above {SOURCES_MISFIT_KEEP}): the support's video is kept",
                self.misfit_ratio
            )
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_support_is_the_bright_pixels_widened_and_refused_when_not_sparse() {
        let (rows, cols) = (20, 30);
        let mut img = vec![0.0f32; rows * cols];
        img[10 * cols + 15] = 10.0;
        img[2 * cols + 3] = 1.9; // below 0.2 of the largest
        img[18 * cols + 28] = 2.1;
        let s = Support::from_still(&[&img], (rows, cols)).expect("sparse");
        let side = 2 * MARGIN_PX + 1;
        // The bright pixel's square; the other at the corner cut by the grid's edge.
        assert_eq!(s.pixels(), side * side + (2 + MARGIN_PX) * (2 + MARGIN_PX));
        assert!(s.keep[(10 + MARGIN_PX) * cols + 15 - MARGIN_PX] && !s.keep[(10 + MARGIN_PX + 1) * cols + 15]);
        assert!(!s.keep[2 * cols + 3], "below the threshold");
        let mut x = vec![1.0f32; 2 * rows * cols];
        s.apply(&mut x);
        assert_eq!(x.iter().filter(|&&v| v == 1.0).count(), 2 * s.pixels());
        // A textured image is not sparse; a dark one has no support.
        let tex: Vec<f32> = crate::model::op::pseudo_random(rows * cols, 3);
        assert!(Support::from_still(&[&tex], (rows, cols)).is_none());
        assert!(Support::from_still(&[&vec![0.0; rows * cols]], (rows, cols)).is_none());
        // Channels: the union.
        let (mut one, mut other) = (vec![0.0f32; rows * cols], vec![0.0f32; rows * cols]);
        one[10 * cols + 15] = 10.0;
        other[5 * cols + 25] = 1.0;
        let two = Support::from_still(&[&one, &other], (rows, cols)).unwrap();
        assert_eq!(two.pixels(), 2 * side * side);
        assert!(two.keep[5 * cols + 25] && two.keep[10 * cols + 15]);
    }

    #[test]
    fn the_sources_line_names_the_frames_the_data_do_not_see() {
        let kept = SourcesReport::new(4, 3, (1.0, 1.0), 0.5);
        assert!(kept.kept && !kept.line(0).contains("a guess"), "{}", kept.line(0));
        let unseen = SourcesReport { unseen_frames: vec![[0, 9], [61, 62]], frames: 62, ..kept.clone() };
        let line = unseen.line(0);
        assert!(line.contains("the video is theirs; in frames 0-8 and 61 (10 of 62) a source's light is under 0.05 of its best frame's"), "{line}");
        // Refused sources: the support's video stands, its frames are not the sources'.
        let refused = SourcesReport { kept: false, ..unseen };
        assert!(!refused.line(0).contains("a guess"), "{}", refused.line(0));
    }
}
