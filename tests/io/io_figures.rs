//! Figures: contact sheets, animated GIFs and line plots, checked by decoding the output.

use std::fs;
use std::io::BufReader;

use image::codecs::gif::GifDecoder;
use image::AnimationDecoder;
use ndarray::Array4;
use rollcam::io::{plot_lines, read_image, write_contact_sheet, write_gif, Display, PlotSpec, Series, CONTACT_SHEET_MAX_FRAMES, SERIES_COLOURS};

#[test]
fn contact_sheet_lays_out_frames_with_separators() {
    let dir = tempfile::tempdir().unwrap();
    let (frames, h, w) = (5, 10, 12);
    let video = Array4::from_shape_fn((frames, h, w, 1), |(f, r, c, _)| (f * 40 + r + c) as f32);
    let d = Display::linear(0.0, 255.0);
    let p = dir.path().join("sheet.png");
    write_contact_sheet(&p, video.view(), 3, &d, 0).unwrap();
    let sheet = read_image(&p).unwrap();
    let sep = 2;
    assert_eq!(sheet.dim(), (2 * h + 3 * sep, 3 * w + 4 * sep, 1));
    for f in 0..frames {
        let (top, left) = (sep + (f / 3) * (h + sep), sep + (f % 3) * (w + sep));
        for r in 0..h {
            for c in 0..w {
                assert_eq!(sheet[[top + r, left + c, 0]], d.level(video[[f, r, c, 0]]) as f32, "frame {f} ({r},{c})");
            }
        }
    }
    // Separator between tiles 0 and 1, and the unused sixth slot, are uniform grey.
    let grey = sheet[[0, 0, 0]];
    assert!((0..sheet.dim().0).all(|r| sheet[[r, sep + w, 0]] == grey));
    let (top, left) = (sep + h + sep, sep + 2 * (w + sep));
    assert!((0..h).all(|r| (0..w).all(|c| sheet[[top + r, left + c, 0]] == grey)));
    assert!(grey > 0.0 && grey < 255.0);
}

#[test]
fn contact_sheet_subsamples_long_videos_and_labels_frames() {
    let dir = tempfile::tempdir().unwrap();
    let (frames, h, w) = (100, 20, 30);
    // Black frames so that any white pixel is label ink.
    let video = Array4::<f32>::zeros((frames, h, w, 3));
    let p = dir.path().join("long.png");
    let cols = 8;
    write_contact_sheet(&p, video.view(), cols, &Display::linear(0.0, 1.0), 5).unwrap();
    let sheet = read_image(&p).unwrap();
    let rows = CONTACT_SHEET_MAX_FRAMES.div_ceil(cols);
    assert_eq!(sheet.dim(), (rows * h + (rows + 1) * 2, cols * w + (cols + 1) * 2, 3));
    let white_in_tile = |k: usize| {
        let (top, left) = (2 + (k / cols) * (h + 2), 2 + (k % cols) * (w + 2));
        (0..h).flat_map(|r| (0..w).map(move |c| (r, c))).filter(|&(r, c)| sheet[[top + r, left + c, 0]] == 255.0).count()
    };
    // Tiles 0, 5, 10.. carry labels; the others none.
    assert!(white_in_tile(0) > 5);
    assert!(white_in_tile(45) > 5);
    for k in [1, 2, 4, 6, 44, 46, 47] {
        assert_eq!(white_in_tile(k), 0, "tile {k} should be unlabelled");
    }
    // Tile 45 shows frame round(45 * 99 / 47) = 95 or so: two digits, more ink than "0".
    assert!(white_in_tile(45) > white_in_tile(0));
}

#[test]
fn gif_has_every_frame_with_shared_scaling_and_delay() {
    let dir = tempfile::tempdir().unwrap();
    let frames = 4;
    // Frame f spans f*60 .. f*60+29: per-frame scaling would stretch each to 0..255.
    let video = Array4::from_shape_fn((frames, 6, 5, 1), |(f, r, c, _)| (f * 60 + r * 5 + c) as f32);
    let d = Display::linear(0.0, 240.0);
    let p = dir.path().join("movie.gif");
    write_gif(&p, video.view(), &d, 40, None).unwrap();
    let dec = GifDecoder::new(BufReader::new(fs::File::open(&p).unwrap())).unwrap();
    let decoded = dec.into_frames().collect_frames().unwrap();
    assert_eq!(decoded.len(), frames);
    for (f, fr) in decoded.iter().enumerate() {
        let (num, den) = fr.delay().numer_denom_ms();
        assert_eq!(num / den, 40);
        let buf = fr.buffer();
        assert_eq!(buf.dimensions(), (5, 6));
        for r in 0..6 {
            for c in 0..5 {
                let want = d.level(video[[f, r, c, 0]]);
                assert_eq!(buf.get_pixel(c as u32, r as u32).0, [want, want, want, 255], "frame {f} ({r},{c})");
            }
        }
    }

    // RGB with few colours survives the palette exactly.
    let rgb = Array4::from_shape_fn((2, 3, 3, 3), |(f, r, _, k)| if (r + k + f) % 3 == 0 { 255.0 } else { 0.0 });
    let p = dir.path().join("rgb.gif");
    write_gif(&p, rgb.view(), &Display::linear(0.0, 255.0), 100, None).unwrap();
    let dec = GifDecoder::new(BufReader::new(fs::File::open(&p).unwrap())).unwrap();
    let decoded = dec.into_frames().collect_frames().unwrap();
    assert_eq!(decoded.len(), 2);
    let px = decoded[1].buffer().get_pixel(0, 2).0;
    let want: Vec<u8> = (0..3).map(|k| if (2 + k + 1) % 3 == 0 { 255 } else { 0 }).collect();
    assert_eq!(&px[..3], &want[..]);
}

