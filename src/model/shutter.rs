//! Rolling-shutter timing: when each sensor row integrates light, and the exact
//! shutter weights `W[row, frame]` that couple the video frames to the rows.
//!
//! Conventions (all times in microseconds):
//! - raw row `i` integrates over `[s_i, s_i + T_e)`, where `s_i` comes from the
//!   shutter mode (or a per-row table) and `t = 0` is the start of the earliest row;
//! - a reconstruction row `r` is the box mean of the `d` raw rows `r*d .. r*d+d`
//!   (spatial downsampling by `d`);
//! - frame `k` covers `[k*T_f, (k+1)*T_f)` with `T_f = d * b * T_l` (`b` = temporal
//!   binning); `K` is the smallest count of frames that covers every row's exposure;
//! - `W[r, k] = (1/d) * sum_{raw rows i of r} |[s_i, s_i+T_e) ∩ frame k| / T_f`,
//!   the fraction of frame k's interval during which row r integrates, averaged over
//!   the raw rows it merges. A static scene `v` (counts per frame interval) then gives
//!   `b = (T_e / T_f) * h * v`.

use serde::{Deserialize, Serialize};
use std::fmt;
use std::ops::Range;

/// Raw line time of the paper's camera (the row-to-row delay of its rolling shutter),
/// microseconds. The default wherever no camera or capture.toml gives one: simulations,
/// the simulated cameras, the benchmark presets and the LED sweep.
pub const DEFAULT_LINE_TIME_US: f64 = 220.0;

/// How the rows of a sensor start their exposures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum ShutterMode {
    /// Every row starts at t = 0.
    Global,
    /// Row i starts at i * T_l (top to bottom).
    Rolling,
    /// Dual shutter, outside-in (PCO edge): rows i and M-1-i start together at i * T_l.
    #[default]
    Dual,
    /// Dual shutter, centre-out: the two central rows start first.
    DualCenterOut,
}

impl ShutterMode {
    pub const ALL: [ShutterMode; 4] = [ShutterMode::Global, ShutterMode::Rolling, ShutterMode::Dual, ShutterMode::DualCenterOut];

    pub fn name(self) -> &'static str {
        match self {
            ShutterMode::Global => "global",
            ShutterMode::Rolling => "rolling",
            ShutterMode::Dual => "dual",
            ShutterMode::DualCenterOut => "dual-center-out",
        }
    }

    /// Start index (in line times) of raw row `i` of `rows`.
    pub fn start_line(self, i: usize, rows: usize) -> usize {
        debug_assert!(i < rows);
        let from_edge = i.min(rows - 1 - i);
        match self {
            ShutterMode::Global => 0,
            ShutterMode::Rolling => i,
            ShutterMode::Dual => from_edge,
            ShutterMode::DualCenterOut => rows.div_ceil(2) - 1 - from_edge,
        }
    }
}

impl ShutterMode {
    /// The latest [`start_line`](Self::start_line) of `rows` rows (0 when `rows` is 0);
    /// the earliest is always 0.
    pub fn last_start_line(self, rows: usize) -> usize {
        let Some(last) = rows.checked_sub(1) else { return 0 };
        match self {
            ShutterMode::Global => 0,
            ShutterMode::Rolling => last,
            ShutterMode::Dual | ShutterMode::DualCenterOut => last / 2,
        }
    }
}

impl fmt::Display for ShutterMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for ShutterMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        ShutterMode::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| format!("unknown shutter mode '{s}': expected global, rolling, dual or dual-center-out"))
    }
}

/// Errors in a timing description.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum TimingError {
    #[error("{field} = {value}: expected {expected}")]
    Invalid { field: &'static str, value: String, expected: String },
}

fn invalid(field: &'static str, value: impl fmt::Display, expected: impl Into<String>) -> TimingError {
    TimingError::Invalid { field, value: value.to_string(), expected: expected.into() }
}

/// The timing of one raw capture, before the tool downsamples it.
#[derive(Clone, Debug, PartialEq)]
pub struct Timing {
    /// Raw sensor rows.
    pub raw_rows: usize,
    /// Delay between the starts of consecutive rows, in microseconds.
    pub line_time_us: f64,
    /// Exposure of every row, in microseconds.
    pub exposure_us: f64,
    pub mode: ShutterMode,
    /// Spatial downsampling factor d (box mean of d x d raw pixels).
    pub downsample: usize,
    /// Temporal binning b (frames of b effective line times).
    pub binning: usize,
    /// Optional per-raw-row start times (us), for sensors with other read patterns.
    /// Overrides `mode` when present.
    pub row_start_us: Option<Vec<f64>>,
}

