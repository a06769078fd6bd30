//! Measurements on a video (frame, row, col, channel): projections, the brightest spots,
//! the dip between neighbouring spots, temporal contrast of a time course.

use super::theory::michelson;
use ndarray::{Array2, ArrayView4};
use serde::Serialize;

/// Projections of a video over one spatial axis, with time as the first axis.
pub struct Projections {
    /// (frame, col): max / sum over rows and channels.
    pub xt_max: Array2<f64>,
    pub xt_sum: Array2<f64>,
    /// (frame, row): max / sum over columns and channels.
    pub yt_max: Array2<f64>,
    pub yt_sum: Array2<f64>,
}

pub fn projections(video: ArrayView4<f32>) -> Projections {
    let (k, m, n, c) = video.dim();
    let mut p = Projections {
        xt_max: Array2::from_elem((k, n), f64::NEG_INFINITY),
        xt_sum: Array2::zeros((k, n)),
        yt_max: Array2::from_elem((k, m), f64::NEG_INFINITY),
        yt_sum: Array2::zeros((k, m)),
    };
    for f in 0..k {
        for r in 0..m {
            for col in 0..n {
                let mut v = 0.0f64;
                for ch in 0..c {
                    v += video[[f, r, col, ch]] as f64;
                }
                v /= c.max(1) as f64;
                p.xt_sum[[f, col]] += v;
                p.yt_sum[[f, r]] += v;
                if v > p.xt_max[[f, col]] {
                    p.xt_max[[f, col]] = v;
                }
                if v > p.yt_max[[f, r]] {
                    p.yt_max[[f, r]] = v;
                }
            }
        }
    }
    p
}

/// The video summed over time (and averaged over channels), (row, col).
pub fn time_sum(video: ArrayView4<f32>) -> Array2<f64> {
    let (k, m, n, c) = video.dim();
    let mut s = Array2::<f64>::zeros((m, n));
    for f in 0..k {
        for r in 0..m {
            for col in 0..n {
                for ch in 0..c {
                    s[[r, col]] += video[[f, r, col, ch]] as f64 / c as f64;
                }
            }
        }
    }
    s
}

/// Median of the values (0 for none).
pub fn median(values: impl Iterator<Item = f64>) -> f64 {
    let mut v: Vec<f64> = values.filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// `q`-quantile (0..1) by nearest rank.
pub fn quantile(values: &[f64], q: f64) -> f64 {
    let mut v: Vec<f64> = values.iter().cloned().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let i = ((q * (v.len() - 1) as f64).round() as usize).min(v.len() - 1);
    v[i]
}

/// A bright spot of the time-summed image.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Spot {
    pub row: usize,
    pub col: usize,
    /// Time-summed value above the background (median).
    pub value: f64,
}

/// How far the brightest pixel must rise above the background, relative to the
/// background's own level, for an image to hold spots at all: the ripples a solver
/// leaves on a flat scene (1e-8 to 1e-6 of it) are not LEDs.
pub const MIN_SPOT_CONTRAST: f64 = 1e-3;

/// Local maxima of `image` (strict within a `(2 radius + 1)^2` window, ties broken
/// by position) that rise above the background (the median) by at least `min_fraction`
/// of the brightest one, brightest first, at most `max_spots`. None when the brightest
/// rises less than [`MIN_SPOT_CONTRAST`] of the background above it (a flat image).
pub fn find_spots(image: &Array2<f64>, radius: usize, min_fraction: f64, max_spots: usize) -> Vec<Spot> {
    let (m, n) = image.dim();
    let bg = median(image.iter().cloned());
    let top = image.iter().cloned().fold(f64::NEG_INFINITY, f64::max) - bg;
    if !(top > 0.0 && top > MIN_SPOT_CONTRAST * bg.abs()) {
        return Vec::new();
    }
    let mut spots = Vec::new();
    for r in 0..m {
        for c in 0..n {
            let v = image[[r, c]];
            if v - bg < min_fraction * top {
                continue;
            }
            let mut is_max = true;
            'win: for rr in r.saturating_sub(radius)..(r + radius + 1).min(m) {
                for cc in c.saturating_sub(radius)..(c + radius + 1).min(n) {
                    let w = image[[rr, cc]];
                    if (rr, cc) != (r, c) && (w > v || (w == v && (rr, cc) < (r, c))) {
                        is_max = false;
                        break 'win;
                    }
                }
            }
            if is_max {
                spots.push(Spot { row: r, col: c, value: v - bg });
            }
        }
    }
    spots.sort_by(|a, b| b.value.total_cmp(&a.value));
    spots.truncate(max_spots);
    spots
}

