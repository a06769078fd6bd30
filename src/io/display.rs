//! 8-bit renderings for people: display scaling, PNG, contact sheets, animated GIF.

use std::path::Path;

use image::codecs::gif::{GifEncoder, Repeat};
use image::{Delay, Frame, RgbaImage};
use ndarray::{ArrayView3, ArrayView4, Axis};

use super::atomic::write_atomic;
use super::error::IoError;
use super::font::{draw_label, label_size};
use super::formats::png::encode_png8;

/// Most frames a contact sheet shows; longer videos are subsampled evenly.
pub const CONTACT_SHEET_MAX_FRAMES: usize = 48;

/// Separator width between contact-sheet tiles, in pixels.
const SEPARATOR: usize = 2;
/// Separator grey level (8-bit).
const SEPARATOR_LEVEL: u8 = 128;

/// Mapping from raw values to 8-bit display levels:
/// `t = clamp((v - lo) / (hi - lo), 0, 1)`, level `= round(255 * t^gamma)`.
/// `gamma < 1` brightens dark values. NaN maps to 0. When `hi <= lo`, values above `lo`
/// map to 255 and the rest to 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Display {
    /// Raw value shown black.
    pub lo: f32,
    /// Raw value shown white.
    pub hi: f32,
    /// Exponent applied to the normalised value.
    pub gamma: f32,
}

impl Display {
    /// A linear mapping of `lo..hi` to 0..255.
    pub fn linear(lo: f32, hi: f32) -> Self {
        Display { lo, hi, gamma: 1.0 }
    }

    /// A linear mapping from the `lo_pct` to the `hi_pct` percentile (0-100) of the finite
    /// values in `data` (e.g. `Display::auto(video.iter(), 0.1, 99.9)`), so a few hot or
    /// dead pixels do not flatten the picture. No finite value gives `0..1`.
    pub fn auto<'a>(data: impl IntoIterator<Item = &'a f32>, lo_pct: f64, hi_pct: f64) -> Self {
        let mut v: Vec<f32> = data.into_iter().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return Display::linear(0.0, 1.0);
        }
        let mut pick = |pct: f64| {
            let idx = ((pct.clamp(0.0, 100.0) / 100.0) * (v.len() - 1) as f64).round() as usize;
            *v.select_nth_unstable_by(idx, f32::total_cmp).1
        };
        let lo = pick(lo_pct);
        let hi = pick(hi_pct);
        Display::linear(lo, hi)
    }

    /// The 8-bit level of a raw value.
    pub fn level(&self, v: f32) -> u8 {
        if v.is_nan() {
            return 0;
        }
        let t = if self.hi > self.lo {
            ((v - self.lo) / (self.hi - self.lo)).clamp(0.0, 1.0)
        } else if v > self.lo {
            1.0
        } else {
            0.0
        };
        let t = if self.gamma == 1.0 { t } else { t.powf(self.gamma) };
        (t * 255.0).round() as u8
    }
}

fn check_channels(path: &Path, ch: usize) -> Result<(), IoError> {
    if ch == 1 || ch == 3 {
        Ok(())
    } else {
        Err(IoError::bad_input(path, format!("expected 1 or 3 channels, found {ch}")))
    }
}

/// Writes one image as an 8-bit grey or RGB PNG through `display`.
pub fn write_png(path: impl AsRef<Path>, image: ArrayView3<f32>, display: &Display) -> Result<(), IoError> {
    let path = path.as_ref();
    let (rows, cols, ch) = image.dim();
    check_channels(path, ch)?;
    let pixels: Vec<u8> = image.iter().map(|&v| display.level(v)).collect();
    write_atomic(path, |w| encode_png8(path, w, rows, cols, ch, &pixels))
}