/// The largest sensor side (rows or columns) any description may give: no sensor is
/// larger, and a typo (or a hostile file) must not size a table before it is checked.
pub const MAX_SENSOR_SIDE: usize = 65_536;

/// The most frames a timing may need (a typo such as an exposure in ns otherwise asks
/// for millions).
pub const MAX_FRAMES: usize = 1_000_000;

/// The longest exposure, in readouts (rows x line time), a timing may give.
pub const MAX_EXPOSURE_READOUTS: f64 = 1000.0;

impl Timing {
    pub fn new(raw_rows: usize, line_time_us: f64, exposure_us: f64, mode: ShutterMode) -> Self {
        Timing { raw_rows, line_time_us, exposure_us, mode, downsample: 1, binning: 1, row_start_us: None }
    }

    /// Check that the timing is physically meaningful. Nothing of a size given here is
    /// allocated before it is checked.
    pub fn validate(&self) -> Result<(), TimingError> {
        if self.raw_rows == 0 {
            return Err(invalid("rows", 0, "at least 1 row"));
        }
        if self.raw_rows > MAX_SENSOR_SIDE {
            return Err(invalid("rows", self.raw_rows, format!("at most {MAX_SENSOR_SIDE} rows (no sensor is larger)")));
        }
        if !(self.line_time_us.is_finite() && self.line_time_us > 0.0) {
            return Err(invalid("line_time_us", self.line_time_us, "a positive, finite time in microseconds"));
        }
        if !(self.exposure_us.is_finite() && self.exposure_us > 0.0) {
            return Err(invalid("exposure_us", self.exposure_us, "a positive, finite time in microseconds"));
        }
        // Relative slack: exposure == line time must pass despite decimal round-off. A
        // still has one frame: no gap in time to leave.
        if !self.is_still() && self.exposure_us < self.line_time_us * (1.0 - 1e-9) {
            return Err(invalid(
                "exposure_us",
                self.exposure_us,
                format!("at least one line time ({} us): shorter exposures leave gaps in time that no row sees", self.line_time_us),
            ));
        }
        if self.downsample == 0 {
            return Err(invalid("downsample", 0, "a factor of at least 1"));
        }
        if self.downsample > self.raw_rows {
            return Err(invalid("downsample", self.downsample, format!("at most the raw row count ({})", self.raw_rows)));
        }
        if self.binning == 0 {
            return Err(invalid("binning", 0, "a factor of at least 1"));
        }
        if let Some(table) = &self.row_start_us {
            if table.len() != self.raw_rows {
                return Err(invalid("row_start_us", format!("{} entries", table.len()), format!("one start time per raw row ({} entries)", self.raw_rows)));
            }
            if let Some((i, v)) = table.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(invalid("row_start_us", format!("entry {i} = {v}"), "finite times in microseconds"));
            }
        }
        // An exposure a thousand readouts long leaves the rolling shutter nothing to
        // resolve: the likely mistake is a time in ns typed as us. A still (one frame
        // whatever its exposure) has no readout to compare with.
        let readout_us = self.raw_rows as f64 * self.line_time_us;
        if !self.is_still() && self.exposure_us > MAX_EXPOSURE_READOUTS * readout_us {
            return Err(invalid(
                "exposure_us",
                self.exposure_us,
                format!(
                    "at most {MAX_EXPOSURE_READOUTS} times the readout ({} rows x {} us = {readout_us} us): is it a time in ns? ({} ns = {} us)",
                    self.raw_rows,
                    self.line_time_us,
                    self.exposure_us,
                    self.exposure_us / 1e3
                ),
            ));
        }
        // Binning past one frame for the whole capture makes the frame longer than the
        // capture (and its weights vanish).
        let unbinned = (self.frames_estimate() * self.binning as f64).ceil().max(1.0);
        if self.binning as f64 > unbinned {
            return Err(invalid("binning", self.binning, format!("at most {unbinned} (one frame then covers the whole capture)")));
        }
        // Guard against absurd frame counts (a typo such as exposure in ns).
        let k = self.frames_estimate();
        if k > MAX_FRAMES as f64 {
            return Err(invalid("exposure_us", self.exposure_us, format!("a timing that needs at most {MAX_FRAMES} frames (this one needs {k:.0})")));
        }
        Ok(())
    }

    /// How many frames the video of this timing has, from the latest row start, before
    /// the weights are built (nothing is allocated; the weights may round it up by one).
    pub fn frames_estimate(&self) -> f64 {
        if self.is_still() {
            return 1.0;
        }
        let span = match &self.row_start_us {
            Some(t) => {
                let (lo, hi) = t.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)));
                (hi - lo).max(0.0)
            }
            None => self.mode.last_start_line(self.raw_rows) as f64 * self.line_time_us,
        };
        (span + self.exposure_us) / (self.downsample as f64 * self.binning as f64 * self.line_time_us)
    }

    /// Rows of the reconstruction grid (raw rows beyond a multiple of d are dropped).
    pub fn rows(&self) -> usize {
        self.raw_rows / self.downsample
    }

    /// A still: a global shutter (without a per-row table) exposes every row over the
    /// same window, so the image holds no time: one frame, of the exposure's length,
    /// whatever the exposure, line time or binning.
    pub fn is_still(&self) -> bool {
        self.mode == ShutterMode::Global && self.row_start_us.is_none()
    }

    /// Frame interval T_f = d * b * T_l; a still's one frame lasts the exposure.
    pub fn frame_time_us(&self) -> f64 {
        if self.is_still() {
            return self.exposure_us;
        }
        self.downsample as f64 * self.binning as f64 * self.line_time_us
    }

    /// Start time of every raw row, shifted so that the earliest row starts at 0.
    pub fn raw_row_starts_us(&self) -> Vec<f64> {
        let starts: Vec<f64> = match &self.row_start_us {
            Some(t) => t.clone(),
            None => (0..self.raw_rows).map(|i| self.mode.start_line(i, self.raw_rows) as f64 * self.line_time_us).collect(),
        };
        let t0 = starts.iter().cloned().fold(f64::INFINITY, f64::min);
        starts.into_iter().map(|s| s - t0).collect()
    }

    /// Exact shutter weights for this timing.
    pub fn weights(&self) -> Result<ShutterWeights, TimingError> {
        self.validate()?;
        Ok(ShutterWeights::compute(self))
    }
}