/// Bilinear sample of `image` at continuous pixel-centre coordinates.
fn bilinear(image: &Array2<f64>, y: f64, x: f64) -> f64 {
    let (m, n) = image.dim();
    let y = y.clamp(0.0, (m - 1) as f64);
    let x = x.clamp(0.0, (n - 1) as f64);
    let (y0, x0) = (y.floor() as usize, x.floor() as usize);
    let (y1, x1) = ((y0 + 1).min(m - 1), (x0 + 1).min(n - 1));
    let (fy, fx) = (y - y0 as f64, x - x0 as f64);
    image[[y0, x0]] * (1.0 - fy) * (1.0 - fx) + image[[y0, x1]] * (1.0 - fy) * fx + image[[y1, x0]] * fy * (1.0 - fx) + image[[y1, x1]] * fy * fx
}

/// The dip between two spots along the line joining them.
#[derive(Clone, Debug, Serialize)]
pub struct Dip {
    pub a: (usize, usize),
    pub b: (usize, usize),
    pub separation_px: f64,
    /// Lower of the two peaks along the line, above the background.
    pub lower_peak: f64,
    /// Lowest value strictly between them, above the background.
    pub dip: f64,
    /// `(lower_peak - dip) / (lower_peak + dip)`: 1 for a dip to the background, 0 for
    /// no dip.
    pub contrast: f64,
    /// Rayleigh-like criterion: the dip falls below 73.5% of the lower peak.
    pub resolved: bool,
}

/// Fraction of the lower peak that the dip must stay below to count as resolved (the
/// Rayleigh criterion's dip for two Airy patterns).
pub const RESOLVED_DIP_RATIO: f64 = 0.735;

/// Dip between two points of `image` (background = median subtracted), sampled every
/// 0.25 px along the segment.
pub fn dip_between(image: &Array2<f64>, a: (usize, usize), b: (usize, usize)) -> Dip {
    let bg = median(image.iter().cloned());
    let (ya, xa, yb, xb) = (a.0 as f64, a.1 as f64, b.0 as f64, b.1 as f64);
    let sep = ((yb - ya).powi(2) + (xb - xa).powi(2)).sqrt();
    let steps = ((sep * 4.0).ceil() as usize).max(2);
    let profile: Vec<f64> = (0..=steps)
        .map(|s| {
            let t = s as f64 / steps as f64;
            (bilinear(image, ya + t * (yb - ya), xa + t * (xb - xa)) - bg).max(0.0)
        })
        .collect();
    // Peaks: the maxima of the first and last thirds; the dip: the minimum between them.
    let third = (steps / 3).max(1);
    let (ia, pa) = profile[..=third].iter().enumerate().fold((0, f64::MIN), |acc, (i, &v)| if v > acc.1 { (i, v) } else { acc });
    let (ib, pb) = profile[steps - third..].iter().enumerate().fold((0, f64::MIN), |acc, (i, &v)| if v > acc.1 { (i + steps - third, v) } else { acc });
    let dip = if ib > ia + 1 { profile[ia + 1..ib].iter().cloned().fold(f64::INFINITY, f64::min) } else { pa.min(pb) };
    let lower_peak = pa.min(pb);
    let contrast = michelson(dip.min(lower_peak), lower_peak);
    Dip { a, b, separation_px: sep, lower_peak, dip, contrast, resolved: lower_peak > 0.0 && dip < RESOLVED_DIP_RATIO * lower_peak }
}

/// Pairs of neighbouring spots: the Gabriel graph (i and j are neighbours when no
/// other spot lies inside the circle whose diameter joins them), so a line of spots
/// gives its consecutive pairs.
pub fn neighbour_pairs(spots: &[Spot]) -> Vec<(usize, usize)> {
    let pos = |s: &Spot| (s.row as f64, s.col as f64);
    let mut pairs = Vec::new();
    for i in 0..spots.len() {
        for j in i + 1..spots.len() {
            let (a, b) = (pos(&spots[i]), pos(&spots[j]));
            let mid = ((a.0 + b.0) / 2.0, (a.1 + b.1) / 2.0);
            let r2 = ((a.0 - b.0).powi(2) + (a.1 - b.1).powi(2)) / 4.0;
            let blocked = (0..spots.len()).filter(|&k| k != i && k != j).any(|k| {
                let c = pos(&spots[k]);
                (c.0 - mid.0).powi(2) + (c.1 - mid.1).powi(2) < r2
            });
            if !blocked {
                pairs.push((i, j));
            }
        }
    }
    pairs
}

