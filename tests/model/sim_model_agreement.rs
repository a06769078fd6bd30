//! The physics and the reconstruction's model agree: the continuous-time simulation,
//! noise-free, dark-subtracted and box-mean downsampled by d, equals `A(truth)` for
//! the discrete operator `A` built from the prepared PSF and the shutter weights.
//!
//! What to expect:
//! - d = 1 with `T_e` and the row starts whole line times: every raw row's window is a
//!   union of whole frames, so `W` is 0/1 and `A(truth)` is the simulation exactly
//!   (float round-off), for any scene, static or not;
//! - `T_e` not a whole number of frames: `W` splits a frame between rows; exact for
//!   static scenes, approximate when the scene changes inside such a frame;
//! - d = 2: the `d` raw rows merged into a reconstruction row start at different
//!   times, and `W` spreads each of them over a frame that it covers only partly
//!   (time discretisation), and the prepared PSF is the box sum of the raw PSF while
//!   the physics convolves at raw resolution (a sub-block shift/blur of up to
//!   `(d-1)/2` raw pixels). Both errors shrink for scenes smooth on the scale of `d`
//!   raw pixels and `T_f`.

use ndarray::{Array2, Array3};
use rollcam::model::capture::CaptureConfig;
use rollcam::model::conv::Conv2d;
use rollcam::model::op::Operator;
use rollcam::model::resample::{box_downsample, box_downsample_psf_centred};
use rollcam::model::rolling::RollingShutterModel;
use rollcam::model::shutter::ShutterMode;
use rollcam::sim::scene::{ImageStack, LedArray, LedLine, MovingDisc, Scene};
use rollcam::sim::{lenslet_psf, simulate, LensletParams, NoiseModel, Simulation};

const M: usize = 32;
const N: usize = 40;
const TL: f64 = 10.0;

fn psf() -> Vec<f32> {
    let p = LensletParams { lenslets: 16, ..LensletParams::default() };
    lenslet_psf(M, N, &p, 5).unwrap().into_raw_vec_and_offset().0
}

/// The PSF as the reconstruction prepares it: d x d box mean, unit sum.
fn prepare(psf: &[f32], d: usize) -> (Vec<f32>, usize, usize) {
    let (mut h, r, c) = box_downsample(psf, M, N, d);
    let s: f64 = h.iter().map(|&v| v as f64).sum();
    h.iter_mut().for_each(|v| *v = (*v as f64 / s) as f32);
    (h, r, c)
}

/// The PSF prepared with blocks centred on its centre pixel, unit sum.
fn prepare_centred(psf: &[f32], d: usize) -> (Vec<f32>, usize, usize) {
    let (mut h, r, c) = box_downsample_psf_centred(psf, M, N, d);
    let s: f64 = h.iter().map(|&v| v as f64).sum();
    h.iter_mut().for_each(|v| *v = (*v as f64 / s) as f32);
    (h, r, c)
}

/// Relative error ||downsample(raw - dark) - A(truth)|| / ||downsample(raw - dark)||.
fn model_error(cfg: &CaptureConfig, model_cfg: &CaptureConfig, sim: &Simulation, psf: &[f32]) -> f64 {
    model_error_with(cfg, model_cfg, sim, prepare(psf, cfg.downsample))
}

fn model_error_with(cfg: &CaptureConfig, model_cfg: &CaptureConfig, sim: &Simulation, hp: (Vec<f32>, usize, usize)) -> f64 {
    let d = cfg.downsample;
    let (y, _, _) = box_downsample(sim.expected_adu().as_slice().unwrap(), M, N, d);
    let (h, r, c) = hp;
    let a = RollingShutterModel::new(Conv2d::sensor(&h, r, c), model_cfg.timing().weights().unwrap());
    assert_eq!(a.video_shape(), sim.truth.dim(), "truth has the model's frames and grid");
    let mut ay = vec![0.0; r * c];
    a.forward(sim.truth.as_slice().unwrap(), &mut ay);
    let num: f64 = y.iter().zip(&ay).map(|(p, q)| (*p as f64 - *q as f64).powi(2)).sum();
    let den: f64 = y.iter().map(|p| (*p as f64).powi(2)).sum();
    (num / den).sqrt()
}

fn cfg(mode: ShutterMode, exposure_us: f64, d: usize) -> CaptureConfig {
    let mut c = CaptureConfig::new(M, N, TL, exposure_us, mode);
    c.downsample = d;
    c
}

fn blob(t_frac: f32) -> Array2<f32> {
    // A smooth Gaussian (sigma 6 px) over a dim background, drifting slowly.
    let (cr, cc) = (14.0 + 4.0 * t_frac, 18.0 + 4.0 * t_frac);
    Array2::from_shape_fn((M, N), |(i, j)| {
        let (dy, dx) = (i as f32 + 0.5 - cr, j as f32 + 0.5 - cc);
        5.0 + 40.0 * (-(dy * dy + dx * dx) / 72.0).exp()
    })
}

fn static_smooth() -> ImageStack {
    ImageStack::still(blob(0.0)).unwrap()
}

fn slow_smooth() -> ImageStack {
    // 40 frames of one line time each: the blob drifts 4 px over the capture.
    let frames = Array3::from_shape_fn((40, M, N), |(f, i, j)| blob(f as f32 / 40.0)[(i, j)]);
    ImageStack::new(frames, TL, false).unwrap()
}

