//! The sequence operator: adjoint consistency with gaps and overlapping captures,
//! equality with the per-capture models on their slices, and its Lipschitz constant
//! between the largest and the sum of the per-capture ones.

use rollcam::model::capture::CaptureConfig;
use rollcam::model::conv::Conv2d;
use rollcam::model::op::{adjoint_mismatch, pseudo_random, Operator};
use rollcam::model::prepare::Plane;
use rollcam::model::rolling::RollingShutterModel;
use rollcam::model::shutter::{ShutterMode, Timing};
use rollcam::solve::lipschitz::power_iteration;
use rollcam::solve::sequence::{Placed, Sequence, SequenceModel, TimeGrid, TimeSource};
use std::sync::Arc;

fn psf(m: usize, n: usize, seed: u64) -> Vec<f32> {
    let r = pseudo_random(m * n, seed);
    let p: Vec<f32> = r.iter().map(|&v| if v > 0.8 { v } else { 0.0 }).collect();
    let s: f32 = p.iter().sum();
    p.iter().map(|v| v / s).collect()
}

fn model(m: usize, n: usize, mode: ShutterMode, exposure_us: f64, seed: u64) -> Arc<RollingShutterModel> {
    let w = Timing::new(m, 10.0, exposure_us, mode).weights().unwrap();
    Arc::new(RollingShutterModel::new(Conv2d::sensor(&psf(m, n, seed), m, n), w))
}

#[test]
fn adjoint_holds_with_gaps_and_overlaps() {
    for mode in [ShutterMode::Rolling, ShutterMode::Dual] {
        let (m, n) = (10, 9);
        let a = model(m, n, mode, 30.0, 3);
        let k = a.frames();
        // Capture 1 overlaps capture 0 by 3 frames, a gap of 4 frames before capture 2,
        // and capture 3 overlaps capture 2 by one frame.
        let offsets = [0, k - 3, 2 * k - 3 + 4, 3 * k - 3 + 4 - 1];
        let frames = offsets[3] + k;
        let parts = offsets.iter().map(|&o| Placed { offset: o, model: a.clone() }).collect();
        let seq = SequenceModel::new(frames, parts);
        assert_eq!(seq.input_shape(), vec![frames, m, n]);
        assert_eq!(seq.output_shape(), vec![4, m, n]);
        for seed in 0..3 {
            let x: Vec<f32> = pseudo_random(seq.input_len(), 10 + seed).iter().map(|v| v - 0.3).collect();
            let y: Vec<f32> = pseudo_random(seq.output_len(), 20 + seed).iter().map(|v| v - 0.5).collect();
            let e = adjoint_mismatch(&seq, &x, &y);
            assert!(e < 1e-5, "{mode}: adjoint mismatch {e}");
        }
        // Forward: capture c's block is its model on its slice; adjoint: gap frames get
        // nothing, shared frames the sum of both captures.
        let x = pseudo_random(seq.input_len(), 5);
        let mut y = vec![0.0; seq.output_len()];
        seq.forward(&x, &mut y);
        let fl = m * n;
        for (c, &o) in offsets.iter().enumerate() {
            let mut yc = vec![0.0; m * n];
            a.forward(&x[o * fl..(o + k) * fl], &mut yc);
            assert_eq!(&y[c * m * n..(c + 1) * m * n], &yc[..]);
        }
        let yv = pseudo_random(seq.output_len(), 6);
        let mut at = vec![f32::NAN; seq.input_len()];
        seq.adjoint(&yv, &mut at);
        let mut expect = vec![0.0f32; seq.input_len()];
        let mut part = vec![0.0f32; k * fl];
        for (c, &o) in offsets.iter().enumerate() {
            a.adjoint(&yv[c * m * n..(c + 1) * m * n], &mut part);
            for (e, p) in expect[o * fl..(o + k) * fl].iter_mut().zip(&part) {
                *e += p;
            }
        }
        for (i, (g, e)) in at.iter().zip(&expect).enumerate() {
            assert!((g - e).abs() <= 1e-5 * e.abs().max(1e-3), "{mode}: adjoint entry {i}: {g} vs {e}");
        }
        for f in offsets[1] + k..offsets[2] {
            assert!(at[f * fl..(f + 1) * fl].iter().all(|&v| v == 0.0), "gap frame {f} must receive nothing");
        }
    }
}

