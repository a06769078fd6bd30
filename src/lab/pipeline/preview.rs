//! The session's preview images, refreshed while it runs: `preview/latest_raw.png`
//! (the latest recorded raw frame) and `preview/latest_frame.png` (the temporal maximum
//! projection of the latest video). Both 8-bit, display-scaled from the 0.1 to the
//! 99.9 percentile, reduced by an integer box mean to at most 1024 pixels on the longer
//! side, and written atomically.

use crate::io::{write_png, Display, IoError};
use ndarray::Array3;
use std::path::Path;

/// Preview folder inside the session folder.
pub const PREVIEW_DIR: &str = "preview";
pub const LATEST_RAW: &str = "preview/latest_raw.png";
pub const LATEST_FRAME: &str = "preview/latest_frame.png";

/// Longest side of a preview image, pixels.
const MAX_SIDE: usize = 1024;

/// Write `image` (rows, cols, channels) to `path` as a display-scaled 8-bit PNG.
pub fn write_preview(path: &Path, image: &Array3<f32>) -> Result<(), IoError> {
    let (rows, cols, ch) = image.dim();
    let d = rows.max(cols).div_ceil(MAX_SIDE).max(1);
    let small = if d == 1 {
        image.clone()
    } else {
        let (r, c) = (rows / d, cols / d);
        let mut out = Array3::<f32>::zeros((r, c, ch));
        for k in 0..ch {
            let plane: Vec<f32> = image.index_axis(ndarray::Axis(2), k).iter().cloned().collect();
            let (v, _, _) = crate::model::resample::box_downsample(&plane, rows, cols, d);
            for (i, x) in v.into_iter().enumerate() {
                out[[i / c, i % c, k]] = x;
            }
        }
        out
    };
    let display = Display::auto(small.iter(), 0.1, 99.9);
    write_png(path, small.view(), &display)
}

/// A raw frame's samples as an image.
pub fn raw_image(width: u32, height: u32, pixels: &[u16]) -> Array3<f32> {
    let n = width as usize * height as usize;
    let mut v: Vec<f32> = pixels.iter().take(n).map(|&p| p as f32).collect();
    v.resize(n, 0.0);
    Array3::from_shape_vec((height as usize, width as usize, 1), v).expect("width x height samples")
}
