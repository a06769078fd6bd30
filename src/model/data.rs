//! The data term apart from the operator: `0.5 ||A x - b||^2` over what a capture
//! measured. The operator ([`crate::model::op::Operator`]) is only the linear map (with
//! a capture's pixel mask, `M A`, in it); the term owns the observations `b`, the
//! entries that are only lower bounds (clipped pixels: `A x >= b` there, the loss
//! one-sided) and how the problem is spread over processes ([`Partition`]: sums over
//! the output count each entry on one rank, sums over the input are summed over the
//! ranks). Every solver minimises this term, or refuses what it cannot handle
//! ([`crate::solve::optimize::SolverKind::check_data`]).

use crate::model::ranks::{Partition, Ranks};

/// `0.5 ||A x - b||^2`, one-sided where `b` is a lower bound, over the ranks of a split
/// problem.
#[derive(Clone, Copy)]
pub struct DataTerm<'a> {
    b: &'a [f32],
    lower_bounds: Option<&'a [bool]>,
    partition: Partition<'a>,
}

impl<'a> DataTerm<'a> {
    /// Every entry of `b` an equality, one process.
    pub fn new(b: &'a [f32]) -> Self {
        DataTerm { b, lower_bounds: None, partition: Partition::ONE }
    }

    /// The term whose entries where `lower` is true are lower bounds (clipped pixels:
    /// the light was at least `b` there), the loss `0.5 max(0, b_i - (A x)_i)^2`;
    /// `None`: none.
    ///
    /// # Panics
    /// When `lower` does not have one entry per observation.
    pub fn with_lower_bounds(mut self, lower: Option<&'a [bool]>) -> Self {
        if let Some(l) = lower {
            assert_eq!(l.len(), self.b.len(), "the lower bounds must have one entry per observation");
        }
        self.lower_bounds = lower;
        self
    }

    /// The term of one rank's block of a split problem ([`crate::model::split::Split::partition`]).
    ///
    /// # Panics
    /// When the owned entries are not one per observation.
    pub fn on(mut self, partition: Partition<'a>) -> Self {
        if let Some(o) = partition.owned {
            assert_eq!(o.len(), self.b.len(), "the owned outputs must have one entry per observation");
        }
        self.partition = partition;
        self
    }

    /// The observations `b`.
    pub fn observations(&self) -> &'a [f32] {
        self.b
    }

    /// Entries that are lower bounds, when any.
    pub fn lower_bounds(&self) -> Option<&'a [bool]> {
        self.lower_bounds
    }

    /// The processes the problem's input is split across (one unless split).
    pub fn ranks(&self) -> &'a dyn Ranks {
        self.partition.ranks
    }

    /// The residual `A x - b` given `ax = A x`, with the lower-bound entries kept only
    /// where `A x` falls below `b`: the gradient of the term is `A^T` of it.
    pub fn residual_into(&self, ax: &[f32], resid: &mut [f32]) {
        for ((r, &p), &q) in resid.iter_mut().zip(ax).zip(self.b) {
            *r = p - q;
        }
        if let Some(lb) = self.lower_bounds {
            for (r, &l) in resid.iter_mut().zip(lb) {
                if l && *r > 0.0 {
                    *r = 0.0;
                }
            }
        }
    }

    /// The term's value at `ax = A x`, in f64: one-sided at the lower bounds, each entry
    /// counted on one rank and summed over the ranks.
    pub fn value(&self, ax: &[f32]) -> f64 {
        let lb = self.lower_bounds;
        let owned = self.partition.owned;
        let local = ax
            .iter()
            .zip(self.b)
            .enumerate()
            .map(|(i, (&p, &q))| {
                let r = (p - q) as f64;
                if (r > 0.0 && lb.is_some_and(|l| l[i])) || owned.is_some_and(|o| !o[i]) {
                    0.0
                } else {
                    r * r
                }
            })
            .sum::<f64>();
        let mut s = [local];
        self.partition.ranks.sum_f64(&mut s);
        0.5 * s[0]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lower_bound_counts_only_when_the_model_falls_short() {
        let b = [1.0, 2.0, 2.0];
        let lower = [false, true, true];
        let data = DataTerm::new(&b).with_lower_bounds(Some(&lower));
        // A x = (1, 3, 4): entries 1 and 2 exceed their bounds, no cost.
        let ax = [1.0, 3.0, 4.0];
        assert_eq!(data.value(&ax), 0.0);
        let mut r = [0.0; 3];
        data.residual_into(&ax, &mut r);
        assert_eq!(r, [0.0, 0.0, 0.0]);
        // A x = (0, 1, 1): below the bounds, the plain residual.
        let ax = [0.0, 1.0, 1.0];
        assert_eq!(data.value(&ax), 0.5 * (1.0 + 1.0 + 1.0));
        data.residual_into(&ax, &mut r);
        assert_eq!(r, [-1.0, -1.0, -1.0]);
        // Without bounds the same observations are a plain least-squares term.
        assert_eq!(DataTerm::new(&b).value(&[1.0, 3.0, 4.0]), 0.5 * (1.0 + 4.0));
    }

    #[test]
    fn entries_another_rank_owns_are_not_counted() {
        let b = [1.0, 2.0];
        let owned = [true, false];
        let part = Partition { ranks: &crate::model::ranks::One, owned: Some(&owned) };
        assert_eq!(DataTerm::new(&b).on(part).value(&[0.0, 0.0]), 0.5);
        assert_eq!(part.output_norm_sq(&[3.0, 4.0]), 9.0);
    }
}
