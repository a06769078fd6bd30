//! The solvers on a CUDA device (`--device cuda`, feature `cuda`): each device step runs
//! the CPU step's iterations on masked and clipped captures of every shutter mode, and
//! what the device cannot run is refused by name. Where no device can run here (a
//! build without the feature, no driver, no GPU) the device tests check that the
//! refusal says what is missing; `scripts/gpu-study.sh` runs them on a GPU.

use crate::support::common;
use common::*;
use rollcam::model::conv::Conv2d;
use rollcam::model::data::DataTerm;
use rollcam::model::rolling::RollingShutterModel;
use rollcam::model::scene::Restricted;
use rollcam::model::shutter::{ShutterMode, Timing};
use rollcam::solve::optimize::{solve, Device, IterInfo, SolveResult, SolverKind};
use rollcam::solve::prox::prior::{PriorSpec, TvPrior};
use rollcam::solve::prox::tv_dual::{TvProx, TvProxChoice};
use rollcam::solve::prox::TotalVariation;
use std::sync::Arc;

/// Whether a CUDA device runs here; where none does, the reason names what is missing.
fn cuda_here() -> bool {
    match SolverKind::AdmmSplit.check_device(Device::Cuda) {
        Ok(()) => true,
        Err(e) => {
            assert!(e.starts_with("--device cuda: ") && (e.contains("without CUDA") || e.contains("not found") || e.contains("no CUDA device")), "{e}");
            eprintln!("no CUDA device here: {e}");
            false
        }
    }
}

/// A capture of `mode` (24 x 20, flashing points), masked (zeros and halves) and with
/// clipped pixels when `masked`.
struct Capture {
    a: RollingShutterModel,
    b: Vec<f32>,
    lower: Vec<bool>,
    l: f64,
    k: usize,
}

fn capture(mode: ShutterMode, seed: u64, masked: bool) -> Capture {
    let (m, n) = (24, 20);
    let psf = sparse_psf(m, n, seed);
    let w = Timing::new(m, 100.0, 300.0, mode).weights().unwrap();
    let mask: Vec<f32> = (0..m * n)
        .map(|i| {
            if i % 13 == 5 {
                0.0
            } else if i % 7 == 2 {
                0.5
            } else {
                1.0
            }
        })
        .collect();
    let a = RollingShutterModel::new(Conv2d::sensor(&psf, m, n), w).with_mask(masked.then(|| Arc::from(mask)));
    let (k, _, _) = a.video_shape();
    let b = forward(&a, &flashing_points(k, m, n, 100.0));
    let lower: Vec<bool> = (0..m * n).map(|i| masked && i % 11 == 3).collect();
    let l = lipschitz(&a);
    Capture { a, b, lower, l, k }
}

/// One solve of `kind` on `device`, `iters` iterations, with every iteration's objective.
fn run_on(c: &Capture, kind: SolverKind, device: Device, tv: &TotalVariation, iters: usize) -> (SolveResult, Vec<f64>) {
    let mut s = settings(kind, c.l, iters);
    s.device = device;
    let data = DataTerm::new(&c.b).with_lower_bounds(Some(&c.lower));
    let mut objs = Vec::new();
    let r = solve(&s, &c.a, &data, tv, None, &mut |i: &IterInfo| {
        objs.push(i.objective());
        true
    });
    (r, objs)
}

/// `||a - b|| / ||a||`.
fn rel_diff(a: &[f32], b: &[f32]) -> f64 {
    let (d2, n2) = a.iter().zip(b).fold((0.0f64, 0.0f64), |(d, s), (&x, &y)| (d + ((x - y) as f64).powi(2), s + (x as f64).powi(2)));
    (d2 / n2.max(1e-300)).sqrt()
}

/// The device step of `kind` follows the CPU step: every iteration's objective within
/// `obj_tol` (relative), the video within `x_tol`, non-negative and finite.
fn follows_the_cpu(kind: SolverKind, iters: usize, obj_tol: f64, x_tol: f64) {
    for (mode, seed, masked) in [(ShutterMode::Rolling, 3u64, false), (ShutterMode::Dual, 7, true), (ShutterMode::DualCenterOut, 5, true)] {
        let c = capture(mode, seed, masked);
        let tv = TotalVariation::new((c.k, 24, 20), 0.5, 2.0);
        let ((cpu, cpu_objs), (gpu, gpu_objs)) = (run_on(&c, kind, Device::Cpu, &tv, iters), run_on(&c, kind, Device::Cuda, &tv, iters));
        assert_eq!((cpu.iterations, gpu_objs.len()), (gpu.iterations, cpu_objs.len()));
        for (it, (c, g)) in cpu_objs.iter().zip(&gpu_objs).enumerate() {
            assert!((c - g).abs() <= obj_tol * c.abs(), "{kind} {}: iteration {}: cpu {c:.8e}, cuda {g:.8e}", mode.name(), it + 1);
        }
        let d = rel_diff(&cpu.x, &gpu.x);
        assert!(d < x_tol, "{kind} {}: videos differ by {d:.2e}", mode.name());
        assert!(gpu.x.iter().all(|&v| v >= 0.0 && v.is_finite()));
        eprintln!("{kind} {}: cpu and cuda agree over {} iterations (video {d:.1e})", mode.name(), gpu.iterations);
    }
}

