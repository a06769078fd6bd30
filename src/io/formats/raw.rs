//! Bayer (CFA) raws in a TIFF container, shared by two formats: DNG (`dng.rs`, a TIFF
//! with a DNGVersion tag, the raw in IFD0 or a sub-IFD) and the CFA TIFF (`tiff.rs`, a
//! plain TIFF whose first directory has PhotometricInterpretation 32803).
//!
//! A raw is read as colour on the **half grid**: each 2x2 Bayer cell becomes one pixel
//! of three channels, R, G (the mean of the cell's two greens) and B, so a sensor of
//! `rows x cols` reads as `rows/2 x cols/2` (an odd last row or column is dropped).
//! Nothing is interpolated (a demosaic would correlate neighbouring pixels' noise,
//! which the solver's data term takes as independent) and every half-grid row is two
//! sensor rows, so the rolling shutter's rows stay rows (a capture description of such
//! a raw describes the half grid: docs/capture-toml.md). Values are the counts as
//! stored (the greens' mean may end in .5); the BlackLevel and WhiteLevel tags are read
//! as the file's dark level and full scale ([`RawInfo`]).
//!
//! The container is read by this file, not by the `tiff` crate, whose decoder refuses
//! a directory with PhotometricInterpretation 32803 and packed 10/12/14-bit samples.
//! Read: classic TIFF of either byte order, uncompressed samples of 8, 10, 12, 14 or 16
//! bits (10/12/14 bit-packed, most significant bit first, rows starting on a byte), in
//! strips or tiles, a 2x2 CFARepeatPatternDim whose CFAPattern is RGGB, BGGR, GRBG or
//! GBRG, the DNG ActiveArea (cropped to; the pattern is its top-left's). Refused by
//! name: compressed raws (lossless JPEG, Deflate...), other CFA layouts (X-Trans,
//! CYGM), linear (demosaicked) DNGs, BigTIFF raws.

use std::path::Path;

use ndarray::{Array3, ArrayView2};

use crate::io::budget::ByteBudget;
use crate::io::error::IoError;

const NEW_SUBFILE_TYPE: u16 = 254;
const IMAGE_WIDTH: u16 = 256;
const IMAGE_LENGTH: u16 = 257;
const BITS_PER_SAMPLE: u16 = 258;
const COMPRESSION: u16 = 259;
const PHOTOMETRIC: u16 = 262;
const STRIP_OFFSETS: u16 = 273;
const SAMPLES_PER_PIXEL: u16 = 277;
const ROWS_PER_STRIP: u16 = 278;
const STRIP_BYTE_COUNTS: u16 = 279;
const TILE_WIDTH: u16 = 322;
const TILE_LENGTH: u16 = 323;
const TILE_OFFSETS: u16 = 324;
const TILE_BYTE_COUNTS: u16 = 325;
const SUB_IFDS: u16 = 330;
const SAMPLE_FORMAT: u16 = 339;
const CFA_REPEAT_PATTERN_DIM: u16 = 33421;
const CFA_PATTERN: u16 = 33422;
const DNG_VERSION: u16 = 50706;
const BLACK_LEVEL: u16 = 50714;
const WHITE_LEVEL: u16 = 50717;
const ACTIVE_AREA: u16 = 50829;

/// PhotometricInterpretation of a colour filter array raw.
pub const PHOTOMETRIC_CFA: u16 = 32803;
/// PhotometricInterpretation of a DNG's linear (already demosaicked) raw.
const PHOTOMETRIC_LINEAR_RAW: u16 = 34892;
/// Most directories looked at for the raw (IFD chain and sub-IFDs together).
const MAX_DIRECTORIES: usize = 64;

/// The four 2x2 Bayer layouts, named by the colours of the first row, then the second.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bayer {
    Rggb,
    Bggr,
    Grbg,
    Gbrg,
}

impl Bayer {
    pub const ALL: [Bayer; 4] = [Bayer::Rggb, Bayer::Bggr, Bayer::Grbg, Bayer::Gbrg];