fn leds(period_us: f64) -> LedArray {
    LedArray::new(
        M,
        N,
        LedLine {
            leds: 4,
            spacing_px: 6.0,
            radius_px: 1.5,
            period_us: vec![period_us, period_us * 1.5, period_us * 2.0, period_us * 3.0],
            duty: 0.5,
            phase_us: vec![3.0],
            e_per_us: 500.0,
        },
    )
    .unwrap()
}

fn disc() -> MovingDisc {
    let mut d = MovingDisc::new(M, N, 4.0, (16.0, 8.0), (0.02, 0.08), 60.0);
    d.background_e_per_us = 2.0;
    d
}

fn run(c: &CaptureConfig, scene: &dyn Scene, h: &[f32]) -> Simulation {
    simulate(c, h, scene, &NoiseModel::noise_free(), 4, 0).unwrap()
}

#[test]
fn whole_line_timing_d1_is_exact_for_every_scene_and_mode() {
    let h = psf();
    let scenes: Vec<(&str, Box<dyn Scene>)> =
        vec![("static", Box::new(static_smooth())), ("drifting", Box::new(slow_smooth())), ("leds", Box::new(leds(37.0))), ("disc", Box::new(disc()))];
    for mode in ShutterMode::ALL {
        let c = cfg(mode, 3.0 * TL, 1);
        for (name, scene) in &scenes {
            let sim = run(&c, scene.as_ref(), &h);
            let e = model_error(&c, &c, &sim, &h);
            println!("d=1 {mode:16} {name:9} rel err {e:.2e}");
            assert!(e < 1e-5, "{mode} {name}: {e}");
        }
    }
}

#[test]
fn fractional_exposure_d1_static_exact_dynamic_close() {
    let h = psf();
    for mode in ShutterMode::ALL {
        let c = cfg(mode, 2.5 * TL, 1);
        let e_static = model_error(&c, &c, &run(&c, &static_smooth(), &h), &h);
        let e_drift = model_error(&c, &c, &run(&c, &slow_smooth(), &h), &h);
        let e_led = model_error(&c, &c, &run(&c, &leds(37.0), &h), &h);
        println!("d=1 T_e=2.5T_l {mode:16} static {e_static:.2e} drifting {e_drift:.2e} leds {e_led:.2e}");
        assert!(e_static < 1e-5, "{mode}: {e_static}");
        assert!(e_drift < 0.01, "{mode}: {e_drift}");
        // Half a frame at each end of every window is attributed to the frame mean.
        assert!(e_led < 0.25, "{mode}: {e_led}");
    }
}

#[test]
fn downsampled_d2_agrees_within_the_discretisation_error() {
    let h = psf();
    for mode in ShutterMode::ALL {
        let c = cfg(mode, 6.0 * TL, 2);
        let e_static = model_error(&c, &c, &run(&c, &static_smooth(), &h), &h);
        let e_drift = model_error(&c, &c, &run(&c, &slow_smooth(), &h), &h);
        let e_disc = model_error(&c, &c, &run(&c, &disc(), &h), &h);
        let e_led = model_error(&c, &c, &run(&c, &leds(97.0), &h), &h);
        println!("d=2 {mode:16} static {e_static:.2e} drifting {e_drift:.2e} disc {e_disc:.2e} leds {e_led:.2e}");
        let hc = || prepare_centred(&h, 2);
        let c_static = model_error_with(&c, &c, &run(&c, &static_smooth(), &h), hc());
        let c_drift = model_error_with(&c, &c, &run(&c, &slow_smooth(), &h), hc());
        let c_disc = model_error_with(&c, &c, &run(&c, &disc(), &h), hc());
        let c_led = model_error_with(&c, &c, &run(&c, &leds(97.0), &h), hc());
        println!("d=2 centred {mode:16} static {c_static:.2e} drifting {c_drift:.2e} disc {c_disc:.2e} leds {c_led:.2e}");
        // With the PSF prepared on centred blocks, what is left is the box-versus-
        // triangle weighting of sub-block positions and the time discretisation.
        assert!(c_static < 0.01, "{mode}: {c_static}");
        assert!(c_drift < 0.01, "{mode}: {c_drift}");
        assert!(c_disc < 0.05, "{mode}: {c_disc}");
        assert!(c_led < 0.15, "{mode}: {c_led}");
        // Block-aligned preparation registers the model half a raw pixel off the
        // box-mean truth: several times the error for smooth scenes.
        assert!(e_static < 0.06 && e_static > 3.0 * c_static, "{mode}: {e_static} vs {c_static}");
        assert!(e_drift < 0.06, "{mode}: {e_drift}");
        assert!(e_disc < 0.12, "{mode}: {e_disc}");
        assert!(e_led < 0.3, "{mode}: {e_led}");
    }
}

#[test]
fn the_check_detects_a_wrong_model() {
    // Same physics, a model with another shutter mode or exposure: the error is
    // large, so the agreement above is evidence and not an artefact of the comparison.
    let h = psf();
    let c = cfg(ShutterMode::Dual, 3.0 * TL, 1);
    let sim = run(&c, &leds(37.0), &h);
    let right = model_error(&c, &c, &sim, &h);
    let wrong_mode = model_error(&c, &cfg(ShutterMode::DualCenterOut, 3.0 * TL, 1), &sim, &h);
    // A model that believes in a shorter exposure (same frame count).
    let short = cfg(ShutterMode::Dual, 2.5 * TL, 1);
    let wrong_time = model_error(&c, &short, &sim, &h);
    println!("right {right:.2e} wrong mode {wrong_mode:.2e} short exposure {wrong_time:.2e}");
    assert!(right < 1e-5);
    assert!(wrong_mode > 0.2, "{wrong_mode}");
    assert!(wrong_time > 0.1, "{wrong_time}");
}
