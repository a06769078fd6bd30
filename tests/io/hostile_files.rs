//! Tiny hostile files: headers that announce huge images, data that is not there, a
//! multi-page raw read as one image. Each gets an error naming the file and the figure,
//! before anything of the announced size is allocated (an allocation of the announced
//! size would abort the test process), and the input is left byte-identical.

use std::fs;
use std::path::Path;
use std::process::Command;

use rollcam::io::budget::LimitSource;
use rollcam::io::{decode_image_bytes, decode_npy, decode_stack_bytes, read_image, read_image_page, read_stack, ByteBudget, IoError};
use tiff::encoder::{colortype, TiffEncoder};

/// A budget of `gb` gigabytes, as `ROLLCAM_MEMORY_LIMIT_GB` would set it.
fn budget(gb: f64) -> ByteBudget {
    ByteBudget { limit_bytes: (gb * 1e9) as u64, source: LimitSource::Environment }
}

/// A classic little-endian TIFF of 124 bytes: one 8-bit grey page whose header says
/// `width` x `height` pixels in one uncompressed strip of 14 bytes (all in the file).
fn tiff_claiming(width: u32, height: u32) -> Vec<u8> {
    // (tag, type, value): type 3 SHORT, 4 LONG.
    let entries: [(u16, u16, u32); 8] = [
        (256, 4, width),
        (257, 4, height),
        (258, 3, 8),
        (259, 3, 1),
        (262, 3, 1),
        (273, 4, 110), // StripOffsets: right after the directory
        (278, 4, height),
        (279, 4, 14), // StripByteCounts
    ];
    let mut b = b"II*\0".to_vec();
    b.extend(8u32.to_le_bytes());
    b.extend((entries.len() as u16).to_le_bytes());
    for (tag, ty, value) in entries {
        b.extend(tag.to_le_bytes());
        b.extend(ty.to_le_bytes());
        b.extend(1u32.to_le_bytes());
        if ty == 3 {
            b.extend((value as u16).to_le_bytes());
            b.extend([0, 0]);
        } else {
            b.extend(value.to_le_bytes());
        }
    }
    b.extend(0u32.to_le_bytes()); // no next directory
    assert_eq!(b.len(), 110);
    b.extend([0u8; 14]);
    b
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &byte in bytes {
        crc ^= u32::from(byte);
        for _ in 0..8 {
            crc = if crc & 1 == 1 { (crc >> 1) ^ 0xEDB8_8320 } else { crc >> 1 };
        }
    }
    !crc
}

fn png_chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend((data.len() as u32).to_be_bytes());
    let mut body = kind.to_vec();
    body.extend(data);
    out.extend(&body);
    out.extend(crc32(&body).to_be_bytes());
}

/// A valid PNG header for a `width` x `height` 8-bit grey image, followed by a tiny
/// IDAT (a zlib stream of one stored block of zero bytes, far short of the image) and
/// IEND: the decoder learns the size from the header before it reads any data.
fn png_claiming(width: u32, height: u32) -> Vec<u8> {
    let mut b = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = width.to_be_bytes().to_vec();
    ihdr.extend(height.to_be_bytes());
    ihdr.extend([8, 0, 0, 0, 0]); // 8-bit, grey, deflate, adaptive filter, no interlace
    png_chunk(&mut b, b"IHDR", &ihdr);
    // zlib header, one final stored block of 16 zero bytes, Adler-32 of 16 zeros.
    let mut idat = vec![0x78, 0x01, 0x01, 16, 0, !16u8, 0xff];
    idat.extend([0u8; 16]);
    idat.extend(0x0010_0001u32.to_be_bytes());
    png_chunk(&mut b, b"IDAT", &idat);
    png_chunk(&mut b, b"IEND", &[]);
    b
}

/// A version-1 NPY header for `descr` and `shape_text` (the tuple's inside), padded to
/// a multiple of 64 bytes, followed by `data`.
fn npy(descr: &str, shape_text: &str, data: &[u8]) -> Vec<u8> {
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': ({shape_text}), }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut b = b"\x93NUMPY\x01\x00".to_vec();
    b.extend((header.len() as u16).to_le_bytes());
    b.extend(header.as_bytes());
    b.extend(data);
    b
}

fn two_page_tiff() -> Vec<u8> {
    let mut buf = std::io::Cursor::new(Vec::new());
    let mut enc = TiffEncoder::new(&mut buf).unwrap();
    enc.write_image::<colortype::Gray16>(3, 2, &[1, 2, 3, 4, 5, 6]).unwrap();
    enc.write_image::<colortype::Gray16>(3, 2, &[7, 8, 9, 10, 11, 12]).unwrap();
    buf.into_inner()
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let p = dir.join(name);
    fs::write(&p, bytes).unwrap();
    p
}

