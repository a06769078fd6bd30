//! Key frames from a second, global-shutter camera fused into the solve: a bright square
//! crossing a textured scene behind a sparse PSF, dual shutter, key frames at the first
//! and the last frame with a gain and a dark level the solver is not told. The gain must
//! be fitted, the moving part must come back better than from the raw alone, and what
//! cannot be taken with key frames is refused by name.

use ndarray::Array3;
use rollcam::io::cache::LipschitzCache;
use rollcam::model::capture::{CaptureConfig, Fov};
use rollcam::model::keyframe::{KeyFrameOp, KeyFrameRef};
use rollcam::model::op::{pseudo_random, Operator};
use rollcam::model::prepare::{prepare_keyframe, KeyFrameImage};
use rollcam::model::prepare::{Plane, Prepared};
use rollcam::model::shutter::ShutterMode;
use rollcam::solve::problem::{build_operator, Problem, SolveSettings};
use rollcam::solve::reconstruct::{reconstruct, Hooks, ModelChoice, Reconstruction, SolveOptions};
use rollcam::solve::trace::motion_error;
use std::sync::atomic::AtomicBool;

const GAIN: f64 = 3.0;
const DARK: f32 = 40.0;

struct Scene {
    cfg: CaptureConfig,
    prepared: Prepared,
    truth: Vec<f32>,
    k: usize,
}

/// A 24 x 32 dual-shutter capture of a 4 x 4 square crossing a texture, and its key
/// frames (with `keyframes`) at the first and last frame.
fn scene(keyframes: bool) -> Scene {
    scene_of(keyframes, 24)
}

/// [`scene`] with `m` sensor rows.
fn scene_of(keyframes: bool, m: usize) -> Scene {
    scene_with(keyframes, m, |f, k, m, n| {
        let c0 = 2 + (f * (n - 8)) / (k - 1);
        let mut frame: Vec<f32> = pseudo_random(m * n, 5).iter().map(|v| 200.0 + 300.0 * v).collect();
        for r in m / 2 - 2..m / 2 + 2 {
            for c in c0..c0 + 4 {
                frame[r * n + c] = 2000.0;
            }
        }
        frame
    })
}

/// A capture of `m` x 32 whose frame `f` of `k` (`m` x `n`) is `frame(f, k, m, n)`, and
/// its key frames (with `keyframes`) at the first and last frame.
fn scene_with(keyframes: bool, m: usize, frame: impl Fn(usize, usize, usize, usize) -> Vec<f32>) -> Scene {
    let n = 32;
    let r = pseudo_random(m * n, 11);
    let psf: Vec<f32> = r.iter().map(|&v| if v > 0.9 { v } else { 0.0 }).collect();
    let sum: f32 = psf.iter().sum();
    let psf: Vec<f32> = psf.iter().map(|v| v / sum).collect();
    let cfg = CaptureConfig::new(m, n, 100.0, 300.0, ShutterMode::Dual);
    let weights = cfg.timing().weights().unwrap();
    let frame_us = weights.frame_time_us();
    let mut prepared = Prepared { psf: vec![Plane { rows: m, cols: n, data: psf }], ..Prepared::default() };
    let model = build_operator(&prepared.psf[0], &weights, Fov::Sensor, &Default::default());
    let (k, _, _) = model.video_shape();
    let mut truth = Vec::with_capacity(k * m * n);
    for f in 0..k {
        truth.extend(frame(f, k, m, n));
    }
    let mut b = vec![0.0; m * n];
    model.forward(&truth, &mut b);
    let noise = pseudo_random(m * n, 9);
    b.iter_mut().zip(&noise).for_each(|(v, &e)| *v += 2.0 * (e - 0.5));
    prepared.raw = vec![Plane { rows: m, cols: n, data: b }];
    if keyframes {
        for (j, start) in [0usize, k - 1].into_iter().enumerate() {
            let spec = KeyFrameRef {
                file: format!("k{j}.tiff"),
                start_us: start as f64 * frame_us,
                exposure_us: frame_us,
                dark_level: Some(DARK as f64),
                gain: None,
                affine: None,
                psf: None,
            };
            let w = spec.time_weights(k, frame_us).unwrap();
            let op = KeyFrameOp::new((k, m, n), (m, n), w, None, None);
            let mut y = vec![0.0; m * n];
            op.forward(&truth, &mut y);
            let noise = pseudo_random(m * n, 20 + j as u64);
            let image: Vec<f32> = y.iter().zip(&noise).map(|(&v, &e)| (GAIN as f32 * v + DARK + 3.0 * (e - 0.5)).round()).collect();
            let image = Array3::from_shape_vec((m, n, 1), image).unwrap();
            let img = KeyFrameImage { name: spec.file.clone(), spec, image, full_scale: Some(65535.0), psf: None };
            prepared.keyframes.push(prepare_keyframe(&img, 1, (m, n)).unwrap());
        }
    }
    Scene { cfg, prepared, truth, k }
}