/// Shutter weights `W[row, frame]` of the reconstruction grid.
#[derive(Clone, Debug)]
pub struct ShutterWeights {
    rows: usize,
    frames: usize,
    frame_time_us: f64,
    /// Row-major rows x frames.
    w: Vec<f32>,
    /// For every frame, the rows whose weight is non-zero (always contiguous ranges
    /// per half for the built-in modes; stored as a sorted list of ranges).
    frame_rows: Vec<Vec<Range<usize>>>,
}

impl ShutterWeights {
    fn compute(t: &Timing) -> Self {
        let d = t.downsample;
        let rows = t.rows();
        let tf = t.frame_time_us();
        let te = t.exposure_us;
        let starts = t.raw_row_starts_us();
        // Frames needed to cover every exposure (relative tolerance for round-off).
        let end_max = starts[..rows * d].iter().map(|s| s + te).fold(0.0f64, f64::max);
        let frames = ((end_max / tf) - 1e-9).ceil().max(1.0) as usize;
        let mut acc = vec![0.0f64; rows * frames];
        for r in 0..rows {
            for &s in &starts[r * d..(r + 1) * d] {
                let e = s + te;
                let k0 = ((s / tf) + 1e-12).floor() as usize;
                let k1 = ((e / tf) - 1e-12).ceil() as usize;
                for k in k0..k1.min(frames) {
                    let lo = s.max(k as f64 * tf);
                    let hi = e.min((k + 1) as f64 * tf);
                    if hi > lo {
                        acc[r * frames + k] += (hi - lo) / tf;
                    }
                }
            }
        }
        let inv_d = 1.0 / d as f64;
        let w: Vec<f32> = acc.iter().map(|&x| (x * inv_d) as f32).collect();
        ShutterWeights::from_table(rows, frames, tf, w)
    }

