//! Only what a scene needs: where the scene obeys its declaration, the declared
//! (restricted) solve is at least as close to the truth as the full solve, and the
//! declaration removes what it says. At these tiny, underdetermined sizes the full
//! problem's minimiser puts light outside the declared support (its objective is lower
//! than the restricted one's, printed), so the two minimisers are not equal; a
//! declaration of the whole grid changes nothing, bit for bit.

use crate::support::common;
use common::*;
use rollcam::model::capture::{CaptureConfig, Fov};
use rollcam::model::op::{pseudo_random, Operator};
use rollcam::model::prepare::{Plane, Prepared};
use rollcam::model::scene::{Colour, SceneSpec};
use rollcam::model::shutter::ShutterMode;
use rollcam::solve::optimize::NoObserver;
use rollcam::solve::optimize::StopRule;
use rollcam::solve::optimize::{solve, OptimizerSettings, SolverKind};
use rollcam::solve::problem::{DeclaredProblem, Problem};
use rollcam::solve::prox::tv_dual::TvProx;

const M: usize = 12;
const N: usize = 10;

fn setup(channels: usize) -> (Prepared, CaptureConfig) {
    let cfg = CaptureConfig::new(M, N, 100.0, 300.0, ShutterMode::Dual);
    let plane = |d: Vec<f32>| Plane { rows: M, cols: N, data: d };
    let p = Prepared {
        raw: (0..channels).map(|_| plane(vec![0.0; M * N])).collect(),
        psf: (0..channels).map(|c| plane(sparse_psf(M, N, 3 + c as u64))).collect(),
        raw_dark: 0.0,
        psf_dark: 0.0,
        dark_estimated: false,
        ..Prepared::default()
    };
    (p, cfg)
}

/// Channel `ch`'s problem as `spec` declares it, from a capture's problem built here.
fn build_problem(p: &Prepared, cfg: &CaptureConfig, fov: Fov, spec: &SceneSpec, tau: f32, alpha: f32, ch: usize) -> Result<DeclaredProblem, String> {
    let problem = Problem::new(p, cfg, fov).map_err(|e| e.to_string())?;
    problem.declare(spec, tau, alpha, ch).map_err(|e| e.to_string())
}

/// Solve the declared problem; return the video on the full grid's frame window.
fn solve_embedded(p: &DeclaredProblem, iters: usize) -> Vec<f32> {
    let s = OptimizerSettings::new(SolverKind::FistaRestart, lipschitz(&p.op), StopRule::iterations(iters));
    let r = solve(&s, &p.op, &p.data(), TvProx::Dual { inner_iters: 10 }.build(p.tv()).as_ref(), None, &mut NoObserver);
    assert!(all_finite(&r.x));
    p.op.embed(&r.x)
}

/// The full problem's objective at a video given on frames `k0..` of the full grid.
fn full_objective(full: &DeclaredProblem, x_window: &[f32], k0: usize) -> f64 {
    let mut x = vec![0.0f32; full.op.input_len()];
    x[k0 * M * N..k0 * M * N + x_window.len()].copy_from_slice(x_window);
    objective(&full.op, &full.b, full.tv(), &x)
}

fn rel(a: &[f32], b: &[f32]) -> f64 {
    let d: f64 = a.iter().zip(b).map(|(&x, &y)| ((x - y) as f64).powi(2)).sum();
    let n: f64 = b.iter().map(|&y| (y as f64).powi(2)).sum();
    (d / n.max(1e-300)).sqrt()
}

fn measure(p: &mut Prepared, cfg: &CaptureConfig, truth_of_channel: &dyn Fn(usize) -> Vec<f32>) {
    for ch in 0..p.raw.len() {
        let full = build_problem(p, cfg, Fov::Sensor, &SceneSpec::default(), 0.0, 1.0, ch).unwrap();
        p.raw[ch].data = forward(&full.op, &truth_of_channel(ch));
    }
}

#[test]
fn declaring_the_whole_grid_changes_nothing() {
    let (mut p, cfg) = setup(1);
    let k = cfg.timing().weights().unwrap().frames();
    measure(&mut p, &cfg, &|_| flashing_points(k, M, N, 100.0));
    let full = build_problem(&p, &cfg, Fov::Sensor, &SceneSpec::default(), 0.5, 2.0, 0).unwrap();
    let spec = SceneSpec { support: Some([0, M, 0, N]), frames: Some([0, k]), ..SceneSpec::default() };
    let same = build_problem(&p, &cfg, Fov::Sensor, &spec, 0.5, 2.0, 0).unwrap();
    assert!(same.plan().left_out.is_empty(), "{:?}", same.plan().left_out);
    assert_eq!(solve_embedded(&full, 50), solve_embedded(&same, 50));
}

