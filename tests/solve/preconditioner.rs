//! The per-frame preconditioner of the gradient methods (`fista-restart:precond=frames`):
//! the TV maps in a per-frame metric against a dense reference and against the plain
//! maps (equal weights), restart FISTA in the metric reaching the plain minimum on a
//! rolling-shutter capture whose outer frames are weak, and no NaN where a frame has no
//! sensitivity at all.

use crate::support::common;
use common::*;
use rollcam::model::data::DataTerm;
use rollcam::model::op::{pseudo_random, Dense, Operator};
use rollcam::model::shutter::ShutterMode;
use rollcam::solve::lipschitz::{power_iteration, LIPSCHITZ_MARGIN};
use rollcam::solve::metric::{FrameMetric, FrameScaled, MIN_FRAME_WEIGHT};
use rollcam::solve::optimize::{Fista, NoObserver, RestartTest, SolverKind, StopRule, Termination};
use rollcam::solve::prox::tv_dual::TvProx;
use rollcam::solve::prox::{Prox, TotalVariation};

/// The maps under test: Haar and the dual map with `inner` iterations.
fn maps(tv: &TotalVariation, inner: usize) -> Vec<(String, Box<dyn Prox>)> {
    [TvProx::Haar, TvProx::Dual { inner_iters: inner }].into_iter().map(|p| (p.name(), p.build(tv))).collect()
}

fn metric_prox(map: &dyn Prox, z: &[f32], gamma: f32, metric: &FrameMetric) -> Vec<f32> {
    let mut out = vec![0.0f32; z.len()];
    map.metric_prox().expect("TV has a map in a metric").prox_in(z, gamma, metric, &mut out);
    out
}

#[test]
fn with_equal_weights_the_metric_prox_is_the_plain_prox() {
    let shape = (5, 6, 7);
    let fl = shape.1 * shape.2;
    let tv = TotalVariation { shape, tau: 0.3, weights: [2.0, 1.0, 1.0], nonneg: true };
    let (plain_maps, metric_maps) = (maps(&tv, 8), maps(&tv, 8));
    for ((name, plain), (_, weighted)) in plain_maps.iter().zip(&metric_maps) {
        // Weights of one: the plain map to the bit, call after call (the dual map's warm
        // start included).
        for call in 0..3 {
            let z: Vec<f32> = pseudo_random(shape.0 * fl, 40 + call).iter().map(|v| v - 0.3).collect();
            let mut want = vec![0.0f32; z.len()];
            plain.prox(&z, 0.7, &mut want);
            assert_eq!(metric_prox(weighted.as_ref(), &z, 0.7, &FrameMetric::identity(shape.0, fl)), want, "{name} call {call}");
        }
    }
    // Every weight d: the plain map at gamma / d (fresh maps, one call).
    for ((name, plain), (_, weighted)) in maps(&tv, 8).iter().zip(&maps(&tv, 8)) {
        let z: Vec<f32> = pseudo_random(shape.0 * fl, 7).iter().map(|v| v - 0.3).collect();
        let mut want = vec![0.0f32; z.len()];
        plain.prox(&z, 0.7 / 0.25, &mut want);
        let got = metric_prox(weighted.as_ref(), &z, 0.7, &FrameMetric::new(vec![0.25; shape.0], fl).unwrap());
        let diff = got.iter().zip(&want).fold(0.0f32, |d, (a, b)| d.max((a - b).abs()));
        assert!(diff < 1e-5, "{name}: {diff}");
    }
}

/// The weighted prox with non-negativity by a plain primal-dual method (Chambolle &
/// Pock 2011) on the dense matrix of weighted differences, in f64, run far past
/// convergence: the independent reference.
fn dense_reference(tv: &TotalVariation, metric: &FrameMetric, z: &[f32], gamma: f32) -> Vec<f64> {
    let (k, m, n) = tv.shape;
    let len = k * m * n;
    let idx = |f: usize, r: usize, c: usize| (f * m + r) * n + c;
    // Rows of K: (i, j, w) for w (x_j - x_i).
    let mut rows: Vec<(usize, usize, f64)> = Vec::new();
    for f in 0..k {
        for r in 0..m {
            for c in 0..n {
                let i = idx(f, r, c);
                if f + 1 < k {
                    rows.push((i, idx(f + 1, r, c), tv.weights[0] as f64));
                }
                if r + 1 < m {
                    rows.push((i, idx(f, r + 1, c), tv.weights[1] as f64));
                }
                if c + 1 < n {
                    rows.push((i, idx(f, r, c + 1), tv.weights[2] as f64));
                }
            }
        }
    }
    let w_max = tv.weights.iter().fold(0.0f32, |a, &b| a.max(b)) as f64;
    let k_norm_sq = 12.0 * w_max * w_max; // ||K||^2 <= 2 * (2 * 3) w_max^2
    let (tau_p, sigma) = (0.9 / k_norm_sq.sqrt(), 0.9 / k_norm_sq.sqrt());
    let bound = gamma as f64 * tv.tau as f64;
    let d: Vec<f64> = (0..len).map(|i| metric.weights()[i / (m * n)] as f64).collect();
    let (mut x, mut x_bar, mut y) = (vec![0.0f64; len], vec![0.0f64; len], vec![0.0f64; rows.len()]);
    for _ in 0..200_000 {
        for (yr, &(i, j, w)) in y.iter_mut().zip(&rows) {
            *yr = (*yr + sigma * w * (x_bar[j] - x_bar[i])).clamp(-bound, bound);
        }
        let mut kty = vec![0.0f64; len];
        for (&yr, &(i, j, w)) in y.iter().zip(&rows) {
            kty[j] += w * yr;
            kty[i] -= w * yr;
        }
        for i in 0..len {
            let v = x[i] - tau_p * kty[i];
            let new = ((d[i] * z[i] as f64 + v / tau_p) / (d[i] + 1.0 / tau_p)).max(0.0);
            x_bar[i] = 2.0 * new - x[i];
            x[i] = new;
        }
    }
    x
}

