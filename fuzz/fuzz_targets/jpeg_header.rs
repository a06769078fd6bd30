//! The JPEG frame header's declared size against the data that follows it: the first
//! four bytes are the width and height a baseline grey header declares, the rest the
//! entropy-coded scan (one-bit DC and AC codes, so every byte can carry four blocks).
//! A decoded image must be the declared size and no more blocks than the file's bits;
//! a header declaring more than its bytes can hold is refused before decoding (the
//! `-rss_limit_mb` of the run catches a decoder that allocates the declared size).
#![no_main]

use libfuzzer_sys::fuzz_target;
use rollcam::io::budget::LimitSource;
use rollcam::io::{decode_image_bytes, ByteBudget};
use std::path::Path;

const BUDGET: ByteBudget = ByteBudget { limit_bytes: 256 << 20, source: LimitSource::Environment };

fn segment(out: &mut Vec<u8>, marker: u8, body: &[u8]) {
    out.extend_from_slice(&[0xff, marker]);
    out.extend_from_slice(&((body.len() + 2) as u16).to_be_bytes());
    out.extend_from_slice(body);
}

fn jpeg(width: u16, height: u16, scan: &[u8]) -> Vec<u8> {
    let mut out = vec![0xff, 0xd8];
    let mut dqt = vec![0u8];
    dqt.extend([1u8; 64]);
    segment(&mut out, 0xdb, &dqt);
    let mut sof = vec![8];
    sof.extend_from_slice(&height.to_be_bytes());
    sof.extend_from_slice(&width.to_be_bytes());
    sof.extend_from_slice(&[1, 1, 0x11, 0]);
    segment(&mut out, 0xc0, &sof);
    let mut dc = vec![0x00, 1];
    dc.extend([0u8; 15]);
    dc.push(0);
    segment(&mut out, 0xc4, &dc);
    let mut ac = vec![0x10, 1];
    ac.extend([0u8; 15]);
    ac.push(0x00);
    segment(&mut out, 0xc4, &ac);
    segment(&mut out, 0xda, &[1, 1, 0x00, 0, 63, 0]);
    out.extend_from_slice(scan);
    out.extend_from_slice(&[0xff, 0xd9]);
    out
}

fuzz_target!(|data: &[u8]| {
    if data.len() < 4 {
        return;
    }
    let width = u16::from_be_bytes([data[0], data[1]]);
    let height = u16::from_be_bytes([data[2], data[3]]);
    let bytes = jpeg(width, height, &data[4..]);
    if let Ok(image) = decode_image_bytes(Path::new("fuzz.jpg"), &bytes, &BUDGET) {
        let (rows, cols, ch) = image.dim();
        assert_eq!((rows, cols, ch), (usize::from(height), usize::from(width), 1));
        let blocks = rows.div_ceil(8) * cols.div_ceil(8);
        assert!(blocks <= 8 * bytes.len(), "{cols} x {rows} decoded from {} bytes", bytes.len());
    }
});