/// Indices of the frames a contact sheet or other overview shows: all when there are at
/// most `cap`, otherwise `cap` evenly spaced ones including the first and the last.
pub(crate) fn subsample(frames: usize, cap: usize) -> Vec<usize> {
    if frames <= cap {
        return (0..frames).collect();
    }
    if cap <= 1 {
        return vec![0];
    }
    (0..cap).map(|i| (i * (frames - 1) + (cap - 1) / 2) / (cap - 1)).collect()
}

/// The frames (indices) a contact sheet of a `frames`-frame video shows: all of them up
/// to [`CONTACT_SHEET_MAX_FRAMES`], else that many evenly spaced, first and last kept.
pub fn contact_sheet_frames(frames: usize) -> Vec<usize> {
    subsample(frames, CONTACT_SHEET_MAX_FRAMES)
}

/// Writes a PNG contact sheet: frames of `video` laid out left to right, top to bottom on a
/// grid of `cols` columns with a 2-pixel grey separator, all through the same `display`.
/// More than [`CONTACT_SHEET_MAX_FRAMES`] frames are subsampled evenly. Every
/// `label_every`-th tile shown (0: none) carries its frame number (index in `video`) in
/// white on black in its top-left corner. Grey video gives a grey PNG, RGB an RGB PNG.
pub fn write_contact_sheet(path: impl AsRef<Path>, video: ArrayView4<f32>, cols: usize, display: &Display, label_every: usize) -> Result<(), IoError> {
    let path = path.as_ref();
    let (frames, h, w, ch) = video.dim();
    check_channels(path, ch)?;
    if frames == 0 || h == 0 || w == 0 {
        return Err(IoError::bad_input(path, "the video is empty"));
    }
    let shown = contact_sheet_frames(frames);
    let grid_cols = cols.clamp(1, shown.len());
    let grid_rows = shown.len().div_ceil(grid_cols);
    let sheet_w = grid_cols * w + (grid_cols + 1) * SEPARATOR;
    let sheet_h = grid_rows * h + (grid_rows + 1) * SEPARATOR;
    let mut sheet = vec![SEPARATOR_LEVEL; sheet_w * sheet_h * ch];
    let scale = if h.min(w) >= 160 { 2 } else { 1 };

    for (k, &f) in shown.iter().enumerate() {
        let (gr, gc) = (k / grid_cols, k % grid_cols);
        let (top, left) = (SEPARATOR + gr * (h + SEPARATOR), SEPARATOR + gc * (w + SEPARATOR));
        let frame = video.index_axis(Axis(0), f);
        for r in 0..h {
            let base = ((top + r) * sheet_w + left) * ch;
            for (i, &v) in frame.index_axis(Axis(0), r).iter().enumerate() {
                sheet[base + i] = display.level(v);
            }
        }
        if label_every > 0 && k % label_every == 0 {
            let text = f.to_string();
            let (lh, lw) = label_size(&text, scale);
            if lh <= h && lw <= w {
                draw_label(&text, scale, top, left, |r, c, on| {
                    let level = if on { 255 } else { 0 };
                    let p = (r * sheet_w + c) * ch;
                    sheet[p..p + ch].fill(level);
                });
            }
        }
    }
    write_atomic(path, |wr| encode_png8(path, wr, sheet_h, sheet_w, ch, &sheet))
}

