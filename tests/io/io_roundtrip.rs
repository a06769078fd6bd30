//! Round trips and error reports of the file-format layer, on files made in a temp dir.

use std::fs;
use std::io::Cursor;
use std::path::Path;

use ndarray::{Array3, Array4, Axis};
use rollcam::io::{
    read_image, read_image_page, read_npy, read_stack, write_npy, write_png, write_stack, write_tiff_f32, write_tiff_stack_f32, write_tiff_u16, Display,
    IoError,
};
use tiff::decoder::{Decoder, DecodingResult};
use tiff::encoder::{colortype, TiffEncoder};
use tiff::tags::Tag;

/// Deterministic test pattern with distinct values in every sample.
fn pattern(rows: usize, cols: usize, ch: usize, max: f32) -> Array3<f32> {
    Array3::from_shape_fn((rows, cols, ch), |(r, c, k)| ((r * 31 + c * 7 + k * 101) as f32 * 13.0) % (max + 1.0))
}

fn video(frames: usize, rows: usize, cols: usize, ch: usize) -> Array4<f32> {
    Array4::from_shape_fn((frames, rows, cols, ch), |(f, r, c, k)| (f as f32 * 1000.0) + (r as f32) * 10.5 - (c as f32) * 0.25 + (k as f32) * 0.125 + 1e-3)
}

/// Writes a TIFF with the `tiff` encoder directly (not through the module under test).
fn encode_tiff<C: colortype::ColorType>(path: &Path, pages: &[(u32, u32, Vec<C::Inner>)])
where
    [C::Inner]: tiff::encoder::TiffValue,
{
    let mut buf = Cursor::new(Vec::new());
    {
        let mut enc = TiffEncoder::new(&mut buf).unwrap();
        for (w, h, data) in pages {
            enc.write_image::<C>(*w, *h, data).unwrap();
        }
    }
    fs::write(path, buf.into_inner()).unwrap();
}

/// Grey+alpha, which the `tiff` encoder does not offer ready-made.
struct GrayAlpha8;
impl colortype::ColorType for GrayAlpha8 {
    type Inner = u8;
    const TIFF_VALUE: tiff::tags::PhotometricInterpretation = tiff::tags::PhotometricInterpretation::BlackIsZero;
    const BITS_PER_SAMPLE: &'static [u16] = &[8, 8];
    const SAMPLE_FORMAT: &'static [tiff::tags::SampleFormat] = &[tiff::tags::SampleFormat::Uint; 2];
}

fn msg(e: IoError) -> String {
    e.to_string()
}

#[test]
fn tiff_u8_grey_and_rgb_read_as_raw_counts() {
    let dir = tempfile::tempdir().unwrap();
    let grey = pattern(5, 7, 1, 255.0);
    let p = dir.path().join("g8.tif");
    encode_tiff::<colortype::Gray8>(&p, &[(7, 5, grey.iter().map(|&v| v as u8).collect())]);
    assert_eq!(read_image(&p).unwrap(), grey);

    let rgb = pattern(4, 6, 3, 255.0);
    let p = dir.path().join("rgb8.tiff");
    encode_tiff::<colortype::RGB8>(&p, &[(6, 4, rgb.iter().map(|&v| v as u8).collect())]);
    let back = read_image(&p).unwrap();
    assert_eq!(back.dim(), (4, 6, 3));
    assert_eq!(back, rgb);
}

#[test]
fn tiff_u16_round_trip_grey_and_rgb_with_clamping_and_rounding() {
    let dir = tempfile::tempdir().unwrap();
    for ch in [1, 3] {
        let img = pattern(9, 11, ch, 65535.0);
        let p = dir.path().join(format!("u16_{ch}.tiff"));
        write_tiff_u16(&p, img.view()).unwrap();
        let back = read_image(&p).unwrap();
        assert_eq!(back, img, "{ch} channels");
        assert!(back.iter().any(|&v| v > 255.0), "values above 8 bits must survive");
    }
    let mut img = Array3::<f32>::zeros((1, 4, 1));
    img.as_slice_mut().unwrap().copy_from_slice(&[-5.0, 2.4, 2.6, 70000.0]);
    let p = dir.path().join("clamp.tif");
    write_tiff_u16(&p, img.view()).unwrap();
    assert_eq!(read_image(&p).unwrap().as_slice().unwrap(), &[0.0, 2.0, 3.0, 65535.0]);
}

