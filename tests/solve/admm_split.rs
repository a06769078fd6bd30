//! ADMM with every update in closed form (`admm-split`): its per-pixel update against a
//! dense solve, its Fourier v-update against a dense system, its minimum against
//! restart FISTA's, and what it refuses, by name.

use crate::support::common;
use common::*;
use rollcam::model::conv::Conv2d;
use rollcam::model::data::DataTerm;
use rollcam::model::op::pseudo_random;
use rollcam::model::ranks::{Partition, Ranks};
use rollcam::model::rolling::RollingShutterModel;
use rollcam::model::scene::Restricted;
use rollcam::model::shutter::{ShutterMode, Timing};
use rollcam::solve::optimize::admm_split::{pixel_gain, VSystem};
use rollcam::solve::optimize::{solve, IterInfo, OptimizerSettings, SolverKind, StopRule};
use rollcam::solve::prox::prior::{PriorSpec, TvPrior};
use rollcam::solve::prox::tv_dual::{TvProx, TvProxChoice};
use rollcam::solve::prox::TotalVariation;
use std::sync::Arc;

/// Solve the small dense system `m x = rhs` (Gaussian elimination with partial
/// pivoting, f64).
fn dense_solve(mut m: Vec<Vec<f64>>, mut rhs: Vec<f64>) -> Vec<f64> {
    let n = rhs.len();
    for c in 0..n {
        let p = (c..n).max_by(|&a, &b| m[a][c].abs().total_cmp(&m[b][c].abs())).unwrap();
        m.swap(c, p);
        rhs.swap(c, p);
        for r in c + 1..n {
            let (top, bottom) = m.split_at_mut(r);
            let f = bottom[0][c] / top[c][c];
            for (x, &y) in bottom[0][c..].iter_mut().zip(&top[c][c..]) {
                *x -= f * y;
            }
            rhs[r] -= f * rhs[c];
        }
    }
    let mut x = vec![0.0; n];
    for r in (0..n).rev() {
        let s: f64 = (r + 1..n).map(|j| m[r][j] * x[j]).sum();
        x[r] = (rhs[r] - s) / m[r][r];
    }
    x
}

/// For every sensor row of rolling, dual and dual-center-out shutters, and pixel masks
/// 1, 0.5 and 0: the Sherman-Morrison update `z = r + a g` equals the direct solve of
/// `(a a^T + mu I) z = mu r + a b` (`a` the row's weights times the mask); at a clipped
/// pixel, `z = r` when the bound already holds, the two-sided solve otherwise.
#[test]
fn the_pixel_update_is_the_direct_solve_for_every_shutter_and_mask() {
    let rows = 12;
    let mut checked = 0;
    for mode in [ShutterMode::Rolling, ShutterMode::Dual, ShutterMode::DualCenterOut] {
        let w = Timing::new(rows, 100.0, 350.0, mode).weights().unwrap();
        let k = w.frames();
        for i in 0..rows {
            for (mask, seed) in [(1.0f32, 1u64), (0.5, 2), (0.0, 3)] {
                let a: Vec<f32> = (0..k).map(|t| mask * w.get(i, t)).collect();
                let r: Vec<f32> = pseudo_random(k, seed + 10 * i as u64).iter().map(|v| v - 0.3).collect();
                let (b, mu) = (0.7f32, 0.37f32);
                let ar: f64 = a.iter().zip(&r).map(|(&a, &r)| a as f64 * r as f64).sum();
                let aa: f64 = a.iter().map(|&a| (a as f64).powi(2)).sum();
                let mat: Vec<Vec<f64>> = (0..k).map(|p| (0..k).map(|q| a[p] as f64 * a[q] as f64 + if p == q { mu as f64 } else { 0.0 }).collect()).collect();
                let rhs: Vec<f64> = (0..k).map(|p| mu as f64 * r[p] as f64 + a[p] as f64 * b as f64).collect();
                let direct = dense_solve(mat, rhs);
                let g = pixel_gain(ar, aa, b, false, mu);
                for p in 0..k {
                    let z = r[p] as f64 + a[p] as f64 * g as f64;
                    assert!((z - direct[p]).abs() < 1e-5, "{} row {i} mask {mask}: {z} vs {}", mode.name(), direct[p]);
                }
                // One-sided: the bound below a . r holds at z = r; above it, the pixel
                // acts as an equality.
                assert_eq!(pixel_gain(ar, aa, (ar - 0.1) as f32, true, mu), 0.0);
                assert_eq!(pixel_gain(ar, aa, (ar + 0.1) as f32, true, mu), pixel_gain(ar, aa, (ar + 0.1) as f32, false, mu));
                checked += 1;
            }
        }
    }
    assert_eq!(checked, 3 * rows * 3);
}