/// Temporal contrast of a time course: Michelson contrast of its 5th and 95th
/// percentiles (robust to single-frame outliers), with negative values clipped to 0.
pub fn temporal_contrast(course: &[f64]) -> f64 {
    let lo = quantile(course, 0.05).max(0.0);
    let hi = quantile(course, 0.95).max(0.0);
    michelson(lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array4;

    fn gauss_image(m: usize, n: usize, centres: &[(f64, f64)], sigma: f64) -> Array2<f64> {
        Array2::from_shape_fn((m, n), |(r, c)| {
            centres.iter().map(|&(y, x)| (-((r as f64 - y).powi(2) + (c as f64 - x).powi(2)) / (2.0 * sigma * sigma)).exp()).sum()
        })
    }

    #[test]
    fn projections_max_and_sum() {
        let mut v = Array4::<f32>::zeros((2, 3, 4, 1));
        v[[1, 2, 3, 0]] = 5.0;
        v[[1, 0, 3, 0]] = 1.0;
        let p = projections(v.view());
        assert_eq!(p.xt_max[[1, 3]], 5.0);
        assert_eq!(p.xt_sum[[1, 3]], 6.0);
        assert_eq!(p.yt_max[[1, 2]], 5.0);
        assert_eq!(p.yt_sum[[0, 2]], 0.0);
    }

    #[test]
    fn spots_found_and_dips_measured() {
        // Two well separated spots and two close ones.
        let img = gauss_image(40, 60, &[(20.0, 10.0), (20.0, 30.0), (20.0, 35.0)], 1.5);
        let spots = find_spots(&img, 2, 0.2, 8);
        assert_eq!(spots.len(), 3, "{spots:?}");
        let far = dip_between(&img, (20, 10), (20, 30));
        assert!(far.resolved && far.contrast > 0.95, "{far:?}");
        let close = dip_between(&img, (20, 30), (20, 35));
        assert!(close.contrast < far.contrast);
        // Spots 2 px apart at sigma 1.5 merge: no dip at all.
        let merged = gauss_image(40, 60, &[(20.0, 30.0), (20.0, 32.0)], 1.5);
        let d = dip_between(&merged, (20, 30), (20, 32));
        assert!(!d.resolved, "{d:?}");
        assert_eq!(neighbour_pairs(&spots).len(), 2);
        // On a bright background they are still spots; a ripple of 1e-6 on it is none.
        let lifted = img.mapv(|v| v + 100.0);
        let at = |s: &[Spot]| s.iter().map(|s| (s.row, s.col)).collect::<Vec<_>>();
        assert_eq!(at(&find_spots(&lifted, 2, 0.2, 8)), at(&spots));
        let ripple = gauss_image(40, 60, &[(20.0, 10.0)], 1.5).mapv(|v| 1000.0 + 1e-3 * v);
        assert!(find_spots(&ripple, 2, 0.2, 8).is_empty());
        // A line of four equally spaced spots: its three consecutive pairs.
        let line: Vec<Spot> = [71, 89, 77, 83].iter().map(|&c| Spot { row: 64, col: c, value: 1.0 }).collect();
        let mut p: Vec<(usize, usize)> = neighbour_pairs(&line)
            .into_iter()
            .map(|(i, j)| {
                let (a, b) = (line[i].col, line[j].col);
                (a.min(b), a.max(b))
            })
            .collect();
        p.sort();
        assert_eq!(p, vec![(71, 77), (77, 83), (83, 89)]);
    }

    #[test]
    fn contrast_of_courses() {
        let square: Vec<f64> = (0..40).map(|i| if (i / 5) % 2 == 0 { 1.0 } else { 0.0 }).collect();
        assert!((temporal_contrast(&square) - 1.0).abs() < 1e-12);
        let flat = vec![2.0; 40];
        assert_eq!(temporal_contrast(&flat), 0.0);
    }
}

/// Solve the 4 x 4 system `a x = b` by Gaussian elimination with partial pivoting.
fn solve4(mut a: [[f64; 4]; 4], mut b: [f64; 4]) -> Option<[f64; 4]> {
    for i in 0..4 {
        let p = (i..4).max_by(|&x, &y| a[x][i].abs().total_cmp(&a[y][i].abs()))?;
        if a[p][i].abs() < 1e-300 {
            return None;
        }
        a.swap(i, p);
        b.swap(i, p);
        for r in i + 1..4 {
            let f = a[r][i] / a[i][i];
            let pivot_row = a[i];
            for (x, p) in a[r][i..].iter_mut().zip(&pivot_row[i..]) {
                *x -= f * p;
            }
            b[r] -= f * b[i];
        }
    }
    let mut x = [0.0; 4];
    for i in (0..4).rev() {
        let s: f64 = (i + 1..4).map(|c| a[i][c] * x[c]).sum();
        x[i] = (b[i] - s) / a[i][i];
    }
    Some(x)
}

/// Fundamental contrast of a time course at `frequency_hz`: least-squares fit of
/// `c + s t + a cos(2 pi f t) + b sin(2 pi f t)` (the slope absorbs slow drifts such as
/// the early frames' wipe), then the modulation `sqrt(a^2 + b^2) / c` divided by that
/// of an ideal 0/1 square wave of duty `duty`, `2 |sin(pi D)| / (pi D)` (`4/pi` at 0.5).
/// 1 for a perfect square wave; `|sinc(f T_e)|` after the exposure's box mean; 0
/// without modulation (or a non-positive mean).
pub fn fundamental_contrast(course: &[f64], frame_time_us: f64, frequency_hz: f64, duty: f64) -> f64 {
    let n = course.len();
    if n < 4 {
        return 0.0;
    }
    let tm = (n as f64 - 1.0) / 2.0;
    let w = 2.0 * std::f64::consts::PI * frequency_hz * frame_time_us * 1e-6;
    let mut ata = [[0.0f64; 4]; 4];
    let mut atb = [0.0f64; 4];
    for (i, &y) in course.iter().enumerate() {
        let t = i as f64 - tm;
        let phi = [1.0, t / n as f64, (w * t).cos(), (w * t).sin()];
        for r in 0..4 {
            for c in 0..4 {
                ata[r][c] += phi[r] * phi[c];
            }
            atb[r] += phi[r] * y;
        }
    }
    let Some(x) = solve4(ata, atb) else { return 0.0 };
    if !(x[0] > 0.0) {
        return 0.0;
    }
    let ideal = 2.0 * (std::f64::consts::PI * duty).sin().abs() / (std::f64::consts::PI * duty);
    (x[2].hypot(x[3]) / x[0]) / ideal
}

#[cfg(test)]
mod fundamental_tests {
    use super::*;
    use crate::sim::scene::square_wave_mean;

    #[test]
    fn fundamental_contrast_of_known_waves() {
        let tf = 220.0;
        // Square wave of period 2640 us averaged over each frame (box of T_f): the
        // fundamental keeps |sinc(f T_f)| of its amplitude.
        let course: Vec<f64> = (0..120).map(|k| square_wave_mean(k as f64 * tf, (k + 1) as f64 * tf, 2640.0, 0.5, 0.0)).collect();
        let f0 = 1e6 / 2640.0;
        let want = crate::analysis::theory::exposure_transfer(f0, tf);
        let got = fundamental_contrast(&course, tf, f0, 0.5);
        assert!((got - want).abs() < 0.03, "{got} vs {want}");
        // A drift of zero mean under the wave (a wipe) leaves it nearly unchanged.
        let ramped: Vec<f64> = course.iter().enumerate().map(|(i, v)| v + 0.01 * (i as f64 - 59.5)).collect();
        let got_r = fundamental_contrast(&ramped, tf, f0, 0.5);
        assert!((got_r - got).abs() < 0.02, "{got_r} vs {got}");
        // Half the modulation on the same mean: half the contrast.
        let half: Vec<f64> = course.iter().map(|v| 0.25 + 0.5 * v).collect();
        assert!((fundamental_contrast(&half, tf, f0, 0.5) - 0.5 * got).abs() < 1e-6);
        // Constant: no modulation.
        assert!(fundamental_contrast(&vec![3.0; 50], tf, f0, 0.5).abs() < 1e-9);
    }
}