#[test]
fn the_metric_prox_matches_a_dense_reference() {
    // A temporal pair with a jump large enough for the Haar map to be exact there (as
    // in the plain metric): the closed form.
    let pair = TotalVariation { shape: (2, 1, 1), tau: 1.0, weights: [1.0, 0.0, 0.0], nonneg: false };
    let metric = FrameMetric::new(vec![0.25, 1.0], 1).unwrap();
    let (a, b, c) = (0.0f32, 4.0f32, 0.3f32);
    // s = clip((b - a) / (1/d_a + 1/d_b), c): x_a = a + s / d_a, x_b = b - s / d_b.
    let s = ((b - a) / (4.0 + 1.0)).clamp(-c, c);
    for (name, map) in maps(&pair, 2000) {
        let got = metric_prox(map.as_ref(), &[a, b], c, &metric);
        assert!((got[0] - (a + 4.0 * s)).abs() < 1e-5 && (got[1] - (b - s)).abs() < 1e-5, "{name}: {got:?}");
    }
    // A small volume, uneven weights: the dual map (run long) is the exact weighted prox.
    let tv = TotalVariation { shape: (3, 2, 3), tau: 0.4, weights: [2.0, 1.0, 1.0], nonneg: true };
    let metric = FrameMetric::new(vec![0.3, 1.0, 0.6], 6).unwrap();
    let z: Vec<f32> = pseudo_random(18, 5).iter().map(|v| 2.0 * v - 0.4).collect();
    let gamma = 0.5;
    let reference = dense_reference(&tv, &metric, &z, gamma);
    let exact = metric_prox(TvProx::Dual { inner_iters: 1000 }.build(&tv).as_ref(), &z, gamma, &metric);
    let err = exact.iter().zip(&reference).fold(0.0f64, |e, (&a, &b)| e.max((a as f64 - b).abs()));
    assert!(err < 1e-4, "dual map in the metric vs the dense reference: {err}");
    // The Haar map: its definition evaluated term by term, each pair's prox exact in the
    // metric, the terms averaged.
    let haar = metric_prox(&tv, &z, gamma, &metric);
    let want = haar_reference(&tv, &metric, &z, gamma);
    let err = haar.iter().zip(&want).fold(0.0f64, |e, (&a, &b)| e.max((a as f64 - b).abs()));
    assert!(err < 1e-5, "Haar map in the metric vs its term-by-term definition: {err}");
}

/// The parallel proximal (Haar) map in the metric, by its definition: for every active
/// axis and shift, the exact weighted prox of `J gamma tau w_a |x_j - x_i|` on each pair
/// `(i, j)` (`x_i = z_i + s / d_i`, `x_j = z_j - s / d_j`, `s = clip((z_j - z_i) / (1/d_i +
/// 1/d_j), c)`), unpaired samples unchanged; the `J` terms averaged, then `max(., 0)`.
fn haar_reference(tv: &TotalVariation, metric: &FrameMetric, z: &[f32], gamma: f32) -> Vec<f64> {
    let (k, m, n) = tv.shape;
    let geometry = [(k, m * n), (m, n), (n, 1)];
    let axes: Vec<usize> = (0..3).filter(|&a| tv.weights[a] > 0.0 && geometry[a].0 > 1).collect();
    let j = (2 * axes.len()) as f64;
    let inv = |i: usize| 1.0 / metric.weights()[i / (m * n)] as f64;
    let mut sum = vec![0.0f64; z.len()];
    for &a in &axes {
        let (len, stride) = geometry[a];
        let c = j * gamma as f64 * tv.tau as f64 * tv.weights[a] as f64;
        for shift in 0..2 {
            let mut term: Vec<f64> = z.iter().map(|&v| v as f64).collect();
            for i in 0..z.len() {
                let coord = (i / stride) % len;
                if coord % 2 == shift && coord + 1 < len {
                    let p = i + stride;
                    let s = ((z[p] as f64 - z[i] as f64) / (inv(i) + inv(p))).clamp(-c, c);
                    term[i] += inv(i) * s;
                    term[p] -= inv(p) * s;
                }
            }
            sum.iter_mut().zip(&term).for_each(|(o, t)| *o += t);
        }
    }
    sum.iter().map(|v| (v / j).max(0.0)).collect()
}

