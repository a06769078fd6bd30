//! Helpers the solver steps share: the start and the gradient step of the gradient
//! methods, the residual and change norms. The loop around the steps (clock, stopping
//! rules, non-finite check, observers) is the executor's.

use crate::model::data::DataTerm;
use crate::model::op::Operator;
use crate::model::ranks::Ranks;
use crate::solve::metric::FrameMetric;

/// Elements per parallel block of the element-wise passes.
pub(crate) const BLOCK: usize = 1 << 15;

/// The start shared by the gradient methods (FISTA, MFISTA, PGD): checks the sizes and
/// the Lipschitz constant, returns the step `1/L`, the start `x0` (zeros when `None`)
/// and `A x0`.
pub(crate) fn gradient_start<A: Operator + ?Sized>(op: &A, data: &DataTerm, lipschitz: f64, x0: Option<Vec<f32>>) -> (f32, Vec<f32>, Vec<f32>) {
    let (n, m) = (op.input_len(), op.output_len());
    assert_eq!(data.observations().len(), m, "measurement size must match the operator's output");
    assert!(lipschitz.is_finite() && lipschitz > 0.0, "Lipschitz constant must be positive");
    let x = x0.unwrap_or_else(|| vec![0.0; n]);
    assert_eq!(x.len(), n);
    let mut ax = vec![0.0f32; m];
    op.forward(&x, &mut ax);
    ((1.0 / lipschitz) as f32, x, ax)
}

/// The gradient step of the data term at `y`, given `A y`:
/// `out = y - step A^T (A y - b)` (one-sided at the term's lower bounds);
/// `resid` is scratch of the measurement's size. Element-wise passes in parallel
/// blocks; no allocation.
pub(crate) fn gradient_step<A: Operator + ?Sized>(op: &A, data: &DataTerm, y: &[f32], ay: &[f32], step: f32, resid: &mut [f32], out: &mut [f32]) {
    gradient_step_in(op, data, (y, ay), (step, None), resid, out)
}

/// [`gradient_step`] in a per-frame metric when given: `out = y - step P^{-1} A^T (A y -
/// b)`, frame `k`'s step `step / d_k`. `(y, ay)`: the point and `A y`; `(step, metric)`:
/// the step and the metric it is taken in.
pub(crate) fn gradient_step_in<A: Operator + ?Sized>(
    op: &A,
    data: &DataTerm,
    (y, ay): (&[f32], &[f32]),
    (step, metric): (f32, Option<&FrameMetric>),
    resid: &mut [f32],
    out: &mut [f32],
) {
    use rayon::prelude::*;
    data.residual_into(ay, resid);
    op.adjoint(resid, out);
    let descend = |g: &mut [f32], y: &[f32], step: f32| {
        for (g, &y) in g.iter_mut().zip(y) {
            *g = y - step * *g;
        }
    };
    match metric {
        None => out.par_chunks_mut(BLOCK).zip(y.par_chunks(BLOCK)).for_each(|(g, y)| descend(g, y, step)),
        Some(m) => out.par_chunks_mut(m.frame_len()).zip(y.par_chunks(m.frame_len())).zip(m.inverse()).for_each(|((g, y), &w)| descend(g, y, step * w)),
    }
}

/// `||a - b|| / ||a||` in f64, the norms over `ranks` when the vectors are a rank's
/// block ([`DataTerm::ranks`]).
pub(crate) fn rel_change(new: &[f32], old: &[f32], ranks: &dyn Ranks) -> f64 {
    let mut s = [0.0f64; 2];
    for (&a, &b) in new.iter().zip(old) {
        s[0] += ((a - b) as f64).powi(2);
        s[1] += (a as f64).powi(2);
    }
    ranks.sum_f64(&mut s);
    (s[0] / s[1].max(1e-300)).sqrt()
}

/// FISTA's momentum step after an iteration from `t` (Beck & Teboulle 2009): the next
/// `t` and the extrapolation weight `beta = (t - 1) / t_next`; a restart (O'Donoghue &
/// Candes 2015) starts again at `t = 1`, `beta = 0`. The CPU and device steps share it.
pub(crate) fn fista_momentum(t: f64, restart: bool) -> (f64, f32) {
    if restart {
        (1.0, 0.0)
    } else {
        let t_new = 0.5 * (1.0 + (1.0 + 4.0 * t * t).sqrt());
        (t_new, ((t - 1.0) / t_new) as f32)
    }
}
