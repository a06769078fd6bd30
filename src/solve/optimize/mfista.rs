//! Monotone FISTA (MFISTA, Beck & Teboulle, IEEE TIP 2009): the accelerated step is
//! taken only when it does not raise the objective; otherwise the iterate stays and the
//! momentum carries the rejected point. The objective is non-increasing by
//! construction, even with an inexact prox (the Haar map, or the dual map with few
//! inner iterations) under which FISTA, with or without restart, can rise. One forward
//! and one adjoint per iteration: `A y` is formed by linearity.

use crate::solve::optimize::types::{IterInfo, Observer, SolveResult, StopRule, Termination};
use crate::model::op::Operator;
use crate::solve::optimize::common::{after_iteration, gradient_start, gradient_step, half_residual_sq, rel_change, Clock};
use crate::solve::prox::tv::Prox;

#[derive(Clone, Debug)]
pub struct MFista {
    pub lipschitz: f64,
    pub stop: StopRule,
}

impl MFista {
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
        let (mut y, mut ay) = (x.clone(), ax.clone());
        let (mut z, mut az) = (vec![0.0f32; n], vec![0.0f32; m]);
        let (mut resid, mut grad) = (vec![0.0f32; m], vec![0.0f32; n]);
        let mut t = 1.0f64;
        let mut data = half_residual_sq(&ax, b);
        let mut regv = reg.value(&x);
        let mut termination = Termination::MaxIterations;
        let mut iterations = 0;
        for it in 1..=self.stop.max_iters {
            gradient_step(op, b, &y, &ay, step, &mut resid, &mut grad);
            reg.prox(&grad, step, &mut z);
            op.forward(&z, &mut az);
            let (dz, rz) = (half_residual_sq(&az, b), reg.value(&z));
            if !(dz + rz).is_finite() || z.iter().any(|v| !v.is_finite()) {
                termination = Termination::NonFinite { iteration: it };
                break;
            }
            let accept = dz + rz <= data + regv;
            // Change measured on the proposed step (x itself stays when it is rejected).
            let rel = rel_change(&z, &x);
            let t_new = 0.5 * (1.0 + (1.0 + 4.0 * t * t).sqrt());
            let (c1, c2) = ((t / t_new) as f32, ((t - 1.0) / t_new) as f32);
            if accept {
                // x_new = z: y = z + c2 (z - x).
                for ((yv, &zv), &xo) in y.iter_mut().zip(&z).zip(&x) {
                    *yv = zv + c2 * (zv - xo);
                }
                for ((a, &zv), &xo) in ay.iter_mut().zip(&az).zip(&ax) {
                    *a = zv + c2 * (zv - xo);
                }
                std::mem::swap(&mut x, &mut z);
                std::mem::swap(&mut ax, &mut az);
                (data, regv) = (dz, rz);
            } else {
                // x stays: y = x + c1 (z - x).
                for ((yv, &zv), &xv) in y.iter_mut().zip(&z).zip(&x) {
                    *yv = xv + c1 * (zv - xv);
                }
                for ((a, &zv), &xv) in ay.iter_mut().zip(&az).zip(&ax) {
                    *a = xv + c1 * (zv - xv);
                }
            }
            t = t_new;
            iterations = it;
            let seconds = clock.seconds();
            if let Some(reason) = after_iteration(&mut clock, observer, &self.stop, IterInfo { iteration: it, seconds, data_term: data, reg_term: regv, rel_change: rel, x: &x }) {
                termination = reason;
                break;
            }
        }
        SolveResult { x, iterations, seconds: clock.seconds(), termination, data_term: data, reg_term: regv }
    }
}
