//! Property tests over random sizes and timings: the imaging operator and its adjoint
//! form an adjoint pair, and the shutter weights keep their invariants.

use proptest::prelude::*;
use rollcam::model::capture::Fov;
use rollcam::model::op::{pseudo_random, Operator};
use rollcam::model::rolling::RollingShutterModel;
use rollcam::model::shutter::{ShutterMode, Timing};

fn mode() -> impl Strategy<Value = ShutterMode> {
    prop::sample::select(ShutterMode::ALL.to_vec())
}

fn dot(a: &[f32], b: &[f32]) -> f64 {
    a.iter().zip(b).map(|(&x, &y)| f64::from(x) * f64::from(y)).sum()
}

fn norm(a: &[f32]) -> f64 {
    dot(a, a).sqrt()
}

/// A timing of `raw_rows` rows: line time, exposure of 1 to 6 line times (a fraction
/// included), downsampling and binning (at most what makes one frame cover the whole
/// capture, the most a timing may bin).
fn timing(raw_rows: usize, line_time_us: f64, lines: f64, mode: ShutterMode, d: usize, b: usize) -> Timing {
    let mut t = Timing::new(raw_rows, line_time_us, line_time_us * lines, mode);
    t.downsample = d;
    t.binning = b.min(t.frames_estimate().ceil().max(1.0) as usize);
    t
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 192, failure_persistence: None, ..ProptestConfig::default() })]

    /// `<A x, y> == <x, A^T y>` for the rolling-shutter operator over random grid sizes,
    /// timings, shutter modes, fields of view and PSFs.
    #[test]
    fn the_operator_and_its_adjoint_are_an_adjoint_pair(
        rows in 2usize..14,
        cols in 2usize..14,
        d in 1usize..3,
        b in 1usize..3,
        line_time_us in 1.0f64..300.0,
        lines in 1.0f64..6.0,
        mode in mode(),
        full in any::<bool>(),
        seed in 0u64..1_000_000,
    ) {
        let t = timing(rows * d, line_time_us, lines, mode, d, b);
        let w = t.weights().unwrap();
        prop_assert_eq!(w.rows(), rows);
        let mut psf: Vec<f32> = pseudo_random(rows * cols, seed).iter().map(|v| if *v > 0.7 { *v } else { 0.0 }).collect();
        psf[seed as usize % (rows * cols)] = 1.0;
        let fov = if full { Fov::Full } else { Fov::Sensor };
        let a = RollingShutterModel::of_psf(&psf, rows, cols, fov, w);
        let x: Vec<f32> = pseudo_random(a.input_len(), seed + 1).iter().map(|v| v - 0.4).collect();
        let y: Vec<f32> = pseudo_random(a.output_len(), seed + 2).iter().map(|v| v - 0.5).collect();
        let mut ax = vec![0.0; a.output_len()];
        let mut aty = vec![0.0; a.input_len()];
        a.forward(&x, &mut ax);
        a.adjoint(&y, &mut aty);
        let (lhs, rhs) = (dot(&ax, &y), dot(&x, &aty));
        // Relative to the sizes of the two products' factors: cancellation in either
        // inner product cannot hide a wrong adjoint, nor make a right one fail.
        let scale = (norm(&ax) * norm(&y)).max(norm(&x) * norm(&aty));
        prop_assert!(scale > 0.0);
        prop_assert!((lhs - rhs).abs() <= 1e-5 * scale, "<Ax,y> = {lhs}, <x,A^T y> = {rhs}, scale {scale}");
    }

    /// Every weight lies in [0, 1]; each row's weights sum to its exposure in frame units
    /// (T_e / T_f); the frames listed for a row are exactly its non-zero weights; the
    /// last frame is needed; dual shutters are symmetric top to bottom.
    #[test]
    fn shutter_weights_keep_their_invariants(
        grid_rows in 1usize..40,
        d in 1usize..4,
        b in 1usize..4,
        line_time_us in 0.5f64..500.0,
        lines in 1.0f64..12.0,
        mode in mode(),
    ) {
        let t = timing(grid_rows * d, line_time_us, lines, mode, d, b);
        let w = t.weights().unwrap();
        let (rows, frames) = (w.rows(), w.frames());
        prop_assert_eq!(rows, grid_rows);
        let expect = t.exposure_us / t.frame_time_us();
        for r in 0..rows {
            let mut total = 0.0f64;
            for k in 0..frames {
                let v = w.get(r, k);
                prop_assert!((0.0..=1.0 + 1e-6).contains(&v), "W[{r},{k}] = {v}");
                total += f64::from(v);
            }
            prop_assert!((total - expect).abs() <= 1e-5 * expect.max(1.0), "row {r}: {total} vs {expect}");
            prop_assert!((w.row_total(r) - expect).abs() <= 1e-5 * expect.max(1.0));
        }
        for k in 0..frames {
            let listed: Vec<usize> = w.rows_of_frame(k).iter().flat_map(|r| r.clone()).collect();
            let nonzero: Vec<usize> = (0..rows).filter(|&r| w.get(r, k) != 0.0).collect();
            prop_assert_eq!(listed, nonzero, "frame {}", k);
        }
        prop_assert!((0..rows).any(|r| w.get(r, frames - 1) > 0.0), "the last frame is empty");
        if matches!(mode, ShutterMode::Dual | ShutterMode::DualCenterOut) {
            for r in 0..rows / 2 {
                for k in 0..frames {
                    prop_assert_eq!(w.get(r, k), w.get(rows - 1 - r, k), "rows {} and {} frame {}", r, rows - 1 - r, k);
                }
            }
        }
        if mode == ShutterMode::Global {
            for r in 1..rows {
                for k in 0..frames {
                    prop_assert_eq!(w.get(r, k), w.get(0, k));
                }
            }
        }
    }
}
