//! A tiny embedded 5×7 bitmap font for labels: A–Z (lower case is drawn upper case), 0–9 and
//! `. , ; = ² × - + : / ( ) % _ · < >`; anything else is drawn as `?`.

use ibl_core::Image;

/// Glyph cell: 5 columns × 7 rows of ink, plus one column of spacing after each glyph.
pub(crate) const GLYPH_W: usize = 5;
pub(crate) const GLYPH_H: usize = 7;
const ADVANCE: usize = GLYPH_W + 1;

/// Each glyph is 7 rows, top first; bit 4 of a row is its leftmost column.
const GLYPHS: &[(char, [u8; 7])] = &[
    ('A', [0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11]),
    ('B', [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E]),
    ('C', [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E]),
    ('D', [0x1E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x1E]),
    ('E', [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F]),
    ('F', [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10]),
    ('G', [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F]),
    ('H', [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11]),
    ('I', [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E]),
    ('J', [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C]),
    ('K', [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11]),
    ('L', [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F]),
    ('M', [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11]),
    ('N', [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11]),
    ('O', [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E]),
    ('P', [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10]),
    ('Q', [0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D]),
    ('R', [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11]),
    ('S', [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E]),
    ('T', [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04]),
    ('U', [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E]),
    ('V', [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04]),
    ('W', [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A]),
    ('X', [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11]),
    ('Y', [0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04]),
    ('Z', [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F]),
    ('0', [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E]),
    ('1', [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E]),
    ('2', [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F]),
    ('3', [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E]),
    ('4', [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02]),
    ('5', [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E]),
    ('6', [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E]),
    ('7', [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08]),
    ('8', [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E]),
    ('9', [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C]),
    (' ', [0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00]),
    ('.', [0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C]),
    (',', [0x00, 0x00, 0x00, 0x00, 0x0C, 0x04, 0x08]),
    ('=', [0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00]),
    ('-', [0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00]),
    ('+', [0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00]),
    (':', [0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00]),
    ('/', [0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00]),
    ('(', [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02]),
    (')', [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08]),
    ('%', [0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03]),
    ('_', [0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1F]),
    ('²', [0x0C, 0x12, 0x04, 0x08, 0x1E, 0x00, 0x00]),
    ('×', [0x00, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x00]),
    ('·', [0x00, 0x00, 0x00, 0x0C, 0x0C, 0x00, 0x00]),
    ('>', [0x08, 0x04, 0x02, 0x01, 0x02, 0x04, 0x08]),
    ('<', [0x02, 0x04, 0x08, 0x10, 0x08, 0x04, 0x02]),
    (';', [0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x04, 0x08]),
    ('?', [0x0E, 0x11, 0x01, 0x02, 0x04, 0x00, 0x04]),
];

/// The rows of `c`'s glyph (lower case folds to upper case; unknown characters give `?`).
pub(crate) fn glyph(c: char) -> [u8; 7] {
    let c = c.to_ascii_uppercase();
    GLYPHS
        .iter()
        .find(|g| g.0 == c)
        .or_else(|| GLYPHS.iter().find(|g| g.0 == '?'))
        .expect("'?' is in the table")
        .1
}

/// Width in pixels of `text` drawn at `scale` (no trailing spacing column).
pub(crate) fn text_width(text: &str, scale: usize) -> usize {
    let n = text.chars().count();
    (n * ADVANCE).saturating_sub(1) * scale
}

/// Height in pixels of a line drawn at `scale`.
pub(crate) fn text_height(scale: usize) -> usize {
    GLYPH_H * scale
}

/// Draws `text` into `img` (RGB or RGBA, alpha set to 1 where inked) with its top-left
/// corner at (x, y), each font pixel a `scale`×`scale` block; ink outside the image is
/// clipped.
pub(crate) fn draw_text(
    img: &mut Image,
    x: usize,
    y: usize,
    text: &str,
    scale: usize,
    rgb: [f32; 3],
) {
    for (k, c) in text.chars().enumerate() {
        let rows = glyph(c);
        let x0 = x + k * ADVANCE * scale;
        for (gy, row) in rows.iter().enumerate() {
            for gx in 0..GLYPH_W {
                if row & (0x10 >> gx) == 0 {
                    continue;
                }
                for dy in 0..scale {
                    for dx in 0..scale {
                        let (px, py) = (x0 + gx * scale + dx, y + gy * scale + dy);
                        if px < img.width && py < img.height {
                            let t = img.texel_mut(px, py);
                            t[..3].copy_from_slice(&rgb);
                            if t.len() == 4 {
                                t[3] = 1.0;
                            }
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bounding box (x0, y0, x1, y1) of the inked texels, exclusive ends.
    fn ink_box(img: &Image) -> Option<(usize, usize, usize, usize)> {
        let mut b: Option<(usize, usize, usize, usize)> = None;
        for y in 0..img.height {
            for x in 0..img.width {
                if img.texel(x, y)[0] > 0.5 {
                    b = Some(match b {
                        None => (x, y, x + 1, y + 1),
                        Some((a, c, d, e)) => (a.min(x), c.min(y), d.max(x + 1), e.max(y + 1)),
                    });
                }
            }
        }
        b
    }

    #[test]
    fn glyphs_render_at_their_size_and_scale() {
        // 'H', 'M' and '0' touch all four edges of the 5×7 cell: their ink box is the cell,
        // scaled, at the requested origin, and the ink count is the bitmap's bits × scale².
        for c in ['H', 'M', '0'] {
            for scale in [1, 2, 3] {
                let mut img = Image::new(40, 40, 3);
                draw_text(&mut img, 3, 4, &c.to_string(), scale, [1.0; 3]);
                assert_eq!(
                    ink_box(&img),
                    Some((3, 4, 3 + GLYPH_W * scale, 4 + GLYPH_H * scale)),
                    "{c} at ×{scale}"
                );
                let inked = img.data.chunks(3).filter(|t| t[0] > 0.5).count();
                let bits: u32 = glyph(c).iter().map(|r| r.count_ones()).sum();
                assert_eq!(inked, bits as usize * scale * scale);
            }
        }
        assert_eq!(text_width("AB", 2), (2 * 6 - 1) * 2);
        assert_eq!(text_height(2), 14);
    }

    #[test]
    fn every_glyph_is_distinct_and_fits_five_columns() {
        for (i, (c, rows)) in GLYPHS.iter().enumerate() {
            assert!(rows.iter().all(|r| *r < 0x20), "{c} wider than 5 columns");
            if *c != ' ' {
                assert!(rows.iter().any(|r| *r != 0), "{c} is blank");
            }
            for (d, other) in &GLYPHS[i + 1..] {
                assert_ne!(rows, other, "{c} and {d} share a bitmap");
                assert_ne!(c, d, "{c} listed twice");
            }
        }
    }

    #[test]
    fn lower_case_folds_and_unknown_characters_show_a_question_mark() {
        assert_eq!(glyph('r'), glyph('R'));
        assert_eq!(glyph('€'), glyph('?'));
        assert_ne!(glyph('R'), glyph('?'));
        // A second glyph starts one spacing column after the first.
        let mut img = Image::new(20, 10, 4);
        draw_text(&mut img, 0, 0, "II", 1, [1.0; 3]);
        let col_inked = |x: usize| (0..7).any(|y| img.texel(x, y)[3] > 0.5);
        assert!(col_inked(1) && col_inked(7) && !col_inked(5) && !col_inked(6));
    }
}
