//! ADMM with the DiffuserCam variable splitting (Antipa et al., Optica 2018), for
//! `min 0.5||A v - b||^2 + tau sum_a w_a |D_a v|_1 + [v >= 0]`:
//! `u_a = w_a D_a v` (TV, shrunk exactly) and `w = v` (non-negativity, clamped), with
//! scaled duals `eta_a`, `rho` and penalties `mu_tv`, `mu_nn`.
//!
//! ## The v-update
//! `(A^T A + mu_tv sum_a w_a^2 D_a^T D_a + mu_nn I) v = A^T b + mu_tv sum_a w_a D_a^T (u_a - eta_a) + mu_nn (w - rho)`.
//! In DiffuserCam this system is diagonal in Fourier space because the convolution is
//! circular on a padded grid, the crop is split off as a third variable, and the
//! differences are periodic. Our operator sums per-frame *linear* convolutions gated
//! row by row by the shutter, and the TV differences stop at the borders (the model the
//! other solvers minimise); a Fourier solve would change the problem. So the system is
//! solved by a few conjugate-gradient steps, warm-started at the current `v`, on the
//! exact operator: ADMM then minimises the same objective as FISTA and PGD. `A v` and
//! `A^T A v` are carried along by linearity (re-synchronised every `resync_every`
//! iterations against f32 drift), so one CG step costs one forward and one adjoint, the
//! price of one FISTA iteration; one ADMM iteration costs `cg_iters` of them.
//!
//! The penalties start at `mu_tv_rel * L` and `mu_nn_rel * L` and are balanced every
//! `balance_every` iterations (Boyd et al. 2011, sec. 3.4.1): a penalty doubles when its
//! primal residual exceeds ten times its dual residual, halves in the opposite case.
//!
//! The reported iterate is `v` (the variable the data term sees); its objective is
//! `0.5||A v - b||^2 + tau TV_w(v)`. `v` meets `v >= 0` only at convergence, so while
//! running its objective may sit slightly below that of a feasible point.

use crate::solve::optimize::types::{IterInfo, Observer, SolveResult, StopRule, Termination};
use crate::solve::prox::grad3::{diff, diff_adjoint_add};
use crate::model::op::{dot, Operator};
use crate::solve::optimize::common::{after_iteration, half_residual_sq, rel_change, Clock};
use crate::solve::prox::tv::{Prox as _, TotalVariation};
use serde::Serialize;

#[derive(Clone, Debug, Serialize)]
pub struct AdmmParams {
    /// Initial TV penalty, relative to the Lipschitz constant L.
    pub mu_tv_rel: f64,
    /// Initial non-negativity penalty, relative to L.
    pub mu_nn_rel: f64,
    /// CG steps per v-update.
    pub cg_iters: usize,
    /// Residual balancing period (0 disables).
    pub balance_every: usize,
    /// Period of the exact recomputation of `A v` and `A^T A v`.
    pub resync_every: usize,
}

impl Default for AdmmParams {
    fn default() -> Self {
        AdmmParams { mu_tv_rel: 1e-3, mu_nn_rel: 1e-3, cg_iters: 4, balance_every: 10, resync_every: 25 }
    }
}

#[derive(Clone, Debug)]
pub struct Admm {
    pub lipschitz: f64,
    pub stop: StopRule,
    pub params: AdmmParams,
}

use crate::solve::prox::tv::soft;