/// admm-split on the device: 80 iterations, objectives within 1e-4, video within 1e-3.
#[test]
fn admm_split_on_cuda_follows_the_cpu_step() {
    if cuda_here() {
        follows_the_cpu(SolverKind::AdmmSplit, 80, 1e-4, 1e-3);
    }
}

/// FISTA (no restart: no decision that rounding could flip) on the device: 150
/// iterations, objectives within 1e-4, video within 1e-3; restart FISTA ends within
/// 1e-3 of the CPU's objective after 300.
#[test]
fn fista_on_cuda_follows_the_cpu_step() {
    if !cuda_here() {
        return;
    }
    follows_the_cpu(SolverKind::Fista, 150, 1e-4, 1e-3);
    let c = capture(ShutterMode::Dual, 11, true);
    let tv = TotalVariation::new((c.k, 24, 20), 0.5, 2.0);
    let ((cpu, _), (gpu, _)) = (run_on(&c, SolverKind::FistaRestart, Device::Cpu, &tv, 300), run_on(&c, SolverKind::FistaRestart, Device::Cuda, &tv, 300));
    let (fc, fg) = (cpu.data_term + cpu.reg_term, gpu.data_term + gpu.reg_term);
    assert!((fc - fg).abs() <= 1e-3 * fc, "fista-restart: cpu {fc:.8e}, cuda {fg:.8e}");
}

/// What the device's FISTA cannot run is refused by name before a solve, here or not:
/// the exact (dual) map, an L1 term, a scene's support, the preconditioner; the other
/// solvers refuse the device; the plain capture with the Haar map is taken, and fits
/// the memory where a device runs.
#[test]
fn the_device_refuses_what_it_cannot_run_by_name() {
    let e = SolverKind::Mfista.check_device(Device::Cuda).unwrap_err();
    assert!(e.contains("mfista runs on the CPU only") && e.contains("fista-restart"), "{e}");
    assert_eq!(SolverKind::Mfista.check_device(Device::Cpu), Ok(()));
    let c = capture(ShutterMode::Dual, 2, true);
    let (k, m, n) = (c.k, 24, 20);
    let data = DataTerm::new(&c.b);
    let kind = SolverKind::FistaRestart;
    let tv = TotalVariation::new((k, m, n), 0.1, 1.0);
    assert!(kind.check_on_device(Device::Cuda, &c.a, &data, &tv, false).is_ok());
    // The memory check: fits where a device runs; elsewhere only the device is missing.
    match kind.check_device_memory(Device::Cuda, &c.a, 3) {
        Ok(()) => assert!(cuda_here()),
        Err(e) => assert!(!cuda_here() && e.starts_with("--device cuda: "), "{e}"),
    }
    assert_eq!(kind.check_device_memory(Device::Cpu, &c.a, 3), Ok(()));
    let dual = PriorSpec::Tv(TvPrior::new(tv.clone(), TvProxChoice::Fixed(TvProx::Dual { inner_iters: 10 }), 0.0)).build(None);
    let e = kind.check_on_device(Device::Cuda, &c.a, &data, dual.as_ref(), false).unwrap_err();
    assert!(e.starts_with("fista-restart on --device cuda: only the TV prior through the Haar map"), "{e}");
    let with_l1 = PriorSpec::Tv(TvPrior::new(tv.clone(), TvProxChoice::Fixed(TvProx::Haar), 0.0).with_l1(0.05)).build(None);
    assert!(kind.check_on_device(Device::Cuda, &c.a, &data, with_l1.as_ref(), false).unwrap_err().contains("L1"));
    let support = Restricted::new(&c.a, 1..m - 1, 0..n, false);
    let e = kind.check_on_device(Device::Cuda, &support, &data, &TotalVariation::new((k, m - 2, n), 0.1, 1.0), false).unwrap_err();
    assert!(e.contains("not one capture's shutter-weighted convolution"), "{e}");
    assert!(kind.check_on_device(Device::Cuda, &c.a, &data, &tv, true).unwrap_err().contains("preconditioner runs on the CPU"));
    // On the CPU every check passes.
    assert!(kind.check_on_device(Device::Cpu, &support, &data, dual.as_ref(), true).is_ok());
}