fn psnr_spec() -> PlotSpec {
    PlotSpec {
        title: "Reconstruction error against run time".into(),
        x_label: "run time (s)".into(),
        y_label: "PSNR (dB)".into(),
        series: vec![
            Series { name: "FISTA".into(), points: (1..40).map(|i| (i as f64 * 0.5, 20.0 + 10.0 * (i as f64).ln())).collect() },
            Series { name: "ISTA".into(), points: (1..40).map(|i| (i as f64 * 0.5, 18.0 + 6.0 * (i as f64).ln())).collect() },
        ],
        size: (640, 400),
        ..PlotSpec::default()
    }
}

#[test]
fn svg_plot_contains_title_labels_and_series_names() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("psnr.svg");
    plot_lines(&p, &psnr_spec()).unwrap();
    let svg = fs::read_to_string(&p).unwrap();
    assert!(svg.starts_with("<svg"), "{}", &svg[..60.min(svg.len())]);
    for text in ["Reconstruction error against run time", "run time (s)", "PSNR (dB)", "FISTA", "ISTA"] {
        assert!(svg.contains(&format!(">\n{text}\n<")) || svg.contains(&format!(">{text}<")), "missing text {text:?}");
    }
    assert!(svg.matches("<polyline").count() >= 2);
}

#[test]
fn png_plot_has_size_lines_and_rendered_text() {
    let dir = tempfile::tempdir().unwrap();
    let spec = psnr_spec();
    let p = dir.path().join("psnr.png");
    plot_lines(&p, &spec).unwrap();
    let img = read_image(&p).unwrap();
    assert_eq!(img.dim(), (400, 640, 3));
    let count = |rgb: [u8; 3], rows: std::ops::Range<usize>| {
        rows.flat_map(|r| (0..640).map(move |c| (r, c))).filter(|&(r, c)| (0..3).all(|k| img[[r, c, k]] == rgb[k] as f32)).count()
    };
    // Both series' colours appear in the plot area (below the title band).
    assert!(count(SERIES_COLOURS[0], 50..400) > 100);
    assert!(count(SERIES_COLOURS[1], 50..400) > 100);
    // The title is rendered as glyphs: dark pixels in the top band, where nothing else is drawn.
    let dark_title = (0..40).flat_map(|r| (0..640).map(move |c| (r, c))).filter(|&(r, c)| img[[r, c, 0]] < 100.0).count();
    assert!(dark_title > 200, "title glyphs missing ({dark_title} dark pixels)");
    // Tick labels: dark pixels left of the y axis.
    let dark_ticks = (60..340).flat_map(|r| (0..60).map(move |c| (r, c))).filter(|&(r, c)| img[[r, c, 0]] < 100.0).count();
    assert!(dark_ticks > 100, "tick labels missing ({dark_ticks})");
}

#[test]
fn log_log_plot_of_a_spectrum_and_bad_extension() {
    let dir = tempfile::tempdir().unwrap();
    let spec = PlotSpec {
        title: "Temporal spectrum".into(),
        x_label: "frequency (Hz)".into(),
        y_label: "power (counts²)".into(),
        series: vec![Series {
            name: "pixel (120, 80)".into(),
            points: (0..200).map(|i| (i as f64 * 10.0, 1e6 / (1.0 + i as f64).powi(2))).collect(), // includes x = 0
        }],
        log_x: true,
        log_y: true,
        size: (500, 300),
    };
    let p = dir.path().join("spectrum.png");
    plot_lines(&p, &spec).unwrap();
    let img = read_image(&p).unwrap();
    assert_eq!(img.dim(), (300, 500, 3));
    let line = (0..300).flat_map(|r| (0..500).map(move |c| (r, c))).filter(|&(r, c)| (0..3).all(|k| img[[r, c, k]] == SERIES_COLOURS[0][k] as f32)).count();
    assert!(line > 100, "{line}");
    let e = plot_lines(dir.path().join("plot.jpg"), &spec).unwrap_err().to_string();
    assert!(e.contains("plot.jpg") && e.contains(".svg or .png"), "{e}");
}
