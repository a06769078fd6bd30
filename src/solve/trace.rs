//! The per-iteration record of a solve (error against run time), as an [`Observer`].

use crate::solve::optimize::{IterInfo, Observer};
use serde::Serialize;

/// Error figures of an estimate against a known truth.
#[derive(Clone, Copy, Debug, Serialize, PartialEq)]
pub struct Error {
    /// 10 log10(peak^2 / MSE), peak = max of the truth.
    pub psnr_db: f64,
    /// ||x - truth|| / ||truth||.
    pub rel_error: f64,
    /// `min_s ||s x - truth|| / ||truth||`: the relative error after the best scale of
    /// the estimate, blind to an overall brightness the data cannot fix (a diffuser's
    /// unknown throughput); the headline figure of a reconstruction.
    pub rel_error_scaled: f64,
}

/// Why a truth that is zero everywhere gives no error figures (summary.json's
/// `error_undefined`).
pub const ZERO_TRUTH: &str = "the truth is zero everywhere: PSNR (peak 0) and relative error (norm 0) are undefined against it";

/// PSNR and relative errors of `x` against `truth` (same length), accumulated in f64;
/// `None` when the truth is zero everywhere ([`ZERO_TRUTH`]).
pub fn compare(x: &[f32], truth: &[f32]) -> Option<Error> {
    assert_eq!(x.len(), truth.len(), "estimate and truth must have the same size");
    let mut sums = ErrorSums::default();
    sums.add(x, truth);
    sums.error(x.len())
}

/// What a reconstruction must beat to mean anything: the figures of an all-zero video
/// and of the truth's own temporal mean (a still image repeated in every frame) against
/// the truth. A mostly dark scene scores a high PSNR with nothing in it; these put a
/// headline PSNR in its place.
#[derive(Clone, Copy, Debug, Serialize, PartialEq)]
pub struct Baselines {
    pub zero_psnr_db: f64,
    /// `None` for a one-frame video (its temporal mean is the truth).
    pub temporal_mean_psnr_db: Option<f64>,
    pub temporal_mean_rel_error_scaled: Option<f64>,
}

impl Baselines {
    /// The baselines of `truth`, `frames` frames of equal size one after another;
    /// `None` when the truth is zero everywhere ([`ZERO_TRUTH`]).
    pub fn of(truth: &[f32], frames: usize) -> Option<Baselines> {
        let zero_psnr_db = compare(&vec![0.0; truth.len()], truth)?.psnr_db;
        if frames < 2 {
            return Some(Baselines { zero_psnr_db, temporal_mean_psnr_db: None, temporal_mean_rel_error_scaled: None });
        }
        let mean: Vec<f32> = temporal_mean(truth, frames).iter().map(|&m| m as f32).collect();
        let repeated = mean.repeat(frames);
        let still = compare(&repeated, truth)?;
        Some(Baselines { zero_psnr_db, temporal_mean_psnr_db: Some(still.psnr_db), temporal_mean_rel_error_scaled: Some(still.rel_error_scaled) })
    }
}

/// The motion error of a video `x` against `truth` (both `frames` frames of equal size,
/// one after another): `||s (x - mean_t x) - (t - mean_t t)|| / ||t - mean_t t||`, with
/// `s = x.t / x.x` the best scale of the whole video (the scale of
/// [`Error::rel_error_scaled`]), accumulated in f64. A still (every frame the same)
/// scores exactly 1, a video that moves where the truth does not or the other way
/// scores above 1, the truth itself 0. The relative error rewards a still on a dense
/// scene (the truth's temporal mean is close to the truth); this figure does not.
/// `None` for fewer than two frames, a truth that does not move (no motion to
/// recover: the norm below is zero) or sizes that do not match.
pub fn motion_error(x: &[f32], truth: &[f32], frames: usize) -> Option<f64> {
    if frames < 2 || x.len() != truth.len() || truth.len() % frames != 0 {
        return None;
    }
    let len = truth.len() / frames;
    if len == 0 {
        return None;
    }
    // The video's best scale and the truth's energy, as the relative error takes them.
    let mut sums = ErrorSums::default();
    sums.add(x, truth);
    let s = if sums.xx > 0.0 { sums.xt / sums.xx } else { 0.0 };
    let (mx, mt) = (temporal_mean(x, frames), temporal_mean(truth, frames));
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (fx, ft) in x.chunks_exact(len).zip(truth.chunks_exact(len)) {
        for p in 0..len {
            let dt = ft[p] as f64 - mt[p];
            let d = s * (fx[p] as f64 - mx[p]) - dt;
            num += d * d;
            den += dt * dt;
        }
    }
    // A truth whose frames differ only by rounding holds no motion to score.
    if !(den > 1e-12 * sums.tn.max(f64::MIN_POSITIVE)) {
        return None;
    }
    let e = (num / den).sqrt();
    e.is_finite().then_some(e)
}

/// Each pixel's mean over `frames` frames of equal size one after another, summed in
/// f64.
pub(crate) fn temporal_mean(v: &[f32], frames: usize) -> Vec<f64> {
    let len = v.len() / frames.max(1);
    let mut mean = vec![0.0f64; len];
    for f in v.chunks_exact(len.max(1)) {
        mean.iter_mut().zip(f).for_each(|(m, &x)| *m += x as f64);
    }
    mean.iter_mut().for_each(|m| *m /= frames as f64);
    mean
}

