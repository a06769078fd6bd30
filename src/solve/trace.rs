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
}

/// PSNR and relative error of `x` against `truth` (same length), accumulated in f64.
pub fn compare(x: &[f32], truth: &[f32]) -> Error {
    assert_eq!(x.len(), truth.len(), "estimate and truth must have the same size");
    let mut se = 0.0f64;
    let mut tn = 0.0f64;
    let mut peak = f64::NEG_INFINITY;
    for (&a, &t) in x.iter().zip(truth) {
        let d = a as f64 - t as f64;
        se += d * d;
        tn += t as f64 * t as f64;
        peak = peak.max(t as f64);
    }
    Error::from_sums(se, tn, peak, x.len())
}

impl Error {
    /// The figures from their sums over `len` values: the squared error `se`, the
    /// truth's energy `tn` and its peak (also for sums gathered from several ranks).
    pub fn from_sums(se: f64, tn: f64, peak: f64, len: usize) -> Error {
        let mse = se / len.max(1) as f64;
        Error {
            psnr_db: if mse > 0.0 { 10.0 * (peak * peak / mse).log10() } else { f64::INFINITY },
            rel_error: if tn > 0.0 { (se / tn).sqrt() } else { se.sqrt() },
        }
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
        }
    }
}

impl Observer for TraceRecorder<'_> {
    fn observe(&mut self, i: &IterInfo) -> bool {
        let err = self.truth.map(|t| compare(i.x, t));
        let row = TraceRow::from_info(i, err);
        let go = self.on_row.as_mut().map(|f| f(&row)).unwrap_or(true);
        self.rows.push(row);
        go
    }
}

/// CSV text of traces, one block of rows per channel.
pub fn to_csv(traces: &[(usize, &[TraceRow])]) -> String {
    let mut s = String::from("channel,iteration,seconds,objective,data_term,tv_term,rel_change,psnr_db,rel_error\n");
    let opt = |v: Option<f64>| v.map(|x| format!("{x:.6}")).unwrap_or_default();
    for (ch, rows) in traces {
        for r in rows.iter() {
            s.push_str(&format!(
                "{ch},{},{:.6},{:.9e},{:.9e},{:.9e},{:.3e},{},{}\n",
                r.iteration,
                r.seconds,
                r.objective,
                r.data_term,
                r.tv_term,
                r.rel_change,
                opt(r.psnr_db),
                opt(r.rel_error)
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
        let e = compare(&x, &t);
        // mse = 4/4 = 1, peak 4 -> 10 log10(16) = 12.04 dB; rel = 2/sqrt(21).
        assert!((e.psnr_db - 10.0 * 16f64.log10()).abs() < 1e-12);
        assert!((e.rel_error - 2.0 / 21f64.sqrt()).abs() < 1e-12);
        assert!(compare(&t, &t).psnr_db.is_infinite());
    }
}