    /// Build weights directly from a table (rows x frames, row-major); used by tests and
    /// by callers with their own exposure patterns.
    pub fn from_table(rows: usize, frames: usize, frame_time_us: f64, w: Vec<f32>) -> Self {
        assert_eq!(w.len(), rows * frames, "weight table must be rows x frames");
        let mut frame_rows = vec![Vec::new(); frames];
        for (k, ranges) in frame_rows.iter_mut().enumerate() {
            let mut r = 0;
            while r < rows {
                if w[r * frames + k] != 0.0 {
                    let start = r;
                    while r < rows && w[r * frames + k] != 0.0 {
                        r += 1;
                    }
                    ranges.push(start..r);
                } else {
                    r += 1;
                }
            }
        }
        ShutterWeights { rows, frames, frame_time_us, w, frame_rows }
    }

    pub fn rows(&self) -> usize {
        self.rows
    }
    pub fn frames(&self) -> usize {
        self.frames
    }
    pub fn frame_time_us(&self) -> f64 {
        self.frame_time_us
    }
    #[inline]
    pub fn get(&self, row: usize, frame: usize) -> f32 {
        self.w[row * self.frames + frame]
    }
    /// Rows with a non-zero weight in `frame`, as sorted ranges.
    pub fn rows_of_frame(&self, frame: usize) -> &[Range<usize>] {
        &self.frame_rows[frame]
    }
    /// Sum over frames of a row's weights: T_e / T_f for every fully exposed row.
    pub fn row_total(&self, row: usize) -> f64 {
        (0..self.frames).map(|k| self.get(row, k) as f64).sum()
    }
    /// The whole table, row-major rows x frames.
    pub fn as_slice(&self) -> &[f32] {
        &self.w
    }
    /// Restrict to the frames `range` (for solving a time window only).
    pub fn window(&self, range: Range<usize>) -> ShutterWeights {
        let f = range.len();
        let mut w = Vec::with_capacity(self.rows * f);
        for r in 0..self.rows {
            w.extend_from_slice(&self.w[r * self.frames + range.start..r * self.frames + range.end]);
        }
        ShutterWeights::from_table(self.rows, f, self.frame_time_us, w)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(t: &Timing) -> Vec<Vec<f32>> {
        let w = t.weights().unwrap();
        (0..w.rows()).map(|r| (0..w.frames()).map(|k| w.get(r, k)).collect()).collect()
    }

    #[test]
    fn the_last_start_line_is_the_latest_row_start_of_every_mode() {
        for mode in ShutterMode::ALL {
            assert_eq!(mode.last_start_line(0), 0);
            for rows in 1..24 {
                let max = (0..rows).map(|i| mode.start_line(i, rows)).max().unwrap();
                let min = (0..rows).map(|i| mode.start_line(i, rows)).min().unwrap();
                assert_eq!((min, mode.last_start_line(rows)), (0, max), "{mode} {rows}");
            }
        }
    }

    #[test]
    fn absurd_row_counts_and_factors_are_refused_without_building_the_row_table() {
        // rows = i64::MAX used to panic ("capacity overflow") and 2e8 rows took 1.6 GB
        // in the row table before the frame count refused them; the row bound refuses
        // them first now, for every mode (a global shutter needs few frames).
        for mode in ShutterMode::ALL {
            for rows in [9_223_372_036_854_775_807usize, usize::MAX, 200_000_000, MAX_SENSOR_SIDE + 1] {
                let e = Timing::new(rows, 10.0, 30.0, mode).validate().unwrap_err().to_string();
                assert!(e.contains("rows") && e.contains("at most 65536 rows"), "{e}");
            }
        }
        // Under the row bound, the frame count still refuses a rolling timing that is too long.
        let e = Timing::new(MAX_SENSOR_SIDE, 10.0, 1e8, ShutterMode::Rolling).validate().unwrap_err().to_string();
        assert!(e.contains("exposure_us") && e.contains("frames"), "{e}");
        // d * b past usize: no overflow panic, a frame time; a binning past one frame for
        // the whole capture is refused (it used to reach the solver, whose weights
        // vanished: "Lipschitz constant must be positive", a panic).
        let mut t = Timing::new(8, 10.0, 30.0, ShutterMode::Dual);
        t.downsample = 8;
        t.binning = usize::MAX;
        assert!(t.frame_time_us().is_finite());
        let e = t.validate().unwrap_err().to_string();
        assert!(e.contains("binning") && e.contains("at most 1 "), "{e}");
        t.binning = 1;
        assert!(t.validate().is_ok());
    }

    #[test]
    fn an_exposure_a_thousand_readouts_long_is_refused_as_a_likely_unit_mistake() {
        // 48 rows of 220 us: exposure_us = 3e7 (30 ms in ns) gave 136387 frames.
        let e = Timing::new(48, 220.0, 3e7, ShutterMode::Dual).validate().unwrap_err().to_string();
        assert!(e.contains("exposure_us") && e.contains("readout") && e.contains("ns") && e.contains("30000 us"), "{e}");
        assert!(Timing::new(48, 220.0, 48.0 * 220.0 * 1000.0, ShutterMode::Dual).validate().is_ok());
    }

    #[test]
    fn rolling_integer_exposure_is_a_band_of_ones() {
        // 4 rows, T_l = 10, T_e = 20: row i covers frames i and i+1 fully.
        let t = Timing::new(4, 10.0, 20.0, ShutterMode::Rolling);
        let w = table(&t);
        assert_eq!(w, vec![vec![1., 1., 0., 0., 0.], vec![0., 1., 1., 0., 0.], vec![0., 0., 1., 1., 0.], vec![0., 0., 0., 1., 1.],]);
    }

    #[test]
    fn rolling_fractional_exposure() {
        // T_e = 15 with T_l = 10: row 0 covers [0,15): frame 0 fully, half of frame 1.
        let t = Timing::new(3, 10.0, 15.0, ShutterMode::Rolling);
        let w = table(&t);
        assert_eq!(w, vec![vec![1., 0.5, 0., 0.], vec![0., 1., 0.5, 0.], vec![0., 0., 1., 0.5]]);
    }

    #[test]
    fn a_global_shutter_is_one_frame_whatever_the_exposure() {
        for (lt, ex) in [(10.0, 25.0), (10.0, 10_000.0), (10.0, 1.0)] {
            let mut t = Timing::new(3, lt, ex, ShutterMode::Global);
            t.binning = 2;
            assert!(t.is_still());
            assert_eq!(t.frame_time_us(), ex);
            assert_eq!(table(&t), vec![vec![1.0]; 3], "line time {lt}, exposure {ex}");
        }
        // All rows starting together from a per-row table is a timing, not a still.
        let mut t = Timing::new(3, 10.0, 25.0, ShutterMode::Global);
        t.row_start_us = Some(vec![0.0; 3]);
        assert!(!t.is_still());
        assert_eq!(table(&t), vec![vec![1., 1., 0.5]; 3]);
    }

    #[test]
    fn dual_outside_in_pairs_rows() {
        // 5 rows: starts 0,1,2,1,0 line times. T_e = T_l.
        let t = Timing::new(5, 2.0, 2.0, ShutterMode::Dual);
        let w = table(&t);
        assert_eq!(w, vec![vec![1., 0., 0.], vec![0., 1., 0.], vec![0., 0., 1.], vec![0., 1., 0.], vec![1., 0., 0.],]);
    }

    #[test]
    fn dual_center_out_starts_in_the_middle() {
        // 4 rows: starts 1,0,0,1.
        let t = Timing::new(4, 1.0, 1.0, ShutterMode::DualCenterOut);
        let w = table(&t);
        assert_eq!(w, vec![vec![0., 1.], vec![1., 0.], vec![1., 0.], vec![0., 1.]]);
        // Odd: starts 2,1,0,1,2.
        let t = Timing::new(5, 1.0, 1.0, ShutterMode::DualCenterOut);
        assert_eq!(table(&t)[2], vec![1., 0., 0.]);
        assert_eq!(table(&t)[0], vec![0., 0., 1.]);
    }

    #[test]
    fn downsampling_gives_fractional_weights() {
        // Rolling, 4 raw rows, d = 2, T_l = 1, T_e = 2: T_f = 2.
        // Downsampled row 0 merges raw rows starting at 0 and 1 (each exposing 2):
        // raw 0 -> [0,2): frame 0 fully (1.0); raw 1 -> [1,3): half of frame 0, half of 1.
        // W[0] = ((1 + 0.5)/2, (0 + 0.5)/2) = (0.75, 0.25).
        let mut t = Timing::new(4, 1.0, 2.0, ShutterMode::Rolling);
        t.downsample = 2;
        let w = table(&t);
        assert_eq!(w, vec![vec![0.75, 0.25, 0.0], vec![0.0, 0.75, 0.25]]);
        // Binning: frames of 2 effective line times (T_f = 4).
        t.binning = 2;
        let w = table(&t);
        // Row 1: raw 2 [2,4) -> 2/4 of frame 0; raw 3 [3,5) -> 1/4 of frames 0 and 1.
        assert_eq!(w, vec![vec![0.5, 0.0], vec![0.375, 0.125]]);
    }

    #[test]
    fn downsampling_drops_remainder_rows() {
        let mut t = Timing::new(7, 1.0, 1.0, ShutterMode::Rolling);
        t.downsample = 2;
        assert_eq!(t.rows(), 3);
        assert_eq!(t.weights().unwrap().rows(), 3);
    }

    #[test]
    fn row_totals_equal_exposure_over_frame_time() {
        for mode in ShutterMode::ALL {
            for (rows, d, b) in [(9, 1, 1), (12, 3, 1), (10, 2, 3), (1, 1, 1), (2, 1, 2)] {
                let mut t = Timing::new(rows, 7.5, 33.0, mode);
                t.downsample = d;
                t.binning = b;
                let w = t.weights().unwrap();
                let expect = 33.0 / t.frame_time_us();
                for r in 0..w.rows() {
                    assert!((w.row_total(r) - expect).abs() < 1e-5, "{mode} rows={rows} d={d} b={b} r={r}");
                }
            }
        }
    }

    #[test]
    fn paper_frame_count() {
        // The paper's 8x setting treated as a 270-row sensor at 220 us, N_l = 3:
        // K = M/2 + N_l - 1 = 137.
        let t = Timing::new(270, 220.0, 660.0, ShutterMode::Dual);
        assert_eq!(t.weights().unwrap().frames(), 137);
    }

    #[test]
    fn per_row_table_overrides_mode_and_is_shifted_to_zero() {
        let mut t = Timing::new(3, 1.0, 1.0, ShutterMode::Global);
        t.row_start_us = Some(vec![5.0, 7.0, 6.0]);
        let w = table(&t);
        assert_eq!(w, vec![vec![1., 0., 0.], vec![0., 0., 1.], vec![0., 1., 0.]]);
    }

    #[test]
    fn frame_rows_lists_nonzero_rows() {
        let t = Timing::new(6, 1.0, 2.0, ShutterMode::Dual);
        let w = t.weights().unwrap();
        // starts 0,1,2,2,1,0; frame 1 sees rows starting at 0 and 1 -> rows 0,1,4,5.
        assert_eq!(w.rows_of_frame(1), &[0..2, 4..6]);
    }

    #[test]
    fn bad_timing_is_refused_with_the_field() {
        let t = Timing::new(4, 10.0, 5.0, ShutterMode::Rolling);
        let e = t.validate().unwrap_err().to_string();
        assert!(e.contains("exposure_us") && e.contains("line time"), "{e}");
        let t = Timing::new(4, -1.0, 5.0, ShutterMode::Rolling);
        assert!(t.validate().unwrap_err().to_string().contains("line_time_us"));
        let t = Timing::new(4, f64::NAN, 5.0, ShutterMode::Rolling);
        assert!(t.validate().is_err());
        let mut t = Timing::new(4, 1.0, 5.0, ShutterMode::Rolling);
        t.downsample = 0;
        assert!(t.validate().unwrap_err().to_string().contains("downsample"));
        let mut t = Timing::new(4, 1.0, 5.0, ShutterMode::Rolling);
        t.row_start_us = Some(vec![0.0; 3]);
        assert!(t.validate().unwrap_err().to_string().contains("row_start_us"));
        let t = Timing::new(4, 1e-6, 1e3, ShutterMode::Rolling);
        assert!(t.validate().is_err(), "1e9 frames must be refused");
        // A one-second exposure over a 48-row readout of 480 us: ns typed as us for a
        // rolling shutter, an ordinary dim still for a global one.
        let e = Timing::new(48, 10.0, 1e6, ShutterMode::Rolling).validate().unwrap_err().to_string();
        assert!(e.contains("exposure_us") && e.contains("ns"), "{e}");
        Timing::new(48, 10.0, 1e6, ShutterMode::Global).validate().unwrap();
    }

    #[test]
    fn window_keeps_columns() {
        let t = Timing::new(4, 10.0, 20.0, ShutterMode::Rolling);
        let w = t.weights().unwrap().window(1..3);
        assert_eq!(w.frames(), 2);
        assert_eq!(w.get(0, 0), 1.0);
        assert_eq!(w.get(3, 0), 0.0);
        assert_eq!(w.get(2, 1), 1.0);
    }
}