/// The sums behind [`Error`], gathered in pieces (blocks, ranks) and then finished.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ErrorSums {
    /// `sum (x - t)^2`.
    pub se: f64,
    /// `sum t^2`.
    pub tn: f64,
    /// `sum x t`.
    pub xt: f64,
    /// `sum x^2`.
    pub xx: f64,
    /// `max t`.
    pub peak: f64,
}

impl Default for ErrorSums {
    fn default() -> Self {
        ErrorSums { se: 0.0, tn: 0.0, xt: 0.0, xx: 0.0, peak: f64::NEG_INFINITY }
    }
}

impl ErrorSums {
    /// Adds the pairs of `x` and `truth`.
    pub fn add(&mut self, x: &[f32], truth: &[f32]) {
        for (&a, &t) in x.iter().zip(truth) {
            let (a, t) = (a as f64, t as f64);
            let d = a - t;
            self.se += d * d;
            self.tn += t * t;
            self.xt += a * t;
            self.xx += a * a;
            self.peak = self.peak.max(t);
        }
    }

    /// The sums as an array for a reduction across ranks (all but the peak, which is a
    /// maximum), and back.
    pub fn to_array(self) -> [f64; 4] {
        [self.se, self.tn, self.xt, self.xx]
    }
    pub fn from_array(s: [f64; 4], peak: f64) -> ErrorSums {
        ErrorSums { se: s[0], tn: s[1], xt: s[2], xx: s[3], peak }
    }

    /// The figures over `len` values; `None` when the truth is zero everywhere (no
    /// peak for the PSNR, no norm for the relative errors: [`ZERO_TRUTH`]).
    pub fn error(&self, len: usize) -> Option<Error> {
        if self.tn <= 0.0 {
            return None;
        }
        let mse = self.se / len.max(1) as f64;
        // ||s x - t||^2 at the best s = xt / xx is tn - xt^2 / xx (tn when x is zero).
        let best_se = if self.xx > 0.0 { (self.tn - self.xt * self.xt / self.xx).max(0.0) } else { self.tn };
        let rel = |se: f64| (se / self.tn).sqrt();
        Some(Error {
            psnr_db: if mse > 0.0 { 10.0 * (self.peak * self.peak / mse).log10() } else { f64::INFINITY },
            rel_error: rel(self.se),
            rel_error_scaled: rel(best_se),
        })
    }
}

/// One row of a trace.
#[derive(Clone, Debug, Serialize)]
pub struct TraceRow {
    pub iteration: usize,
    pub seconds: f64,
    pub objective: f64,
    pub data_term: f64,
    pub tv_term: f64,
    pub rel_change: f64,
    pub psnr_db: Option<f64>,
    pub rel_error: Option<f64>,
    pub rel_error_scaled: Option<f64>,
    /// The iterate's motion error ([`motion_error`]) where the trace knows the video's
    /// frames (a plain video's channel solve with a truth).
    pub motion_error: Option<f64>,
}

/// Records every iteration; compares with the truth when one is given.
/// A trace consumer: called with each new row, returns false to stop the solve.
type RowCallback<'a> = Box<dyn FnMut(&TraceRow) -> bool + 'a>;

pub struct TraceRecorder<'a> {
    pub rows: Vec<TraceRow>,
    truth: Option<&'a [f32]>,
    /// Called after each row (progress bars, logs); returns false to stop.
    on_row: Option<RowCallback<'a>>,
}

impl<'a> TraceRecorder<'a> {
    pub fn new(truth: Option<&'a [f32]>) -> Self {
        TraceRecorder { rows: Vec::new(), truth, on_row: None }
    }
    pub fn with_callback(mut self, f: impl FnMut(&TraceRow) -> bool + 'a) -> Self {
        self.on_row = Some(Box::new(f));
        self
    }
    pub fn last(&self) -> Option<&TraceRow> {
        self.rows.last()
    }
}

impl TraceRow {
    /// The row of one iteration, with its error against the truth when known.
    pub fn from_info(i: &IterInfo, err: Option<Error>) -> TraceRow {
        TraceRow {
            iteration: i.iteration,
            seconds: i.seconds,
            objective: i.objective(),
            data_term: i.data_term,
            tv_term: i.reg_term,
            rel_change: i.rel_change,
            psnr_db: err.map(|e| e.psnr_db),
            rel_error: err.map(|e| e.rel_error),
            rel_error_scaled: err.map(|e| e.rel_error_scaled),
            motion_error: None,
        }
    }

    /// This row with the iterate's motion error.
    pub fn with_motion(mut self, motion_error: Option<f64>) -> TraceRow {
        self.motion_error = motion_error;
        self
    }
}

impl Observer for TraceRecorder<'_> {
    fn observe(&mut self, i: &IterInfo) -> bool {
        let err = self.truth.and_then(|t| compare(i.x, t));
        let row = TraceRow::from_info(i, err);
        let go = self.on_row.as_mut().map(|f| f(&row)).unwrap_or(true);
        self.rows.push(row);
        go
    }
}

