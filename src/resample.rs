//! Spatial resampling shared by the raw image, the PSF and the simulator's truth:
//! `d x d` box means on a grid cropped to a multiple of `d`.

/// Box-mean downsampling by `d`: the image (`rows x cols`, row-major) is cropped to
/// `(rows/d)*d x (cols/d)*d` (trailing rows and columns dropped) and every `d x d`
/// block is replaced by its mean. Returns `(pixels, rows/d, cols/d)`.
///
/// Block sums are accumulated in f64. `d = 1` returns a copy.
///
/// # Panics
/// When `d == 0` or `img.len() != rows * cols`.
pub fn box_downsample(img: &[f32], rows: usize, cols: usize, d: usize) -> (Vec<f32>, usize, usize) {
    assert!(d >= 1, "downsampling factor must be at least 1");
    assert_eq!(img.len(), rows * cols, "image must be rows x cols");
    let (r, c) = (rows / d, cols / d);
    let mut out = vec![0.0f32; r * c];
    box_downsample_into(img, cols, d, r, c, |i, v| out[i] = v as f32);
    (out, r, c)
}

/// [`box_downsample`] of an f64 image (long accumulations), returned as f32.
pub fn box_downsample_f64(img: &[f64], rows: usize, cols: usize, d: usize) -> (Vec<f32>, usize, usize) {
    assert!(d >= 1, "downsampling factor must be at least 1");
    assert_eq!(img.len(), rows * cols, "image must be rows x cols");
    let (r, c) = (rows / d, cols / d);
    let mut out = vec![0.0f32; r * c];
    box_downsample_into(img, cols, d, r, c, |i, v| out[i] = v as f32);
    (out, r, c)
}

fn box_downsample_into<T: Copy + Into<f64>>(
    img: &[T],
    cols: usize,
    d: usize,
    r: usize,
    c: usize,
    mut put: impl FnMut(usize, f64),
) {
    let inv = 1.0 / (d * d) as f64;
    let mut acc = vec![0.0f64; c];
    for br in 0..r {
        acc.fill(0.0);
        for i in br * d..(br + 1) * d {
            let row = &img[i * cols..i * cols + c * d];
            for (bc, block) in row.chunks_exact(d).enumerate() {
                acc[bc] += block.iter().map(|&v| v.into()).sum::<f64>();
            }
        }
        for (bc, &a) in acc.iter().enumerate() {
            put(br * c + bc, a * inv);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn block_means_and_crop() {
        // 5 x 5 ramp, d = 2: the last row and column are dropped.
        let img: Vec<f32> = (0..25).map(|v| v as f32).collect();
        let (out, r, c) = box_downsample(&img, 5, 5, 2);
        assert_eq!((r, c), (2, 2));
        // Block (0,0): 0,1,5,6 -> 3; (0,1): 2,3,7,8 -> 5; (1,0): 10,11,15,16 -> 13.
        assert_eq!(out, vec![3.0, 5.0, 13.0, 15.0]);
        let (same, r, c) = box_downsample(&img, 5, 5, 1);
        assert_eq!((r, c), (5, 5));
        assert_eq!(same, img);
    }

    #[test]
    fn mean_is_preserved_on_exact_multiples() {
        let img: Vec<f32> = (0..6 * 9).map(|v| ((v * 37) % 11) as f32).collect();
        let (out, r, c) = box_downsample(&img, 6, 9, 3);
        assert_eq!((r, c), (2, 3));
        let m0: f64 = img.iter().map(|&v| v as f64).sum::<f64>() / img.len() as f64;
        let m1: f64 = out.iter().map(|&v| v as f64).sum::<f64>() / out.len() as f64;
        assert!((m0 - m1).abs() < 1e-5 * m0.abs(), "{m0} vs {m1}");
        let img64: Vec<f64> = img.iter().map(|&v| v as f64).collect();
        assert_eq!(box_downsample_f64(&img64, 6, 9, 3).0, out);
    }
}
