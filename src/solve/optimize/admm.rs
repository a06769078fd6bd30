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
//! The data term must be a plain equality on one process: the v-update is the
//! quadratic one, so clipped pixels (lower bounds) and a split problem are refused
//! ([`crate::solve::optimize::SolverKind::check_data`]), as is any prior but TV.
//!
//! The reported iterate is `v` (the variable the data term sees); its objective is
//! `0.5||A v - b||^2 + tau TV_w(v)`. `v` meets `v >= 0` only at convergence, so while
//! running its objective may sit slightly below that of a feasible point.
//!
//! A [`Step`] run by the executor (clock, [`StopRule`], the non-finite check of the
//! objective and of `v`, the [`Observer`] calls, the [`SolveResult`]): `propose` runs
//! the v-update and the u, w and dual updates; `accept` balances the penalties and
//! measures the change of `v`; `abandon` puts back the `v` of the iteration before.

use crate::model::data::DataTerm;
use crate::model::op::{dot, Operator};
use crate::solve::optimize::common::rel_change;
use crate::solve::optimize::executor::{run, Accepted, Objective, Step};
use crate::solve::optimize::types::{Observer, SolveResult, StopRule};
use crate::solve::prox::grad3::{diff, diff_adjoint_add};
use crate::solve::prox::tv::soft;
use crate::solve::prox::Prox as _;
use crate::solve::prox::TotalVariation;
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

/// The most CG steps per v-update: each costs one FISTA iteration, and a few reach
/// the accuracy ADMM needs; more would run past any time budget inside one iteration.
pub const MAX_CG_ITERS: usize = 1000;

impl AdmmParams {
    /// A CG step count given as text (`admm:cg=N`), read and checked as [`Self::check_cg`].
    pub fn parse_cg(text: &str) -> Result<usize, String> {
        text.trim().parse().map_or_else(|_| Self::check_cg(0), Self::check_cg)
    }

    /// An initial penalty given as text (`admm:mu=X`), read and checked as [`Self::check_mu`].
    pub fn parse_mu(text: &str) -> Result<f64, String> {
        text.trim().parse().map_or_else(|_| Self::check_mu(0.0), Self::check_mu)
    }

    /// The one check of a CG step count: 1 to [`MAX_CG_ITERS`].
    pub fn check_cg(cg_iters: usize) -> Result<usize, String> {
        if (1..=MAX_CG_ITERS).contains(&cg_iters) {
            Ok(cg_iters)
        } else {
            Err(format!("a whole number of CG steps from 1 to {MAX_CG_ITERS}"))
        }
    }

    /// The one check of an initial penalty relative to L: positive and finite.
    pub fn check_mu(mu_rel: f64) -> Result<f64, String> {
        if mu_rel.is_finite() && mu_rel > 0.0 {
            Ok(mu_rel)
        } else {
            Err("a positive penalty relative to L".into())
        }
    }
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

impl Admm {
    /// # Panics
    /// On a data term ADMM refuses: clipped pixels' lower bounds or a split problem
    /// (`SolverKind::check_data` says which, in words, before a solve is started).
    pub fn solve<A: Operator + ?Sized>(&self, op: &A, data: &DataTerm, tv: &TotalVariation, x0: Option<Vec<f32>>, observer: &mut dyn Observer) -> SolveResult {
        assert!(
            !data.lower_bounds().is_some_and(|l| l.iter().any(|&b| b)) && data.ranks().size() == 1,
            "ADMM's data update takes no lower bounds and no split problem"
        );
        let (n, b) = (op.input_len(), data.observations());
        assert_eq!(b.len(), op.output_len(), "measurement size must match the operator's output");
        assert_eq!(tv.shape.0 * tv.shape.1 * tv.shape.2, n, "TV shape must match the operator's input");
        assert!(self.lipschitz.is_finite() && self.lipschitz > 0.0, "Lipschitz constant must be positive");
        run(&self.stop, observer, || AdmmStep::new(op, *data, tv, &self.params, self.lipschitz, x0))
    }
}

/// ADMM's state between iterations: `v` with `A v` and `A^T A v`, the splitting
/// variables `u_a`, `w`, the scaled duals `eta_a`, `rho`, the penalties, the CG
/// buffers, and the residuals of the last update (for balancing).
struct AdmmStep<'a, A: ?Sized> {
    op: &'a A,
    data: DataTerm<'a>,
    tv: &'a TotalVariation,
    p: &'a AdmmParams,
    shape: (usize, usize, usize),
    axes: Vec<usize>,
    wts: Vec<f32>,
    mu_tv: f32,
    mu_nn: f32,
    v: Vec<f32>,
    av: Vec<f32>,
    atav: Vec<f32>,
    atb: Vec<f32>,
    d: Vec<f32>,
    u: Vec<Vec<f32>>,
    eta: Vec<Vec<f32>>,
    w: Vec<f32>,
    rho: Vec<f32>,
    rhs: Vec<f32>,
    r: Vec<f32>,
    pv: Vec<f32>,
    mp: Vec<f32>,
    atap: Vec<f32>,
    ap: Vec<f32>,
    v_old: Vec<f32>,
    /// Squared primal and dual residuals (TV split, non-negativity split) of the last
    /// `propose`.
    residuals: [f64; 4],
}

