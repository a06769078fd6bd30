//! SCRATCH (delete): dumps every solver's iterates bit for bit, to compare before/after
//! the executor refactor.
mod common;
use common::*;
use rollcam::model::op::{pseudo_random, Dense, Operator};
use rollcam::model::shutter::ShutterMode;
use rollcam::solve::optimize::{solve, IterInfo, SolverKind, SolverSettings, StopRule};
use rollcam::solve::prox::tv::TotalVariation;
use rollcam::solve::prox::tv_dual::TvProx;
use std::fmt::Write as _;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Writes NaN into `y[0]` from the `from`-th forward call on.
struct NanAfter<'a, A: ?Sized> {
    op: &'a A,
    from: usize,
    calls: AtomicUsize,
}
impl<A: Operator + ?Sized> Operator for NanAfter<'_, A> {
    fn input_shape(&self) -> Vec<usize> {
        self.op.input_shape()
    }
    fn output_shape(&self) -> Vec<usize> {
        self.op.output_shape()
    }
    fn forward(&self, x: &[f32], y: &mut [f32]) {
        self.op.forward(x, y);
        if self.calls.fetch_add(1, Ordering::SeqCst) + 1 >= self.from {
            y[0] = f32::NAN;
        }
    }
    fn adjoint(&self, y: &[f32], x: &mut [f32]) {
        self.op.adjoint(y, x)
    }
}

fn hash(x: &[f32]) -> u64 {
    let mut h = 0xcbf29ce484222325u64;
    for v in x {
        h ^= v.to_bits() as u64;
        h = h.wrapping_mul(0x100000001b3);
    }
    h
}

fn record<A: Operator + ?Sized>(
    out: &mut String,
    label: &str,
    s: &SolverSettings,
    a: &A,
    b: &[f32],
    tv: &TotalVariation,
    x0: Option<Vec<f32>>,
    stop_after: usize,
) {
    let mut lines = String::new();
    let mut count = 0;
    let r = solve(s, a, b, tv, x0, &mut |i: &IterInfo| {
        writeln!(
            lines,
            "  it {} d {:016x} r {:016x} rel {:016x} x {:016x}",
            i.iteration,
            i.data_term.to_bits(),
            i.reg_term.to_bits(),
            i.rel_change.to_bits(),
            hash(i.x)
        )
        .unwrap();
        count += 1;
        count < stop_after
    });
    writeln!(
        out,
        "{label} {}: {:?} iters {} d {:016x} r {:016x} x {:016x} len {}",
        s.kind,
        r.termination,
        r.iterations,
        r.data_term.to_bits(),
        r.reg_term.to_bits(),
        hash(&r.x),
        r.x.len()
    )
    .unwrap();
    out.push_str(&lines);
}

#[test]
fn dump_solver_bits() {
    let path = std::env::var("SCRATCH_BITS_OUT").unwrap_or_else(|_| "/tmp/scratch_bits.txt".into());
    let mut out = String::new();
    // A rolling-shutter problem with a video above one BLOCK (1 << 15).
    let (m, n) = (44, 40);
    let a = model(&sparse_psf(m, n, 3), m, n, 100.0, 300.0, ShutterMode::Dual);
    let (k, _, _) = a.video_shape();
    writeln!(out, "video {k}x{m}x{n} = {}", a.input_len()).unwrap();
    let truth = flashing_points(k, m, n, 100.0);
    let b = forward(&a, &truth);
    let l = lipschitz(&a);
    let tv = TotalVariation::new((k, m, n), 0.5, 2.0);
    let x0: Vec<f32> = pseudo_random(a.input_len(), 9).iter().map(|v| v.abs() * 10.0).collect();
    for kind in SolverKind::ALL {
        for prox in [TvProx::Haar, TvProx::Dual { inner_iters: 5 }] {
            let mut s = SolverSettings::new(kind, l, StopRule::iterations(30));
            s.tv_prox = prox;
            record(&mut out, &format!("rs {prox:?}"), &s, &a, &b, &tv, None, usize::MAX);
            record(&mut out, &format!("rs-warm {prox:?}"), &s, &a, &b, &tv, Some(x0.clone()), usize::MAX);
        }
        // Observer stop, rel_tol.
        let s = SolverSettings::new(kind, l, StopRule::iterations(30));
        record(&mut out, "rs-stop", &s, &a, &b, &tv, None, 7);
        let s = SolverSettings::new(kind, l, StopRule { max_iters: 400, rel_tol: 1e-3, time_budget_s: None });
        record(&mut out, "rs-reltol", &s, &a, &b, &tv, None, usize::MAX);
        // Divergence (step far too long): non-finite at a later iteration.
        let s = SolverSettings::new(kind, l * 1e-3, StopRule::iterations(60));
        record(&mut out, "rs-diverge", &s, &a, &b, &tv, None, usize::MAX);
        // NaN from the operator, later on.
        let s = SolverSettings::new(kind, l, StopRule::iterations(30));
        let late = NanAfter { op: &a, from: 12, calls: AtomicUsize::new(0) };
        record(&mut out, "rs-late-nan", &s, &late, &b, &tv, Some(x0.clone()), usize::MAX);
        // NaN in the data.
        let mut bn = b.clone();
        bn[11] = f32::NAN;
        let s = SolverSettings::new(kind, l, StopRule::iterations(30));
        record(&mut out, "rs-nan", &s, &a, &bn, &tv, None, usize::MAX);
    }
    // A small dense problem.
    let d = Dense { rows: 40, cols: 24, a: pseudo_random(40 * 24, 5) };
    let bd = pseudo_random(40, 6);
    let ld = dense_lambda_max(&d) * 1.01;
    let tvd = TotalVariation::new((2, 3, 4), 0.1, 1.0);
    for kind in SolverKind::ALL {
        let s = SolverSettings::new(kind, ld, StopRule::iterations(30));
        record(&mut out, "dense", &s, &d, &bd, &tvd, None, usize::MAX);
        let s = SolverSettings::new(kind, ld * 1e-3, StopRule::iterations(60));
        record(&mut out, "dense-diverge", &s, &d, &bd, &tvd, None, usize::MAX);
    }
    std::fs::write(&path, out).unwrap();
}