#[test]
fn a_124_byte_tiff_announcing_200000_by_200000_is_refused_with_the_figure() {
    let bytes = tiff_claiming(200_000, 200_000);
    assert_eq!(bytes.len(), 124);
    let e = decode_image_bytes(Path::new("huge.tiff"), &bytes, &budget(64.0)).unwrap_err();
    assert!(matches!(e, IoError::TooLarge { .. }), "{e:?}");
    let m = e.to_string();
    assert!(m.starts_with("huge.tiff: page 1 (200000 x 200000 pixels grey, 8-bit samples"), "{m}");
    assert!(m.contains("186.3 GiB"), "{m}");
    // As a stack, the same figure counts the stacked copy too.
    let m = decode_stack_bytes(Path::new("huge.tiff"), &bytes, &budget(64.0)).unwrap_err().to_string();
    assert!(m.contains("a stack of 1 pages") && m.contains("335.3 GiB"), "{m}");

    // From disk, under the process's own budget: refused, the file untouched.
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "huge.tiff", &bytes);
    for e in [read_image(&p).unwrap_err(), read_stack(&p).unwrap_err()] {
        assert!(matches!(e, IoError::TooLarge { .. }), "{e:?}");
        assert!(e.to_string().starts_with(&p.display().to_string()), "{e}");
    }
    assert_eq!(fs::read(&p).unwrap(), bytes);
}

#[test]
fn a_tiff_within_the_budget_but_over_what_its_bytes_can_hold_is_refused_by_the_decoder_limits() {
    // 2000 x 2000 8-bit (4 MB) is within a 1 GB budget, but 14 bytes of uncompressed strip
    // cannot hold it: a clear error, not a 4 MB buffer of zeros.
    let e = decode_image_bytes(Path::new("short.tif"), &tiff_claiming(2000, 2000), &budget(1.0)).unwrap_err();
    assert!(e.to_string().starts_with("short.tif: "), "{e}");
    assert!(!matches!(e, IoError::TooLarge { .. }), "{e:?}");
}

#[test]
fn a_small_png_announcing_20000_by_20000_is_refused_before_decoding() {
    let bytes = png_claiming(20_000, 20_000);
    assert!(bytes.len() < 100, "{}", bytes.len());
    // 400 MB of samples and 1.6 GB as f32: over a 1 GB budget, refused from the header.
    let e = decode_image_bytes(Path::new("big.png"), &bytes, &budget(1.0)).unwrap_err();
    assert!(matches!(e, IoError::TooLarge { .. }), "{e:?}");
    let m = e.to_string();
    assert!(m.starts_with("big.png: 20000 x 20000 pixels L8") && m.contains("1.9 GiB"), "{m}");
    // Within the budget, the missing data is an error naming the file, not an image of zeros.
    let e = decode_image_bytes(Path::new("big.png"), &png_claiming(300, 200), &budget(1.0)).unwrap_err();
    assert!(e.to_string().starts_with("big.png: ") && !matches!(e, IoError::TooLarge { .. }), "{e:?}");
}

#[test]
fn an_npy_header_announcing_a_huge_shape_is_refused_before_allocating() {
    let b = budget(1000.0);
    for shape in ["100000, 100000, 100000", "18446744073709551615, 18446744073709551615", "4000000000,"] {
        let bytes = npy("<f4", shape, &[0u8; 64]);
        let e = decode_npy(Path::new("truth.npy"), &bytes, &b).unwrap_err();
        assert!(matches!(e, IoError::Truncated { .. }), "{shape}: {e:?}");
        let m = e.to_string();
        assert!(m.starts_with("truth.npy: truncated NPY") && m.contains("the file holds 64 bytes of data"), "{m}");
    }
    // The data present but over the budget: the figure.
    let bytes = npy("<f4", "10, 10", &[0u8; 400]);
    let e = decode_npy(Path::new("truth.npy"), &bytes, &ByteBudget { limit_bytes: 500, source: LimitSource::Environment }).unwrap_err();
    assert!(matches!(e, IoError::TooLarge { .. }), "{e:?}");
    assert!(e.to_string().contains("shape [10, 10] (<f4"), "{e}");
    // And within it, read as before.
    let a = decode_npy(Path::new("truth.npy"), &bytes, &b).unwrap();
    assert_eq!(a.shape(), &[10, 10]);
    // A bad shape entry and an unsupported dtype are named.
    let e = decode_npy(Path::new("t.npy"), &npy("<f4", "3, -1", &[]), &b).unwrap_err().to_string();
    assert!(e.contains("t.npy") && e.contains("\"-1\""), "{e}");
    let e = decode_npy(Path::new("t.npy"), &npy("<i8", "2,", &[0; 16]), &b).unwrap_err().to_string();
    assert!(e.contains("t.npy") && e.contains("dtype <i8"), "{e}");

    // From disk, as --raw or --truth would read it: refused, the file untouched.
    let dir = tempfile::tempdir().unwrap();
    let bytes = npy("<f4", "100000, 100000, 100000", &[]);
    let p = write(dir.path(), "truth.npy", &bytes);
    assert!(matches!(read_stack(&p), Err(IoError::Truncated { .. })));
    assert!(matches!(read_image(&p), Err(IoError::Truncated { .. })));
    assert_eq!(fs::read(&p).unwrap(), bytes);
}

