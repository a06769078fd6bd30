//! The noise of a prepared raw, measured from the raw itself.
//!
//! Through a diffuser every sensor pixel sums light from the whole scene, so a raw of an
//! extended scene is smooth at the scale of one pixel and what a fine Laplacian sees is
//! mostly noise. [`noise_sigma`] is Immerkaer's estimator (1996) made robust: the
//! mask below (the difference of two discrete Laplacians)
//!
//! ```text
//!  1 -2  1
//! -2  4 -2
//!  1 -2  1
//! ```
//!
//! has a response of standard deviation `6 sigma` on independent noise of standard
//! deviation `sigma` and none on planes; the median of its magnitude over the raw,
//! over `0.6745 * 6`, is `sigma`. The median ignores edges and caustic lines (a minority
//! of windows) and, on a mostly dark scene (LEDs), gives the noise of the dark pixels.
//! Windows touching a pixel left out of the data term or clipped are skipped.

use crate::model::mask::DataMask;

/// The fewest 3 x 3 windows an estimate is made from.
pub const MIN_NOISE_WINDOWS: usize = 64;

/// `median |Laplacian| / (6 * NORMAL_MAD)` is the standard deviation of Gaussian noise.
const NORMAL_MAD: f64 = 0.674_489_75;

/// The most windows an estimate reads: a larger raw is read on a regular lattice of
/// window centres (every `step`-th row and column), so the estimate's memory stays
/// under 4 MB whatever the raw's size.
pub const MAX_NOISE_WINDOWS: usize = 1 << 20;

/// The standard deviation of the noise of `data` (`rows x cols`, row-major, in the
/// data's units), from the windows whose nine pixels are all finite, kept by `mask`
/// and not clipped (at most [`MAX_NOISE_WINDOWS`] of them, evenly spread); `None` with
/// fewer than [`MIN_NOISE_WINDOWS`] such windows.
pub fn noise_sigma(data: &[f32], rows: usize, cols: usize, mask: &DataMask) -> Option<f32> {
    assert_eq!(data.len(), rows * cols, "noise_sigma: data of {} values for {rows} x {cols}", data.len());
    if rows < 3 || cols < 3 {
        return None;
    }
    let usable = |i: usize| data[i].is_finite() && mask.mask.as_ref().map_or(true, |m| m[i] > 0.0) && mask.lower_bounds.as_ref().map_or(true, |l| !l[i]);
    let windows = (rows - 2) * (cols - 2);
    let step = lattice_step(windows);
    let mut responses: Vec<f32> = Vec::with_capacity(windows.div_ceil(step * step).min(MAX_NOISE_WINDOWS));
    for r in (1..rows - 1).step_by(step) {
        for c in (1..cols - 1).step_by(step) {
            let window = |dr: usize, dc: usize| (r + dr - 1) * cols + c + dc - 1;
            if !(0..3).all(|dr| (0..3).all(|dc| usable(window(dr, dc)))) {
                continue;
            }
            let v = |dr, dc| f64::from(data[window(dr, dc)]);
            let corners = v(0, 0) + v(0, 2) + v(2, 0) + v(2, 2);
            let edges = v(0, 1) + v(1, 0) + v(1, 2) + v(2, 1);
            responses.push((corners - 2.0 * edges + 4.0 * v(1, 1)).abs() as f32);
        }
    }
    if responses.len() < MIN_NOISE_WINDOWS {
        return None;
    }
    let mid = responses.len() / 2;
    let (_, median, _) = responses.select_nth_unstable_by(mid, f32::total_cmp);
    Some((f64::from(*median) / (6.0 * NORMAL_MAD)) as f32)
}

/// The lattice step that keeps `windows` windows within [`MAX_NOISE_WINDOWS`].
fn lattice_step(windows: usize) -> usize {
    (1..).find(|s| windows.div_ceil(s * s) <= MAX_NOISE_WINDOWS).expect("a step that fits exists")
}

