//! Precision: the f32 solver (f64 reductions) against the same FISTA written in f64 on
//! a dense f64 copy of the operator, with the same TV map.

use crate::support::common;
use common::*;
use rollcam::model::data::DataTerm;
use rollcam::model::op::Dense;
use rollcam::model::shutter::ShutterMode;
use rollcam::solve::optimize::{Fista, NoObserver, StopRule};
use rollcam::solve::prox::TotalVariation;

/// The parallel Haar TV map in f64, written from its definition (pairs along each
/// active axis with shifts 0 and 1, threshold J gamma tau w_a, average of J terms).
fn haar_prox_f64(shape: (usize, usize, usize), tau: f64, w: [f64; 3], z: &[f64], gamma: f64) -> Vec<f64> {
    let (k, m, n) = shape;
    let dims = [k, m, n];
    let strides = [m * n, n, 1];
    let axes: Vec<usize> = (0..3).filter(|&a| w[a] > 0.0 && dims[a] > 1 && tau > 0.0).collect();
    let j = 2.0 * axes.len() as f64;
    let mut out = vec![0.0; z.len()];
    if axes.is_empty() {
        out.copy_from_slice(z);
    } else {
        for &a in &axes {
            let c = j * gamma * tau * w[a];
            for s in 0..2 {
                let mut term = z.to_vec();
                for i in 0..z.len() {
                    let co = (i / strides[a]) % dims[a];
                    if co >= s && (co - s) % 2 == 0 && co + 1 < dims[a] {
                        let (p, q) = (z[i], z[i + strides[a]]);
                        let mean = 0.5 * (p + q);
                        let d = 0.5 * (q - p);
                        let d = d.signum() * (d.abs() - c).max(0.0);
                        term[i] = mean - d;
                        term[i + strides[a]] = mean + d;
                    }
                }
                out.iter_mut().zip(&term).for_each(|(o, t)| *o += t);
            }
        }
        out.iter_mut().for_each(|v| *v /= j);
    }
    out.iter_mut().for_each(|v| *v = v.max(0.0));
    out
}

#[test]
fn f32_fista_matches_an_f64_reference_within_1e_4() {
    let (m, n) = (6, 5);
    let a = model(&sparse_psf(m, n, 3), m, n, 100.0, 300.0, ShutterMode::Dual);
    let (k, _, _) = a.video_shape();
    let truth = flashing_points(k, m, n, 10.0);
    let b = forward(&a, &truth);
    let l = lipschitz(&a);
    let (tau, alpha) = (0.05f32, 2.0f32);
    let tv = TotalVariation::new((k, m, n), tau, alpha);
    let iters = 150;
    let r = Fista { lipschitz: l, stop: StopRule::iterations(iters), restart: None }.solve(&a, &DataTerm::new(&b), &tv, None, &mut NoObserver);

    // Same algorithm in f64.
    let d = Dense::from_operator(&a);
    let (rows, cols) = (d.rows, d.cols);
    let am: Vec<f64> = d.a.iter().map(|&v| v as f64).collect();
    let bd: Vec<f64> = b.iter().map(|&v| v as f64).collect();
    let fwd = |x: &[f64]| -> Vec<f64> { (0..rows).map(|i| (0..cols).map(|j| am[i * cols + j] * x[j]).sum()).collect() };
    let adj = |y: &[f64]| -> Vec<f64> { (0..cols).map(|j| (0..rows).map(|i| am[i * cols + j] * y[i]).sum()).collect() };
    let step = 1.0 / l;
    let (mut x, mut y, mut t) = (vec![0.0f64; cols], vec![0.0f64; cols], 1.0f64);
    for _ in 0..iters {
        let ay = fwd(&y);
        let res: Vec<f64> = ay.iter().zip(&bd).map(|(p, q)| p - q).collect();
        let g = adj(&res);
        let z: Vec<f64> = y.iter().zip(&g).map(|(v, gv)| v - step * gv).collect();
        let xn = haar_prox_f64((k, m, n), tau as f64, [alpha as f64, 1.0, 1.0], &z, step);
        let tn = 0.5 * (1.0 + (1.0 + 4.0 * t * t).sqrt());
        let beta = (t - 1.0) / tn;
        y = xn.iter().zip(&x).map(|(a, b)| a + beta * (a - b)).collect();
        x = xn;
        t = tn;
    }
    let norm: f64 = x.iter().map(|v| v * v).sum::<f64>().sqrt();
    let diff: f64 = r.x.iter().zip(&x).map(|(&p, q)| (p as f64 - q).powi(2)).sum::<f64>().sqrt();
    eprintln!("relative difference f32 vs f64: {:.3e}", diff / norm);
    assert!(norm > 0.0);
    assert!(diff / norm < 1e-4, "relative difference {}", diff / norm);
}