fn solve(s: &Scene, settings: SolveSettings, options: &SolveOptions) -> Result<Reconstruction, String> {
    solve_against(s, settings, options, false)
}

/// [`solve`], scored against the scene's truth when `scored`.
fn solve_against(s: &Scene, settings: SolveSettings, options: &SolveOptions, scored: bool) -> Result<Reconstruction, String> {
    let stop = AtomicBool::new(false);
    let hooks = Hooks { on_row: &|_, _| {}, stop: &stop };
    let problem = Problem::new(&s.prepared, &s.cfg, Fov::Sensor).unwrap();
    let settings = settings.validate().unwrap();
    let (m, n) = (s.cfg.rows, s.cfg.cols);
    let truth = ndarray::Array4::from_shape_vec((s.k, m, n, 1), s.truth.clone()).unwrap();
    let truth = scored.then(|| (truth.view(), "truth"));
    reconstruct(&problem, &settings, options, truth, &LipschitzCache::disabled(), &hooks).map(|(r, _)| r).map_err(|e| e.to_string())
}

fn settings() -> SolveSettings {
    SolveSettings { tau: rollcam::solve::tau::Tau::Absolute(0.5), iters: 400, ..SolveSettings::default() }
}

#[test]
fn key_frames_bring_back_what_moves_and_their_gain() {
    let with = scene(true);
    let without = scene(false);
    let a = solve(&with, settings(), &SolveOptions::default()).unwrap();
    let b = solve(&without, settings(), &SolveOptions::default()).unwrap();
    let va: Vec<f32> = a.video.iter().copied().collect();
    let vb: Vec<f32> = b.video.iter().copied().collect();
    let me_a = motion_error(&va, &with.truth, with.k).unwrap();
    let me_b = motion_error(&vb, &without.truth, without.k).unwrap();
    eprintln!("motion error with key frames {me_a:.3}, without {me_b:.3}");
    assert!(me_a < me_b - 0.08, "with key frames {me_a}, without {me_b}");
    let fits = &a.channels[0].keyframes;
    assert_eq!(fits.len(), 2);
    for f in fits {
        assert_eq!(f.gain_from, "fitted");
        // 12% of the light moves here; the still model of the key frames misses it by ~2%.
        assert!((f.gain / GAIN - 1.0).abs() < 0.05, "gain {} against {GAIN}", f.gain);
        assert!(f.chi2.is_some_and(|c| c.is_finite() && c < 20.0), "{:?}", f.chi2);
    }
    assert!(b.channels[0].keyframes.is_empty());
    assert!(va.iter().all(|v| v.is_finite() && *v >= 0.0));
    // With key frames the default is the static + dynamic model (its parts reported,
    // its key frames weighted at its own cap); without them on this mostly still scene,
    // the same model, chosen by the still check.
    let sb = a.static_background.as_ref().expect("key frames are solved with the static + dynamic model by default");
    assert_eq!(sb.report.channels.len(), 1);
    assert!(
        matches!(sb.report.chosen_by, ModelChoice::KeyFrames { moving_share: Some(share) } if share < rollcam::solve::keyframes::SMALL_MOTION_SHARE),
        "{:?}",
        sb.report.chosen_by
    );
    assert!(fits.iter().all(|f| f.stiffness_cap == rollcam::solve::keyframes::STATIC_DYNAMIC_STIFFNESS_CAP));
    let sb_b = b.static_background.as_ref().expect("a mostly still scene is solved with the static + dynamic model by default");
    assert!(
        matches!(sb_b.report.chosen_by, ModelChoice::MostlyStill { still_residual } if still_residual <= rollcam::solve::start::STILL_RESIDUAL_MAX),
        "{:?}",
        sb_b.report.chosen_by
    );
    // The key frames see the static image: it weighs as one frame of the noise rule
    // (`tau sqrt(K)`, not `tau K`).
    let part = &sb.report.channels[0];
    assert!((part.tau_static / (part.tau_dynamic * (with.k as f32).sqrt()) - 1.0).abs() < 1e-5, "{part:?}");
    // A reweighted round asked for runs as many iterations as the first round
    // (docs/usage.md, *The static + dynamic model's rounds*), within the cap of 400 each.
    let r = solve(&with, SolveSettings { l1_reweight: Some(1), ..settings() }, &SolveOptions::default()).unwrap();
    let st = &r.channels[0].stats;
    assert!(st.iterations % 2 == 0 && st.iterations <= 800 && st.iterations >= 2 * 5, "{} iterations", st.iterations);
    assert_eq!(st.converged, st.iterations < 800, "{:?} after {} iterations", st.termination, st.iterations);
    // By default reweighted rounds of the first round's length (at least
    // MIN_ROUND_ITERS) until the budget is spent (problem::reweight_plan): the first
    // round as above, then at most MAX_L1_REWEIGHT rounds, the last one shorter.
    let first = st.iterations / 2;
    use rollcam::solve::problem::{MAX_L1_REWEIGHT, MIN_ROUND_ITERS, REWEIGHT_BUDGET_ITERS};
    let (rounds, budget) = (MAX_L1_REWEIGHT, REWEIGHT_BUDGET_ITERS);
    let expected = budget.min(first + rounds * first.max(MIN_ROUND_ITERS)).max(first);
    let st = &a.channels[0].stats;
    assert!(st.iterations.abs_diff(expected) <= 6, "{} iterations, expected {expected} (first round {first})", st.iterations);
    assert!(st.iterations <= budget.max(first + 3), "{} iterations", st.iterations);
    assert_eq!(st.converged, first < 400, "{:?} after {} iterations", st.termination, st.iterations);
    // A first round ended by the time budget has no reweighted round after it (a
    // budget of a nanosecond: one iteration).
    let r = solve(&with, SolveSettings { time_budget_s: Some(1e-9), ..settings() }, &SolveOptions::default()).unwrap();
    let st = &r.channels[0].stats;
    assert_eq!(st.iterations, 1, "{:?}", st.termination);
    assert!(!st.converged);
    // `static_background = false` asks for the plain video with the key frames.
    let c = solve(&with, settings(), &plain()).unwrap();
    assert!(c.static_background.is_none());
    assert!(c.channels[0].keyframes.iter().all(|f| f.stiffness_cap == rollcam::solve::keyframes::STIFFNESS_CAP));
    let vc: Vec<f32> = c.video.iter().copied().collect();
    let me_c = motion_error(&vc, &with.truth, with.k).unwrap();
    let d = solve(&without, settings(), &plain()).unwrap();
    assert!(d.static_background.is_none());
    let vd: Vec<f32> = d.video.iter().copied().collect();
    let me_d = motion_error(&vd, &without.truth, without.k).unwrap();
    eprintln!("motion error with key frames: static + dynamic {me_a:.3}, plain video {me_c:.3}; without, plain video {me_d:.3}");
    assert!(me_c < me_d - 0.08, "plain video with key frames {me_c}, without {me_d}");
}

