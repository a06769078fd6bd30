//! One rank's block of a split problem: the frames `frames` of a `total_frames` video,
//! on a process that holds only those. The imaging model is a sum over frames, so the
//! full `A v` is the sum over ranks of each block's `A_r v_r`.
//!
//! A block's frames touch only some sensor rows (a rolling shutter exposes each row in
//! its own window), and its adjoint reads only those rows. So the forward sums over
//! the ranks only the rows that more than one rank touches ([`RowShare`]; the whole
//! sensor image when that is smaller), and each rank's output is exact on the rows it
//! touches; the rows it does not touch hold its own zeros, which nothing reads. Sums
//! over the output (the data term, `||A x||^2`) count each row on one rank
//! ([`Split::partition`]): the lowest rank that touches it, rank 0 for rows no
//! frame touches. The adjoint is local (`A_r^T y`, the block's frames of `A^T y`).

use crate::model::op::Operator;
use crate::model::ranks::{Partition, Ranks};
use crate::model::shutter::ShutterWeights;
use std::ops::Range;
use std::sync::Mutex;

/// How a rank's sensor rows relate to the other ranks': the rows more than one rank
/// touches (summed across ranks by the forward) and the rows this rank counts.
#[derive(Clone, Debug)]
pub struct RowShare {
    /// Sensor rows touched by two or more ranks, ascending.
    pub shared: Vec<usize>,
    /// Per sensor row: whether this rank counts it in sums over the output.
    pub owned: Vec<bool>,
    pub rows: usize,
}

impl RowShare {
    /// From the whole capture's shutter weights and every rank's block of frames
    /// (`blocks[r]`, in the weights' frame numbers), for `rank`.
    pub fn new(weights: &ShutterWeights, blocks: &[Range<usize>], rank: usize) -> Self {
        let rows = weights.rows();
        let mut users = vec![0u32; rows];
        let mut first = vec![usize::MAX; rows];
        for (r, b) in blocks.iter().enumerate() {
            let mut touched = vec![false; rows];
            for k in b.clone() {
                for range in weights.rows_of_frame(k) {
                    range.clone().for_each(|i| touched[i] = true);
                }
            }
            for (i, &t) in touched.iter().enumerate() {
                if t {
                    users[i] += 1;
                    first[i] = first[i].min(r);
                }
            }
        }
        let shared = (0..rows).filter(|&i| users[i] > 1).collect();
        let owned = (0..rows).map(|i| if users[i] == 0 { rank == 0 } else { first[i] == rank }).collect();
        RowShare { shared, owned, rows }
    }
}

/// The block operator `A_r` of one rank, whose forward is exact on the rows the block
/// touches.
pub struct Split<'r, A> {
    /// The operator of the block's frames alone (shutter weights restricted to them).
    pub inner: A,
    pub ranks: &'r dyn Ranks,
    /// The block's frames in the whole video.
    pub frames: Range<usize>,
    pub total_frames: usize,
    share: RowShare,
    /// Per output entry: `share.owned` of its row.
    owned: Vec<bool>,
    /// The shared rows, packed for the sum.
    packed: Mutex<Vec<f32>>,
}

impl<'r, A: Operator> Split<'r, A> {
    /// `share` describes the rows of `inner`'s output (`share.rows` of the sensor).
    pub fn new(inner: A, ranks: &'r dyn Ranks, frames: Range<usize>, total_frames: usize, share: RowShare) -> Self {
        let len = inner.output_len();
        assert_eq!(len % share.rows, 0, "the output must be whole sensor rows");
        let cols = len / share.rows;
        let owned = share.owned.iter().flat_map(|&o| std::iter::repeat(o).take(cols)).collect();
        Split { inner, ranks, frames, total_frames, share, owned, packed: Mutex::new(Vec::new()) }
    }
    /// Values per frame of the input.
    pub fn frame_len(&self) -> usize {
        self.inner.input_len() / self.frames.len().max(1)
    }
    /// Offset of the block's first value in the whole video's input.
    pub fn offset(&self) -> usize {
        self.frames.start * self.frame_len()
    }
    /// How this block's vectors are spread over the ranks: sums over the input over
    /// `ranks`, sums over the output over the rows this rank counts (every output
    /// entry with one process), for the data term and the power iteration.
    pub fn partition(&self) -> Partition<'_> {
        Partition { ranks: self.ranks, owned: (self.ranks.size() > 1).then_some(&self.owned[..]) }
    }
    /// The rows summed across ranks by each forward (all of them when the shared rows
    /// are as many).
    pub fn summed_rows(&self) -> usize {
        self.share.shared.len().min(self.share.rows)
    }
}

impl<A: Operator> Operator for Split<'_, A> {
    fn input_shape(&self) -> Vec<usize> {
        self.inner.input_shape()
    }
    fn output_shape(&self) -> Vec<usize> {
        self.inner.output_shape()
    }
    fn forward(&self, x: &[f32], y: &mut [f32]) {
        self.inner.forward(x, y);
        if self.ranks.size() == 1 || self.share.shared.is_empty() {
            return;
        }
        let cols = y.len() / self.share.rows;
        if self.share.shared.len() >= self.share.rows {
            self.ranks.sum_f32(y);
            return;
        }
        let mut packed = self.packed.lock().unwrap();
        packed.clear();
        for &i in &self.share.shared {
            packed.extend_from_slice(&y[i * cols..(i + 1) * cols]);
        }
        self.ranks.sum_f32(&mut packed);
        for (j, &i) in self.share.shared.iter().enumerate() {
            y[i * cols..(i + 1) * cols].copy_from_slice(&packed[j * cols..(j + 1) * cols]);
        }
    }
    fn adjoint(&self, y: &[f32], x: &mut [f32]) {
        self.inner.adjoint(y, x);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::shutter::{ShutterMode, Timing};

    #[test]
    fn every_row_is_counted_once_and_shared_rows_are_those_of_two_blocks() {
        for mode in [ShutterMode::Rolling, ShutterMode::Dual] {
            let w = Timing::new(40, 10.0, 30.0, mode).weights().unwrap();
            let k = w.frames();
            let blocks = vec![0..k / 3, k / 3..k / 2, k / 2..k];
            let shares: Vec<RowShare> = (0..3).map(|r| RowShare::new(&w, &blocks, r)).collect();
            for i in 0..40 {
                assert_eq!(shares.iter().filter(|s| s.owned[i]).count(), 1, "{mode:?} row {i}");
            }
            assert_eq!(shares[0].shared, shares[2].shared);
            // A row is shared exactly when frames of two blocks expose it.
            for i in 0..40 {
                let users = blocks.iter().filter(|&b| b.clone().any(|f| w.rows_of_frame(f).iter().any(|r| r.contains(&i)))).count();
                assert_eq!(shares[1].shared.contains(&i), users > 1, "{mode:?} row {i}");
            }
            // Few rows cross the block edges (N_l - 1 = 2 per edge, mirrored for dual).
            assert!(shares[0].shared.len() <= 2 * 2 * 2, "{mode:?}: {:?}", shares[0].shared);
        }
    }
}