    /// Its name: `RGGB`.
    pub fn name(self) -> &'static str {
        match self {
            Bayer::Rggb => "RGGB",
            Bayer::Bggr => "BGGR",
            Bayer::Grbg => "GRBG",
            Bayer::Gbrg => "GBRG",
        }
    }

    /// The CFAPattern values (0 red, 1 green, 2 blue) of cells (0,0), (0,1), (1,0), (1,1).
    pub fn cells(self) -> [u8; 4] {
        match self {
            Bayer::Rggb => [0, 1, 1, 2],
            Bayer::Bggr => [2, 1, 1, 0],
            Bayer::Grbg => [1, 0, 2, 1],
            Bayer::Gbrg => [1, 2, 0, 1],
        }
    }

    fn from_cells(cells: &[f64]) -> Option<Bayer> {
        Bayer::ALL.into_iter().find(|b| cells.len() == 4 && b.cells().iter().zip(cells).all(|(&a, &v)| f64::from(a) == v))
    }
}

/// What a raw's directory says beyond its samples.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RawInfo {
    pub pattern: Bayer,
    /// The sensor's rows and columns read (the ActiveArea's when there is one).
    pub sensor_rows: usize,
    pub sensor_cols: usize,
    pub bits: u32,
    /// BlackLevel (counts; the mean of its values when it gives one per cell), `None`
    /// when the file has none.
    pub black_level: Option<f64>,
    /// WhiteLevel (counts), else the largest value of the samples' bits (2^bits - 1).
    pub white_level: f64,
}

impl RawInfo {
    /// The half grid the raw reads as: (rows, cols).
    pub fn half_grid(&self) -> (usize, usize) {
        (self.sensor_rows / 2, self.sensor_cols / 2)
    }
}

/// The file being read, for messages: its path and format name.
#[derive(Clone, Copy)]
struct Ctx<'p> {
    path: &'p Path,
    format: &'static str,
}

impl Ctx<'_> {
    fn truncated(&self, detail: String) -> IoError {
        IoError::Truncated { path: self.path.to_path_buf(), format: self.format, detail }
    }
    fn malformed(&self, detail: String) -> IoError {
        IoError::malformed(self.path, self.format, detail)
    }
    fn unexpected(&self, expected: &str, found: String) -> IoError {
        IoError::unexpected(self.path, expected, found)
    }
}

/// A classic TIFF in memory.
struct Container<'a> {
    b: &'a [u8],
    le: bool,
}

/// One directory entry: its type, count and where its values lie.
#[derive(Clone, Copy)]
struct Entry {
    tag: u16,
    typ: u16,
    count: u64,
    at: u64,
}

/// One image directory.
struct Ifd {
    offset: u64,
    entries: Vec<Entry>,
    next: u64,
}

fn type_size(typ: u16) -> Option<u64> {
    match typ {
        1 | 2 | 6 | 7 => Some(1),
        3 | 8 => Some(2),
        4 | 9 | 11 | 13 => Some(4),
        5 | 10 | 12 => Some(8),
        _ => None,
    }
}

impl<'a> Container<'a> {
    /// A classic TIFF's byte order and first directory's offset; `None` for anything
    /// else (BigTIFF included).
    fn open(b: &'a [u8]) -> Option<(Self, u64)> {
        let le = match b.get(0..2)? {
            b"II" => true,
            b"MM" => false,
            _ => return None,
        };
        let c = Container { b, le };
        (c.u16_at(2)? == 42).then_some(())?;
        let first = c.u32_at(4)?;
        Some((c, u64::from(first)))
    }

