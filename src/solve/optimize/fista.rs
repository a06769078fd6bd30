//! FISTA (Beck & Teboulle 2009) for `min 0.5||A v - b||^2 + R(v)`, generic over the
//! operator and the proximal term, with optional adaptive restart: a [`Step`] run by
//! the executor, which owns the loop (clock, [`StopRule`], the non-finite check,
//! the [`Observer`] calls, the [`SolveResult`]).
//!
//! One forward and one adjoint per iteration: the step keeps `A x_k` and forms
//! `A y_k = A x_k + beta (A x_k - A x_{k-1})` by linearity, so the objective at every
//! iterate `x_k` is exact and free. The non-finite check looks at the objective only
//! (no extra pass over the video for the iterate's elements).
//!
//! Memory: four video-sized vectors (`x`, `x_{k+1}`, `y`, the gradient), allocated
//! before the first iteration; an iteration allocates nothing. Element-wise passes over
//! the video run in parallel in fixed blocks; sums are taken per block in f64 lanes and
//! added in block order, so results do not depend on the thread count. The change
//! `||x_{k+1} - x_k||`, `||x_{k+1}||` and the momentum step are one pass.

use crate::model::data::DataTerm;
use crate::model::op::Operator;
use crate::model::ranks::Ranks;
use crate::solve::metric::FrameMetric;
use crate::solve::optimize::common::{fista_momentum, gradient_start, gradient_step_in, BLOCK};
use crate::solve::optimize::executor::{run, Accepted, Objective, Step};
use crate::solve::optimize::types::{Observer, SolveResult, StopRule};
use crate::solve::prox::Prox;
use rayon::prelude::*;
use serde::Serialize;

/// FISTA settings.
#[derive(Clone, Debug, Serialize)]
pub struct Fista {
    /// Lipschitz constant of the gradient of the data term (largest eigenvalue of A^T A).
    pub lipschitz: f64,
    pub stop: StopRule,
    /// Adaptive restart (O'Donoghue & Candes 2015): reset momentum when the test says
    /// the last step went uphill (`None`: plain FISTA). The CUDA step judges the
    /// objective whichever test is given.
    pub restart: Option<RestartTest>,
}

/// When adaptive restart resets the momentum (O'Donoghue & Candes 2015).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RestartTest {
    /// When the objective rose: `F(x_{k+1}) > F(x_k)`.
    #[default]
    Objective,
    /// When the step went against the momentum: `(y_k - x_{k+1}) . (x_{k+1} - x_k) > 0`.
    /// Blind to the objective's value, so a step the TV map makes non-monotone (the
    /// Haar map is not the exact prox of the TV the objective measures) does not reset
    /// the momentum every iteration; one extra pass over three vectors per iteration.
    Gradient,
}

/// One pass: `y = x_new + beta (x_new - x)`, and per block `(||x_new - x||^2,
/// ||x_new||^2, (y - x_new) . (x_new - x))` into `parts` (the last with the `y` before
/// this pass: the gradient restart test, [`RestartTest::Gradient`]; f32 lanes over runs
/// of 256 values, f64 beyond); returns the three sums, added in block order.
fn momentum_and_change(y: &mut [f32], x_new: &[f32], x: &[f32], beta: f32, parts: &mut [[f64; 3]]) -> [f64; 3] {
    parts.par_iter_mut().zip(y.par_chunks_mut(BLOCK)).zip(x_new.par_chunks(BLOCK)).zip(x.par_chunks(BLOCK)).for_each(|(((part, y), xn), xo)| {
        // f32 lanes over runs of 256 values (16 terms per lane), then f64.
        let mut sums = [0.0f64; 3];
        for ((y, xn), xo) in y.chunks_mut(256).zip(xn.chunks(256)).zip(xo.chunks(256)) {
            let (mut dl, mut ql, mut gl) = ([0.0f32; 16], [0.0f32; 16], [0.0f32; 16]);
            for ((y, xn), xo) in y.chunks_mut(16).zip(xn.chunks(16)).zip(xo.chunks(16)) {
                for i in 0..y.len() {
                    let diff = xn[i] - xo[i];
                    gl[i] += (y[i] - xn[i]) * diff;
                    y[i] = xn[i] + beta * diff;
                    dl[i] += diff * diff;
                    ql[i] += xn[i] * xn[i];
                }
            }
            for (s, l) in sums.iter_mut().zip([dl, ql, gl]) {
                *s += l.iter().map(|&v| v as f64).sum::<f64>();
            }
        }
        *part = sums;
    });
    parts.iter().fold([0.0; 3], |a, p| [a[0] + p[0], a[1] + p[1], a[2] + p[2]])
}

