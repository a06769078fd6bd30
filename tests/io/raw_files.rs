//! Bayer raws (DNG and CFA TIFF) read as colour on the half grid: every pattern to the
//! right planes, exactly; the black and white levels; an independently written DNG
//! (big-endian, preview in IFD0, raw in a sub-IFD, 12-bit packed tiles, ActiveArea);
//! compressed, malformed and misnamed raws refused naming the file and what was expected.

use std::fs;
use std::path::{Path, PathBuf};

use ndarray::{Array2, Array3};
use rollcam::io::formats::raw::{encode_raw, RawSpec};
use rollcam::io::{decode_image_bytes, raw_info, read_image, read_stack, sample_black_level, sample_full_scale, Bayer, ByteBudget, IoError};

/// A mosaic whose every sample says where it is: 100 * row + col (+ 7).
fn mosaic(rows: usize, cols: usize) -> Array2<u16> {
    Array2::from_shape_fn((rows, cols), |(r, c)| (100 * r + c + 7) as u16)
}

/// The half grid a pattern makes of `m`, from the pattern's name: R, mean of the two
/// greens, B of each 2x2 cell.
fn expected_planes(m: &Array2<u16>, pattern: &str) -> Array3<f32> {
    let names: Vec<char> = pattern.chars().collect();
    let (rows, cols) = (m.nrows() / 2, m.ncols() / 2);
    Array3::from_shape_fn((rows, cols, 3), |(r, c, ch)| {
        let want = ['R', 'G', 'B'][ch];
        let picked: Vec<f32> = (0..4).filter(|&k| names[k] == want).map(|k| f32::from(m[[2 * r + k / 2, 2 * c + k % 2]])).collect();
        picked.iter().sum::<f32>() / picked.len() as f32
    })
}

fn spec(m: &Array2<u16>, pattern: Bayer, bits: u32, dng: bool) -> RawSpec<'_> {
    RawSpec { mosaic: m.view(), pattern, bits, dng, black_level: None, white_level: None, compression: 1 }
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    fs::write(&p, bytes).unwrap();
    p
}

#[test]
fn every_bayer_pattern_reads_to_its_planes_exactly_from_dng_and_cfa_tiff() {
    let dir = tempfile::tempdir().unwrap();
    // Odd sizes: the last row and column are dropped.
    let m = mosaic(6, 9);
    for pattern in Bayer::ALL {
        let want = expected_planes(&m, pattern.name());
        assert_eq!(want.dim(), (3, 4, 3));
        for bits in [16, 12, 10, 8] {
            let m = if bits == 8 { m.mapv(|v| v % 256) } else { m.clone() };
            let want = if bits == 8 { expected_planes(&m, pattern.name()) } else { want.clone() };
            for (dng, ext) in [(true, "dng"), (false, "tif")] {
                let p = write(dir.path(), &format!("{}-{bits}.{ext}", pattern.name()), &encode_raw(&spec(&m, pattern, bits, dng)));
                let got = read_image(&p).unwrap();
                assert_eq!(got, want, "{} {bits}-bit .{ext}", pattern.name());
                assert_eq!(read_stack(&p).unwrap().index_axis(ndarray::Axis(0), 0), want, "read as a one-frame video");
                let info = raw_info(&p).unwrap();
                assert_eq!((info.pattern, info.sensor_rows, info.sensor_cols, info.bits), (pattern, 6, 9, bits));
                assert_eq!(info.half_grid(), (3, 4));
            }
        }
    }
    // The greens differ: G is their mean (not one of them), R and B are single samples.
    let got = read_image(write(dir.path(), "g.dng", &encode_raw(&spec(&m, Bayer::Rggb, 16, true)))).unwrap();
    assert_eq!((got[[0, 0, 0]], got[[0, 0, 1]], got[[0, 0, 2]]), (7.0, (8.0 + 107.0) / 2.0, 108.0));
}

#[test]
fn black_and_white_levels_come_from_the_raw_and_the_full_scale_defaults_to_its_bits() {
    let dir = tempfile::tempdir().unwrap();
    let m = mosaic(4, 4);
    let with = RawSpec { black_level: Some(256), white_level: Some(4000), ..spec(&m, Bayer::Bggr, 12, true) };
    let p = write(dir.path(), "levels.dng", &encode_raw(&with));
    assert_eq!(sample_black_level(&p), Some(256.0));
    assert_eq!(sample_full_scale(&p), Some(4000.0));
    let p = write(dir.path(), "bare.tif", &encode_raw(&spec(&m, Bayer::Bggr, 12, false)));
    assert_eq!(sample_black_level(&p), None);
    assert_eq!(sample_full_scale(&p), Some(4095.0), "2^12 - 1 without a WhiteLevel");
    let p = write(dir.path(), "ten.dng", &encode_raw(&spec(&m, Bayer::Bggr, 10, true)));
    assert_eq!(sample_full_scale(&p), Some(1023.0));
    // A grey TIFF is no raw: its full scale is its bits' as before.
    let grey = dir.path().join("grey.tif");
    rollcam::io::write_tiff_u16(&grey, Array3::<f32>::zeros((2, 2, 1)).view()).unwrap();
    assert_eq!((raw_info(&grey), sample_black_level(&grey), sample_full_scale(&grey)), (None, None, Some(65535.0)));
}

