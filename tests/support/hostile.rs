//! Hostile files built by hand for the hostile-input tests of several binaries.
#![allow(dead_code)]

/// A baseline 8-bit grey JPEG whose frame header declares `width` x `height` pixels,
/// followed by `scan_bytes` bytes of entropy-coded data (all zero bits: a DC difference
/// of 0 and an end of block, two bits per 8 x 8 block) and the end marker. With few
/// scan bytes and a large size it is the header bomb of a few hundred bytes; with
/// `blocks / 4` scan bytes it is a complete, flat mid-grey image.
pub fn jpeg_claiming(width: u16, height: u16, scan_bytes: usize) -> Vec<u8> {
    let mut out = vec![0xff, 0xd8];
    let segment = |out: &mut Vec<u8>, marker: u8, body: &[u8]| {
        out.extend_from_slice(&[0xff, marker]);
        out.extend_from_slice(&((body.len() + 2) as u16).to_be_bytes());
        out.extend_from_slice(body);
    };
    let mut dqt = vec![0u8];
    dqt.extend([1u8; 64]);
    segment(&mut out, 0xdb, &dqt);
    let mut sof = vec![8];
    sof.extend_from_slice(&height.to_be_bytes());
    sof.extend_from_slice(&width.to_be_bytes());
    sof.extend_from_slice(&[1, 1, 0x11, 0]);
    segment(&mut out, 0xc0, &sof);
    // DC: one code of one bit ("0") for category 0; AC: one code of one bit for EOB.
    let mut dc = vec![0x00, 1];
    dc.extend([0u8; 15]);
    dc.push(0);
    segment(&mut out, 0xc4, &dc);
    let mut ac = vec![0x10, 1];
    ac.extend([0u8; 15]);
    ac.push(0x00);
    segment(&mut out, 0xc4, &ac);
    segment(&mut out, 0xda, &[1, 1, 0x00, 0, 63, 0]);
    out.resize(out.len() + scan_bytes, 0);
    out.extend_from_slice(&[0xff, 0xd9]);
    out
}