/// The plain video declared (`static_background = false`): the key frames' other model.
fn plain() -> SolveOptions {
    SolveOptions { scene: Some(rollcam::model::scene::SceneSpec { static_background: Some(false), ..Default::default() }), ..SolveOptions::default() }
}

#[test]
fn a_given_gain_is_used_as_given() {
    let mut s = scene(true);
    for k in &mut s.prepared.keyframes {
        k.spec.gain = Some(2.5);
    }
    let r = solve(&s, SolveSettings { iters: 20, ..settings() }, &SolveOptions::default()).unwrap();
    assert!(r.channels[0].keyframes.iter().all(|f| f.gain == 2.5 && f.gain_from == "given"));
}

#[test]
fn what_key_frames_are_not_solved_with_is_refused_by_name() {
    let s = scene(true);
    let spec = rollcam::model::scene::SceneSpec { static_scene: true, ..Default::default() };
    let e = solve(&s, settings(), &SolveOptions { scene: Some(spec), ..SolveOptions::default() }).err().expect("refused");
    assert!(e.contains("[[keyframes]]") && e.contains("declared [scene]"), "{e}");
    // The default model (static + dynamic) has no map in the ADMMs' splittings: the
    // refusal says the model is the key frames' default and how to get the plain video.
    let admm = SolveSettings { solver: rollcam::solve::optimize::SolverKind::Admm, ..settings() };
    let e = solve(&s, admm.clone(), &SolveOptions::default()).err().expect("refused");
    assert!(e.contains("static + dynamic model") && e.contains("static_background = false") && e.contains("admm"), "{e}");
    // The plain video with the key frames takes it.
    let r = solve(&s, SolveSettings { iters: 5, ..admm }, &plain()).unwrap();
    assert!(r.static_background.is_none() && r.channels[0].keyframes.len() == 2);
    // A window after the video's end says nothing about it.
    let mut late = scene(true);
    late.prepared.keyframes[1].spec.start_us = 1e9;
    let e = solve(&late, settings(), &SolveOptions::default()).err().expect("refused");
    assert!(e.contains("keyframes.start_us") && e.contains("k1.tiff"), "{e}");
    // Key frames with no light (the key camera not triggered): said so, not a NaN gain.
    let mut dark = scene(true);
    for k in dark.prepared.keyframes.iter_mut() {
        k.planes.iter_mut().for_each(|p| p.iter_mut().for_each(|v| *v = 0.0));
    }
    let e = solve(&dark, settings(), &SolveOptions::default()).err().expect("refused");
    assert!(e.contains("no light above the key frames' dark level") && e.contains("k1.tiff") && !e.contains("NaN"), "{e}");
}

