//! FISTA (Beck & Teboulle 2009) for `min 0.5||A v - b||^2 + R(v)`, generic over the
//! operator and the proximal term. Stopping rules are data ([`StopRule`]), the
//! per-iteration record goes to an [`Observer`] (the trace is one), and the reason a
//! run ended is a [`Termination`].
//!
//! One forward and one adjoint per iteration: the solver keeps `A x_k` and forms
//! `A y_k = A x_k + beta (A x_k - A x_{k-1})` by linearity, so the objective at every
//! iterate `x_k` is exact and free.
//!
//! Memory: four video-sized vectors (`x`, `x_{k+1}`, `y`, the gradient), allocated
//! before the first iteration; the loop allocates nothing. Element-wise passes over the
//! video run in parallel in fixed blocks; sums are taken per block in f64 lanes and
//! added in block order, so results do not depend on the thread count. The change
//! `||x_{k+1} - x_k||`, `||x_{k+1}||` and the momentum step are one pass.

use crate::model::op::Operator;
use crate::solve::prox::tv::Prox;
use rayon::prelude::*;
use serde::Serialize;
use crate::solve::optimize::common::{after_iteration, gradient_start, gradient_step, half_residual_sq, Clock, BLOCK};
use crate::solve::optimize::types::{Observer, SolveResult, StopRule, Termination, IterInfo};

/// FISTA settings.
#[derive(Clone, Debug, Serialize)]
pub struct Fista {
    /// Lipschitz constant of the gradient of the data term (largest eigenvalue of A^T A).
    pub lipschitz: f64,
    pub stop: StopRule,
    /// Adaptive restart (O'Donoghue & Candes 2015): reset momentum when the objective
    /// increases.
    pub restart: bool,
}


/// One pass: `y = x_new + beta (x_new - x)`, and per block `(||x_new - x||^2,
/// ||x_new||^2)` into `parts` (f32 lanes over runs of 256 values, f64 beyond);
/// returns the two sums, added in block order.
fn momentum_and_change(y: &mut [f32], x_new: &[f32], x: &[f32], beta: f32, parts: &mut [[f64; 2]]) -> (f64, f64) {
    parts.par_iter_mut().zip(y.par_chunks_mut(BLOCK)).zip(x_new.par_chunks(BLOCK)).zip(x.par_chunks(BLOCK)).for_each(
        |(((part, y), xn), xo)| {
            // f32 lanes over runs of 256 values (16 terms per lane), then f64.
            let (mut d, mut q) = (0.0f64, 0.0f64);
            for ((y, xn), xo) in y.chunks_mut(256).zip(xn.chunks(256)).zip(xo.chunks(256)) {
                let (mut dl, mut ql) = ([0.0f32; 16], [0.0f32; 16]);
                for ((y, xn), xo) in y.chunks_mut(16).zip(xn.chunks(16)).zip(xo.chunks(16)) {
                    for i in 0..y.len() {
                        let diff = xn[i] - xo[i];
                        y[i] = xn[i] + beta * diff;
                        dl[i] += diff * diff;
                        ql[i] += xn[i] * xn[i];
                    }
                }
                d += dl.iter().map(|&v| v as f64).sum::<f64>();
                q += ql.iter().map(|&v| v as f64).sum::<f64>();
            }
            *part = [d, q];
        },
    );
    parts.iter().fold((0.0, 0.0), |a, p| (a.0 + p[0], a.1 + p[1]))
}

impl Fista {
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
        let mut y = x.clone();
        let mut ay = ax.clone();
        let mut x_new = vec![0.0f32; n];
        let mut ax_new = vec![0.0f32; m];
        let mut grad = vec![0.0f32; n];
        let mut resid = vec![0.0f32; m];
        let mut parts = vec![[0.0f64; 2]; n.div_ceil(BLOCK)];
        let mut t = 1.0f64;
        let mut data = half_residual_sq(&ax, b);
        let mut regv = reg.value(&x);
        let mut termination = Termination::MaxIterations;
        let mut iterations = 0;