impl Fista {
    pub fn solve<A: Operator + ?Sized, R: Prox + ?Sized>(
        &self,
        op: &A,
        data: &DataTerm,
        reg: &R,
        x0: Option<Vec<f32>>,
        observer: &mut dyn Observer,
    ) -> SolveResult {
        run(&self.stop, observer, || FistaStep::new(op, *data, reg, self.lipschitz, self.restart, None, x0))
    }

    /// FISTA in the per-frame metric `P` ([`crate::solve::metric`]): the gradient step
    /// `P^{-1} grad / L`, the prox in the metric. `self.lipschitz` must be that of the
    /// metric (`lambda_max(P^{-1/2} A^T A P^{-1/2})`, [`crate::solve::metric::FrameScaled`]).
    ///
    /// # Panics
    /// When the prior has no map in a metric ([`Prox::metric_prox`]) or the metric's
    /// frames do not cover the video.
    pub fn solve_in<A: Operator + ?Sized, R: Prox + ?Sized>(
        &self,
        metric: &FrameMetric,
        op: &A,
        data: &DataTerm,
        reg: &R,
        x0: Option<Vec<f32>>,
        observer: &mut dyn Observer,
    ) -> SolveResult {
        assert!(reg.metric_prox().is_some(), "the prior has no proximal map in a frame metric");
        assert_eq!(metric.frames() * metric.frame_len(), op.input_len(), "the metric's frames must cover the video");
        run(&self.stop, observer, || FistaStep::new(op, *data, reg, self.lipschitz, self.restart, Some(metric), x0))
    }
}

/// FISTA's state between iterations: the iterate `x` and `A x`, the extrapolated point
/// `y` and `A y`, the momentum `t`; `x_new`, `A x_new` hold the proposal.
struct FistaStep<'a, A: ?Sized, R: ?Sized> {
    op: &'a A,
    data: DataTerm<'a>,
    reg: &'a R,
    restart: Option<RestartTest>,
    /// The per-frame metric of the steps (`None`: plain steps).
    metric: Option<&'a FrameMetric>,
    step: f32,
    x: Vec<f32>,
    ax: Vec<f32>,
    y: Vec<f32>,
    ay: Vec<f32>,
    x_new: Vec<f32>,
    ax_new: Vec<f32>,
    grad: Vec<f32>,
    resid: Vec<f32>,
    parts: Vec<[f64; 3]>,
    t: f64,
}

impl<'a, A: Operator + ?Sized, R: Prox + ?Sized> FistaStep<'a, A, R> {
    fn new(
        op: &'a A,
        data: DataTerm<'a>,
        reg: &'a R,
        lipschitz: f64,
        restart: Option<RestartTest>,
        metric: Option<&'a FrameMetric>,
        x0: Option<Vec<f32>>,
    ) -> (Self, Objective) {
        let (n, m) = (op.input_len(), op.output_len());
        let (step, x, ax) = gradient_start(op, &data, lipschitz, x0);
        let y = x.clone();
        let ay = ax.clone();
        let x_new = vec![0.0f32; n];
        let ax_new = vec![0.0f32; m];
        let grad = vec![0.0f32; n];
        let resid = vec![0.0f32; m];
        let parts = vec![[0.0f64; 3]; n.div_ceil(BLOCK)];
        let objective = Objective { data_term: data.value(&ax), reg_term: reg.value(&x) };
        (FistaStep { op, data, reg, restart, metric, step, x, ax, y, ay, x_new, ax_new, grad, resid, parts, t: 1.0 }, objective)
    }
}

