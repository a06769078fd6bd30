//! The optimised evaluation against the straightforward one on a benchmark preset
//! (sparse PSF, dual shutter, moving-disc scene): the imaging operator's row path
//! against the 2D-FFT path, the one-pass TV prox against its term-by-term reference,
//! and whole FISTA runs through either operator.

use rollcam::model::data::DataTerm;
use rollcam::model::op::{pseudo_random, Operator};
use rollcam::model::rolling::RollingShutterModel;
use rollcam::perf::bench::{build, preset, scene};
use rollcam::solve::lipschitz::power_iteration;
use rollcam::solve::optimize::{Fista, NoObserver, RestartTest, StopRule};
use rollcam::solve::prox::Prox;
use rollcam::solve::prox::TotalVariation;

fn max_rel(a: &[f32], b: &[f32]) -> f64 {
    let scale = b.iter().fold(0.0f64, |m, &x| m.max(x.abs() as f64));
    a.iter().zip(b).fold(0.0f64, |m, (&x, &y)| m.max((x as f64 - y as f64).abs())) / scale
}

/// The model evaluated by its 2D-FFT reference path.
struct Reference<'a>(&'a RollingShutterModel);
impl Operator for Reference<'_> {
    fn input_shape(&self) -> Vec<usize> {
        self.0.input_shape()
    }
    fn output_shape(&self) -> Vec<usize> {
        self.0.output_shape()
    }
    fn forward(&self, x: &[f32], y: &mut [f32]) {
        self.0.forward_reference(x, y)
    }
    fn adjoint(&self, y: &[f32], x: &mut [f32]) {
        self.0.adjoint_reference(y, x)
    }
}

/// TV evaluated by its reference prox.
struct ReferenceTv<'a>(&'a TotalVariation);
impl Prox for ReferenceTv<'_> {
    fn value(&self, x: &[f32]) -> f64 {
        self.0.value(x)
    }
    fn prox(&self, z: &[f32], gamma: f32, out: &mut [f32]) {
        self.0.prox_reference(z, gamma, out)
    }
}

#[test]
fn small_preset_operator_matches_the_2d_fft_path() {
    let p = preset("small").unwrap();
    let a = build(&p, None);
    let (k, m, n) = a.video_shape();
    assert_eq!(k, p.frames());
    for x in [scene(k, m, n), pseudo_random(k * m * n, 4)] {
        let (mut fast, mut slow) = (vec![0.0; m * n], vec![0.0; m * n]);
        a.forward(&x, &mut fast);
        a.forward_reference(&x, &mut slow);
        assert!(max_rel(&fast, &slow) < 1e-5, "forward: {}", max_rel(&fast, &slow));
        let (mut gf, mut gs) = (vec![0.0; x.len()], vec![0.0; x.len()]);
        a.adjoint(&fast, &mut gf);
        a.adjoint_reference(&fast, &mut gs);
        assert!(max_rel(&gf, &gs) < 1e-5, "adjoint: {}", max_rel(&gf, &gs));
    }
}

#[test]
fn fista_through_the_fast_kernels_follows_the_reference_iterates() {
    let p = preset("small").unwrap();
    let a = build(&p, None);
    let (k, m, n) = a.video_shape();
    let truth = scene(k, m, n);
    let mut b = vec![0.0; m * n];
    a.forward_reference(&truth, &mut b);
    let l = power_iteration(&Reference(&a), 50, 1e-4, 3).lambda_max * 1.01;
    let tv = TotalVariation::new((k, m, n), 1e-3, 2.0);
    let f = Fista { lipschitz: l, stop: StopRule::iterations(8), restart: Some(RestartTest::Objective) };
    let fast = f.solve(&a, &DataTerm::new(&b), &tv, None, &mut NoObserver);
    let slow = f.solve(&Reference(&a), &DataTerm::new(&b), &ReferenceTv(&tv), None, &mut NoObserver);
    assert_eq!(fast.iterations, slow.iterations);
    let e = max_rel(&fast.x, &slow.x);
    assert!(e < 1e-4, "iterates differ by {e}");
    assert!((fast.data_term - slow.data_term).abs() <= 1e-4 * slow.data_term.abs(), "{} vs {}", fast.data_term, slow.data_term);
    // And the solve moved: the iterate is not the zero start.
    assert!(fast.x.iter().any(|&v| v > 0.0));
}
