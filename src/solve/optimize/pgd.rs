//! Plain proximal gradient (ISTA; projected gradient when the prox is a projection):
//! `x_{k+1} = prox_{R/L}(x_k - A^T(A x_k - b) / L)`, the baseline the accelerated
//! solvers are measured against. One forward and one adjoint per iteration (`A x_{k+1}`
//! serves the next gradient and the objective alike).
//!
//! A [`Step`] run by the executor (clock, [`StopRule`], the non-finite check of the
//! proposal's objective and elements, the [`Observer`] calls, the [`SolveResult`]).

use crate::model::data::DataTerm;
use crate::model::op::Operator;
use crate::model::ranks::Ranks;
use crate::solve::optimize::common::{gradient_start, gradient_step, rel_change};
use crate::solve::optimize::executor::{run, Accepted, Objective, Step};
use crate::solve::optimize::types::{Observer, SolveResult, StopRule};
use crate::solve::prox::Prox;

#[derive(Clone, Debug)]
pub struct Pgd {
    pub lipschitz: f64,
    pub stop: StopRule,
}

impl Pgd {
    pub fn solve<A: Operator + ?Sized, R: Prox + ?Sized>(
        &self,
        op: &A,
        data: &DataTerm,
        reg: &R,
        x0: Option<Vec<f32>>,
        observer: &mut dyn Observer,
    ) -> SolveResult {
        run(&self.stop, observer, || PgdStep::new(op, *data, reg, self.lipschitz, x0))
    }
}

/// PGD's state between iterations: the iterate `x`; `x_new` holds the proposal. `ax`
/// is `A x` before `propose` and `A x_new` after it (one measurement-sized buffer).
struct PgdStep<'a, A: ?Sized, R: ?Sized> {
    op: &'a A,
    data: DataTerm<'a>,
    reg: &'a R,
    step: f32,
    x: Vec<f32>,
    ax: Vec<f32>,
    resid: Vec<f32>,
    grad: Vec<f32>,
    x_new: Vec<f32>,
}

impl<'a, A: Operator + ?Sized, R: Prox + ?Sized> PgdStep<'a, A, R> {
    fn new(op: &'a A, data: DataTerm<'a>, reg: &'a R, lipschitz: f64, x0: Option<Vec<f32>>) -> (Self, Objective) {
        let (n, m) = (op.input_len(), op.output_len());
        let (step, x, ax) = gradient_start(op, &data, lipschitz, x0);
        let resid = vec![0.0f32; m];
        let grad = vec![0.0f32; n];
        let x_new = vec![0.0f32; n];
        let objective = Objective { data_term: data.value(&ax), reg_term: reg.value(&x) };
        (PgdStep { op, data, reg, step, x, ax, resid, grad, x_new }, objective)
    }
}

impl<A: Operator + ?Sized, R: Prox + ?Sized> Step for PgdStep<'_, A, R> {
    fn propose(&mut self, _: usize) -> Objective {
        gradient_step(self.op, &self.data, &self.x, &self.ax, self.step, &mut self.resid, &mut self.grad);
        self.reg.prox(&self.grad, self.step, &mut self.x_new);
        self.op.forward(&self.x_new, &mut self.ax);
        Objective { data_term: self.data.value(&self.ax), reg_term: self.reg.value(&self.x_new) }
    }

    fn proposal(&self) -> &[f32] {
        &self.x_new
    }

    fn accept(&mut self, _: usize, _: Objective, proposed: Objective) -> Accepted {
        let rel = rel_change(&self.x_new, &self.x, self.data.ranks());
        std::mem::swap(&mut self.x, &mut self.x_new);
        Accepted { objective: proposed, rel_change: rel }
    }

    // `abandon` keeps the default: `x` was not touched (`ax` now holds `A x_new`, which
    // nothing reads once the run ends).

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
