//! One rank's block of a split problem: the frames `frames` of a `total_frames` video,
//! on a process that holds only those. The imaging model is a sum over frames, so the
//! full `A v` is the sum over ranks of each block's `A_r v_r`: the forward adds the
//! blocks' sensor images over the ranks ([`Ranks::sum_f32`]); the adjoint of a sensor
//! image every rank holds is local (`A_r^T y`, the block's frames of `A^T y`).

use crate::model::op::Operator;
use crate::model::ranks::Ranks;
use std::ops::Range;

/// The block operator `A_r` of one rank, whose forward returns the full `A v`.
pub struct Split<'r, A> {
    /// The operator of the block's frames alone (shutter weights restricted to them).
    pub inner: A,
    pub ranks: &'r dyn Ranks,
    /// The block's frames in the whole video.
    pub frames: Range<usize>,
    pub total_frames: usize,
}

impl<A: Operator> Split<'_, A> {
    /// Values per frame of the input.
    pub fn frame_len(&self) -> usize {
        self.inner.input_len() / self.frames.len().max(1)
    }
    /// Offset of the block's first value in the whole video's input.
    pub fn offset(&self) -> usize {
        self.frames.start * self.frame_len()
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
        self.ranks.sum_f32(y);
    }
    fn adjoint(&self, y: &[f32], x: &mut [f32]) {
        self.inner.adjoint(y, x);
    }
    fn lower_bounds(&self) -> Option<&[bool]> {
        self.inner.lower_bounds()
    }
    fn ranks(&self) -> &dyn Ranks {
        self.ranks
    }
}