#[test]
fn tiff_f32_round_trip_is_exact_including_nan_and_infinities() {
    let dir = tempfile::tempdir().unwrap();
    for ch in [1, 3] {
        let mut img = pattern(6, 5, ch, 1000.0).mapv(|v| v * 0.37 - 12.5);
        img[[0, 0, 0]] = f32::NAN;
        img[[1, 2, ch - 1]] = f32::INFINITY;
        img[[2, 3, 0]] = f32::NEG_INFINITY;
        img[[3, 1, 0]] = 1e-40; // subnormal
        let p = dir.path().join(format!("f32_{ch}.tif"));
        write_tiff_f32(&p, img.view()).unwrap();
        let back = read_image(&p).unwrap();
        assert_eq!(back.dim(), img.dim());
        for (a, b) in img.iter().zip(back.iter()) {
            assert_eq!(a.to_bits(), b.to_bits(), "{a} read back as {b}");
        }
    }
}

#[test]
fn float_stack_is_imagej_hyperstack_read_back_page_by_page() {
    let dir = tempfile::tempdir().unwrap();
    for ch in [1usize, 3] {
        let mut v = video(4, 3, 5, ch);
        v[[2, 1, 1, 0]] = f32::NAN;
        v[[3, 0, 0, ch - 1]] = -77.0;
        let p = dir.path().join(format!("stack{ch}.tif"));
        write_tiff_stack_f32(&p, v.view()).unwrap();

        // Independent decoder: every page, every value, the description.
        let bytes = fs::read(&p).unwrap();
        let mut dec = Decoder::new(Cursor::new(&bytes)).unwrap();
        let desc = dec.get_tag_ascii_string(Tag::ImageDescription).unwrap();
        let finite: Vec<f32> = v.iter().copied().filter(|x| x.is_finite()).collect();
        let lo = finite.iter().copied().fold(f32::INFINITY, f32::min);
        let hi = finite.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        let expected = format!("ImageJ=1.11a\nimages={}\nchannels={ch}\nframes=4\nhyperstack=true\nmode=grayscale\nmin={lo}\nmax={hi}\n", 4 * ch);
        assert!(desc.starts_with(&expected), "description {desc:?}");
        let mut page = 0;
        let mut offsets = Vec::new();
        loop {
            assert_eq!(dec.dimensions().unwrap(), (5, 3));
            assert_eq!(dec.colortype().unwrap(), tiff::ColorType::Gray(32));
            offsets.push(dec.get_tag_u64_vec(Tag::StripOffsets).unwrap());
            let DecodingResult::F32(data) = dec.read_image().unwrap() else { panic!("page {page} is not float32") };
            let (f, k) = (page / ch, page % ch);
            let want: Vec<f32> = v.index_axis(Axis(0), f).index_axis(Axis(2), k).iter().copied().collect();
            assert_eq!(data.len(), want.len());
            for (a, b) in want.iter().zip(&data) {
                assert_eq!(a.to_bits(), b.to_bits(), "page {page}");
            }
            page += 1;
            if !dec.more_images() {
                break;
            }
            dec.next_image().unwrap();
        }
        assert_eq!(page, 4 * ch);
        // ImageJ reads its stacks as contiguous planes after the first one.
        let plane = (3 * 5 * 4) as u64;
        for (i, o) in offsets.iter().enumerate() {
            assert_eq!(o, &vec![offsets[0][0] + i as u64 * plane], "plane {i} is not contiguous");
        }

        // Our own reader regroups the channels.
        let back = read_stack(&p).unwrap();
        assert_eq!(back.dim(), v.dim());
        for (a, b) in v.iter().zip(back.iter()) {
            assert_eq!(a.to_bits(), b.to_bits());
        }
    }
}

#[test]
fn multi_page_u16_tiff_reads_as_stack_and_read_image_page_takes_one_page() {
    let dir = tempfile::tempdir().unwrap();
    let frames: Vec<Array3<f32>> = (0..3).map(|i| pattern(4, 5, 1, 65535.0).mapv(|v| (v + i as f32 * 999.0) % 65536.0)).collect();
    let p = dir.path().join("pages.tif");
    let pages: Vec<(u32, u32, Vec<u16>)> = frames.iter().map(|f| (5, 4, f.iter().map(|&v| v as u16).collect())).collect();
    encode_tiff::<colortype::Gray16>(&p, &pages);
    let st = read_stack(&p).unwrap();
    assert_eq!(st.dim(), (3, 4, 5, 1));
    for (i, f) in frames.iter().enumerate() {
        assert_eq!(st.index_axis(Axis(0), i), f.view());
    }
    // A single image of a multi-page file: refused, saying how many pages (the library
    // names no flag: only the raw has `--page`, and the command line says so).
    let e = msg(read_image(&p).unwrap_err());
    assert!(e.contains("pages.tif") && e.contains("3 pages") && !e.contains("--page"), "{e}");
    assert_eq!(read_image_page(&p, Some(1)).unwrap(), frames[0]);
    assert_eq!(read_image_page(&p, Some(3)).unwrap(), frames[2]);
    for bad in [0, 4] {
        let e = msg(read_image_page(&p, Some(bad)).unwrap_err());
        assert!(e.contains("pages.tif") && e.contains(&format!("page {bad}")), "{e}");
    }
    assert!(msg(read_image_page(&p, Some(4)).unwrap_err()).contains("holds 3 page"));
}