#[test]
fn a_multi_page_raw_read_as_one_image_is_refused_and_a_page_can_be_chosen() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "raw.tiff", &two_page_tiff());
    let e = read_image(&p).unwrap_err();
    assert!(matches!(e, IoError::PageRequired { pages: 2, .. }), "{e:?}");
    let m = e.to_string();
    assert!(m.starts_with(&p.display().to_string()) && m.contains("holds 2 pages") && !m.contains("--page"), "{m}");
    // Pages are counted from 1.
    assert_eq!(read_image_page(&p, Some(1)).unwrap().iter().copied().collect::<Vec<_>>(), [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    assert_eq!(read_image_page(&p, Some(2)).unwrap().iter().copied().collect::<Vec<_>>(), [7.0, 8.0, 9.0, 10.0, 11.0, 12.0]);
    let m = read_image_page(&p, Some(3)).unwrap_err().to_string();
    assert!(m.contains("page 3 requested") && m.contains("holds 2 page"), "{m}");
    let m = read_image_page(&p, Some(0)).unwrap_err().to_string();
    assert!(m.contains("counted from 1"), "{m}");
    // A single-image file takes page 1 (or none), nothing else.
    let one = write(dir.path(), "one.npy", &npy("|u1", "2, 2", &[1, 2, 3, 4]));
    assert_eq!(read_image_page(&one, Some(1)).unwrap(), read_image(&one).unwrap());
    assert!(read_image_page(&one, Some(2)).unwrap_err().to_string().contains("page 2 requested"));
    // The stack reader still takes every page.
    assert_eq!(read_stack(&p).unwrap().dim(), (2, 2, 3, 1));
}

#[test]
fn a_tiff_whose_directories_loop_is_refused() {
    let mut bytes = tiff_claiming(2, 7);
    // The next-directory link points back at the first directory.
    bytes[106..110].copy_from_slice(&8u32.to_le_bytes());
    let e = decode_stack_bytes(Path::new("loop.tif"), &bytes, &budget(1.0)).unwrap_err().to_string();
    assert!(e.contains("loop.tif") && e.contains("loops back"), "{e}");
}

/// The command line: `reconstruct --raw` of each hostile file exits non-zero with the
/// message, writes no output, and leaves the input byte-identical.
#[test]
fn reconstruct_refuses_hostile_raws_and_leaves_them_untouched() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, Vec<u8>, &str); 4] = [
        ("huge.tiff", tiff_claiming(200_000, 200_000), "200000 x 200000 pixels"),
        ("big.png", png_claiming(20_000, 20_000), "20000 x 20000 pixels"),
        ("raw.npy", npy("<f4", "100000, 100000", &[]), "truncated NPY"),
        ("pages.tiff", two_page_tiff(), "--page N"),
    ];
    for (name, bytes, expected) in cases {
        let raw = write(dir.path(), name, &bytes);
        let out = dir.path().join(format!("out_{name}"));
        let o = Command::new(env!("CARGO_BIN_EXE_rollcam"))
            .args(["reconstruct", "--raw"])
            .arg(&raw)
            .arg("--out")
            .arg(&out)
            .env("ROLLCAM_MEMORY_LIMIT_GB", "1")
            .env("ROLLCAM_CACHE_DIR", dir.path().join("cache"))
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{name}: {stderr}");
        assert!(stderr.contains(name) && stderr.contains(expected), "{name}: {stderr}");
        assert!(!stderr.contains("memory allocation"), "{name}: {stderr}");
        assert_eq!(fs::read(&raw).unwrap(), bytes, "{name} changed");
        assert!(!out.exists(), "{name}: output written");
    }
}

#[test]
fn a_strip_whose_end_overflows_is_refused_not_a_panic() {
    // Found by `scripts/fuzz-smoke.sh` (tiff): a strip offset plus its byte count past
    // u64 overflowed while the error message was written.
    let name = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus/tiff/seed-regression-strip-end-overflow");
    let bytes = std::fs::read(&name).unwrap();
    let e = decode_image_bytes(Path::new("overflow.tiff"), &bytes, &ByteBudget::system()).unwrap_err();
    assert!(e.to_string().starts_with("overflow.tiff"), "{e}");
}