    fn bytes_at(&self, o: u64, n: usize) -> Option<&'a [u8]> {
        let o = usize::try_from(o).ok()?;
        self.b.get(o..o.checked_add(n)?)
    }
    fn u16_at(&self, o: u64) -> Option<u16> {
        let b: [u8; 2] = self.bytes_at(o, 2)?.try_into().ok()?;
        Some(if self.le { u16::from_le_bytes(b) } else { u16::from_be_bytes(b) })
    }
    fn u32_at(&self, o: u64) -> Option<u32> {
        let b: [u8; 4] = self.bytes_at(o, 4)?.try_into().ok()?;
        Some(if self.le { u32::from_le_bytes(b) } else { u32::from_be_bytes(b) })
    }

    /// The directory at `offset`, every entry's values inside the file.
    fn ifd(&self, offset: u64) -> Result<Ifd, String> {
        let len = self.b.len();
        let n = self.u16_at(offset).ok_or_else(|| format!("an image directory at byte {offset} lies past the end of the file ({len} bytes)"))?;
        let mut entries = Vec::with_capacity(usize::from(n));
        for k in 0..u64::from(n) {
            let e = offset + 2 + 12 * k;
            let (Some(tag), Some(typ), Some(count)) = (self.u16_at(e), self.u16_at(e + 2), self.u32_at(e + 4)) else {
                return Err(format!("the image directory at byte {offset} ({n} entries) runs past the end of the file ({len} bytes)"));
            };
            let Some(size) = type_size(typ) else { continue };
            let bytes = size * u64::from(count);
            let at = if bytes <= 4 { e + 8 } else { u64::from(self.u32_at(e + 8).unwrap_or(u32::MAX)) };
            if at.saturating_add(bytes) > len as u64 {
                return Err(format!("tag {tag}'s {count} values at byte {at} run past the end of the file ({len} bytes)"));
            }
            entries.push(Entry { tag, typ, count: u64::from(count), at });
        }
        let next = self.u32_at(offset + 2 + 12 * u64::from(n)).map(u64::from).unwrap_or(0);
        Ok(Ifd { offset, entries, next })
    }

    /// The numeric values of `tag` in `ifd` (rationals divided out), `None` when absent.
    fn values(&self, ifd: &Ifd, tag: u16) -> Option<Vec<f64>> {
        let e = ifd.entries.iter().find(|e| e.tag == tag)?;
        let size = type_size(e.typ)?;
        let read = |k: u64| -> Option<f64> {
            let o = e.at + k * size;
            Some(match e.typ {
                1 | 7 => f64::from(self.bytes_at(o, 1)?[0]),
                6 => f64::from(self.bytes_at(o, 1)?[0] as i8),
                3 => f64::from(self.u16_at(o)?),
                8 => f64::from(self.u16_at(o)? as i16),
                4 | 13 => f64::from(self.u32_at(o)?),
                9 => f64::from(self.u32_at(o)? as i32),
                5 => f64::from(self.u32_at(o)?) / f64::from(self.u32_at(o + 4)?.max(1)),
                10 => f64::from(self.u32_at(o)? as i32) / f64::from((self.u32_at(o + 4)? as i32).max(1)),
                11 => f64::from(f32::from_bits(self.u32_at(o)?)),
                12 => {
                    let hi = u64::from(self.u32_at(if self.le { o + 4 } else { o })?);
                    let lo = u64::from(self.u32_at(if self.le { o } else { o + 4 })?);
                    f64::from_bits((hi << 32) | lo)
                }
                _ => return None,
            })
        };
        (0..e.count).map(read).collect()
    }

    fn value(&self, ifd: &Ifd, tag: u16) -> Option<f64> {
        self.values(ifd, tag).and_then(|v| v.first().copied())
    }
}

/// Whether `bytes` are a classic TIFF whose first directory has a DNGVersion tag.
pub(crate) fn is_dng(bytes: &[u8]) -> bool {
    let Some((c, first)) = Container::open(bytes) else { return false };
    c.ifd(first).is_ok_and(|ifd| ifd.entries.iter().any(|e| e.tag == DNG_VERSION))
}

/// Whether `bytes` are a classic TIFF whose first directory is a CFA raw
/// (PhotometricInterpretation 32803).
pub(crate) fn is_cfa_tiff(bytes: &[u8]) -> bool {
    let Some((c, first)) = Container::open(bytes) else { return false };
    c.ifd(first).is_ok_and(|ifd| c.value(&ifd, PHOTOMETRIC) == Some(f64::from(PHOTOMETRIC_CFA)))
}