impl<A: Operator + ?Sized, R: Prox + ?Sized> Step for FistaStep<'_, A, R> {
    const CHECK_ITERATE: bool = false;

    fn propose(&mut self, _: usize) -> Objective {
        // Gradient step at y, then prox.
        gradient_step_in(self.op, &self.data, (&self.y, &self.ay), (self.step, self.metric), &mut self.resid, &mut self.grad);
        match self.metric {
            None => self.reg.prox(&self.grad, self.step, &mut self.x_new),
            Some(m) => self.reg.metric_prox().expect("checked in solve_in").prox_in(&self.grad, self.step, m, &mut self.x_new),
        }
        self.op.forward(&self.x_new, &mut self.ax_new);
        Objective { data_term: self.data.value(&self.ax_new), reg_term: self.reg.value(&self.x_new) }
    }

    fn proposal(&self) -> &[f32] {
        &self.x_new
    }

    fn accept(&mut self, _: usize, current: Objective, proposed: Objective) -> Accepted {
        let t = self.t;
        // The objective test decides before the pass; the gradient test reads the old
        // `y` in it, so the pass takes FISTA's step and a restart then sets `y = x_new`
        // (the step with beta = 0).
        let objective_uphill = self.restart == Some(RestartTest::Objective) && proposed.total() > current.total();
        let (mut t_new, mut beta) = fista_momentum(t, objective_uphill);
        // y = x_new + beta (x_new - x), with the change of the iterate; A y likewise.
        // Over every rank's block when the video is split (one process: as is).
        let mut sums = momentum_and_change(&mut self.y, &self.x_new, &self.x, beta, &mut self.parts);
        self.data.ranks().sum_f64(&mut sums);
        let [diff_sq, norm_sq, against] = sums;
        if self.restart == Some(RestartTest::Gradient) && against > 0.0 {
            (t_new, beta) = fista_momentum(t, true);
            self.y.copy_from_slice(&self.x_new);
        }
        let rel_change = (diff_sq / norm_sq.max(1e-300)).sqrt();
        for ((ayv, &an), &ao) in self.ay.iter_mut().zip(&self.ax_new).zip(&self.ax) {
            *ayv = an + beta * (an - ao);
        }
        std::mem::swap(&mut self.x, &mut self.x_new);
        std::mem::swap(&mut self.ax, &mut self.ax_new);
        self.t = t_new;
        Accepted { objective: proposed, rel_change }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::op::{pseudo_random, Dense};
    use crate::solve::lipschitz::power_iteration;
    use crate::solve::optimize::types::{IterInfo, NoObserver, Termination};
    use crate::solve::prox::tv::NonNegative;

    #[test]
    fn solves_a_nonnegative_least_squares_problem_under_either_restart_test() {
        // Overdetermined, well-conditioned: FISTA must reach the known solution.
        let a = Dense { rows: 12, cols: 5, a: pseudo_random(60, 3) };
        let x_true = vec![0.0, 1.0, 2.0, 0.5, 0.0];
        let mut b = vec![0.0; 12];
        a.forward(&x_true, &mut b);
        let l = power_iteration(&a, 200, 1e-9, 1).lambda_max;
        for test in [RestartTest::Objective, RestartTest::Gradient] {
            let f = Fista { lipschitz: l * 1.01, stop: StopRule::iterations(5000), restart: Some(test) };
            let r = f.solve(&a, &DataTerm::new(&b), &NonNegative, None, &mut NoObserver);
            for (x, t) in r.x.iter().zip(&x_true) {
                assert!((x - t).abs() < 1e-3, "{test:?}: {:?}", r.x);
            }
        }
    }

    #[test]
    fn the_gradient_restart_test_fires_only_against_the_momentum() {
        // Over more values than one block of lanes: a step along the momentum (y behind
        // x_new, x_new ahead of x) is downhill, a step back is uphill.
        let n = 3 * BLOCK + 17;
        let (x, x_new) = (vec![0.0f32; n], vec![1.0f32; n]);
        let mut parts = vec![[0.0f64; 3]; n.div_ceil(BLOCK)];
        for (y0, sign) in [(0.5f32, -1.0), (1.5, 1.0)] {
            let mut y = vec![y0; n];
            let [diff_sq, norm_sq, against] = momentum_and_change(&mut y, &x_new, &x, 0.25, &mut parts);
            assert!((against - sign * 0.5 * n as f64).abs() < 1e-6 * n as f64, "y = {y0}: {against}");
            assert!((diff_sq - n as f64).abs() < 1e-6 * n as f64 && (norm_sq - n as f64).abs() < 1e-6 * n as f64);
            // The same pass took the momentum step.
            assert!(y.iter().all(|&v| v == 1.25), "y = x_new + beta (x_new - x)");
        }
    }

    #[test]
    fn objective_reported_is_the_objective_at_x() {
        let a = Dense { rows: 6, cols: 4, a: pseudo_random(24, 5) };
        let b = pseudo_random(6, 6);
        let l = power_iteration(&a, 200, 1e-9, 1).lambda_max;
        let f = Fista { lipschitz: l * 1.01, stop: StopRule::iterations(30), restart: None };
        let mut seen = Vec::new();
        let mut obs = |i: &IterInfo| {
            let mut ax = vec![0.0; 6];
            a.forward(i.x, &mut ax);
            seen.push((i.data_term, DataTerm::new(&b).value(&ax)));
            true
        };
        f.solve(&a, &DataTerm::new(&b), &NonNegative, None, &mut obs);
        for (reported, direct) in seen {
            assert!((reported - direct).abs() <= 1e-5 * direct.max(1e-12), "{reported} vs {direct}");
        }
    }

    #[test]
    fn stops_for_the_stated_reason() {
        let a = Dense { rows: 6, cols: 4, a: pseudo_random(24, 5) };
        let b = pseudo_random(6, 6);
        let l = power_iteration(&a, 200, 1e-9, 1).lambda_max;
        let f = Fista {
            lipschitz: l,
            stop: StopRule { max_iters: 100_000, rel_tol: 1e-6, time_budget_s: None, obj_tol: 0.0, noise_floor: None, wait_for_iterate: true },
            restart: Some(RestartTest::Objective),
        };
        let r = f.solve(&a, &DataTerm::new(&b), &NonNegative, None, &mut NoObserver);
        assert_eq!(r.termination, Termination::Converged);
        let mut count = 0;
        let mut stop_at_3 = |_: &IterInfo| {
            count += 1;
            count < 3
        };
        let r = f.solve(&a, &DataTerm::new(&b), &NonNegative, None, &mut stop_at_3);
        assert_eq!((r.termination, r.iterations), (Termination::Stopped, 3));
    }

    #[test]
    fn non_finite_data_never_escapes() {
        let a = Dense { rows: 3, cols: 3, a: pseudo_random(9, 5) };
        let b = vec![1.0, f32::NAN, 0.0];
        let f = Fista { lipschitz: 10.0, stop: StopRule::iterations(10), restart: None };
        let r = f.solve(&a, &DataTerm::new(&b), &NonNegative, None, &mut NoObserver);
        assert_eq!(r.termination, Termination::NonFinite { iteration: 1 });
        assert!(r.x.iter().all(|v| v.is_finite()));
    }
}
