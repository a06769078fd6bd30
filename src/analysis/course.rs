//! Time courses of regions of a video and their agreement with a known waveform.

use ndarray::ArrayView4;

/// Sum over a square region of half-width `radius` around `(row, col)` of channel
/// `channel`, for every frame (f64 sums). Pixels outside the frame are skipped.
pub fn region_time_course(video: ArrayView4<f32>, channel: usize, row: usize, col: usize, radius: usize) -> Vec<f64> {
    let (k, m, n, _) = video.dim();
    let (r0, r1) = (row.saturating_sub(radius), (row + radius + 1).min(m));
    let (c0, c1) = (col.saturating_sub(radius), (col + radius + 1).min(n));
    (0..k)
        .map(|f| {
            let mut s = 0.0f64;
            for r in r0..r1 {
                for c in c0..c1 {
                    s += video[[f, r, c, channel]] as f64;
                }
            }
            s
        })
        .collect()
}

/// Pearson correlation of two equally long series (0 when either is constant).
pub fn correlation(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len(), "series must have the same length");
    let n = a.len() as f64;
    if a.is_empty() {
        return 0.0;
    }
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let mut cov = 0.0;
    let mut va = 0.0;
    let mut vb = 0.0;
    for (x, y) in a.iter().zip(b) {
        cov += (x - ma) * (y - mb);
        va += (x - ma).powi(2);
        vb += (y - mb).powi(2);
    }
    if va <= 0.0 || vb <= 0.0 {
        0.0
    } else {
        cov / (va * vb).sqrt()
    }
}

/// Whether `course` changes over its frames: its spread above 1e-9 of its largest
/// magnitude (a region of a still part of the truth sums to the same value in every
/// frame, to the last bit or to f32 rounding).
pub fn course_varies(course: &[f64]) -> bool {
    let (lo, hi) = course.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    let scale = course.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    hi - lo > 1e-9 * scale
}

/// A region's time course (its sum per frame) against the truth's in the same region.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CourseAgainstTruth {
    pub name: String,
    /// The truth's course is the same in every frame (a still part of the scene, as
    /// the texture of a dense one): there is no time course to compare, and the
    /// correlations are `null`.
    pub truth_constant: bool,
    /// Pearson correlation over every frame.
    pub correlation: Option<f64>,
    /// Over the frames the data see (`null`: none named unseen, or a constant truth):
    /// the frames in `unseen` (runs `[first, end)`, a reconstruction's
    /// `support.sources.unseen_frames`) left out.
    pub correlation_seen: Option<f64>,
    pub seen_frames: usize,
}

/// Each analysed region's time course in `video` against `truth`'s (same shape), over
/// every frame and over those outside `unseen`.
pub fn courses_against_truth(
    regions: &[super::report::RegionReport],
    video: ArrayView4<f32>,
    truth: ArrayView4<f32>,
    unseen: &[[usize; 2]],
) -> Vec<CourseAgainstTruth> {
    let frames = video.dim().0;
    let seen: Vec<usize> = (0..frames).filter(|k| !unseen.iter().any(|&[s, e]| (s..e).contains(k))).collect();
    let pick = |c: &[f64]| seen.iter().map(|&k| c[k]).collect::<Vec<f64>>();
    regions
        .iter()
        .map(|r| {
            let (got, want) = (r.region.time_course(video), r.region.time_course(truth));
            let varies = course_varies(&want);
            CourseAgainstTruth {
                name: r.name.clone(),
                truth_constant: !varies,
                correlation: varies.then(|| correlation(&got, &want)),
                correlation_seen: (varies && !unseen.is_empty()).then(|| correlation(&pick(&got), &pick(&want))),
                seen_frames: seen.len(),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array4;

    #[test]
    fn correlation_of_known_series() {
        assert!((correlation(&[1.0, 2.0, 3.0], &[2.0, 4.0, 6.0]) - 1.0).abs() < 1e-12);
        assert!((correlation(&[1.0, 2.0, 3.0], &[3.0, 2.0, 1.0]) + 1.0).abs() < 1e-12);
        assert_eq!(correlation(&[1.0, 1.0], &[1.0, 2.0]), 0.0);
    }

    #[test]
    fn a_course_varies_unless_it_is_the_same_in_every_frame() {
        assert!(!course_varies(&[4.0, 4.0, 4.0]));
        assert!(!course_varies(&[1e6, 1e6 * (1.0 + 1e-12)]), "rounding is not a change");
        assert!(course_varies(&[4.0, 4.0, 4.0001]));
        assert!(course_varies(&[0.0, 1e-30]), "a change from zero is one");
        assert!(!course_varies(&[0.0, 0.0]) && !course_varies(&[]));
    }

    #[test]
    fn region_sums_clip_at_the_border() {
        let mut v = Array4::<f32>::zeros((2, 3, 3, 1));
        v[[1, 0, 0, 0]] = 2.0;
        v[[1, 2, 2, 0]] = 5.0;
        assert_eq!(region_time_course(v.view(), 0, 0, 0, 1), vec![0.0, 2.0]);
        assert_eq!(region_time_course(v.view(), 0, 1, 1, 1), vec![0.0, 7.0]);
    }
}