#[test]
fn preconditioned_fista_reaches_the_plain_minimum_with_weak_outer_frames() {
    let (m, n) = (16, 20);
    let psf = sparse_psf(m, n, 3);
    let model = model(&psf, m, n, 100.0, 300.0, ShutterMode::Rolling);
    let (k, _, _) = model.video_shape();
    let metric = FrameMetric::from_sensitivity(&model.frame_sensitivity(&psf), m * n);
    // The capture has weak outer frames: the metric is not the identity.
    let weakest = metric.weights().iter().fold(1.0f32, |a, &b| a.min(b));
    assert!(weakest < 0.7, "weights {:?}", metric.weights());
    let b = forward(&model, &flashing_points(k, m, n, 1000.0));
    let mut atb = vec![0.0f32; model.input_len()];
    model.adjoint(&b, &mut atb);
    let tau = 2e-3 * atb.iter().fold(0.0f32, |a, &v| a.max(v));
    let tv = TotalVariation::new((k, m, n), tau, 5.0);
    let data = DataTerm::new(&b);
    let iters = 3000;
    let plain_l = lipschitz(&model);
    let metric_l = power_iteration(&FrameScaled { op: &model, metric: &metric }, 500, 1e-7, 0x5eed).lambda_max * LIPSCHITZ_MARGIN;
    let prior = TvProx::Dual { inner_iters: 20 }.build(&tv);
    let plain = Fista { lipschitz: plain_l, stop: StopRule::iterations(iters), restart: Some(RestartTest::Objective) }.solve(
        &model,
        &data,
        prior.as_ref(),
        None,
        &mut NoObserver,
    );
    let prior = TvProx::Dual { inner_iters: 20 }.build(&tv);
    let pre = Fista { lipschitz: metric_l, stop: StopRule::iterations(iters), restart: Some(RestartTest::Objective) }.solve_in(
        &metric,
        &model,
        &data,
        prior.as_ref(),
        None,
        &mut NoObserver,
    );
    let (f_plain, f_pre) = (plain.data_term + plain.reg_term, pre.data_term + pre.reg_term);
    assert!(((f_pre - f_plain) / f_plain).abs() < 1e-3, "preconditioned {f_pre} vs plain {f_plain} (L {metric_l:.4e} vs {plain_l:.4e})");
    // Through the one interface, as compare runs it.
    let mut s = settings(SolverKind::FistaRestart, metric_l, iters);
    s.metric = Some(metric.clone());
    let (r, _) = run(&s, &model, &b, TvProx::Dual { inner_iters: 20 }.build(&tv).as_ref());
    assert!(((r.data_term + r.reg_term - f_plain) / f_plain).abs() < 1e-3);
    // Solvers that cannot step in a metric say so.
    for kind in [SolverKind::Admm, SolverKind::Pgd, SolverKind::Mfista, SolverKind::AdmmSplit] {
        assert!(kind.check_precondition(&tv).unwrap_err().contains("fista and fista-restart"), "{kind}");
    }
}

#[test]
fn no_nan_where_a_frame_has_no_sensitivity() {
    // Three frames of four pixels; the data never see the middle frame.
    let (k, fl) = (3, 4);
    let mut a = pseudo_random(6 * k * fl, 9);
    for row in a.chunks_mut(k * fl) {
        row[fl..2 * fl].fill(0.0);
    }
    let op = Dense { rows: 6, cols: k * fl, a };
    let b = pseudo_random(6, 10);
    let tv = TotalVariation { shape: (k, 2, 2), tau: 0.05, weights: [5.0, 1.0, 1.0], nonneg: true };
    // From the sensitivity (floored) and, harder, a weight of 1e-6 given as is.
    for metric in [FrameMetric::from_sensitivity(&[1.0, 0.0, 0.5], fl), FrameMetric::new(vec![1.0, 1e-6, 0.5], fl).unwrap()] {
        let l = power_iteration(&FrameScaled { op: &op, metric: &metric }, 500, 1e-9, 1).lambda_max * LIPSCHITZ_MARGIN;
        assert!(l.is_finite() && l > 0.0);
        for (name, prior) in maps(&tv, 10) {
            let r = Fista { lipschitz: l, stop: StopRule::iterations(200), restart: Some(RestartTest::Objective) }.solve_in(
                &metric,
                &op,
                &DataTerm::new(&b),
                prior.as_ref(),
                None,
                &mut NoObserver,
            );
            assert_eq!(r.termination, Termination::MaxIterations, "{name} {:?}", metric.weights());
            assert!(all_finite(&r.x) && (r.data_term + r.reg_term).is_finite(), "{name} {:?}", metric.weights());
        }
    }
    assert_eq!(FrameMetric::from_sensitivity(&[1.0, 0.0, 0.5], fl).weights()[1], MIN_FRAME_WEIGHT);
}