/// Whether the file at `path` is a CFA TIFF ([`is_cfa_tiff`]), reading only its header
/// and first directory (not the whole file: a TIFF stack may be large).
pub(crate) fn is_cfa_tiff_file(path: &Path) -> bool {
    use std::io::{Read, Seek, SeekFrom};
    let read_header = || -> std::io::Result<bool> {
        let mut f = std::fs::File::open(path)?;
        let mut head = [0u8; 8];
        f.read_exact(&mut head)?;
        let Some((c, first)) = Container::open(&head) else { return Ok(false) };
        let le = c.le;
        f.seek(SeekFrom::Start(first))?;
        let mut n = [0u8; 2];
        f.read_exact(&mut n)?;
        let n = if le { u16::from_le_bytes(n) } else { u16::from_be_bytes(n) };
        let mut entries = vec![0u8; 12 * usize::from(n)];
        f.read_exact(&mut entries)?;
        // The directory alone, at offset 8 of a header of the file's byte order.
        let mut bytes = head[..4].to_vec();
        bytes.extend(if le { 8u32.to_le_bytes() } else { 8u32.to_be_bytes() });
        bytes.extend(if le { n.to_le_bytes() } else { n.to_be_bytes() });
        bytes.extend(entries);
        bytes.extend([0u8; 4]);
        let Some((c, _)) = Container::open(&bytes) else { return Ok(false) };
        let photometric = (0..u64::from(n)).map(|k| 10 + 12 * k).find(|&e| c.u16_at(e) == Some(PHOTOMETRIC)).and_then(|e| c.u16_at(e + 8));
        Ok(photometric == Some(PHOTOMETRIC_CFA))
    };
    read_header().unwrap_or(false)
}

/// The raw's directory: the first CFA directory of full resolution (NewSubfileType 0
/// or absent) among the chain of directories and their sub-IFDs, in file order.
fn find_raw(c: &Container, first: u64, ctx: Ctx) -> Result<Ifd, IoError> {
    let mut queue = vec![first];
    let mut seen = Vec::new();
    let mut linear = false;
    let mut photometrics = Vec::new();
    while let Some(offset) = queue.pop() {
        if offset == 0 || seen.contains(&offset) || seen.len() >= MAX_DIRECTORIES {
            continue;
        }
        seen.push(offset);
        let ifd = c.ifd(offset).map_err(|d| ctx.truncated(d))?;
        let main = c.value(&ifd, NEW_SUBFILE_TYPE).unwrap_or(0.0) == 0.0;
        let photometric = c.value(&ifd, PHOTOMETRIC).unwrap_or(-1.0);
        if main && photometric == f64::from(PHOTOMETRIC_CFA) {
            return Ok(ifd);
        }
        linear |= main && photometric == f64::from(PHOTOMETRIC_LINEAR_RAW);
        photometrics.push(photometric);
        // Depth first, sub-IFDs before the next directory of the chain.
        queue.push(ifd.next);
        for sub in c.values(&ifd, SUB_IFDS).unwrap_or_default().into_iter().rev() {
            queue.push(sub as u64);
        }
    }
    let expected = "a CFA (Bayer) raw: a directory with PhotometricInterpretation 32803";
    if linear {
        return Err(ctx.unexpected(expected, "only a linear (demosaicked) raw, PhotometricInterpretation 34892".into()));
    }
    let found: Vec<String> = photometrics.iter().map(|p| if *p < 0.0 { "none".into() } else { format!("{p}") }).collect();
    Err(ctx.unexpected(expected, format!("{} directories, PhotometricInterpretation {}", seen.len(), found.join(", "))))
}

/// Where one strip or tile lies and which pixels it holds.
struct Chunk {
    offset: u64,
    bytes: u64,
    row0: usize,
    col0: usize,
    rows: usize,
    cols: usize,
}

/// The raw directory's samples in words, and where they lie.
struct Layout {
    width: usize,
    height: usize,
    bits: u32,
    chunks: Vec<Chunk>,
    unit: &'static str,
}

/// The compression in words, for the refusal of a compressed raw.
fn compression_name(c: f64) -> String {
    let name = match c as u32 {
        7 => "lossless JPEG",
        8 => "Deflate",
        34892 => "lossy JPEG",
        5 => "LZW",
        32773 => "PackBits",
        52546 => "JPEG XL",
        _ => "a compression",
    };
    format!("{name} (Compression = {c})")
}