#[test]
fn support_restricted_solve_is_at_least_as_close_to_the_truth_as_the_full_solve() {
    let (mut p, cfg) = setup(1);
    let k = cfg.timing().weights().unwrap().frames();
    // Light only in rows 3..9, cols 2..8.
    let truth: Vec<f32> = flashing_points(k, M, N, 100.0);
    let inside = |i: usize| {
        let (r, c) = ((i / N) % M, i % N);
        (3..9).contains(&r) && (2..8).contains(&c)
    };
    assert!(truth.iter().enumerate().all(|(i, &v)| v == 0.0 || inside(i)));
    measure(&mut p, &cfg, &|_| truth.clone());
    let full = build_problem(&p, &cfg, Fov::Sensor, &SceneSpec::default(), 0.5, 2.0, 0).unwrap();
    let spec = SceneSpec { support: Some([3, 9, 2, 8]), ..SceneSpec::default() };
    let part = build_problem(&p, &cfg, Fov::Sensor, &spec, 0.5, 2.0, 0).unwrap();
    assert_eq!(part.op.input_len() * M * N, full.op.input_len() * 36);
    let (xf, xp) = (solve_embedded(&full, 1500), solve_embedded(&part, 1500));
    let (ef, ep, d) = (rel(&xf, &truth), rel(&xp, &truth), rel(&xp, &xf));
    let (ff, fp) = (full_objective(&full, &xf, 0), full_objective(&full, &xp, 0));
    eprintln!("support: full error {ef:.3e}, restricted error {ep:.3e}, difference {d:.3e}; full objective {ff:.6e} vs restricted {fp:.6e}");
    assert!(ep <= ef * 1.05, "the restricted solve knows more: error {ep} vs {ef}");
}

#[test]
fn frame_window_solve_is_at_least_as_close_to_the_truth_as_the_full_solve() {
    let (mut p, cfg) = setup(1);
    let k = cfg.timing().weights().unwrap().frames();
    let (k0, k1) = (2, k - 3);
    let mut truth = flashing_points(k, M, N, 100.0);
    for f in (0..k0).chain(k1..k) {
        truth[f * M * N..(f + 1) * M * N].iter_mut().for_each(|v| *v = 0.0);
    }
    measure(&mut p, &cfg, &|_| truth.clone());
    let full = build_problem(&p, &cfg, Fov::Sensor, &SceneSpec::default(), 0.5, 2.0, 0).unwrap();
    let spec = SceneSpec { frames: Some([k0, k1]), ..SceneSpec::default() };
    let part = build_problem(&p, &cfg, Fov::Sensor, &spec, 0.5, 2.0, 0).unwrap();
    assert_eq!(part.op.input_shape()[0], k1 - k0);
    assert!(part.plan().left_out.iter().any(|l| l.starts_with("frames")));
    let xf = solve_embedded(&full, 1500);
    let xp = solve_embedded(&part, 1500);
    let window = &xf[k0 * M * N..k1 * M * N];
    let tw = &truth[k0 * M * N..k1 * M * N];
    let (ef, ep, d) = (rel(window, tw), rel(&xp, tw), rel(&xp, window));
    let (ff, fp) = (full_objective(&full, &xf, 0), full_objective(&full, &xp, k0));
    eprintln!("frames: full error {ef:.3e}, windowed error {ep:.3e}, difference {d:.3e}; full objective {ff:.6e} vs windowed {fp:.6e}");
    assert!(ep <= ef * 1.05, "error {ep} vs {ef}");
}

#[test]
fn static_scene_is_solved_as_one_frame_at_least_as_close_to_the_truth() {
    let (mut p, cfg) = setup(1);
    let k = cfg.timing().weights().unwrap().frames();
    let frame: Vec<f32> = pseudo_random(M * N, 5).iter().map(|v| if *v > 0.8 { 50.0 * v } else { 0.0 }).collect();
    let truth: Vec<f32> = (0..k).flat_map(|_| frame.iter().cloned()).collect();
    measure(&mut p, &cfg, &|_| truth.clone());
    let full = build_problem(&p, &cfg, Fov::Sensor, &SceneSpec::default(), 0.2, 2.0, 0).unwrap();
    let spec = SceneSpec { static_scene: true, ..SceneSpec::default() };
    // One frame stands for k: its TV counts k times, so the objectives agree on static videos.
    let part = build_problem(&p, &cfg, Fov::Sensor, &spec, 0.2 * k as f32, 2.0, 0).unwrap();
    assert_eq!(part.op.input_shape(), vec![1, M, N]);
    assert_eq!(part.plan().tv_axes, vec!["y", "x"], "no temporal TV for a static scene");
    let (xf, xp) = (solve_embedded(&full, 1500), solve_embedded(&part, 1500));
    let (ef, ep, d) = (rel(&xf, &truth), rel(&xp, &truth), rel(&xp, &xf));
    let (ff, fp) = (full_objective(&full, &xf, 0), full_objective(&full, &xp, 0));
    eprintln!("static: full error {ef:.3e}, static error {ep:.3e}, difference {d:.3e}; full objective {ff:.6e} vs static {fp:.6e}");
    assert!(ep <= ef * 1.05, "error {ep} vs {ef}");
}