#[test]
fn a_long_video_starts_from_a_key_frame_solve_coarser_in_time() {
    // 64 rows, dual shutter: 34 frames, enough for a coarse solve of 8.
    let with = scene_of(true, 64);
    let without = scene_of(false, 64);
    assert!(rollcam::solve::keyframes::coarse_binning(with.k).is_some(), "{} frames", with.k);
    let a = solve(&with, settings(), &plain()).unwrap();
    let b = solve(&without, settings(), &plain()).unwrap();
    let ch = &a.channels[0];
    let c = ch.coarse.as_ref().expect("a coarse solve started the key-frame solve");
    assert_eq!(c.binning, rollcam::solve::keyframes::COARSE_BINNING);
    assert!(c.frames >= rollcam::solve::keyframes::COARSE_MIN_FRAMES && c.frames * c.binning >= with.k, "{c:?}");
    assert!(c.iterations > 0 && c.seconds > 0.0, "{c:?}");
    // Error against run time: its seconds are in the run's and before the first row.
    assert!(ch.stats.seconds >= c.seconds && ch.trace[0].seconds >= c.seconds, "{} / {} against {}", ch.stats.seconds, ch.trace[0].seconds, c.seconds);
    assert!(b.channels[0].coarse.is_none());
    let va: Vec<f32> = a.video.iter().copied().collect();
    let vb: Vec<f32> = b.video.iter().copied().collect();
    let me_a = motion_error(&va, &with.truth, with.k).unwrap();
    let me_b = motion_error(&vb, &without.truth, without.k).unwrap();
    eprintln!("34 frames: motion error with key frames {me_a:.3} (coarse {} iterations, fine {}), without {me_b:.3}", c.iterations, ch.stats.iterations);
    // Measured 0.789 against 0.828 (the square is 4 of 64 rows here, against 4 of 24
    // above; the video solved as its departure from the key frames' interpolation).
    assert!(me_a < me_b - 0.03, "with key frames {me_a}, without {me_b}");
    assert!(va.iter().all(|v| v.is_finite() && *v >= 0.0));
    // The short capture is solved on its own frames.
    assert!(solve(&scene(true), SolveSettings { iters: 5, ..settings() }, &plain()).unwrap().channels[0].coarse.is_none());
}

#[test]
fn a_scene_that_moves_everywhere_departs_from_the_key_frames_interpolation_and_beats_it() {
    // The texture pans 6 columns across the video: every pixel changes between the key
    // frames, more than one static image and a small moving part can hold.
    let wide: Vec<f32> = pseudo_random(24 * 40, 5).iter().map(|v| 200.0 + 300.0 * v).collect();
    let pan = scene_with(true, 24, |f, k, m, n| {
        let shift = (f * 6 + (k - 1) / 2) / (k - 1);
        (0..m * n).map(|p| wide[(p / n) * 40 + p % n + shift]).collect()
    });
    let r = solve_against(&pan, settings(), &SolveOptions::default(), true).unwrap();
    assert!(r.static_background.is_none(), "a scene that moves everywhere is not one static image and a small moving part");
    let ch = &r.channels[0];
    let i = ch.interpolation.as_ref().expect("solved as its departure from the key frames' interpolation");
    let (ie, im) = (i.interpolation_rel_error_scaled.unwrap(), i.interpolation_motion_error.unwrap());
    let (ve, vm) = (ch.stats.error.as_ref().unwrap().rel_error_scaled, ch.motion_error.unwrap());
    eprintln!("pan: video {ve:.4} / {vm:.4}, interpolation {ie:.4} / {im:.4}, departure {:.3}", i.departure_rel);
    assert!(ve < ie && vm < im, "video {ve} / {vm} against the interpolation {ie} / {im}");
    // The raw says so: it is explained better by the video than by the interpolation.
    assert!(i.raw_residual_video < i.raw_residual_interpolation, "{i:?}");
    assert!(i.departure_rel > 0.0 && i.departure_rel.is_finite());
    let v: Vec<f32> = r.video.iter().copied().collect();
    assert!(v.iter().all(|x| x.is_finite() && *x >= 0.0));
}
