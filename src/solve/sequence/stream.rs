//! Streaming reconstruction fed capture by capture, as a live pipeline receives them:
//! [`Streamer::push`] places the new capture on the grid, solves its window (warm-
//! started from the result so far) and says which frames no later capture can change.
//! Fed the captures of a folder in order, it produces exactly
//! [`Sequence::solve_streaming`]'s video.

use super::error::SequenceError;
use super::solve::{Sequence, SequenceVideo, SolveReport};
use crate::model::capture::CaptureConfig;
use crate::model::prepare::{DataMask, Plane};
use crate::model::shutter::ShutterWeights;
use crate::model::time_grid::{TimeGrid, TimeSource};
use crate::solve::lipschitz::EigenStore;
use crate::solve::reconstruct::{Hooks, SolveParams};
use std::ops::Range;

/// What one pushed capture produced.
pub struct StreamStep {
    pub report: SolveReport,
    /// Frames final from now on: later windows start after them.
    pub final_frames: Range<usize>,
}

/// How a stream's windows are solved: the frames of the result so far each window
/// re-solves, and whether it starts from that result (else from zero).
#[derive(Clone, Copy, Debug)]
pub struct StreamWindows {
    pub overlap: usize,
    pub warm: bool,
}

/// Capture-by-capture streaming solver.
pub struct Streamer<'a> {
    cfg: CaptureConfig,
    /// The capture's shutter weights, computed once for every capture of the stream.
    weights: ShutterWeights,
    psf: Plane,
    params: SolveParams,
    overlap: usize,
    warm: bool,
    source: TimeSource,
    cache: &'a dyn EigenStore,
    start_us: Vec<f64>,
    seq: Option<Sequence>,
    x: Vec<f32>,
    solved_end: usize,
    solves: Vec<SolveReport>,
}

impl<'a> Streamer<'a> {
    /// A stream of captures of `cfg` (whose shutter weights are `weights`, computed
    /// once by the caller) through `psf`, solved with `params`.
    pub fn new(
        cfg: &CaptureConfig,
        weights: ShutterWeights,
        psf: Plane,
        params: SolveParams,
        windows: StreamWindows,
        source: TimeSource,
        cache: &'a dyn EigenStore,
    ) -> Streamer<'a> {
        Streamer {
            cfg: cfg.clone(),
            weights,
            psf,
            params,
            overlap: windows.overlap,
            warm: windows.warm,
            source,
            cache,
            start_us: Vec::new(),
            seq: None,
            x: Vec::new(),
            solved_end: 0,
            solves: Vec::new(),
        }
    }

    /// Add the next capture (prepared measurement and its data-term mask, first-row
    /// exposure start in microseconds on any clock shared by all captures) and solve
    /// its window.
    pub fn push(&mut self, raw: Plane, mask: DataMask, start_us: f64, hooks: &Hooks) -> Result<StreamStep, SequenceError> {
        let timing = self.cfg.timing();
        if let Some(&prev) = self.start_us.last() {
            super::error::check_spacing(
                format!("capture {} start - capture {}'s", self.start_us.len(), self.start_us.len() - 1),
                start_us - prev,
                timing.frame_time_us(),
                timing.exposure_us,
            )?;
        }
        self.start_us.push(start_us);
        let grid = TimeGrid::new(&self.start_us, &self.weights, self.source).inspect_err(|_| {
            // Refused: the stream stays as it was.
            self.start_us.pop();
        })?;
        match &mut self.seq {
            None => self.seq = Some(Sequence::new(&self.cfg, self.weights.clone(), self.psf.clone(), grid, vec![raw]).with_masks(vec![mask])),
            Some(seq) => {
                assert_eq!(raw.data.len(), seq.raws[0].len(), "every capture has the size of the first");
                seq.grid = grid;
                seq.raws.push(raw.data);
                seq.masks.push(mask);
            }
        }
        let seq = self.seq.as_ref().expect("set above");
        let (f, mv, nv) = seq.video_shape();
        let fl = mv * nv;
        self.x.resize(f * fl, 0.0);
        let c = self.start_us.len() - 1;
        let w = seq.window(c, self.solved_end, self.overlap, &self.x);
        let x0 = (self.warm && self.solved_end > 0).then(|| seq.warm_start(&w, self.solved_end, &self.x));
        let (xw, report) = seq.solve_window(&w, x0, &self.params, None, self.cache, hooks)?;
        self.x[w.frames.start * fl..w.frames.end * fl].copy_from_slice(&xw);
        self.solved_end = self.solved_end.max(w.frames.end);
        // The next window starts at min(o_next, solved_end) - H with o_next > o_c.
        let final_end = (seq.grid.offsets[c] + 1).min(self.solved_end).saturating_sub(self.overlap);
        self.solves.push(report.clone());
        Ok(StreamStep { report, final_frames: 0..final_end })
    }

    /// The grid so far.
    pub fn grid(&self) -> Option<&TimeGrid> {
        self.seq.as_ref().map(|s| &s.grid)
    }

    /// (frames, rows, cols) of the video so far ((0, 0, 0) before the first capture).
    pub fn shape(&self) -> (usize, usize, usize) {
        self.seq.as_ref().map(|s| s.video_shape()).unwrap_or((0, 0, 0))
    }

    /// Every window's report so far.
    pub fn solves(&self) -> &[SolveReport] {
        &self.solves
    }

    /// The video so far, `(frames, rows, cols)` row-major.
    pub fn video(&self) -> &[f32] {
        &self.x
    }

    /// The whole video and every window's report.
    pub fn finish(self) -> SequenceVideo {
        let shape = self.seq.as_ref().map(|s| s.video_shape()).unwrap_or((0, 0, 0));
        SequenceVideo { video: self.x, shape, solves: self.solves, error: None }
    }
}