#[test]
fn grey_scene_from_an_rgb_raw_is_solved_once() {
    let (mut p, cfg) = setup(3);
    let k = cfg.timing().weights().unwrap().frames();
    let truth = flashing_points(k, M, N, 100.0);
    measure(&mut p, &cfg, &|_| truth.clone());
    let spec = SceneSpec { colour: Colour::Grey, ..SceneSpec::default() };
    let grey = build_problem(&p, &cfg, Fov::Sensor, &spec, 0.5, 2.0, 0).unwrap();
    assert_eq!((grey.plan().channels_captured, grey.plan().channels_solved), (3, 1));
    // The grey data are the mean of the channels and the grey PSF the mean of theirs: the
    // grey truth explains them exactly.
    let ag = forward(&grey.op, &truth);
    let r: f64 = ag.iter().zip(&grey.b).map(|(a, b)| ((a - b) as f64).powi(2)).sum::<f64>().sqrt();
    let nb: f64 = grey.b.iter().map(|&b| (b as f64).powi(2)).sum::<f64>().sqrt();
    assert!(r < 1e-5 * nb, "residual of the truth {r} vs {nb}");
    // One solve of the combined data recovers the grey video as well as (or better
    // than) each channel's own solve, which it replaces.
    let xg = solve_embedded(&grey, 1500);
    let eg = rel(&xg, &truth);
    for ch in 0..3 {
        let one = build_problem(&p, &cfg, Fov::Sensor, &SceneSpec::default(), 0.5, 2.0, ch).unwrap();
        let e = rel(&solve_embedded(&one, 1500), &truth);
        eprintln!("grey error {eg:.3e}, channel {ch} alone {e:.3e}");
        assert!(eg <= e * 1.05, "grey {eg} vs channel {ch} {e}");
    }
}

#[test]
fn a_declared_scene_wraps_the_channels_operator_built_once() {
    let (p, cfg) = setup(2);
    let k = cfg.timing().weights().unwrap().frames();
    let problem = Problem::new(&p, &cfg, Fov::Sensor).unwrap();
    let channel = problem.channel(1);
    // The default declaration is the channel's problem itself: the same operator, the
    // same cache key and scale.
    let plain = problem.declare(&SceneSpec::default(), 0.5, 2.0, 1).unwrap();
    assert!(std::ptr::eq(plain.model(), channel.model()), "the undeclared operator was built again");
    assert!(std::ptr::eq(&*plain.declaration.full, channel.model()));
    assert_eq!(plain.key(), channel.key());
    assert_eq!(plain.atb_max(), channel.atb_max());
    // A support box and a static scene restrict the same operator, under keys of their
    // own (a restricted operator never takes the full one's constant).
    for spec in [SceneSpec { support: Some([2, 10, 1, 9]), ..SceneSpec::default() }, SceneSpec { static_scene: true, ..SceneSpec::default() }] {
        let part = problem.declare(&spec, 0.5, 2.0, 1).unwrap();
        assert!(std::ptr::eq(part.model(), channel.model()), "{spec:?}");
        assert_ne!(part.key(), channel.key(), "{spec:?}");
    }
    let boxed = problem.declare(&SceneSpec { support: Some([2, 10, 1, 9]), ..SceneSpec::default() }, 0.5, 2.0, 1).unwrap();
    let still = problem.declare(&SceneSpec { static_scene: true, ..SceneSpec::default() }, 0.5, 2.0, 1).unwrap();
    assert_ne!(boxed.key(), still.key());
    // A frame window changes the operator itself (its shutter weights): an operator and
    // a key of its own, checked against the channel's undeclared one.
    let window = problem.declare(&SceneSpec { frames: Some([1, k - 1]), ..SceneSpec::default() }, 0.5, 2.0, 1).unwrap();
    assert!(!std::ptr::eq(window.model(), channel.model()));
    assert!(std::ptr::eq(&*window.declaration.full, channel.model()));
    assert_ne!(window.key(), channel.key());
    assert_eq!(window.model().frames(), k - 2);
    // Another channel's operator is another operator.
    assert_ne!(problem.channel(0).key(), channel.key());
}
