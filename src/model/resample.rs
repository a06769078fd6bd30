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
    box_downsample_any(img, rows, cols, d)
}

/// [`box_downsample`] of an f64 image (long accumulations), returned as f32.
pub fn box_downsample_f64(img: &[f64], rows: usize, cols: usize, d: usize) -> (Vec<f32>, usize, usize) {
    box_downsample_any(img, rows, cols, d)
}

fn box_downsample_any<T: Copy + Into<f64>>(img: &[T], rows: usize, cols: usize, d: usize) -> (Vec<f32>, usize, usize) {
    assert!(d >= 1, "downsampling factor must be at least 1");
    assert_eq!(img.len(), rows * cols, "image must be rows x cols");
    let (r, c) = (rows / d, cols / d);
    let mut out = vec![0.0f32; r * c];
    box_downsample_into(img, cols, d, r, c, |i, v| out[i] = v as f32);
    (out, r, c)
}

/// Box-mean downsampling of a PSF by `d` with blocks centred on the PSF centre pixel
/// `(rows/2, cols/2)` (the convention of [`crate::model::conv`]) instead of blocks aligned
/// with the sensor's first row and column.
///
/// Why: a reconstruction pixel `P` stands for the `d x d` raw block `dP .. dP+d`,
/// whose centre is `dP + (d-1)/2`. Light from there lands with the raw PSF centre on
/// that raw position; box-summing the sensor then samples the raw PSF over blocks
/// centred on its centre. [`box_downsample`] of the PSF instead sums it over blocks
/// starting at the centre pixel, which registers the model `(d-1)/2` raw pixels off
/// the box-mean video. This function shifts the raw PSF by the needed (possibly
/// half-integer, then linearly interpolated) offset before taking block means, so
/// `A` built from it agrees with the box-mean truth (for `d = 1` it is a copy).
/// Returns `(pixels, rows/d, cols/d)`; the caller normalises.
pub fn box_downsample_psf_centred(psf: &[f32], rows: usize, cols: usize, d: usize) -> (Vec<f32>, usize, usize) {
    assert!(d >= 1, "downsampling factor must be at least 1");
    assert_eq!(psf.len(), rows * cols, "PSF must be rows x cols");
    let (r, c) = (rows / d, cols / d);
    // Shift s (down/right, raw pixels) that puts the block of the reduced centre
    // (r/2, c/2) symmetric about the raw centre: s = d * (r/2) - rows/2 + (d-1)/2.
    let shift = |n_raw: usize, n_red: usize| (d * (n_red / 2)) as f64 - (n_raw / 2) as f64 + (d as f64 - 1.0) / 2.0;
    let taps = |s: f64| -> Vec<(isize, f64)> {
        let s0 = s.floor();
        let f = s - s0;
        [(s0 as isize, 1.0 - f), (s0 as isize + 1, f)].into_iter().filter(|&(_, w)| w > 0.0).collect()
    };
    let (tr, tc) = (taps(shift(rows, r)), taps(shift(cols, c)));
    let mut shifted = vec![0.0f64; rows * cols];
    for &(sr, wr) in &tr {
        for &(sc, wc) in &tc {
            for i in 0..rows as isize {
                let si = i - sr;
                if si < 0 || si >= rows as isize {
                    continue;
                }
                for j in 0..cols as isize {
                    let sj = j - sc;
                    if sj < 0 || sj >= cols as isize {
                        continue;
                    }
                    shifted[i as usize * cols + j as usize] += wr * wc * psf[si as usize * cols + sj as usize] as f64;
                }
            }
        }
    }
    box_downsample_f64(&shifted, rows, cols, d)
}

fn box_downsample_into<T: Copy + Into<f64>>(img: &[T], cols: usize, d: usize, r: usize, c: usize, mut put: impl FnMut(usize, f64)) {
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
    fn centred_psf_blocks_are_symmetric_about_the_centre() {
        // 8 x 8, d = 2: raw centre 4, reduced centre 2. Centred blocks weigh the raw
        // PSF by the triangle (1/2, 1, 1/2) over raw (2J-1, 2J, 2J+1) - the raw
        // centre pixel falls wholly in the reduced centre block, its right-hand
        // neighbour splits evenly between blocks 2 and 3.
        let mut psf = vec![0.0f32; 64];
        psf[4 * 8 + 4] = 1.0;
        let (h, r, c) = box_downsample_psf_centred(&psf, 8, 8, 2);
        assert_eq!((r, c), (4, 4));
        let mut expect = vec![0.0f32; 16];
        expect[2 * 4 + 2] = 0.25;
        assert_eq!(h, expect);
        // The plain block-aligned box mean gives the same here: the difference shows
        // for a point one pixel right of the centre.
        let mut psf = vec![0.0f32; 64];
        psf[4 * 8 + 5] = 1.0;
        let (h, _, _) = box_downsample_psf_centred(&psf, 8, 8, 2);
        assert!((h[2 * 4 + 2] - 0.125).abs() < 1e-7 && (h[2 * 4 + 3] - 0.125).abs() < 1e-7, "{h:?}");
        let (plain, _, _) = box_downsample(&psf, 8, 8, 2);
        assert_eq!(plain[2 * 4 + 2], 0.25);
        let mut psf = vec![0.0f32; 64];
        psf[4 * 8 + 4] = 1.0;
        // Odd d: whole-pixel shift only; d = 1: identity.
        let (h1, _, _) = box_downsample_psf_centred(&psf, 8, 8, 1);
        assert_eq!(h1, psf);
        let mut p9 = vec![0.0f32; 81];
        p9[4 * 9 + 4] = 1.0;
        let (h3, r3, _) = box_downsample_psf_centred(&p9, 9, 9, 3);
        assert_eq!(r3, 3);
        assert!((h3[4] - 1.0 / 9.0).abs() < 1e-7, "{h3:?}");
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
