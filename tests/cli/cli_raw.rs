//! A Bayer raw end to end: a simulated grey capture mosaicked into an RGGB DNG (each
//! half-grid cell's four samples the grey raw's pixel, its dark as the DNG's
//! BlackLevel), with the PSF as a DNG too, reconstructs through `rollcam reconstruct
//! --raw x.dng --psf p.dng --config ...` to the grey capture's video in each channel;
//! a description of the full sensor is refused naming the half grid, a compressed DNG
//! naming its compression.

use std::path::Path;

use ndarray::{Array2, Array3, Axis};
use rollcam::io::formats::raw::{encode_raw, RawSpec};
use rollcam::io::{read_image, read_npy, write_tiff_u16, Bayer};

use crate::support::cli::{fails, json, ok, rollcam, simulate_small};

/// A 2x-size RGGB DNG whose every cell holds `grey`'s pixel in its four samples.
fn mosaic_dng(path: &Path, grey: &Array3<f32>, black: Option<u32>) {
    let (rows, cols, _) = grey.dim();
    let m = Array2::from_shape_fn((2 * rows, 2 * cols), |(r, c)| grey[[r / 2, c / 2, 0]] as u16);
    let spec = RawSpec { mosaic: m.view(), pattern: Bayer::Rggb, bits: 16, dng: true, black_level: black, white_level: Some(65535), compression: 1 };
    std::fs::write(path, encode_raw(&spec)).unwrap();
}

#[test]
fn a_mosaicked_dng_raw_and_psf_reconstruct_like_the_grey_capture_in_every_channel() {
    let dir = tempfile::tempdir().unwrap();
    let sim = simulate_small(dir.path(), "moving-disc");
    let d = dir.path();
    let text = std::fs::read_to_string(sim.join("capture.toml")).unwrap();
    let dark_line = text.lines().find(|l| l.starts_with("dark_level")).expect("simulate writes dark_level").to_string();
    let dark: f64 = dark_line.split('=').nth(1).unwrap().trim().parse().unwrap();
    assert_eq!(dark, dark.round(), "a whole-count dark");
    // The grey baseline as whole counts, and the PSF as the same camera would record it
    // (4000 levels above the dark), as u16 TIFFs.
    let raw = read_image(sim.join("raw.tiff")).unwrap().mapv(|v| v.round().clamp(0.0, 65535.0));
    let psf = read_image(sim.join("psf.tiff")).unwrap();
    let top = psf.iter().fold(0f32, |m, &v| m.max(v));
    let psf = psf.mapv(|v| (v / top * 4000.0).round().max(0.0) + dark as f32);
    write_tiff_u16(d.join("raw.tiff"), raw.view()).unwrap();
    write_tiff_u16(d.join("psf.tiff"), psf.view()).unwrap();
    mosaic_dng(&d.join("raw.dng"), &raw, Some(dark as u32));
    mosaic_dng(&d.join("psf.dng"), &psf, Some(dark as u32));
    // The DNG's description has no dark_level: the raw's and the PSF's BlackLevel is
    // their dark (the grey run takes dark_level for both).
    std::fs::write(d.join("dng.toml"), text.replace(&format!("{dark_line}\n"), "")).unwrap();

    let run = |raw: &str, psf: &str, cfg: &Path, out: &str| {
        let args = ["reconstruct", "--raw", raw, "--psf", psf, "--config", cfg.to_str().unwrap(), "--iters", "40", "--out", out];
        let args: Vec<String> =
            args.iter().map(|a| if a.ends_with(".tiff") || a.ends_with(".dng") { d.join(a).display().to_string() } else { a.to_string() }).collect();
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        rollcam(&args, d)
    };
    let out_grey = d.join("grey").display().to_string();
    let out_dng = d.join("dng").display().to_string();
    ok(&run("raw.tiff", "psf.tiff", &sim.join("capture.toml"), &out_grey));
    ok(&run("raw.dng", "psf.dng", &d.join("dng.toml"), &out_dng));
    let s = json(&d.join("dng/summary.json"));
    assert_eq!(s["sensor"]["dark_source"], "file-black-level", "{}", s["sensor"]);
    let grey = read_npy(d.join("grey/video.npy")).unwrap();
    let colour = read_npy(d.join("dng/video.npy")).unwrap();
    assert_eq!((grey.dim().3, colour.dim().3), (1, 3));
    assert_eq!(grey.index_axis(Axis(3), 0).dim(), colour.index_axis(Axis(3), 0).dim());
    let scale = grey.iter().fold(0f32, |m, &v| m.max(v.abs()));
    assert!(scale > 0.0);
    for ch in 0..3 {
        let worst = grey.index_axis(Axis(3), 0).iter().zip(colour.index_axis(Axis(3), ch)).fold(0f32, |m, (&a, &b)| m.max((a - b).abs()));
        assert!(worst <= 1e-3 * scale, "channel {ch}: differs from the grey video by {worst} (scale {scale})");
    }

    // A description of the full sensor (128 x 160) is refused naming the half grid.
    let full = text.replace("rows = 64", "rows = 128").replace("cols = 80", "cols = 160");
    assert_ne!(full, text);
    std::fs::write(d.join("full.toml"), full).unwrap();
    let e = fails(&run("raw.dng", "psf.dng", &d.join("full.toml"), &d.join("full").display().to_string()));
    assert!(e.contains("raw.dng") && e.contains("half grid of 64 x 80") && e.contains("128 x 160, the sensor's") && e.contains("line_time_us = twice"), "{e}");
    assert!(!d.join("full").join("video.npy").exists());

    // A compressed DNG (lossless JPEG) is refused naming the file and the compression,
    // before any output is made.
    let mut lj92 = std::fs::read(d.join("raw.dng")).unwrap();
    let n = u16::from_le_bytes([lj92[8], lj92[9]]) as usize;
    let e = (0..n).map(|k| 10 + 12 * k).find(|&e| u16::from_le_bytes([lj92[e], lj92[e + 1]]) == 259).unwrap();
    lj92[e + 8] = 7;
    std::fs::write(d.join("lj92.dng"), &lj92).unwrap();
    let e = fails(&run("lj92.dng", "psf.dng", &d.join("dng.toml"), &d.join("lj92").display().to_string()));
    assert!(e.contains("lj92.dng") && e.contains("lossless JPEG (Compression = 7)") && e.contains("uncompressed"), "{e}");
    assert!(!d.join("lj92").join("video.npy").exists());
}