impl Admm {
    pub fn solve<A: Operator + ?Sized>(
        &self,
        op: &A,
        b: &[f32],
        tv: &TotalVariation,
        x0: Option<Vec<f32>>,
        observer: &mut dyn Observer,
    ) -> SolveResult {
        let (n, m) = (op.input_len(), op.output_len());
        assert_eq!(b.len(), m, "measurement size must match the operator's output");
        assert_eq!(tv.shape.0 * tv.shape.1 * tv.shape.2, n, "TV shape must match the operator's input");
        assert!(self.lipschitz.is_finite() && self.lipschitz > 0.0, "Lipschitz constant must be positive");
        let p = &self.params;
        let shape = tv.shape;
        let axes = tv.active_axes();
        let wts: Vec<f32> = axes.iter().map(|&a| tv.weights[a]).collect();
        let mut mu_tv = (p.mu_tv_rel * self.lipschitz) as f32;
        let mut mu_nn = (p.mu_nn_rel * self.lipschitz) as f32;
        let clamp = |v: f32| if tv.nonneg { v.max(0.0) } else { v };
        let mut clock = Clock::start();

        let mut v = x0.unwrap_or_else(|| vec![0.0; n]);
        assert_eq!(v.len(), n);
        let mut av = vec![0.0f32; m];
        let mut atav = vec![0.0f32; n];
        let mut atb = vec![0.0f32; n];
        op.adjoint(b, &mut atb);
        op.forward(&v, &mut av);
        op.adjoint(&av, &mut atav);
        let mut d = vec![0.0f32; n];
        // Splitting variables and scaled duals.
        let mut u: Vec<Vec<f32>> = axes
            .iter()
            .zip(&wts)
            .map(|(&a, &w)| {
                let mut g = vec![0.0; n];
                diff(shape, a, &v, &mut g);
                g.iter_mut().for_each(|x| *x *= w);
                g
            })
            .collect();
        let mut eta: Vec<Vec<f32>> = vec![vec![0.0; n]; axes.len()];
        let mut w: Vec<f32> = v.iter().map(|&x| clamp(x)).collect();
        let mut rho = vec![0.0f32; n];
        // CG buffers.
        let (mut rhs, mut r, mut pv, mut mp, mut atap) = (vec![0.0f32; n], vec![0.0f32; n], vec![0.0f32; n], vec![0.0f32; n], vec![0.0f32; n]);
        let mut ap = vec![0.0f32; m];
        let mut v_old = v.clone();

        // M x = AtAx + mu_tv sum w_a^2 D_a^T D_a x + mu_nn x, with AtAx given.
        let apply_m = |x: &[f32], atax: &[f32], out: &mut [f32], d: &mut [f32], mu_tv: f32, mu_nn: f32| {
            for ((o, &a), &xv) in out.iter_mut().zip(atax).zip(x) {
                *o = a + mu_nn * xv;
            }
            for (&a, &wa) in axes.iter().zip(&wts) {
                diff(shape, a, x, d);
                diff_adjoint_add(shape, a, d, mu_tv * wa * wa, out);
            }
        };

        let mut termination = Termination::MaxIterations;
        let (mut data, mut regv, mut iterations) = (half_residual_sq(&av, b), tv.value(&v), 0);
        for it in 1..=self.stop.max_iters {
            if p.resync_every > 0 && it % p.resync_every == 0 {
                op.forward(&v, &mut av);
                op.adjoint(&av, &mut atav);
            }
            v_old.copy_from_slice(&v);
            // Right-hand side.
            for (((o, &a), &wv), &rv) in rhs.iter_mut().zip(&atb).zip(&w).zip(&rho) {
                *o = a + mu_nn * (wv - rv);
            }
            for (ai, (&a, &wa)) in axes.iter().zip(&wts).enumerate() {
                for ((dv, &uv), &ev) in d.iter_mut().zip(&u[ai]).zip(&eta[ai]) {
                    *dv = uv - ev;
                }
                diff_adjoint_add(shape, a, &d, mu_tv * wa, &mut rhs);
            }
            // Warm-started CG.
            apply_m(&v, &atav, &mut mp, &mut d, mu_tv, mu_nn);
            for ((rv, &h), &q) in r.iter_mut().zip(&rhs).zip(&mp) {
                *rv = h - q;
            }
            pv.copy_from_slice(&r);
            let mut rr = dot(&r, &r);
            for _ in 0..p.cg_iters {
                if !(rr > 0.0) || !rr.is_finite() {
                    break;
                }
                op.forward(&pv, &mut ap);
                op.adjoint(&ap, &mut atap);
                apply_m(&pv, &atap, &mut mp, &mut d, mu_tv, mu_nn);
                let pmp = dot(&pv, &mp);
                if !(pmp > 0.0) {
                    break;
                }
                let alpha = (rr / pmp) as f32;
                for i in 0..n {
                    v[i] += alpha * pv[i];
                    atav[i] += alpha * atap[i];
                    r[i] -= alpha * mp[i];
                }
                for (a, &q) in av.iter_mut().zip(&ap) {
                    *a += alpha * q;
                }
                let rr_new = dot(&r, &r);
                let beta = (rr_new / rr) as f32;
                for (pi, &ri) in pv.iter_mut().zip(&r) {
                    *pi = ri + beta * *pi;
                }
                rr = rr_new;
            }
            // u, w and dual updates; residuals for balancing.
            let (mut prim_tv, mut dual_tv) = (0.0f64, 0.0f64);
            for (ai, (&a, &wa)) in axes.iter().zip(&wts).enumerate() {
                diff(shape, a, &v, &mut d);
                let thr = tv.tau / mu_tv;
                for i in 0..n {
                    let g = wa * d[i];
                    let un = soft(g + eta[ai][i], thr);
                    dual_tv += ((un - u[ai][i]) as f64).powi(2);
                    u[ai][i] = un;
                    eta[ai][i] += g - un;
                    prim_tv += ((g - un) as f64).powi(2);
                }
            }
            let (mut prim_nn, mut dual_nn) = (0.0f64, 0.0f64);
            for i in 0..n {
                let wn = clamp(v[i] + rho[i]);
                dual_nn += ((wn - w[i]) as f64).powi(2);
                w[i] = wn;
                rho[i] += v[i] - wn;
                prim_nn += ((v[i] - wn) as f64).powi(2);
            }
            let d_new = half_residual_sq(&av, b);
            let r_new = tv.value(&v);
            if !(d_new + r_new).is_finite() || v.iter().any(|x| !x.is_finite()) {
                termination = Termination::NonFinite { iteration: it };
                v.copy_from_slice(&v_old);
                break;
            }
            if p.balance_every > 0 && it % p.balance_every == 0 {
                // Dual residual of a split z = G v is mu * G^T (z - z_old); its size is
                // bounded by mu ||G|| ||z - z_old||; ||G|| ~ 1 is close enough to balance.
                let bal = |prim: f64, dual: f64, mu: &mut f32, duals: &mut dyn FnMut(f32)| {
                    let s = (*mu as f64) * dual.sqrt();
                    let r = prim.sqrt();
                    if r > 10.0 * s {
                        *mu *= 2.0;
                        duals(0.5);
                    } else if s > 10.0 * r {
                        *mu *= 0.5;
                        duals(2.0);
                    }
                };
                if !axes.is_empty() {
                    bal(prim_tv, dual_tv, &mut mu_tv, &mut |f| eta.iter_mut().flatten().for_each(|e| *e *= f));
                }
                bal(prim_nn, dual_nn, &mut mu_nn, &mut |f| rho.iter_mut().for_each(|e| *e *= f));
            }
            let rel = rel_change(&v, &v_old);
            (data, regv, iterations) = (d_new, r_new, it);
            let seconds = clock.seconds();
            if let Some(reason) = after_iteration(&mut clock, observer, &self.stop, IterInfo { iteration: it, seconds, data_term: data, reg_term: regv, rel_change: rel, x: &v }) {
                termination = reason;
                break;
            }
        }
        SolveResult { x: v, iterations, seconds: clock.seconds(), termination, data_term: data, reg_term: regv }
    }
}