#[test]
fn a_one_bit_tiff_is_refused_by_its_depth_not_called_truncated() {
    let mut bytes = tiff_claiming(8, 14);
    // BitsPerSample is the third directory entry; its value sits 8 bytes into the entry.
    let at = 10 + 2 * 12 + 8;
    assert_eq!(u16::from_le_bytes([bytes[at], bytes[at + 1]]), 8);
    bytes[at..at + 2].copy_from_slice(&1u16.to_le_bytes());
    let e = decode_image_bytes(Path::new("bilevel.tif"), &bytes, &budget(1.0)).unwrap_err().to_string();
    assert!(e.contains("bilevel.tif") && e.contains("1-bit samples") && e.contains("8/16-bit") && !e.contains("truncated"), "{e}");
}

#[test]
fn a_folder_given_as_an_image_is_called_a_folder() {
    let dir = tempfile::tempdir().unwrap();
    let e = read_image(dir.path()).unwrap_err().to_string();
    assert!(e.contains("expected an image file (.tif") && e.contains("found a folder"), "{e}");
}

/// A 333-byte JPEG whose header declares 65500 x 65500 pixels was decoded at full size
/// (6.4 GB resident and growing at 20 s, as a raw or a PSF): the decoder fills the
/// missing data with zeros. Every 8 x 8 block takes at least one bit, so the size is
/// refused from the file's length before anything is decoded, under any budget.
#[test]
fn a_333_byte_jpeg_announcing_65500_by_65500_is_refused_before_decoding() {
    use crate::support::hostile::jpeg_claiming;
    let bytes = jpeg_claiming(65_500, 65_500, 193);
    assert_eq!(bytes.len(), 333);
    let t = std::time::Instant::now();
    let e = decode_image_bytes(Path::new("bomb.jpg"), &bytes, &budget(1e6)).unwrap_err();
    assert!(t.elapsed().as_secs_f64() < 5.0, "{:?}", t.elapsed());
    let m = e.to_string();
    assert!(m.starts_with("bomb.jpg: ") && m.contains("65500 x 65500 pixels") && m.contains("333 bytes can hold"), "{m}");
    // A complete image of the same construction (two bits per block) still reads.
    let whole = jpeg_claiming(64, 32, 8 * 4 / 4);
    let img = decode_image_bytes(Path::new("flat.jpg"), &whole, &budget(1.0)).unwrap();
    assert_eq!(img.dim(), (32, 64, 1));
    assert!(img.iter().all(|&v| v == 128.0), "a DC of 0 is mid-grey");

    // On the command line, as a raw and as a PSF: refused naming the file, quickly.
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "bomb.jpg", &bytes);
    let run = |args: &[&str]| {
        let t = std::time::Instant::now();
        let o = Command::new(env!("CARGO_BIN_EXE_rollcam")).args(args).env("ROLLCAM_CACHE_DIR", dir.path().join("cache")).output().unwrap();
        (o, t.elapsed())
    };
    let (never, pp) = (dir.path().join("never"), p.to_str().unwrap());
    for args in [vec!["reconstruct", "--raw", pp, "--out", never.to_str().unwrap()], vec!["simulate", "--psf", pp, "--out", never.to_str().unwrap()]] {
        let (o, took) = run(&args);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(stderr.contains("bomb.jpg") && stderr.contains("65500 x 65500"), "{args:?}: {stderr}");
        assert!(took.as_secs_f64() < 20.0, "{args:?}: {took:?}");
        assert!(!never.exists());
    }
    assert_eq!(fs::read(&p).unwrap(), bytes);
}

/// A structured-dtype `.npy` (NumPy's record arrays) was "the header has no 'descr'
/// entry": it has one, a list of fields.
#[test]
fn a_structured_dtype_npy_is_called_structured() {
    let mut header = "{'descr': [('x', '<f4'), ('y', '<f4')], 'fortran_order': False, 'shape': (2, 2), }".to_string();
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut b = b"\x93NUMPY\x01\x00".to_vec();
    b.extend((header.len() as u16).to_le_bytes());
    b.extend(header.as_bytes());
    b.extend([0u8; 32]);
    let e = decode_npy(Path::new("records.npy"), &b, &budget(1.0)).unwrap_err().to_string();
    assert!(e.starts_with("records.npy") && e.contains("a structured dtype") && e.contains("('x', '<f4')"), "{e}");
    assert!(!e.contains("no 'descr'"), "{e}");
}
