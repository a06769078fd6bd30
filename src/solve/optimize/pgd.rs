//! Plain proximal gradient (ISTA; projected gradient when the prox is a projection):
//! `x_{k+1} = prox_{R/L}(x_k - A^T(A x_k - b) / L)`, the baseline the accelerated
//! solvers are measured against. One forward and one adjoint per iteration (`A x_{k+1}`
//! serves the next gradient and the objective alike).

use crate::solve::optimize::types::{IterInfo, Observer, SolveResult, StopRule, Termination};
use crate::model::op::Operator;
use crate::solve::optimize::common::{after_iteration, gradient_start, gradient_step, half_residual_sq, rel_change, Clock};
use crate::solve::prox::tv::Prox;

#[derive(Clone, Debug)]
pub struct Pgd {
    pub lipschitz: f64,
    pub stop: StopRule,
}

impl Pgd {
    pub fn solve<A: Operator + ?Sized, R: Prox + ?Sized>(
        &self,
        op: &A,
        b: &[f32],
        reg: &R,
        x0: Option<Vec<f32>>,
        observer: &mut dyn Observer,
    ) -> SolveResult {
        let (n, m) = (op.input_len(), op.output_len());
        let mut clock = Clock::start();
        let (step, mut x, mut ax) = gradient_start(op, b, self.lipschitz, x0);
        let mut resid = vec![0.0f32; m];
        let mut grad = vec![0.0f32; n];
        let mut x_new = vec![0.0f32; n];
        let mut data = half_residual_sq(&ax, b);
        let mut regv = reg.value(&x);
        let mut termination = Termination::MaxIterations;
        let mut iterations = 0;
        for it in 1..=self.stop.max_iters {
            gradient_step(op, b, &x, &ax, step, &mut resid, &mut grad);
            reg.prox(&grad, step, &mut x_new);
            op.forward(&x_new, &mut ax);
            let d = half_residual_sq(&ax, b);
            let r = reg.value(&x_new);
            if !(d + r).is_finite() || x_new.iter().any(|v| !v.is_finite()) {
                termination = Termination::NonFinite { iteration: it };
                op.forward(&x, &mut ax);
                break;
            }
            let rel = rel_change(&x_new, &x);
            std::mem::swap(&mut x, &mut x_new);
            (data, regv, iterations) = (d, r, it);
            let seconds = clock.seconds();
            if let Some(reason) = after_iteration(&mut clock, observer, &self.stop, IterInfo { iteration: it, seconds, data_term: data, reg_term: regv, rel_change: rel, x: &x }) {
                termination = reason;
                break;
            }
        }
        SolveResult { x, iterations, seconds: clock.seconds(), termination, data_term: data, reg_term: regv }
    }
}