/// The raw directory's header: checked (one sample per pixel, unsigned 8-16 bits,
/// uncompressed, a 2x2 Bayer pattern) and read into [`RawInfo`] and [`Layout`].
fn read_header(c: &Container, ifd: &Ifd, ctx: Ctx) -> Result<(RawInfo, Layout), IoError> {
    let at = format!("the raw's directory (byte {})", ifd.offset);
    let need = |tag: u16, name: &str| c.value(ifd, tag).ok_or_else(|| ctx.malformed(format!("{at} has no {name} (tag {tag})")));
    let (width, height) = (need(IMAGE_WIDTH, "ImageWidth")? as usize, need(IMAGE_LENGTH, "ImageLength")? as usize);
    let bits = c.value(ifd, BITS_PER_SAMPLE).unwrap_or(1.0) as u32;
    let compression = c.value(ifd, COMPRESSION).unwrap_or(1.0);
    if compression != 1.0 {
        return Err(ctx.unexpected(
            "an uncompressed raw (Compression = 1): re-save it uncompressed (a DNG converter's uncompressed option)",
            format!("{} on {at}", compression_name(compression)),
        ));
    }
    let samples = c.value(ifd, SAMPLES_PER_PIXEL).unwrap_or(1.0);
    if samples != 1.0 {
        return Err(ctx.unexpected("one sample per pixel in a CFA raw", format!("{samples} on {at}")));
    }
    if c.value(ifd, SAMPLE_FORMAT).is_some_and(|f| f != 1.0) || ![8, 10, 12, 14, 16].contains(&bits) {
        let kind = if c.value(ifd, SAMPLE_FORMAT).is_some_and(|f| f != 1.0) { "non-integer or signed" } else { "unsigned" };
        return Err(ctx.unexpected("unsigned 8, 10, 12, 14 or 16-bit raw samples", format!("{kind} {bits}-bit samples on {at}")));
    }
    let dim = c.values(ifd, CFA_REPEAT_PATTERN_DIM).unwrap_or_default();
    let cells = c.values(ifd, CFA_PATTERN).unwrap_or_default();
    let pattern = match (dim.as_slice(), Bayer::from_cells(&cells)) {
        ([2.0, 2.0], Some(p)) => p,
        _ => {
            let show = |v: &[f64]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(" ");
            return Err(ctx.unexpected(
                "a 2x2 Bayer CFA (CFARepeatPatternDim 2 2, CFAPattern RGGB, BGGR, GRBG or GBRG as 0=R 1=G 2=B)",
                format!("CFARepeatPatternDim [{}], CFAPattern [{}] on {at}", show(&dim), show(&cells)),
            ));
        }
    };
    let (top, left, bottom, right) = match c.values(ifd, ACTIVE_AREA).as_deref() {
        Some([t, l, b, r]) => (*t as usize, *l as usize, *b as usize, *r as usize),
        _ => (0, 0, height, width),
    };
    if top >= bottom || left >= right || bottom > height || right > width || bottom - top < 2 || right - left < 2 {
        return Err(ctx.unexpected(
            "an active area of at least 2 x 2 pixels inside the image",
            format!("ActiveArea {top} {left} {bottom} {right} in {height} x {width} on {at}"),
        ));
    }
    let blacks = c.values(ifd, BLACK_LEVEL).filter(|v| !v.is_empty());
    let black_level = blacks.map(|v| v.iter().sum::<f64>() / v.len() as f64);
    let white_level = c.value(ifd, WHITE_LEVEL).unwrap_or(f64::from((1u32 << bits) - 1));
    let info = RawInfo { pattern, sensor_rows: bottom - top, sensor_cols: right - left, bits, black_level, white_level };
    let layout = chunks(c, ifd, width, height, bits, ctx)?;
    Ok((info, layout))
}