/// The v-update (FFTs per plane, a tridiagonal sweep along time) solves
/// `(mu1 H^T H + mu2 sum_a w_a^2 D_a^T D_a + mu3 I) v = rhs` with `H` the circular
/// convolution on the padded grid, spatial differences periodic and temporal ones
/// without wrap: the dense system built here independently, applied to its solution,
/// gives the right-hand side back.
#[test]
fn the_fourier_v_update_solves_the_dense_system() {
    let (m, n) = (3, 4);
    let (k, p, q) = (4, 6, 8);
    let psf = pseudo_random(m * n, 4);
    let weights = [2.0f32, 1.0, 0.5];
    let idx = |t: usize, r: usize, c: usize| (t * p + r) * q + c;
    let len = k * p * q;
    // Columns of H: the PSF's centre (m/2, n/2) lands on the pixel.
    let h = |r: usize, c: usize, r0: usize, c0: usize| -> f64 {
        let a = (r as isize - r0 as isize + (m / 2) as isize).rem_euclid(p as isize) as usize;
        let b = (c as isize - c0 as isize + (n / 2) as isize).rem_euclid(q as isize) as usize;
        if a < m && b < n {
            psf[a * n + b] as f64
        } else {
            0.0
        }
    };
    let mu = [0.8f32, 0.3, 0.05];
    let mut sys = vec![vec![0.0f64; len]; len];
    // H^T H per frame.
    for t in 0..k {
        for r0 in 0..p {
            for c0 in 0..q {
                for r1 in 0..p {
                    for c1 in 0..q {
                        let s: f64 = (0..p).flat_map(|r| (0..q).map(move |c| (r, c))).map(|(r, c)| h(r, c, r0, c0) * h(r, c, r1, c1)).sum();
                        sys[idx(t, r0, c0)][idx(t, r1, c1)] += mu[0] as f64 * s;
                    }
                }
            }
        }
    }
    // D^T D: each difference (i, j) adds w^2 (e_j - e_i)(e_j - e_i)^T.
    let mut add_diff = |i: usize, j: usize, w: f32| {
        let c = mu[1] as f64 * (w as f64).powi(2);
        sys[i][i] += c;
        sys[j][j] += c;
        sys[i][j] -= c;
        sys[j][i] -= c;
    };
    for t in 0..k {
        for r in 0..p {
            for c in 0..q {
                if t + 1 < k {
                    add_diff(idx(t, r, c), idx(t + 1, r, c), weights[0]);
                }
                add_diff(idx(t, r, c), idx(t, (r + 1) % p, c), weights[1]);
                add_diff(idx(t, r, c), idx(t, r, (c + 1) % q), weights[2]);
            }
        }
    }
    for (i, row) in sys.iter_mut().enumerate() {
        row[i] += mu[2] as f64;
    }
    let truth = pseudo_random(len, 8);
    let rhs: Vec<f32> = sys.iter().map(|row| row.iter().zip(&truth).map(|(&a, &x)| a * x as f64).sum::<f64>() as f32).collect();
    let v = VSystem::new(&psf, (m, n), (k, p, q), weights).solve(&rhs, mu);
    let err = v.iter().zip(&truth).map(|(&a, &b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(err < 1e-4, "largest error {err}");
    // Without temporal TV the frames decouple: the same system minus the time terms.
    let solo = VSystem::new(&psf, (m, n), (1, p, q), weights).solve(&rhs[..p * q], mu);
    assert!(solo.iter().all(|v| v.is_finite()));
}

/// A masked, partly clipped capture: admm-split reaches the minimum restart FISTA
/// (exact TV map) reaches in a long run, within 0.1% of the objective, for a rolling
/// and a dual shutter; it never reports a non-finite value.
#[test]
fn admm_split_reaches_restart_fistas_minimum() {
    let (m, n) = (10, 8);
    for (mode, seed) in [(ShutterMode::Rolling, 3u64), (ShutterMode::Dual, 7)] {
        let psf = sparse_psf(m, n, seed);
        let w = Timing::new(m, 100.0, 300.0, mode).weights().unwrap();
        let mask: Vec<f32> = (0..m * n).map(|i| if i % 13 == 5 { 0.0 } else { 1.0 }).collect();
        let a = RollingShutterModel::new(Conv2d::sensor(&psf, m, n), w).with_mask(Some(Arc::from(mask)));
        let (k, _, _) = a.video_shape();
        let b = forward(&a, &flashing_points(k, m, n, 100.0));
        let lower: Vec<bool> = (0..m * n).map(|i| i % 11 == 3).collect();
        let data = DataTerm::new(&b).with_lower_bounds(Some(&lower));
        let l = lipschitz(&a);
        let tv = TotalVariation::new((k, m, n), 0.5, 2.0);
        let exact = TvProx::Dual { inner_iters: 30 }.build(&tv);
        let long = solve(&settings(SolverKind::FistaRestart, l, 4000), &a, &data, exact.as_ref(), None, &mut |_: &IterInfo| true);
        let best = long.data_term + long.reg_term;
        let mut objs = Vec::new();
        let r = solve(&settings(SolverKind::AdmmSplit, l, 3000), &a, &data, &tv, None, &mut |i: &IterInfo| {
            objs.push(i.objective());
            true
        });
        let f = r.data_term + r.reg_term;
        eprintln!("{}: admm-split {f:.6e} after {} iterations, fista-restart {best:.6e}", mode.name(), r.iterations);
        assert!(all_finite(&r.x) && objs.iter().all(|o| o.is_finite()));
        assert!(r.x.iter().all(|&v| v >= 0.0), "the reported iterate is feasible");
        assert!(f <= best * 1.001 && f >= best * 0.999, "{}: {f} vs {best}", mode.name());
    }
}

/// Two ranks, for the refusal of a split problem (never communicates).
struct TwoRanks;
impl Ranks for TwoRanks {
    fn rank(&self) -> usize {
        0
    }
    fn size(&self) -> usize {
        2
    }
    fn sum_f64(&self, _: &mut [f64]) {}
    fn max_f64(&self, _: &mut [f64]) {}
    fn sum_f32(&self, _: &mut [f32]) {}
    fn broadcast_f64(&self, _: &mut [f64]) {}
    fn exchange_halo(&self, _: &[f32], _: &[f32], _: &mut [f32], _: &mut [f32]) {}
    fn gather_frames(&self, _: &[f32], _: &[std::ops::Range<usize>], _: usize, _: Option<&mut [f32]>) {}
}

/// What admm-split cannot split is refused by name before a solve: a problem split
/// across ranks, an L1 term beside TV, an operator restricted to a scene's support;
/// the plain capture is taken.
#[test]
fn admm_split_refuses_what_it_cannot_split_by_name() {
    let (m, n) = (8, 6);
    let a = model(&sparse_psf(m, n, 2), m, n, 100.0, 200.0, ShutterMode::Dual);
    let (k, _, _) = a.video_shape();
    let b = forward(&a, &flashing_points(k, m, n, 1.0));
    let kind = SolverKind::AdmmSplit;
    assert!(kind.check_data(&DataTerm::new(&b)).is_ok() && kind.check_operator(&a).is_ok());
    let owned = vec![true; b.len()];
    let split = DataTerm::new(&b).on(Partition { ranks: &TwoRanks, owned: Some(&owned) });
    let e = kind.check_data(&split).unwrap_err();
    assert!(e.starts_with("admm-split: a problem split across ranks"), "{e}");
    let tv = TotalVariation::new((k, m, n), 0.1, 1.0);
    let with_l1 = PriorSpec::Tv(TvPrior::new(tv.clone(), TvProxChoice::Fixed(TvProx::Haar), 0.0).with_l1(0.05)).build(None);
    let e = kind.check_prior(with_l1.as_ref()).unwrap_err();
    assert!(e.starts_with("admm-split: only the TV prior") && e.contains("L1"), "{e}");
    assert!(kind.check_prior(&tv).is_ok());
    let support = Restricted::new(&a, 1..m - 1, 0..n, false);
    let e = kind.check_operator(&support).unwrap_err();
    assert!(e.starts_with("admm-split: the operator is not one capture's shutter-weighted convolution") && e.contains("support"), "{e}");
    assert!(kind.check_operator(&Restricted::new(&a, 0..m, 0..n, false)).is_ok(), "an identity restriction is the capture");
    // The solve itself refuses too (a caller that skipped the checks).
    let s = OptimizerSettings::new(kind, lipschitz(&a), StopRule::iterations(1));
    let tv_s = TotalVariation::new((k, m - 2, n), 0.1, 1.0);
    let refused = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| solve(&s, &support, &DataTerm::new(&b), &tv_s, None, &mut |_: &IterInfo| true)));
    assert!(refused.is_err());
}