/// `v` clamped by the non-negativity split (unchanged without the constraint).
fn clamp(nonneg: bool, v: f32) -> f32 {
    if nonneg {
        v.max(0.0)
    } else {
        v
    }
}

/// The system matrix of ADMM's x-update, `M = A^T A + mu_tv sum_a w_a^2 D_a^T D_a +
/// mu_nn I`, but for `A^T A` (applied by the caller).
struct SystemM<'a> {
    shape: (usize, usize, usize),
    axes: &'a [usize],
    wts: &'a [f32],
    mu_tv: f32,
    mu_nn: f32,
}

/// `out = M x = AtAx + mu_tv sum_a w_a^2 D_a^T D_a x + mu_nn x`, with `AtAx` given;
/// `d` is scratch.
fn apply_m(sys: &SystemM, x: &[f32], atax: &[f32], out: &mut [f32], d: &mut [f32]) {
    let SystemM { shape, axes, wts, mu_tv, mu_nn } = *sys;
    for ((o, &a), &xv) in out.iter_mut().zip(atax).zip(x) {
        *o = a + mu_nn * xv;
    }
    for (&a, &wa) in axes.iter().zip(wts) {
        diff(shape, a, x, d);
        diff_adjoint_add(shape, a, d, mu_tv * wa * wa, out);
    }
}

impl<'a, A: Operator + ?Sized> AdmmStep<'a, A> {
    fn new(op: &'a A, data: DataTerm<'a>, tv: &'a TotalVariation, p: &'a AdmmParams, lipschitz: f64, x0: Option<Vec<f32>>) -> (Self, Objective) {
        let (n, m) = (op.input_len(), op.output_len());
        let shape = tv.shape;
        let axes = tv.active_axes();
        let wts: Vec<f32> = axes.iter().map(|&a| tv.weights[a]).collect();
        let mu_tv = (p.mu_tv_rel * lipschitz) as f32;
        let mu_nn = (p.mu_nn_rel * lipschitz) as f32;

        let v = x0.unwrap_or_else(|| vec![0.0; n]);
        assert_eq!(v.len(), n);
        let mut av = vec![0.0f32; m];
        let mut atav = vec![0.0f32; n];
        let mut atb = vec![0.0f32; n];
        op.adjoint(data.observations(), &mut atb);
        op.forward(&v, &mut av);
        op.adjoint(&av, &mut atav);
        let d = vec![0.0f32; n];
        // Splitting variables and scaled duals.
        let u: Vec<Vec<f32>> = axes
            .iter()
            .zip(&wts)
            .map(|(&a, &w)| {
                let mut g = vec![0.0; n];
                diff(shape, a, &v, &mut g);
                g.iter_mut().for_each(|x| *x *= w);
                g
            })
            .collect();
        let eta: Vec<Vec<f32>> = vec![vec![0.0; n]; axes.len()];
        let w: Vec<f32> = v.iter().map(|&x| clamp(tv.nonneg, x)).collect();
        let rho = vec![0.0f32; n];
        // CG buffers.
        let (rhs, r, pv, mp, atap) = (vec![0.0f32; n], vec![0.0f32; n], vec![0.0f32; n], vec![0.0f32; n], vec![0.0f32; n]);
        let ap = vec![0.0f32; m];
        let v_old = v.clone();
        let objective = Objective { data_term: data.value(&av), reg_term: tv.value(&v) };
        let step = AdmmStep {
            op,
            data,
            tv,
            p,
            shape,
            axes,
            wts,
            mu_tv,
            mu_nn,
            v,
            av,
            atav,
            atb,
            d,
            u,
            eta,
            w,
            rho,
            rhs,
            r,
            pv,
            mp,
            atap,
            ap,
            v_old,
            residuals: [0.0; 4],
        };
        (step, objective)
    }
}