/// The strips (or tiles) of the raw directory.
fn chunks(c: &Container, ifd: &Ifd, width: usize, height: usize, bits: u32, ctx: Ctx) -> Result<Layout, IoError> {
    let mut out = Vec::new();
    let tiled = c.values(ifd, TILE_OFFSETS).is_some();
    let (offsets, counts, unit) = if tiled {
        (c.values(ifd, TILE_OFFSETS), c.values(ifd, TILE_BYTE_COUNTS), "tile")
    } else {
        (c.values(ifd, STRIP_OFFSETS), c.values(ifd, STRIP_BYTE_COUNTS), "strip")
    };
    let (Some(offsets), Some(counts)) = (offsets, counts) else {
        return Err(ctx.malformed(format!("the raw's directory has no {unit} offsets or byte counts")));
    };
    let (cw, ch) = if tiled {
        let tw = c.value(ifd, TILE_WIDTH).unwrap_or(0.0) as usize;
        let tl = c.value(ifd, TILE_LENGTH).unwrap_or(0.0) as usize;
        (tw, tl)
    } else {
        (width, (c.value(ifd, ROWS_PER_STRIP).unwrap_or(height as f64) as usize).min(height))
    };
    if cw == 0 || ch == 0 {
        return Err(ctx.malformed(format!("{unit}s of {cw} x {ch} pixels")));
    }
    let across = width.div_ceil(cw);
    let wanted = across * height.div_ceil(ch);
    if offsets.len() < wanted || counts.len() < wanted {
        return Err(ctx.malformed(format!(
            "{} {unit} offsets and {} byte counts for the {wanted} {unit}s of {height} x {width} pixels",
            offsets.len(),
            counts.len()
        )));
    }
    for k in 0..wanted {
        let (row0, col0) = ((k / across) * ch, (k % across) * cw);
        let rows = if tiled { ch } else { ch.min(height - row0) };
        out.push(Chunk { offset: offsets[k] as u64, bytes: counts[k] as u64, row0, col0, rows, cols: cw });
    }
    Ok(Layout { width, height, bits, chunks: out, unit })
}

/// Bytes of one row of `cols` samples of `bits` bits (rows start on a byte).
fn row_bytes(cols: usize, bits: u32) -> usize {
    cols.saturating_mul(bits as usize).div_ceil(8)
}

/// The sensor's samples (height x width, row-major) from the raw's strips or tiles.
fn read_mosaic(c: &Container, l: &Layout, ctx: Ctx) -> Result<Vec<u16>, IoError> {
    let len = c.b.len() as u64;
    let mut mosaic = vec![0u16; l.width * l.height];
    let n = l.chunks.len();
    for (k, ch) in l.chunks.iter().enumerate() {
        let rb = row_bytes(ch.cols, l.bits);
        let need = (rb as u64).saturating_mul(ch.rows as u64);
        if ch.bytes < need || ch.offset.saturating_add(need) > len {
            let end = ch.offset.saturating_add(need);
            let what = format!("{} {k} of {n} needs {need} bytes at {}..{end} ({} rows of {rb} bytes)", l.unit, ch.offset, ch.rows);
            return Err(ctx.truncated(format!("{what}; it holds {} and the file has {len}", ch.bytes)));
        }
        for r in 0..ch.rows.min(l.height.saturating_sub(ch.row0)) {
            let row = c.bytes_at(ch.offset + (r * rb) as u64, rb).unwrap_or_default();
            let dest_row = (ch.row0 + r) * l.width;
            let take = ch.cols.min(l.width - ch.col0);
            unpack_row(row, l.bits, c.le, &mut mosaic[dest_row + ch.col0..dest_row + ch.col0 + take]);
        }
    }
    Ok(mosaic)
}

/// The first `out.len()` samples of one row: 8 bits a byte, 16 bits in the file's byte
/// order, 10/12/14 bits packed most significant bit first.
fn unpack_row(row: &[u8], bits: u32, le: bool, out: &mut [u16]) {
    match bits {
        8 => out.iter_mut().zip(row).for_each(|(o, &b)| *o = u16::from(b)),
        16 => {
            out.iter_mut().zip(row.chunks_exact(2)).for_each(|(o, b)| *o = if le { u16::from_le_bytes([b[0], b[1]]) } else { u16::from_be_bytes([b[0], b[1]]) })
        }
        _ => {
            let mut bit = 0usize;
            for o in out.iter_mut() {
                let mut v = 0u32;
                for _ in 0..bits {
                    let byte = row[bit / 8];
                    v = (v << 1) | u32::from((byte >> (7 - bit % 8)) & 1);
                    bit += 1;
                }
                *o = v as u16;
            }
        }
    }
}