#[test]
fn mismatched_page_sizes_name_the_page() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("mixed.tif");
    encode_tiff::<colortype::Gray8>(&p, &[(4, 4, vec![1; 16]), (4, 4, vec![2; 16]), (4, 5, vec![3; 20])]);
    let e = msg(read_stack(&p).unwrap_err());
    // Pages are counted from 1 in messages.
    assert!(e.contains("mixed.tif") && e.contains("page 3 is 5x4") && e.contains("page 1 is 4x4"), "{e}");
    assert!(!e.contains("page 2"), "{e}");
}

#[test]
fn truncated_tiff_is_reported_as_truncated() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("raw.tiff");
    write_tiff_u16(&p, pattern(64, 64, 1, 65535.0).view()).unwrap();
    let bytes = fs::read(&p).unwrap();
    fs::write(&p, &bytes[..bytes.len() / 2]).unwrap();
    let e = msg(read_image(&p).unwrap_err());
    assert!(e.starts_with(&p.display().to_string()) && e.contains("truncated TIFF"), "{e}");

    // A stack cut after its first pages: both readers report the cut (the page count
    // cannot be known, so a single-image read is not silently the first page).
    let p3 = dir.path().join("stack_cut.tif");
    let pages: Vec<(u32, u32, Vec<u8>)> = (0..3).map(|i| (32, 32, vec![i as u8; 1024])).collect();
    encode_tiff::<colortype::Gray8>(&p3, &pages);
    let bytes = fs::read(&p3).unwrap();
    fs::write(&p3, &bytes[..bytes.len() * 3 / 5]).unwrap();
    let e = msg(read_image(&p3).unwrap_err());
    assert!(e.contains("stack_cut.tif: truncated TIFF") && e.contains("page 2"), "{e}");
    let e = msg(read_stack(&p3).unwrap_err());
    assert!(e.contains("stack_cut.tif: truncated TIFF") && e.contains("page"), "{e}");

    // Directory intact but pixel data cut: names the missing strip.
    let p2 = dir.path().join("cut_strip.tif");
    let mut buf = Cursor::new(Vec::new());
    {
        let mut enc = TiffEncoder::new(&mut buf).unwrap();
        let mut im = enc.new_image::<colortype::Gray8>(16, 8).unwrap();
        im.rows_per_strip(2).unwrap();
        im.write_data(&[7u8; 128]).unwrap();
    }
    let mut bytes = buf.into_inner();
    // Move the last strip's offset past the end of file, as a cut download would leave it.
    let mut dec = Decoder::new(Cursor::new(&bytes)).unwrap();
    let offsets = dec.get_tag_u32_vec(Tag::StripOffsets).unwrap();
    assert_eq!(offsets.len(), 4);
    let needle = offsets[3].to_le_bytes();
    let pos = bytes.windows(4).rposition(|w| w == needle).unwrap();
    let beyond = (bytes.len() as u32 + 100).to_le_bytes();
    bytes[pos..pos + 4].copy_from_slice(&beyond);
    fs::write(&p2, &bytes).unwrap();
    let e = msg(read_image(&p2).unwrap_err());
    assert!(e.contains("truncated TIFF") && e.contains("strip 3 missing"), "{e}");
}

#[test]
fn wrong_magic_names_both_formats() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("real.png");
    write_png(&png, pattern(3, 3, 1, 255.0).view(), &Display::linear(0.0, 255.0)).unwrap();
    let fake = dir.path().join("psf.tiff");
    fs::copy(&png, &fake).unwrap();
    let e = msg(read_image(&fake).unwrap_err());
    assert!(e.contains("psf.tiff") && e.contains("TIFF") && e.contains("PNG"), "{e}");
    let fake_npy = dir.path().join("truth.npy");
    fs::copy(&png, &fake_npy).unwrap();
    let e = msg(read_stack(&fake_npy).unwrap_err());
    assert!(e.contains("truth.npy") && e.contains("NPY") && e.contains("PNG"), "{e}");
}