/// CSV text of traces, one block of rows per channel.
pub fn to_csv(traces: &[(usize, &[TraceRow])]) -> String {
    let mut s = String::from("channel,iteration,seconds,objective,data_term,tv_term,rel_change,psnr_db,rel_error,rel_error_scaled,motion_error\n");
    let opt = |v: Option<f64>| v.map(|x| format!("{x:.6}")).unwrap_or_default();
    for (ch, rows) in traces {
        for r in rows.iter() {
            s.push_str(&format!(
                "{ch},{},{:.6},{:.9e},{:.9e},{:.9e},{:.3e},{},{},{},{}\n",
                r.iteration,
                r.seconds,
                r.objective,
                r.data_term,
                r.tv_term,
                r.rel_change,
                opt(r.psnr_db),
                opt(r.rel_error),
                opt(r.rel_error_scaled),
                opt(r.motion_error)
            ));
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn psnr_of_a_known_error() {
        let t = vec![0.0, 1.0, 2.0, 4.0];
        let x = vec![0.0, 1.0, 2.0, 2.0];
        let e = compare(&x, &t).unwrap();
        // mse = 4/4 = 1, peak 4 -> 10 log10(16) = 12.04 dB; rel = 2/sqrt(21).
        assert!((e.psnr_db - 10.0 * 16f64.log10()).abs() < 1e-12);
        assert!((e.rel_error - 2.0 / 21f64.sqrt()).abs() < 1e-12);
        assert!(compare(&t, &t).unwrap().psnr_db.is_infinite());
        // A truth that is zero everywhere: no figures (not -inf dB, not NaN).
        assert_eq!(compare(&x, &[0.0; 4]), None);
        assert_eq!(Baselines::of(&[0.0; 4], 2), None);
        // Two frames: the zero video's PSNR is peak^2 / mean(t^2); the temporal mean
        // of a still video is exact.
        let b = Baselines::of(&[1.0, 3.0, 1.0, 3.0], 2).unwrap();
        assert!((b.zero_psnr_db - 10.0 * (9.0f64 / 5.0).log10()).abs() < 1e-12);
        assert!(b.temporal_mean_psnr_db.unwrap().is_infinite() && b.temporal_mean_rel_error_scaled.unwrap() < 1e-7);
        let b = Baselines::of(&[0.0, 2.0, 2.0, 0.0], 2).unwrap();
        // The mean (1, 1) is off by 1 everywhere: MSE 1, peak 2.
        assert!((b.temporal_mean_psnr_db.unwrap() - 10.0 * 4f64.log10()).abs() < 1e-12);
        // One frame: no temporal mean to beat.
        assert_eq!(Baselines::of(&[1.0, 3.0], 1).unwrap().temporal_mean_psnr_db, None);
        // Twice the truth: 100% off as given, exact after the best scale.
        let twice: Vec<f32> = t.iter().map(|v| 2.0 * v).collect();
        let e = compare(&twice, &t).unwrap();
        assert!((e.rel_error - 1.0).abs() < 1e-12 && e.rel_error_scaled < 1e-7);
        // Zero: 100% off either way; the best scale of x against t is x.t / x.x.
        assert!((compare(&[0.0; 4], &t).unwrap().rel_error_scaled - 1.0).abs() < 1e-12);
        // x.t = 13, x.x = 9, t.t = 21: the best scale leaves 21 - 169/9 of the energy.
        assert!((compare(&x, &t).unwrap().rel_error_scaled - ((21.0 - 169.0 / 9.0) / 21.0f64).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn motion_error_scores_a_still_one_and_the_truth_zero() {
        // Two frames of two pixels: a spot moving from pixel 0 to pixel 1 on a background.
        let t = [3.0, 1.0, 1.0, 3.0];
        assert!(motion_error(&t, &t, 2).unwrap() < 1e-12);
        // Twice the truth: the best scale undoes it.
        assert!(motion_error(&[6.0, 2.0, 2.0, 6.0], &t, 2).unwrap() < 1e-12);
        // The truth's own temporal mean repeated: a still, exactly 1.
        assert!((motion_error(&[2.0, 2.0, 2.0, 2.0], &t, 2).unwrap() - 1.0).abs() < 1e-12);
        // Zero: nothing moves, 1.
        assert!((motion_error(&[0.0; 4], &t, 2).unwrap() - 1.0).abs() < 1e-12);
        // The motion reversed: x - mean x = -(t - mean t); s = x.t/x.x = 6/10, so
        // ||-s d - d|| / ||d|| = 1 + s = 1.6.
        assert!((motion_error(&[1.0, 3.0, 3.0, 1.0], &t, 2).unwrap() - 1.6).abs() < 1e-12);
        // No motion in the truth, one frame, or mismatched sizes: no figure.
        assert_eq!(motion_error(&t, &[1.0, 1.0, 1.0, 1.0], 2), None);
        assert_eq!(motion_error(&t, &t, 1), None);
        assert_eq!(motion_error(&t[..3], &t, 2), None);
    }
}