/// The header of the raw of an in-memory DNG or CFA TIFF (`format` names it in
/// messages), its samples not read.
pub(crate) fn read_raw_info(path: &Path, format: &'static str, bytes: &[u8]) -> Result<RawInfo, IoError> {
    let ctx = Ctx { path, format };
    let (c, first) = Container::open(bytes).ok_or_else(|| ctx.unexpected("a classic TIFF container (BigTIFF raws are not read)", "another header".into()))?;
    let ifd = find_raw(&c, first, ctx)?;
    Ok(read_header(&c, &ifd, ctx)?.0)
}

/// Decodes the raw of an in-memory DNG or CFA TIFF (`format` names it in messages) as
/// a half-grid colour image (rows/2, cols/2, 3: R, mean G, B), counts as stored.
pub(crate) fn decode_raw(path: &Path, format: &'static str, bytes: &[u8], budget: &ByteBudget) -> Result<(Array3<f32>, RawInfo), IoError> {
    let ctx = Ctx { path, format };
    let (c, first) = Container::open(bytes).ok_or_else(|| ctx.unexpected("a classic TIFF container (BigTIFF raws are not read)", "another header".into()))?;
    let ifd = find_raw(&c, first, ctx)?;
    let (info, layout) = read_header(&c, &ifd, ctx)?;
    let (hr, hc) = info.half_grid();
    let need = (layout.width as u128 * layout.height as u128 * 2).saturating_add(hr as u128 * hc as u128 * 3 * 4);
    let what = || format!("a {} x {} {}-bit Bayer raw (its samples, and its half grid as f32)", layout.height, layout.width, info.bits);
    budget.check(what, need).map_err(|source| IoError::TooLarge { path: path.to_path_buf(), source: Box::new(source) })?;
    let mosaic = read_mosaic(&c, &layout, ctx)?;
    let mosaic = ArrayView2::from_shape((layout.height, layout.width), &mosaic).map_err(|e| ctx.malformed(e.to_string()))?;
    let (top, left) = active_origin(&c, &ifd);
    let cells = info.pattern.cells();
    let image = Array3::from_shape_fn((hr, hc, 3), |(r, col, channel)| {
        let mut sum = 0.0f32;
        let mut n = 0.0f32;
        for (k, &colour) in cells.iter().enumerate() {
            if usize::from(colour) == channel {
                sum += f32::from(mosaic[[top + 2 * r + k / 2, left + 2 * col + k % 2]]);
                n += 1.0;
            }
        }
        sum / n
    });
    Ok((image, info))
}

/// The ActiveArea's top-left corner (0, 0 without one).
fn active_origin(c: &Container, ifd: &Ifd) -> (usize, usize) {
    match c.values(ifd, ACTIVE_AREA).as_deref() {
        Some([t, l, _, _]) => (*t as usize, *l as usize),
        _ => (0, 0),
    }
}

/// A Bayer raw to write ([`encode_raw`]): a sensor's samples under a pattern.
#[derive(Clone, Copy, Debug)]
pub struct RawSpec<'a> {
    /// The sensor's samples (rows, cols), each below 2^bits.
    pub mosaic: ArrayView2<'a, u16>,
    pub pattern: Bayer,
    /// 8, 10, 12, 14 or 16 (10/12/14 bit-packed, most significant bit first).
    pub bits: u32,
    /// A DNG (DNGVersion 1.4, the raw in IFD0) or a CFA TIFF.
    pub dng: bool,
    pub black_level: Option<u32>,
    pub white_level: Option<u32>,
    /// The Compression tag written (1: none; another value makes a file that is
    /// refused, for tests: the samples stay uncompressed).
    pub compression: u16,
}