#[test]
fn missing_file_and_unknown_extension_name_the_path() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("no_such_frame.tiff");
    let e = read_image(&p).unwrap_err();
    assert!(matches!(e, IoError::Os { .. }), "{e:?}");
    assert!(msg(e).contains(&p.display().to_string()));
    let e = msg(read_stack(dir.path().join("x.bmp")).unwrap_err());
    assert!(e.contains("x.bmp") && e.contains(".tif"), "{e}");
}

#[test]
fn alpha_and_four_channel_images_are_refused_clearly() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("ga.tif");
    encode_tiff::<GrayAlpha8>(&p, &[(2, 2, vec![1; 8])]);
    let e = msg(read_image(&p).unwrap_err());
    assert!(e.contains("ga.tif") && e.contains("expected a grey or RGB image") && e.contains("alpha"), "{e}");
    let p = dir.path().join("psf.tiff");
    encode_tiff::<colortype::RGBA8>(&p, &[(2, 2, vec![1; 16])]);
    let e = msg(read_image(&p).unwrap_err());
    assert!(e.contains("psf.tiff: expected a grey or RGB image, found 4 channels"), "{e}");
}

#[test]
fn npy_round_trip_drops_single_channel_axis() {
    let dir = tempfile::tempdir().unwrap();
    let grey = video(3, 4, 5, 1);
    let p = dir.path().join("truth.npy");
    write_npy(&p, grey.view()).unwrap();
    let bytes = fs::read(&p).unwrap();
    let header = String::from_utf8_lossy(&bytes[..128]);
    assert!(header.contains("'<f4'") && header.contains("(3, 4, 5)"), "{header}");
    assert_eq!(read_npy(&p).unwrap(), grey);
    assert_eq!(read_stack(&p).unwrap(), grey);

    let rgb = video(2, 3, 4, 3);
    let p = dir.path().join("rgb.npy");
    write_npy(&p, rgb.view()).unwrap();
    let header = String::from_utf8_lossy(&fs::read(&p).unwrap()[..128]).into_owned();
    assert!(header.contains("(2, 3, 4, 3)"), "{header}");
    assert_eq!(read_npy(&p).unwrap(), rgb);
}

#[test]
fn npy_images_of_other_dtypes_and_wrong_axes() {
    use ndarray_npy::WriteNpyExt;
    let dir = tempfile::tempdir().unwrap();
    let img = pattern(3, 4, 1, 65535.0);
    let p = dir.path().join("u16.npy");
    img.index_axis(Axis(2), 0).mapv(|v| v as u16).write_npy(fs::File::create(&p).unwrap()).unwrap();
    assert_eq!(read_image(&p).unwrap(), img);
    let p = dir.path().join("f64.npy");
    img.mapv(|v| v as f64 + 0.5).write_npy(fs::File::create(&p).unwrap()).unwrap();
    assert_eq!(read_image(&p).unwrap(), img.mapv(|v| v + 0.5));
    let p = dir.path().join("rgb_u8.npy");
    let rgb = pattern(2, 2, 3, 255.0);
    rgb.mapv(|v| v as u8).write_npy(fs::File::create(&p).unwrap()).unwrap();
    assert_eq!(read_image(&p).unwrap(), rgb);

    // A 2-axis array is not a video.
    let p = dir.path().join("truth.npy");
    img.index_axis(Axis(2), 0).write_npy(fs::File::create(&p).unwrap()).unwrap();
    let e = msg(read_npy(&p).unwrap_err());
    assert!(e.contains("truth.npy: expected float32 array with 3 or 4 axes") && e.ends_with("found 2"), "{e}");
    // Unsupported dtype is named.
    let p = dir.path().join("i32.npy");
    ndarray::Array3::<i32>::zeros((1, 2, 2)).write_npy(fs::File::create(&p).unwrap()).unwrap();
    let e = msg(read_stack(&p).unwrap_err());
    assert!(e.contains("i32.npy") && e.contains("<i4"), "{e}");
}

#[test]
fn png_round_trip_with_identity_display_grey_and_rgb() {
    let dir = tempfile::tempdir().unwrap();
    for ch in [1, 3] {
        let img = pattern(7, 9, ch, 255.0);
        let p = dir.path().join(format!("im{ch}.png"));
        write_png(&p, img.view(), &Display::linear(0.0, 255.0)).unwrap();
        assert_eq!(read_image(&p).unwrap(), img);
    }
    // Display scaling: lo..hi maps to 0..255.
    let img = Array3::from_shape_vec((1, 3, 1), vec![100.0, 150.0, 200.0]).unwrap();
    let p = dir.path().join("scaled.png");
    write_png(&p, img.view(), &Display::linear(100.0, 200.0)).unwrap();
    assert_eq!(read_image(&p).unwrap().as_slice().unwrap(), &[0.0, 128.0, 255.0]);
}

