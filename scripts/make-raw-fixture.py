#!/usr/bin/env python3
"""Writes fixtures/raw/gbrg-12bit-subifd.dng: a tiny DNG made independently of
rollcam's own raw writer (src/io/formats/raw.rs `encode_raw`), to test the reader on
what that writer never makes: big-endian ("MM"), a preview in IFD0 and the raw in a
sub-IFD (SubIFDs, tag 330), 12-bit samples packed most significant bit first, tiles,
an ActiveArea, and one RATIONAL BlackLevel per Bayer cell.

Raw: 6 x 8 sensor samples, value(r, c) = (r * 37 + c * 11 + 100) % 4096 at sensor row r,
column c; ActiveArea rows 1..5, columns 2..8 (4 x 6 pixels), CFAPattern GBRG from the
active area's top-left; 4 x 4 tiles (2 x 2 of them, rows past the sensor zero);
BlackLevelRepeatDim 2 2, BlackLevel 64 64 66 66 (mean 65); WhiteLevel 4000.
Standard library only:  python3 scripts/make-raw-fixture.py
"""
import pathlib
import struct

ROWS, COLS, TILE, BITS = 6, 8, 4, 12


def value(r, c):
    return (r * 37 + c * 11 + 100) % 4096


def pack12(samples):
    bits = "".join(format(v, "012b") for v in samples)
    bits += "0" * (-len(bits) % 8)
    return bytes(int(bits[i:i + 8], 2) for i in range(0, len(bits), 8))


def tiles():
    out = []
    for tr in range(0, ROWS, TILE):
        for tc in range(0, COLS, TILE):
            data = b""
            for r in range(tr, tr + TILE):
                data += pack12([value(r, c) if r < ROWS else 0 for c in range(tc, tc + TILE)])
            out.append(data)
    return out


class Ifd:
    """Big-endian classic TIFF directory; values over 4 bytes go to `extra`."""
    SIZES = {1: 1, 3: 2, 4: 4, 5: 8}
    FMT = {1: "B", 3: "H", 4: "I"}

    def __init__(self):
        self.entries = []

    def add(self, tag, typ, values):
        self.entries.append((tag, typ, values))

    def encode(self, at, next_ifd=0):
        self.entries.sort()
        extra_at = at + 2 + 12 * len(self.entries) + 4
        head, extra = struct.pack(">H", len(self.entries)), b""
        for tag, typ, values in self.entries:
            if typ == 5:
                raw = b"".join(struct.pack(">II", n, d) for n, d in values)
            else:
                raw = b"".join(struct.pack(">" + self.FMT[typ], v) for v in values)
            if len(raw) <= 4:
                field = raw.ljust(4, b"\0")
            else:
                field = struct.pack(">I", extra_at + len(extra))
                extra += raw + b"\0" * (len(raw) % 2)
            head += struct.pack(">HHI", tag, typ, len(values)) + field
        return head + struct.pack(">I", next_ifd) + extra


def main():
    thumb = bytes([10, 20, 30] * 4)
    raw_tiles = tiles()
    # Layout: header, thumbnail pixels, raw tiles, IFD0, raw IFD.
    data_at = 8
    thumb_at = data_at
    tile_at = []
    pos = thumb_at + len(thumb)
    for t in raw_tiles:
        tile_at.append(pos)
        pos += len(t)
    pos += pos % 2
    ifd0_at = pos

    raw = Ifd()
    raw.add(254, 4, [0])
    raw.add(256, 4, [COLS])
    raw.add(257, 4, [ROWS])
    raw.add(258, 3, [BITS])
    raw.add(259, 3, [1])
    raw.add(262, 3, [32803])
    raw.add(277, 3, [1])
    raw.add(322, 3, [TILE])
    raw.add(323, 3, [TILE])
    raw.add(324, 4, tile_at)
    raw.add(325, 4, [len(t) for t in raw_tiles])
    raw.add(33421, 3, [2, 2])
    raw.add(33422, 1, [1, 2, 0, 1])
    raw.add(50713, 3, [2, 2])
    raw.add(50714, 5, [(64, 1), (128, 2), (66, 1), (198, 3)])
    raw.add(50717, 3, [4000])
    raw.add(50829, 4, [1, 2, 5, 8])

    ifd0 = Ifd()
    ifd0.add(254, 4, [1])
    ifd0.add(256, 4, [2])
    ifd0.add(257, 4, [2])
    ifd0.add(258, 3, [8, 8, 8])
    ifd0.add(259, 3, [1])
    ifd0.add(262, 3, [2])
    ifd0.add(273, 4, [thumb_at])
    ifd0.add(277, 3, [3])
    ifd0.add(278, 4, [2])
    ifd0.add(279, 4, [len(thumb)])
    ifd0.add(330, 4, [0])  # patched below
    ifd0.add(50706, 1, [1, 4, 0, 0])
    first = ifd0.encode(ifd0_at)
    raw_at = ifd0_at + len(first)
    ifd0.entries = [(t, ty, [raw_at] if t == 330 else v) for t, ty, v in ifd0.entries]
    first = ifd0.encode(ifd0_at)
    assert ifd0_at + len(first) == raw_at

    out = b"MM\0*" + struct.pack(">I", ifd0_at) + thumb + b"".join(raw_tiles)
    out += b"\0" * (ifd0_at - len(out))
    out += first + raw.encode(raw_at)
    path = pathlib.Path(__file__).resolve().parent.parent / "fixtures" / "raw" / "gbrg-12bit-subifd.dng"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(out)
    print(f"{path}: {len(out)} bytes")


if __name__ == "__main__":
    main()
