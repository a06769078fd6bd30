//! Plain proximal gradient (ISTA; projected gradient when the prox is a projection):
//! `x_{k+1} = prox_{R/L}(x_k - A^T(A x_k - b) / L)`, the baseline the accelerated
//! solvers are measured against. One forward and one adjoint per iteration (`A x_{k+1}`
//! serves the next gradient and the objective alike).

use crate::fista::{IterInfo, Observer, SolveResult, StopRule, Termination};
use crate::op::Operator;
use crate::solver::{half_residual_sq, rel_change, stop_reason, Clock};
use crate::tv::Prox;

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
        assert_eq!(b.len(), m, "measurement size must match the operator's output");
        assert!(self.lipschitz.is_finite() && self.lipschitz > 0.0, "Lipschitz constant must be positive");
        let step = (1.0 / self.lipschitz) as f32;
        let mut clock = Clock::start();
        let mut x = x0.unwrap_or_else(|| vec![0.0; n]);
        assert_eq!(x.len(), n);
        let mut ax = vec![0.0f32; m];
        op.forward(&x, &mut ax);
        let mut resid = vec![0.0f32; m];
        let mut grad = vec![0.0f32; n];
        let mut x_new = vec![0.0f32; n];
        let mut data = half_residual_sq(&ax, b);
        let mut regv = reg.value(&x);
        let mut termination = Termination::MaxIterations;
        let mut iterations = 0;
        for it in 1..=self.stop.max_iters {
            for ((r, &p), &q) in resid.iter_mut().zip(&ax).zip(b) {
                *r = p - q;
            }
            op.adjoint(&resid, &mut grad);
            for (g, &xv) in grad.iter_mut().zip(&x) {
                *g = xv - step * *g;
            }
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
            let go = clock.off(|| observer.observe(&IterInfo { iteration: it, seconds, data_term: data, reg_term: regv, rel_change: rel, x: &x }));
            if !go {
                termination = Termination::Stopped;
                break;
            }
            if let Some(t) = stop_reason(&self.stop, rel, seconds) {
                termination = t;
                break;
            }
        }
        SolveResult { x, iterations, seconds: clock.seconds(), termination, data_term: data, reg_term: regv }
    }
}
