//! Monotone FISTA (MFISTA, Beck & Teboulle, IEEE TIP 2009): the accelerated step is
//! taken only when it does not raise the objective; otherwise the iterate stays and the
//! momentum carries the rejected point. The objective is non-increasing by
//! construction, even with an inexact prox (the Haar map, or the dual map with few
//! inner iterations) under which FISTA, with or without restart, can rise. One forward
//! and one adjoint per iteration: `A y` is formed by linearity.
//!
//! A [`Step`] run by the executor (clock, [`StopRule`], the non-finite check of the
//! proposal's objective and elements, the [`Observer`] calls, the [`SolveResult`]).
//! The reported change is that of the proposal against the current iterate, also when
//! the proposal is rejected.

use crate::model::data::DataTerm;
use crate::model::op::Operator;
use crate::model::ranks::Ranks;
use crate::solve::optimize::common::{gradient_start, gradient_step, rel_change};
use crate::solve::optimize::executor::{run, Accepted, Objective, Step};
use crate::solve::optimize::types::{Observer, SolveResult, StopRule};
use crate::solve::prox::Prox;

#[derive(Clone, Debug)]
pub struct MFista {
    pub lipschitz: f64,
    pub stop: StopRule,
}

impl MFista {
    pub fn solve<A: Operator + ?Sized, R: Prox + ?Sized>(
        &self,
        op: &A,
        data: &DataTerm,
        reg: &R,
        x0: Option<Vec<f32>>,
        observer: &mut dyn Observer,
    ) -> SolveResult {
        run(&self.stop, observer, || MFistaStep::new(op, *data, reg, self.lipschitz, x0))
    }
}

/// MFISTA's state between iterations: the iterate `x` and `A x`, the extrapolated point
/// `y` and `A y`, the momentum `t`; `z`, `A z` hold the proposal.
struct MFistaStep<'a, A: ?Sized, R: ?Sized> {
    op: &'a A,
    data: DataTerm<'a>,
    reg: &'a R,
    step: f32,
    x: Vec<f32>,
    ax: Vec<f32>,
    y: Vec<f32>,
    ay: Vec<f32>,
    z: Vec<f32>,
    az: Vec<f32>,
    resid: Vec<f32>,
    grad: Vec<f32>,
    t: f64,
}

impl<'a, A: Operator + ?Sized, R: Prox + ?Sized> MFistaStep<'a, A, R> {
    fn new(op: &'a A, data: DataTerm<'a>, reg: &'a R, lipschitz: f64, x0: Option<Vec<f32>>) -> (Self, Objective) {
        let (n, m) = (op.input_len(), op.output_len());
        let (step, x, ax) = gradient_start(op, &data, lipschitz, x0);
        let (y, ay) = (x.clone(), ax.clone());
        let (z, az) = (vec![0.0f32; n], vec![0.0f32; m]);
        let (resid, grad) = (vec![0.0f32; m], vec![0.0f32; n]);
        let objective = Objective { data_term: data.value(&ax), reg_term: reg.value(&x) };
        (MFistaStep { op, data, reg, step, x, ax, y, ay, z, az, resid, grad, t: 1.0 }, objective)
    }
}

impl<A: Operator + ?Sized, R: Prox + ?Sized> Step for MFistaStep<'_, A, R> {
    fn propose(&mut self, _: usize) -> Objective {
        gradient_step(self.op, &self.data, &self.y, &self.ay, self.step, &mut self.resid, &mut self.grad);
        self.reg.prox(&self.grad, self.step, &mut self.z);
        self.op.forward(&self.z, &mut self.az);
        Objective { data_term: self.data.value(&self.az), reg_term: self.reg.value(&self.z) }
    }

    fn proposal(&self) -> &[f32] {
        &self.z
    }

    fn accept(&mut self, _: usize, current: Objective, proposed: Objective) -> Accepted {
        let MFistaStep { x, ax, y, ay, z, az, t, .. } = self;
        let accept = proposed.total() <= current.total();
        // Change measured on the proposed step (x itself stays when it is rejected).
        let rel = rel_change(z, x, self.data.ranks());
        let t_new = 0.5 * (1.0 + (1.0 + 4.0 * *t * *t).sqrt());
        let (c1, c2) = ((*t / t_new) as f32, ((*t - 1.0) / t_new) as f32);
        let objective = if accept {
            // x_new = z: y = z + c2 (z - x).
            for ((yv, &zv), &xo) in y.iter_mut().zip(z.iter()).zip(x.iter()) {
                *yv = zv + c2 * (zv - xo);
            }
            for ((a, &zv), &xo) in ay.iter_mut().zip(az.iter()).zip(ax.iter()) {
                *a = zv + c2 * (zv - xo);
            }
            std::mem::swap(x, z);
            std::mem::swap(ax, az);
            proposed
        } else {
            // x stays: y = x + c1 (z - x).
            for ((yv, &zv), &xv) in y.iter_mut().zip(z.iter()).zip(x.iter()) {
                *yv = xv + c1 * (zv - xv);
            }
            for ((a, &zv), &xv) in ay.iter_mut().zip(az.iter()).zip(ax.iter()) {
                *a = xv + c1 * (zv - xv);
            }
            current
        };
        *t = t_new;
        Accepted { objective, rel_change: rel }
    }

    fn x(&self) -> &[f32] {
        &self.x
    }

    fn into_x(self) -> Vec<f32> {
        self.x
    }

    fn ranks(&self) -> &dyn Ranks {
        self.data.ranks()
    }
}
