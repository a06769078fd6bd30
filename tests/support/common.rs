//! Small problems shared by the solver and stiff-case tests.
#![allow(dead_code)]

use rollcam::model::conv::Conv2d;
use rollcam::model::data::DataTerm;
use rollcam::model::op::{pseudo_random, Dense, Operator};
use rollcam::model::rolling::RollingShutterModel;
use rollcam::model::shutter::{ShutterMode, Timing};
use rollcam::solve::lipschitz::{power_iteration, LIPSCHITZ_MARGIN};
use rollcam::solve::optimize::{solve, OptimizerSettings, SolverKind};
use rollcam::solve::optimize::{IterInfo, SolveResult, StopRule};
use rollcam::solve::prox::Prox;

/// A caustic-like PSF: a few bright random points, unit sum.
pub fn sparse_psf(m: usize, n: usize, seed: u64) -> Vec<f32> {
    let r = pseudo_random(m * n, seed);
    let mut psf: Vec<f32> = r.iter().map(|&v| if v > 0.85 { v } else { 0.0 }).collect();
    if psf.iter().all(|&v| v == 0.0) {
        psf[0] = 1.0;
    }
    let s: f32 = psf.iter().sum();
    psf.iter().map(|v| v / s).collect()
}

pub fn model(psf: &[f32], m: usize, n: usize, line_us: f64, exposure_us: f64, mode: ShutterMode) -> RollingShutterModel {
    let w = Timing::new(m, line_us, exposure_us, mode).weights().unwrap();
    RollingShutterModel::new(Conv2d::sensor(psf, m, n), w)
}

pub fn lipschitz<A: Operator + ?Sized>(op: &A) -> f64 {
    power_iteration(op, 500, 1e-7, 0x5eed).lambda_max * LIPSCHITZ_MARGIN
}

/// Two point sources flashing with periods 4 and 6 frames.
pub fn flashing_points(k: usize, m: usize, n: usize, level: f32) -> Vec<f32> {
    let mut x = vec![0.0f32; k * m * n];
    let pts = [((m / 3, n / 3), 4usize), ((2 * m / 3, 2 * n / 3), 6usize)];
    for f in 0..k {
        for &((r, c), p) in &pts {
            if f % p < p / 2 {
                x[(f * m + r) * n + c] = level;
            }
        }
    }
    x
}

pub fn forward<A: Operator + ?Sized>(op: &A, x: &[f32]) -> Vec<f32> {
    let mut y = vec![0.0; op.output_len()];
    op.forward(x, &mut y);
    y
}

pub fn objective<A: Operator + ?Sized>(op: &A, b: &[f32], tv: &dyn Prox, x: &[f32]) -> f64 {
    let ax = forward(op, x);
    0.5 * ax.iter().zip(b).map(|(&p, &q)| ((p - q) as f64).powi(2)).sum::<f64>() + tv.value(x)
}

/// Run a solver on `0.5 ||A x - b||^2 + prior` and record the objective after every
/// iteration.
pub fn run<A: Operator + ?Sized, R: Prox + ?Sized>(s: &OptimizerSettings, op: &A, b: &[f32], prior: &R) -> (SolveResult, Vec<f64>) {
    let mut objs = Vec::new();
    let mut obs = |i: &IterInfo| {
        objs.push(i.objective());
        true
    };
    let r = solve(s, op, &DataTerm::new(b), prior, None, &mut obs);
    (r, objs)
}

pub fn settings(kind: SolverKind, l: f64, iters: usize) -> OptimizerSettings {
    OptimizerSettings::new(kind, l, StopRule::iterations(iters))
}

pub fn all_finite(x: &[f32]) -> bool {
    x.iter().all(|v| v.is_finite())
}

/// Largest eigenvalue of `A^T A` (dense reference).
pub fn dense_lambda_max(a: &Dense) -> f64 {
    a.gram_lambda_max()
}

/// Iterations that let each solver converge on a tiny problem: the baseline (PGD) is
/// slower by design and gets more.
pub fn iters_for(kind: SolverKind, n: usize) -> usize {
    if kind == SolverKind::Pgd {
        8 * n
    } else {
        n
    }
}

/// Converged enough: at or below 1.1 x the objective of a feasible point (the truth).
pub fn near_truth_objective(last: f64, f_truth: f64) -> bool {
    last <= 1.1 * f_truth + 1e-12
}

/// Pearson correlation of two equally long sequences.
pub fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let cov: f64 = a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum();
    let va: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
    let vb: f64 = b.iter().map(|y| (y - mb).powi(2)).sum();
    cov / (va * vb).sqrt()
}