impl<A: Operator + ?Sized> Step for AdmmStep<'_, A> {
    fn propose(&mut self, it: usize) -> Objective {
        let AdmmStep { op, data, tv, p, shape, axes, wts, mu_tv, mu_nn, v, av, atav, atb, d, u, eta, w, rho, rhs, r, pv, mp, atap, ap, v_old, residuals } =
            self;
        let (shape, mu_tv, mu_nn, n) = (*shape, *mu_tv, *mu_nn, v.len());
        if p.resync_every > 0 && it % p.resync_every == 0 {
            op.forward(v, av);
            op.adjoint(av, atav);
        }
        v_old.copy_from_slice(v);
        // Right-hand side.
        for (((o, &a), &wv), &rv) in rhs.iter_mut().zip(atb.iter()).zip(w.iter()).zip(rho.iter()) {
            *o = a + mu_nn * (wv - rv);
        }
        for (ai, (&a, &wa)) in axes.iter().zip(wts.iter()).enumerate() {
            for ((dv, &uv), &ev) in d.iter_mut().zip(&u[ai]).zip(&eta[ai]) {
                *dv = uv - ev;
            }
            diff_adjoint_add(shape, a, d, mu_tv * wa, rhs);
        }
        // Warm-started CG.
        let sys = SystemM { shape, axes, wts, mu_tv, mu_nn };
        apply_m(&sys, v, atav, mp, d);
        for ((rv, &h), &q) in r.iter_mut().zip(rhs.iter()).zip(mp.iter()) {
            *rv = h - q;
        }
        pv.copy_from_slice(r);
        let mut rr = dot(r, r);
        for _ in 0..p.cg_iters {
            if !(rr > 0.0) || !rr.is_finite() {
                break;
            }
            op.forward(pv, ap);
            op.adjoint(ap, atap);
            apply_m(&sys, pv, atap, mp, d);
            let pmp = dot(pv, mp);
            if !(pmp > 0.0) {
                break;
            }
            let alpha = (rr / pmp) as f32;
            for i in 0..n {
                v[i] += alpha * pv[i];
                atav[i] += alpha * atap[i];
                r[i] -= alpha * mp[i];
            }
            for (a, &q) in av.iter_mut().zip(ap.iter()) {
                *a += alpha * q;
            }
            let rr_new = dot(r, r);
            let beta = (rr_new / rr) as f32;
            for (pi, &ri) in pv.iter_mut().zip(r.iter()) {
                *pi = ri + beta * *pi;
            }
            rr = rr_new;
        }
        // u, w and dual updates; residuals for balancing.
        let (mut prim_tv, mut dual_tv) = (0.0f64, 0.0f64);
        for (ai, (&a, &wa)) in axes.iter().zip(wts.iter()).enumerate() {
            diff(shape, a, v, d);
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
            let wn = clamp(tv.nonneg, v[i] + rho[i]);
            dual_nn += ((wn - w[i]) as f64).powi(2);
            w[i] = wn;
            rho[i] += v[i] - wn;
            prim_nn += ((v[i] - wn) as f64).powi(2);
        }
        *residuals = [prim_tv, dual_tv, prim_nn, dual_nn];
        Objective { data_term: data.value(av), reg_term: tv.value(v) }
    }

    fn proposal(&self) -> &[f32] {
        &self.v
    }

    fn accept(&mut self, it: usize, _: Objective, proposed: Objective) -> Accepted {
        let [prim_tv, dual_tv, prim_nn, dual_nn] = self.residuals;
        if self.p.balance_every > 0 && it % self.p.balance_every == 0 {
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
            let eta = &mut self.eta;
            let rho = &mut self.rho;
            if !self.axes.is_empty() {
                bal(prim_tv, dual_tv, &mut self.mu_tv, &mut |f| eta.iter_mut().flatten().for_each(|e| *e *= f));
            }
            bal(prim_nn, dual_nn, &mut self.mu_nn, &mut |f| rho.iter_mut().for_each(|e| *e *= f));
        }
        Accepted { objective: proposed, rel_change: rel_change(&self.v, &self.v_old, &crate::model::ranks::One) }
    }

    fn abandon(&mut self) {
        self.v.copy_from_slice(&self.v_old);
    }

    fn x(&self) -> &[f32] {
        &self.v
    }

    fn into_x(self) -> Vec<f32> {
        self.v
    }
}