        for it in 1..=self.stop.max_iters {
            // Gradient step at y, then prox.
            gradient_step(op, b, &y, &ay, step, &mut resid, &mut grad);
            reg.prox(&grad, step, &mut x_new);
            op.forward(&x_new, &mut ax_new);
            let data_new = half_residual_sq(&ax_new, b);
            let reg_new = reg.value(&x_new);
            let obj_new = data_new + reg_new;
            if !obj_new.is_finite() {
                termination = Termination::NonFinite { iteration: it };
                break;
            }
            let restart = self.restart && obj_new > data + regv;
            let (t_new, beta) = if restart {
                (1.0, 0.0f32)
            } else {
                let t_new = 0.5 * (1.0 + (1.0 + 4.0 * t * t).sqrt());
                (t_new, ((t - 1.0) / t_new) as f32)
            };
            // y = x_new + beta (x_new - x), with the change of the iterate; A y likewise.
            let (diff_sq, norm_sq) = momentum_and_change(&mut y, &x_new, &x, beta, &mut parts);
            let rel_change = (diff_sq / norm_sq.max(1e-300)).sqrt();
            for ((ayv, &an), &ao) in ay.iter_mut().zip(&ax_new).zip(&ax) {
                *ayv = an + beta * (an - ao);
            }
            std::mem::swap(&mut x, &mut x_new);
            std::mem::swap(&mut ax, &mut ax_new);
            t = t_new;
            data = data_new;
            regv = reg_new;
            iterations = it;

            let seconds = clock.seconds();
            if let Some(reason) = after_iteration(&mut clock, observer, &self.stop, IterInfo { iteration: it, seconds, data_term: data, reg_term: regv, rel_change, x: &x }) {
                termination = reason;
                break;
            }
        }
        SolveResult { x, iterations, seconds: clock.seconds(), termination, data_term: data, reg_term: regv }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solve::optimize::types::NoObserver;
    use crate::solve::lipschitz::power_iteration;
    use crate::model::op::{pseudo_random, Dense};
    use crate::solve::prox::tv::NonNegative;

    #[test]
    fn solves_a_nonnegative_least_squares_problem() {
        // Overdetermined, well-conditioned: FISTA must reach the known solution.
        let a = Dense { rows: 12, cols: 5, a: pseudo_random(60, 3) };
        let x_true = vec![0.0, 1.0, 2.0, 0.5, 0.0];
        let mut b = vec![0.0; 12];
        a.forward(&x_true, &mut b);
        let l = power_iteration(&a, 200, 1e-9, 1).lambda_max;
        let f = Fista { lipschitz: l * 1.01, stop: StopRule::iterations(5000), restart: true };
        let r = f.solve(&a, &b, &NonNegative, None, &mut NoObserver);
        for (x, t) in r.x.iter().zip(&x_true) {
            assert!((x - t).abs() < 1e-3, "{:?}", r.x);
        }
    }

    #[test]
    fn objective_reported_is_the_objective_at_x() {
        let a = Dense { rows: 6, cols: 4, a: pseudo_random(24, 5) };
        let b = pseudo_random(6, 6);
        let l = power_iteration(&a, 200, 1e-9, 1).lambda_max;
        let f = Fista { lipschitz: l * 1.01, stop: StopRule::iterations(30), restart: false };
        let mut seen = Vec::new();
        let mut obs = |i: &IterInfo| {
            let mut ax = vec![0.0; 6];
            a.forward(i.x, &mut ax);
            seen.push((i.data_term, half_residual_sq(&ax, &b)));
            true
        };
        f.solve(&a, &b, &NonNegative, None, &mut obs);
        for (reported, direct) in seen {
            assert!((reported - direct).abs() <= 1e-5 * direct.max(1e-12), "{reported} vs {direct}");
        }
    }

    #[test]
    fn stops_for_the_stated_reason() {
        let a = Dense { rows: 6, cols: 4, a: pseudo_random(24, 5) };
        let b = pseudo_random(6, 6);
        let l = power_iteration(&a, 200, 1e-9, 1).lambda_max;
        let f = Fista { lipschitz: l, stop: StopRule { max_iters: 100_000, rel_tol: 1e-6, time_budget_s: None }, restart: true };
        let r = f.solve(&a, &b, &NonNegative, None, &mut NoObserver);
        assert_eq!(r.termination, Termination::Converged);
        let mut count = 0;
        let mut stop_at_3 = |_: &IterInfo| {
            count += 1;
            count < 3
        };
        let r = f.solve(&a, &b, &NonNegative, None, &mut stop_at_3);
        assert_eq!((r.termination, r.iterations), (Termination::Stopped, 3));
    }

    #[test]
    fn non_finite_data_never_escapes() {
        let a = Dense { rows: 3, cols: 3, a: pseudo_random(9, 5) };
        let b = vec![1.0, f32::NAN, 0.0];
        let f = Fista { lipschitz: 10.0, stop: StopRule::iterations(10), restart: false };
        let r = f.solve(&a, &b, &NonNegative, None, &mut NoObserver);
        assert_eq!(r.termination, Termination::NonFinite { iteration: 1 });
        assert!(r.x.iter().all(|v| v.is_finite()));
    }
}
