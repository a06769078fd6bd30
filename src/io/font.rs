//! A 5x7 bitmap font for the digits 0-9, for frame numbers on contact sheets.

/// Glyph width and height in font pixels.
pub(crate) const GLYPH_W: usize = 5;
pub(crate) const GLYPH_H: usize = 7;

/// Rows of each digit, top to bottom; bit 4 is the leftmost pixel.
const DIGITS: [[u8; GLYPH_H]; 10] = [
    [0b01110, 0b10001, 0b10011, 0b10101, 0b11001, 0b10001, 0b01110], // 0
    [0b00100, 0b01100, 0b00100, 0b00100, 0b00100, 0b00100, 0b01110], // 1
    [0b01110, 0b10001, 0b00001, 0b00010, 0b00100, 0b01000, 0b11111], // 2
    [0b11111, 0b00010, 0b00100, 0b00010, 0b00001, 0b10001, 0b01110], // 3
    [0b00010, 0b00110, 0b01010, 0b10010, 0b11111, 0b00010, 0b00010], // 4
    [0b11111, 0b10000, 0b11110, 0b00001, 0b00001, 0b10001, 0b01110], // 5
    [0b00110, 0b01000, 0b10000, 0b11110, 0b10001, 0b10001, 0b01110], // 6
    [0b11111, 0b00001, 0b00010, 0b00100, 0b01000, 0b01000, 0b01000], // 7
    [0b01110, 0b10001, 0b10001, 0b01110, 0b10001, 0b10001, 0b01110], // 8
    [0b01110, 0b10001, 0b10001, 0b01111, 0b00001, 0b00010, 0b01100], // 9
];

/// Whether font pixel (row, col) of `digit` is set.
pub(crate) fn digit_pixel(digit: u8, row: usize, col: usize) -> bool {
    row < GLYPH_H && col < GLYPH_W && (DIGITS[digit as usize % 10][row] >> (GLYPH_W - 1 - col)) & 1 == 1
}

/// Size in pixels of `text` (digits) drawn at `scale` with a 1-font-pixel gap and margin.
pub(crate) fn label_size(text: &str, scale: usize) -> (usize, usize) {
    let n = text.len();
    ((GLYPH_H + 2) * scale, (n * (GLYPH_W + 1) + 1) * scale)
}

/// Draws `text` (digits only; other characters leave a blank) as white on a black box whose
/// top-left corner is (row0, col0), calling `put(row, col, on)` for every pixel of the box
/// (`on` = glyph pixel). Pixels outside the canvas are the caller's to skip.
pub(crate) fn draw_label(text: &str, scale: usize, row0: usize, col0: usize, mut put: impl FnMut(usize, usize, bool)) {
    let (h, w) = label_size(text, scale);
    let digits: Vec<Option<u8>> = text.bytes().map(|b| b.is_ascii_digit().then(|| b - b'0')).collect();
    for r in 0..h {
        for c in 0..w {
            let (fr, fc) = (r / scale, c / scale);
            let on = fr >= 1 && fc >= 1 && {
                let (gr, gc) = (fr - 1, fc - 1);
                let (k, x) = (gc / (GLYPH_W + 1), gc % (GLYPH_W + 1));
                x < GLYPH_W && k < digits.len() && digits[k].is_some_and(|d| digit_pixel(d, gr, x))
            };
            put(row0 + r, col0 + c, on);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_digit_glyph_is_distinct_and_non_empty() {
        let bitmaps: Vec<Vec<bool>> = (0..10u8).map(|d| (0..GLYPH_H * GLYPH_W).map(|i| digit_pixel(d, i / GLYPH_W, i % GLYPH_W)).collect()).collect();
        for (i, a) in bitmaps.iter().enumerate() {
            assert!(a.iter().any(|&p| p), "digit {i} is blank");
            for (j, b) in bitmaps.iter().enumerate().skip(i + 1) {
                assert_ne!(a, b, "digits {i} and {j} look the same");
            }
        }
    }

    #[test]
    fn label_draws_the_digits_at_scale() {
        let (h, w) = label_size("10", 2);
        let mut canvas = vec![vec![false; w]; h];
        draw_label("10", 2, 0, 0, |r, c, on| canvas[r][c] = on);
        // Each font pixel of '1' at glyph (0, 2) covers a 2x2 block starting at (2, 6).
        for (r, c) in [(2, 6), (2, 7), (3, 6), (3, 7)] {
            assert!(canvas[r][c], "pixel ({r},{c}) of the '1' should be lit");
        }
        // The margin row is dark.
        assert!(canvas[0].iter().all(|&p| !p));
        let lit = canvas.iter().flatten().filter(|&&p| p).count();
        let expected: usize = [1u8, 0].iter().map(|&d| (0..GLYPH_H * GLYPH_W).filter(|&i| digit_pixel(d, i / GLYPH_W, i % GLYPH_W)).count() * 4).sum();
        assert_eq!(lit, expected);
    }
}