/// Writes an endlessly looping animated GIF, one GIF frame per video frame, `frame_delay_ms`
/// apart, all frames through the same `display` (no per-frame rescaling, so brightness
/// changes stay visible). Grey video stays exact (≤ 256 levels); RGB frames are quantised
/// to a 256-colour palette each by the encoder. With `frame_time_us`, every frame carries
/// its start time in whole microseconds (`k * frame_time_us`) in its top-left corner,
/// where the frame is large enough for it.
pub fn write_gif(path: impl AsRef<Path>, video: ArrayView4<f32>, display: &Display, frame_delay_ms: u32, frame_time_us: Option<f64>) -> Result<(), IoError> {
    let path = path.as_ref();
    let (frames, h, w, ch) = video.dim();
    check_channels(path, ch)?;
    if frames == 0 || h == 0 || w == 0 {
        return Err(IoError::bad_input(path, "the video is empty"));
    }
    let (gw, gh) = match (u16::try_from(w), u16::try_from(h)) {
        (Ok(a), Ok(b)) => (u32::from(a), u32::from(b)),
        _ => return Err(IoError::bad_input(path, format!("GIF frames are at most 65535 pixels wide and high, found {h}x{w}"))),
    };
    let gif_err = |e: image::ImageError| match e {
        image::ImageError::IoError(io) => IoError::os(path, "cannot write", io),
        other => IoError::bad_input(path, format!("GIF encoder: {other}")),
    };
    write_atomic(path, |wr| {
        let mut enc = GifEncoder::new(wr);
        enc.set_repeat(Repeat::Infinite).map_err(gif_err)?;
        for f in 0..frames {
            let frame = video.index_axis(Axis(0), f);
            let mut rgba = Vec::with_capacity(h * w * 4);
            for px in frame.rows() {
                let l: Vec<u8> = px.iter().map(|&v| display.level(v)).collect();
                let (r, g, b) = if ch == 1 { (l[0], l[0], l[0]) } else { (l[0], l[1], l[2]) };
                rgba.extend_from_slice(&[r, g, b, 255]);
            }
            if let Some(tf) = frame_time_us {
                let text = format!("{:.0}", f as f64 * tf);
                let (lh, lw) = label_size(&text, 1);
                if lh <= h && lw <= w {
                    draw_label(&text, 1, 0, 0, |r, c, on| rgba[(r * w + c) * 4..(r * w + c) * 4 + 3].fill(if on { 255 } else { 0 }));
                }
            }
            let img = RgbaImage::from_raw(gw, gh, rgba).expect("buffer size matches frame size");
            let delay = Delay::from_numer_denom_ms(frame_delay_ms, 1);
            enc.encode_frame(Frame::from_parts(img, 0, 0, delay)).map_err(gif_err)?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subsample_keeps_ends_and_is_increasing() {
        assert_eq!(subsample(5, 48), vec![0, 1, 2, 3, 4]);
        let s = subsample(1000, 48);
        assert_eq!(s.len(), 48);
        assert_eq!((s[0], s[47]), (0, 999));
        assert!(s.windows(2).all(|p| p[1] > p[0]));
        let gaps: Vec<usize> = s.windows(2).map(|p| p[1] - p[0]).collect();
        assert!(gaps.iter().max().unwrap() - gaps.iter().min().unwrap() <= 1, "{gaps:?}");
    }

    #[test]
    fn display_maps_lo_hi_gamma_and_nan() {
        let d = Display::linear(10.0, 20.0);
        assert_eq!(d.level(5.0), 0);
        assert_eq!(d.level(10.0), 0);
        assert_eq!(d.level(15.0), 128);
        assert_eq!(d.level(20.0), 255);
        assert_eq!(d.level(1e9), 255);
        assert_eq!(d.level(f32::NAN), 0);
        let g = Display { gamma: 0.5, ..d };
        assert_eq!(g.level(12.5), (255.0 * 0.25f32.sqrt()).round() as u8);
    }

    #[test]
    fn auto_ignores_outliers_and_non_finite() {
        let mut v: Vec<f32> = (0..1000).map(|i| i as f32).collect();
        v.push(f32::NAN);
        v.push(f32::INFINITY);
        v[0] = -1e6;
        v[999] = 1e6;
        let d = Display::auto(v.iter(), 1.0, 99.0);
        assert!(d.lo > 0.0 && d.lo < 20.0, "{d:?}");
        assert!(d.hi > 980.0 && d.hi < 999.0, "{d:?}");
        assert_eq!(Display::auto([f32::NAN].iter(), 0.1, 99.9), Display::linear(0.0, 1.0));
    }
}