/// The noise of several planes (the channels of one capture, or the captures of a
/// sequence): the median of their estimates, `None` if none has one.
pub fn median_sigma(sigmas: impl IntoIterator<Item = Option<f32>>) -> Option<f32> {
    let mut s: Vec<f32> = sigmas.into_iter().flatten().collect();
    if s.is_empty() {
        return None;
    }
    s.sort_by(f32::total_cmp);
    let n = s.len();
    Some(if n % 2 == 1 { s[n / 2] } else { 0.5 * (s[n / 2 - 1] + s[n / 2]) })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic standard normal sequence (Box-Muller on a 64-bit LCG).
    fn normals(n: usize, seed: u64) -> Vec<f64> {
        let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        let mut uniform = move || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((s >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        (0..n).map(|_| (-2.0 * uniform().ln()).sqrt() * (2.0 * std::f64::consts::PI * uniform()).cos()).collect()
    }

    #[test]
    fn gaussian_noise_on_a_smooth_signal_is_measured_within_five_percent() {
        let (rows, cols) = (120, 160);
        for (sigma, seed) in [(0.5f64, 1u64), (3.0, 2), (40.0, 3)] {
            let n = normals(rows * cols, seed);
            // A smooth ramp and a slow wave: the Laplacian of a plane is zero and of the
            // wave far below the noise.
            let data: Vec<f32> = (0..rows * cols)
                .map(|i| {
                    let (r, c) = ((i / cols) as f64, (i % cols) as f64);
                    (1000.0 + 5.0 * r + 2.0 * c + 200.0 * (r / 30.0).sin() * (c / 40.0).cos() + sigma * n[i]) as f32
                })
                .collect();
            let got = f64::from(noise_sigma(&data, rows, cols, &DataMask::default()).unwrap());
            assert!((got / sigma - 1.0).abs() < 0.05, "sigma {sigma}: measured {got}");
        }
    }

    #[test]
    fn a_few_bright_spots_do_not_move_the_estimate_and_masked_or_clipped_windows_are_skipped() {
        let (rows, cols) = (64, 64);
        let n = normals(rows * cols, 7);
        let mut data: Vec<f32> = n.iter().map(|&z| (100.0 + 2.0 * z) as f32).collect();
        let clean = noise_sigma(&data, rows, cols, &DataMask::default()).unwrap();
        // Twenty isolated spots of 1e4: under 20 x 9 of 3844 windows change.
        for k in 0..20 {
            data[(3 + 3 * k) * cols + 5 + 2 * k] = 1e4;
        }
        let spotted = noise_sigma(&data, rows, cols, &DataMask::default()).unwrap();
        assert!((spotted / clean - 1.0).abs() < 0.06, "{clean} -> {spotted}");
        // Masking the spots' pixels (or marking them clipped) skips their windows.
        let marked: Vec<bool> = data.iter().map(|&v| v > 1e3).collect();
        let mask = DataMask { mask: Some(marked.iter().map(|&m| if m { 0.0 } else { 1.0 }).collect()), lower_bounds: None };
        let clipped = DataMask { mask: None, lower_bounds: Some(marked) };
        for m in [mask, clipped] {
            let s = noise_sigma(&data, rows, cols, &m).unwrap();
            assert!((s / clean - 1.0).abs() < 0.03, "{clean} -> {s}");
        }
        // Non-finite pixels are skipped too.
        data[10 * cols + 10] = f32::NAN;
        assert!(noise_sigma(&data, rows, cols, &DataMask::default()).unwrap().is_finite());
    }

    #[test]
    fn a_raw_of_more_windows_than_the_cap_is_read_on_a_lattice_with_the_same_answer() {
        // 1100 x 1000: 1.09M windows, over the cap: every second row and column is read.
        let (rows, cols) = (1100, 1000);
        assert_eq!((lattice_step(1000 * 1000), lattice_step(1098 * 998), lattice_step(10_000 * 10_000)), (1, 2, 10));
        let n = normals(rows * cols, 11);
        let data: Vec<f32> = n.iter().map(|&z| (500.0 + 7.0 * z) as f32).collect();
        let got = f64::from(noise_sigma(&data, rows, cols, &DataMask::default()).unwrap());
        assert!((got / 7.0 - 1.0).abs() < 0.02, "{got}");
    }

    #[test]
    fn too_small_or_mostly_left_out_raws_have_no_estimate() {
        assert_eq!(noise_sigma(&[1.0; 10], 2, 5, &DataMask::default()), None);
        assert_eq!(noise_sigma(&[1.0; 90], 9, 10, &DataMask::default()), None, "56 windows, 64 needed");
        let data = vec![1.0f32; 400];
        assert_eq!(noise_sigma(&data, 20, 20, &DataMask::default()), Some(0.0), "a constant raw has no noise");
        let none_kept = DataMask { mask: Some(vec![0.0; 400]), lower_bounds: None };
        assert_eq!(noise_sigma(&data, 20, 20, &none_kept), None);
    }

    #[test]
    fn the_median_of_several_estimates_skips_the_missing() {
        assert_eq!(median_sigma([Some(3.0), None, Some(1.0), Some(2.0)]), Some(2.0));
        assert_eq!(median_sigma([Some(3.0), Some(1.0)]), Some(2.0));
        assert_eq!(median_sigma([None, None]), None);
    }
}