/// An uncompressed little-endian Bayer raw (DNG or CFA TIFF, one strip, the raw in the
/// first directory) holding `spec`: for test fixtures and simulated raws.
pub fn encode_raw(spec: &RawSpec) -> Vec<u8> {
    let (rows, cols) = spec.mosaic.dim();
    let rb = row_bytes(cols, spec.bits);
    let mut data = Vec::with_capacity(rb * rows);
    for r in 0..rows {
        let row = spec.mosaic.row(r);
        match spec.bits {
            8 => data.extend(row.iter().map(|&v| v as u8)),
            16 => row.iter().for_each(|&v| data.extend(v.to_le_bytes())),
            bits => {
                let mut packed = vec![0u8; rb];
                let mut bit = 0usize;
                for &v in row.iter() {
                    for k in (0..bits).rev() {
                        packed[bit / 8] |= (((v >> k) & 1) as u8) << (7 - bit % 8);
                        bit += 1;
                    }
                }
                data.extend(packed);
            }
        }
    }
    let cells = spec.pattern.cells();
    // (tag, type, count, inline value bytes, little-endian, at most 4).
    let short = |v: u16| v.to_le_bytes().to_vec();
    let long = |v: u32| v.to_le_bytes().to_vec();
    let mut entries: Vec<(u16, u16, u32, Vec<u8>)> = vec![
        (NEW_SUBFILE_TYPE, 4, 1, long(0)),
        (IMAGE_WIDTH, 4, 1, long(cols as u32)),
        (IMAGE_LENGTH, 4, 1, long(rows as u32)),
        (BITS_PER_SAMPLE, 3, 1, short(spec.bits as u16)),
        (COMPRESSION, 3, 1, short(spec.compression)),
        (PHOTOMETRIC, 3, 1, short(PHOTOMETRIC_CFA)),
        (STRIP_OFFSETS, 4, 1, long(0)),
        (SAMPLES_PER_PIXEL, 3, 1, short(1)),
        (ROWS_PER_STRIP, 4, 1, long(rows as u32)),
        (STRIP_BYTE_COUNTS, 4, 1, long(data.len() as u32)),
        (CFA_REPEAT_PATTERN_DIM, 3, 2, [short(2), short(2)].concat()),
        (CFA_PATTERN, 1, 4, cells.to_vec()),
    ];
    if spec.dng {
        entries.push((DNG_VERSION, 1, 4, vec![1, 4, 0, 0]));
    }
    if let Some(b) = spec.black_level {
        entries.push((BLACK_LEVEL, 4, 1, long(b)));
    }
    if let Some(w) = spec.white_level {
        entries.push((WHITE_LEVEL, 4, 1, long(w)));
    }
    let data_at = 8 + 2 + 12 * entries.len() as u32 + 4;
    let mut out = Vec::with_capacity(data_at as usize + data.len());
    out.extend(b"II*\0");
    out.extend(8u32.to_le_bytes());
    out.extend((entries.len() as u16).to_le_bytes());
    for (tag, typ, count, mut value) in entries {
        if tag == STRIP_OFFSETS {
            value = long(data_at);
        }
        value.resize(4, 0);
        out.extend(tag.to_le_bytes());
        out.extend(typ.to_le_bytes());
        out.extend(count.to_le_bytes());
        out.extend(value);
    }
    out.extend(0u32.to_le_bytes());
    out.extend(data);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;

    #[test]
    fn packed_rows_round_trip_most_significant_bit_first() {
        for bits in [10u32, 12, 14] {
            let vals: Vec<u16> = (0..7).map(|k| ((k * 977 + 5) % (1 << bits)) as u16).collect();
            let m = Array2::from_shape_vec((1, 7), vals.clone()).unwrap();
            let bytes = encode_raw(&RawSpec { mosaic: m.view(), pattern: Bayer::Rggb, bits, dng: true, black_level: None, white_level: None, compression: 1 });
            let row = &bytes[bytes.len() - row_bytes(7, bits)..];
            let mut out = vec![0u16; 7];
            unpack_row(row, bits, true, &mut out);
            assert_eq!(out, vals, "{bits} bits");
        }
        // 12 bits: 0xABC, 0xDEF pack as AB CD EF.
        let mut out = [0u16; 2];
        unpack_row(&[0xab, 0xcd, 0xef], 12, false, &mut out);
        assert_eq!(out, [0xabc, 0xdef]);
    }
}
