//! The demo's size: a 128 x 160 raw capture, dual shutter, 70 frames, 4 sub-steps per
//! line, through a synthetic lenslet PSF. Checks that the simulation at this size
//! still agrees exactly with the model (d = 1, whole line times), that the noisy raw
//! image is sane, and prints the wall time (run in release for the figure).

use rollcam::model::capture::CaptureConfig;
use rollcam::model::conv::Conv2d;
use rollcam::model::op::Operator;
use rollcam::model::rolling::RollingShutterModel;
use rollcam::model::shutter::ShutterMode;
use rollcam::sim::{lenslet_psf, simulate, LedArray, LensletParams, NoiseModel};
use std::time::Instant;

#[test]
fn demo_size_led_capture() {
    let (m, n) = (128, 160);
    let t = Instant::now();
    let h = lenslet_psf(m, n, &LensletParams::default(), 1).unwrap().into_raw_vec_and_offset().0;
    let t_psf = t.elapsed();
    let psr = rollcam::sim::psf::peak_to_sidelobe(&h, m, n, 4.0);
    let mut sorted = h.clone();
    sorted.sort_by(|a, b| b.partial_cmp(a).unwrap());
    let top5: f64 = sorted[..m * n / 20].iter().map(|&v| v as f64).sum();
    println!("PSF peak-to-sidelobe {psr:.2}, top 5% of pixels hold {:.1}% of the light", top5 * 100.0);
    assert!(psr > 3.0 && top5 > 0.5);
    // The paper's LED target flashing with a 9-line period (T = 9 T_l).
    let cfg = CaptureConfig::new(m, n, 22.0, 7.0 * 22.0, ShutterMode::Dual);
    let scene = LedArray::paper(m, n, 9.0 * 22.0).unwrap();
    let t = Instant::now();
    let sim = simulate(&cfg, &h, &scene, &NoiseModel::default(), 4, 3).unwrap();
    let t_sim = t.elapsed();
    let (k, _, _) = sim.truth.dim();
    println!(
        "psf {:.1} ms, simulate {:.1} ms: {} frames, {} sub-steps, {} convolutions, {} saturated",
        t_psf.as_secs_f64() * 1e3,
        t_sim.as_secs_f64() * 1e3,
        k,
        sim.substeps,
        sim.convolutions,
        sim.saturated_pixels
    );
    assert_eq!(k, 70);
    assert_eq!(sim.saturated_pixels, 0);
    // Exact agreement with the model at this size.
    let a = RollingShutterModel::new(Conv2d::sensor(&h, m, n), cfg.timing().weights().unwrap());
    let mut ay = vec![0.0; m * n];
    a.forward(sim.truth.as_slice().unwrap(), &mut ay);
    let y = sim.expected_adu();
    let num: f64 = y.iter().zip(&ay).map(|(p, q)| (*p as f64 - *q as f64).powi(2)).sum();
    let den: f64 = y.iter().map(|p| (*p as f64).powi(2)).sum();
    let rel = (num / den).sqrt();
    println!("model agreement {rel:.2e}");
    assert!(rel < 1e-5, "{rel}");
    // Noisy raw: mean of (raw - dark) / gain matches the expected electrons.
    let mean_e: f64 = sim.electrons.iter().map(|&v| v as f64).sum::<f64>() / (m * n) as f64;
    let mean_raw: f64 = sim.raw.iter().map(|&v| (v as f64 - 100.0) / 0.5).sum::<f64>() / (m * n) as f64;
    assert!((mean_raw - mean_e).abs() < 0.05 * mean_e + 0.1, "{mean_raw} vs {mean_e}");
}