#[test]
fn png_16_bit_is_read_as_raw_counts() {
    use image::{ImageBuffer, Luma};
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("deep.png");
    let buf: ImageBuffer<Luma<u16>, Vec<u16>> = ImageBuffer::from_fn(3, 2, |x, y| Luma([1000 * x as u16 + 30000 * y as u16 + 7]));
    buf.save(&p).unwrap();
    let img = read_image(&p).unwrap();
    assert_eq!(img.dim(), (2, 3, 1));
    assert_eq!(img[[1, 2, 0]], 32007.0);
}

#[test]
fn directory_of_numbered_frames_is_sorted_naturally() {
    let dir = tempfile::tempdir().unwrap();
    let d = Display::linear(0.0, 255.0);
    // Written out of order; frame n holds value 10 * n everywhere.
    for n in [10usize, 2, 1, 0] {
        let img = Array3::from_elem((3, 2, 1), (10 * n) as f32);
        if n % 2 == 0 {
            write_png(dir.path().join(format!("frame{n}.png")), img.view(), &d).unwrap();
        } else {
            write_tiff_u16(dir.path().join(format!("frame{n}.tif")), img.view()).unwrap();
        }
    }
    fs::write(dir.path().join("notes.txt"), "ignored").unwrap();
    let st = read_stack(dir.path()).unwrap();
    let firsts: Vec<f32> = (0..st.dim().0).map(|f| st[[f, 0, 0, 0]]).collect();
    assert_eq!(firsts, vec![0.0, 10.0, 20.0, 100.0]);

    write_png(dir.path().join("frame11.png"), Array3::from_elem((2, 2, 1), 0.0).view(), &d).unwrap();
    let e = msg(read_stack(dir.path()).unwrap_err());
    assert!(e.contains("frame11.png") && e.contains("frame0.png"), "{e}");
}

#[test]
fn writers_leave_no_temporary_files_and_replace_atomically() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("out.tif");
    write_tiff_f32(&p, pattern(2, 2, 1, 9.0).view()).unwrap();
    write_tiff_f32(&p, pattern(3, 3, 1, 9.0).view()).unwrap();
    assert_eq!(read_image(&p).unwrap().dim(), (3, 3, 1));
    // A failing write (4 channels) leaves the previous file and no debris.
    assert!(write_tiff_f32(&p, Array3::<f32>::zeros((2, 2, 4)).view()).is_err());
    assert!(write_png(dir.path().join("bad.png"), Array3::<f32>::zeros((2, 2, 2)).view(), &Display::linear(0.0, 1.0)).is_err());
    // A writer that fails half-way through leaves the destination untouched.
    let e = rollcam::io::write_atomic(&p, |w| {
        use std::io::Write;
        w.write_all(b"half a file").unwrap();
        Err(IoError::BadInput { path: p.clone(), detail: "stopped".into() })
    });
    assert!(e.is_err());
    assert_eq!(read_image(&p).unwrap().dim(), (3, 3, 1));
    let names: Vec<String> = fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert_eq!(names, vec!["out.tif".to_string()]);
}

/// `write_stack` writes what the name's format writes, byte for byte (`video.tiff` and
/// `video.npy` of a reconstruction go through it), and refuses a name it cannot write.
#[test]
fn write_stack_follows_the_name_and_writes_the_formats_own_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let v = video(3, 4, 5, 3);
    for (generic, own) in [("g.tiff", "own.tiff"), ("g.TIF", "own.tif"), ("g.npy", "own.npy")] {
        let (g, o) = (dir.path().join(generic), dir.path().join(own));
        write_stack(&g, v.view()).unwrap();
        if own.ends_with(".npy") {
            write_npy(&o, v.view()).unwrap();
        } else {
            write_tiff_stack_f32(&o, v.view()).unwrap();
        }
        assert_eq!(fs::read(&g).unwrap(), fs::read(&o).unwrap(), "{generic}");
        assert_eq!(read_stack(&g).unwrap(), v, "{generic}");
    }
    let e = msg(write_stack(dir.path().join("v.png"), v.view()).unwrap_err());
    assert!(e.contains("v.png") && e.contains("PNG") && e.contains(".npy"), "{e}");
    let e = msg(write_stack(dir.path().join("v.bmp"), v.view()).unwrap_err());
    assert!(e.contains("v.bmp: unknown file type") && e.contains(".tiff"), "{e}");
}