/// `fixtures/raw/gbrg-12bit-subifd.dng`, written by `scripts/make-raw-fixture.py`
/// (standard-library Python, not rollcam's writer): sensor value(r, c) =
/// (37 r + 11 c + 100) % 4096, ActiveArea rows 1..5 and columns 2..8, GBRG from its
/// top-left, BlackLevel 64 64 66 66, WhiteLevel 4000.
#[test]
fn an_independently_written_big_endian_dng_with_a_sub_ifd_reads_exactly() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/raw/gbrg-12bit-subifd.dng");
    let active = Array2::from_shape_fn((4, 6), |(r, c)| ((37 * (r + 1) + 11 * (c + 2) + 100) % 4096) as u16);
    let got = read_image(&p).unwrap();
    assert_eq!(got, expected_planes(&active, "GBRG"));
    let info = raw_info(&p).unwrap();
    assert_eq!((info.pattern, info.sensor_rows, info.sensor_cols, info.bits, info.black_level, info.white_level), (Bayer::Gbrg, 4, 6, 12, Some(65.0), 4000.0));
    // The same bytes under a .tif name are refused as a DNG, not read as a TIFF.
    let dir = tempfile::tempdir().unwrap();
    let e = read_image(write(dir.path(), "raw.tif", &fs::read(&p).unwrap())).unwrap_err();
    assert!(matches!(&e, IoError::WrongMagic { named: "TIFF", found: "DNG", .. }), "{e:?}");
}

/// Sets the 4 value bytes of `tag`'s entry in the first directory of a little-endian
/// file `encode_raw` wrote.
fn patch_entry(bytes: &mut [u8], tag: u16, value: [u8; 4]) {
    let n = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let e = (0..n).map(|k| 10 + 12 * k).find(|&e| u16::from_le_bytes([bytes[e], bytes[e + 1]]) == tag).expect("tag written");
    bytes[e + 8..e + 12].copy_from_slice(&value);
}

#[test]
fn compressed_malformed_and_unsupported_raws_are_refused_naming_the_file_and_what_was_expected() {
    let dir = tempfile::tempdir().unwrap();
    let m = mosaic(4, 6);
    let refused = |name: &str, bytes: &[u8], wanted: &[&str]| {
        let p = write(dir.path(), name, bytes);
        let e = read_image(&p).unwrap_err().to_string();
        assert!(e.starts_with(&p.display().to_string()), "{e}");
        for w in wanted {
            assert!(e.contains(w), "{name}: {e} lacks {w}");
        }
        e
    };
    let lj92 = encode_raw(&RawSpec { compression: 7, ..spec(&m, Bayer::Rggb, 16, true) });
    refused("lj92.dng", &lj92, &["lossless JPEG (Compression = 7)", "expected an uncompressed raw"]);
    let deflate = encode_raw(&RawSpec { compression: 8, ..spec(&m, Bayer::Rggb, 16, false) });
    refused("deflate.tif", &deflate, &["Deflate (Compression = 8)"]);

    let good = encode_raw(&spec(&m, Bayer::Rggb, 16, true));
    refused("cut.dng", &good[..good.len() - 5], &["truncated DNG", "strip 0 of 1 needs 48 bytes"]);
    let mut xtrans = good.clone();
    patch_entry(&mut xtrans, 33421, [6, 0, 6, 0]);
    refused("xtrans.dng", &xtrans, &["expected a 2x2 Bayer CFA", "CFARepeatPatternDim [6 6]"]);
    let mut cygm = good.clone();
    patch_entry(&mut cygm, 33422, [0, 1, 3, 2]);
    refused("cygm.dng", &cygm, &["CFAPattern [0 1 3 2]"]);
    let mut linear = good.clone();
    patch_entry(&mut linear, 262, [0x4c, 0x88, 0, 0]); // 34892
    refused("linear.dng", &linear, &["expected a CFA (Bayer) raw", "linear (demosaicked)"]);
    let mut odd_bits = good.clone();
    patch_entry(&mut odd_bits, 258, [11, 0, 0, 0]);
    refused("bits.dng", &odd_bits, &["unsigned 8, 10, 12, 14 or 16-bit raw samples", "11-bit"]);
    let mut pointer = good.clone();
    patch_entry(&mut pointer, 33422, [0, 1, 1, 2]);
    patch_entry(&mut pointer, 273, [0xff, 0xff, 0xff, 0x0f]);
    refused("far.dng", &pointer, &["truncated DNG", "strip 0 of 1"]);
    // A raw over the byte budget is refused before its samples are allocated.
    let small = ByteBudget { limit_bytes: 100, source: rollcam::io::budget::LimitSource::Environment };
    let e = decode_image_bytes(Path::new("big.dng"), &good, &small).unwrap_err().to_string();
    assert!(e.starts_with("big.dng: ") && e.contains("4 x 6 16-bit Bayer raw"), "{e}");
}