#[test]
fn lipschitz_between_largest_and_sum_of_the_captures() {
    let (m, n) = (12, 10);
    // Different PSFs and exposures so the per-capture constants differ.
    let parts_models = [model(m, n, ShutterMode::Dual, 30.0, 1), model(m, n, ShutterMode::Dual, 30.0, 2), model(m, n, ShutterMode::Dual, 50.0, 4)];
    let l_each: Vec<f64> = parts_models.iter().map(|a| power_iteration(a.as_ref(), 2000, 1e-9, 7).lambda_max).collect();
    let (lmax, lsum) = (l_each.iter().cloned().fold(0.0, f64::max), l_each.iter().sum::<f64>());
    let k0 = parts_models[0].frames();
    // Heavy overlap (captures one frame apart), continuous readout, and gaps.
    for spacing in [1usize, k0 - 2, k0 + 5] {
        let offsets = [0, spacing, 2 * spacing];
        let frames = (0..3).map(|c| offsets[c] + parts_models[c].frames()).max().unwrap();
        let parts = (0..3).map(|c| Placed { offset: offsets[c], model: parts_models[c].clone() }).collect();
        let seq = SequenceModel::new(frames, parts);
        let l = power_iteration(&seq, 3000, 1e-10, 7).lambda_max;
        assert!(l >= lmax * (1.0 - 1e-4), "spacing {spacing}: {l} below the largest capture's {lmax}");
        assert!(l <= lsum * (1.0 + 1e-4), "spacing {spacing}: {l} above the sum {lsum}");
        if spacing > k0 {
            // Disjoint captures: the largest.
            assert!((l - lmax).abs() <= 1e-3 * lmax, "disjoint captures: {l} vs {lmax}");
        }
        if spacing == 1 {
            // Strong overlap couples them: clearly above the largest.
            assert!(l > 1.2 * lmax, "overlapping captures: {l} vs largest {lmax}");
        }
    }
}

#[test]
fn streaming_windows_are_consistent_operators() {
    // A window that starts inside the previous capture restricts it to the window's
    // frames; its adjoint must still hold, and on a video that is zero before the
    // window it must reproduce the whole-sequence forward.
    let (m, n) = (12, 10);
    let mut cfg = CaptureConfig::new(m, n, 10.0, 30.0, ShutterMode::Dual);
    cfg.dark_level = Some(0.0);
    let w = cfg.timing().weights().unwrap();
    let k = w.frames();
    let grid = TimeGrid::with_offsets(&[0, k - 2, 2 * k + 1], &w, TimeSource::FramePeriod { period_us: 0.0 });
    let p = Plane { rows: m, cols: n, data: psf(m, n, 9) };
    let raws: Vec<Plane> = (0..3).map(|c| Plane { rows: m, cols: n, data: pseudo_random(m * n, 30 + c) }).collect();
    let seq = Sequence::new(&cfg, w.clone(), p, grid.clone(), raws);
    let (f, mv, nv) = seq.video_shape();
    let fl = mv * nv;
    let x = pseudo_random(f * fl, 40);
    for (c, solved_end, h) in [(1usize, k, 3usize), (2, 2 * k - 2, 4)] {
        let win = seq.window(c, solved_end, h, &x);
        assert_eq!(win.frames.start, grid.offsets[c].min(solved_end) - h);
        let xw = pseudo_random(win.op.input_len(), 50 + c as u64);
        let yw = pseudo_random(win.op.output_len(), 60 + c as u64);
        assert!(adjoint_mismatch(&win.op, &xw, &yw) < 1e-5);
        // The window's data = full data minus the fixed frames' contribution: with the
        // result so far equal to x, A_window x[window] == b_window exactly when b = A x.
        let full = seq.operator();
        let mut b = vec![0.0; full.output_len()];
        full.forward(&x, &mut b);
        let seq_b = Sequence::new(
            &cfg,
            w.clone(),
            seq.psf.clone(),
            grid.clone(),
            (0..3).map(|j| Plane { rows: m, cols: n, data: b[j * m * n..(j + 1) * m * n].to_vec() }).collect(),
        );
        let win = seq_b.window(c, solved_end, h, &x);
        let mut aw = vec![0.0; win.op.output_len()];
        win.op.forward(&x[win.frames.start * fl..win.frames.end * fl], &mut aw);
        let scale = win.b.iter().fold(0.0f32, |a, v| a.max(v.abs()));
        for (i, (p, q)) in aw.iter().zip(&win.b).enumerate() {
            assert!((p - q).abs() <= 1e-4 * scale, "window {c} entry {i}: {p} vs {q}");
        }
    }
}
