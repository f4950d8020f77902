//! A tiny built-in stroke font (tiny-skia draws no text): digits, capitals and a few signs.
//!
//! Glyphs are polylines on a 4 x 6 grid (y down), drawn as anti-aliased strokes. Lower case
//! is drawn as upper case; characters without a glyph are drawn as a question mark.

use tiny_skia::{Color, LineCap, LineJoin, Paint, PathBuilder, Pixmap, Stroke, Transform};

/// Grid units from one glyph's left edge to the next: 4 wide plus 2 of spacing.
const ADVANCE_UNITS: f32 = 6.0;
/// Grid units of the cap height.
const HEIGHT_UNITS: f32 = 6.0;
/// Most characters drawn from one string; the rest are dropped.
pub const MAX_TEXT_CHARS: usize = 256;

/// Strokes of a glyph: polylines separated by `|`, points as two digits `xy`.
fn glyph(c: char) -> &'static str {
    match c.to_ascii_uppercase() {
        '0' => "00 40 46 06 00|06 40",
        '1' => "11 20 26|06 46",
        '2' => "00 40 43 03 06 46",
        '3' => "00 40 46 06|03 43",
        '4' => "00 03 43|40 46",
        '5' => "40 00 03 43 46 06",
        '6' => "40 00 06 46 43 03",
        '7' => "00 40 26",
        '8' => "00 40 46 06 00|03 43",
        '9' => "43 03 00 40 46 06",
        'A' => "06 02 20 42 46|03 43",
        'B' => "00 30 41 42 33 03|33 44 45 36 06 00",
        'C' => "40 00 06 46",
        'D' => "00 30 42 44 36 06 00",
        'E' => "40 00 06 46|03 33",
        'F' => "40 00 06|03 33",
        'G' => "40 00 06 46 43 23",
        'H' => "00 06|40 46|03 43",
        'I' => "10 30|20 26|16 36",
        'J' => "40 46 06 04",
        'K' => "00 06|40 03 46",
        'L' => "00 06 46",
        'M' => "06 00 23 40 46",
        'N' => "06 00 46 40",
        'O' => "00 40 46 06 00",
        'P' => "06 00 40 43 03",
        'Q' => "00 40 46 06 00|24 46",
        'R' => "06 00 40 43 03 46",
        'S' => "40 00 03 43 46 06",
        'T' => "00 40|20 26",
        'U' => "00 06 46 40",
        'V' => "00 26 40",
        'W' => "00 06 23 46 40",
        'X' => "00 46|40 06",
        'Y' => "00 23 40|23 26",
        'Z' => "00 40 06 46",
        '.' => "15 25 26 16 15",
        ',' => "25 16",
        '-' => "13 33",
        '+' => "13 33|22 24",
        ':' => "11 21|15 25",
        '/' => "06 40",
        '(' => "30 11 15 36",
        ')' => "10 31 35 16",
        '=' => "12 32|14 34",
        '%' => "06 40|00 11|35 46",
        '_' => "06 46",
        '[' => "30 10 16 36",
        ']' => "10 30 36 16",
        ' ' => "",
        _ => "01 00 40 42 22 24|25 26",
    }
}

/// Width in pixels of `text` drawn with cap height `size` (no trailing spacing).
pub fn text_width(text: &str, size: f32) -> f32 {
    let n = text.chars().take(MAX_TEXT_CHARS).count() as f32;
    if n == 0.0 {
        0.0
    } else {
        (n * ADVANCE_UNITS - 2.0) * size / HEIGHT_UNITS
    }
}

/// Draws `text` with its top-left corner at (x, y) and cap height `size`, in `colour`.
pub fn draw_text(pixmap: &mut Pixmap, text: &str, x: f32, y: f32, size: f32, colour: Color) {
    let unit = size / HEIGHT_UNITS;
    let mut pb = PathBuilder::new();
    for (i, c) in text.chars().take(MAX_TEXT_CHARS).enumerate() {
        let x0 = x + i as f32 * ADVANCE_UNITS * unit;
        for stroke in glyph(c).split('|').filter(|s| !s.is_empty()) {
            for (k, pt) in stroke.split(' ').enumerate() {
                let b = pt.as_bytes();
                let (gx, gy) = (f32::from(b[0] - b'0'), f32::from(b[1] - b'0'));
                let (px, py) = (x0 + gx * unit, y + gy * unit);
                if k == 0 {
                    pb.move_to(px, py)
                } else {
                    pb.line_to(px, py)
                }
            }
        }
    }
    let Some(path) = pb.finish() else { return };
    let mut paint = Paint::default();
    paint.set_color(colour);
    paint.anti_alias = true;
    let stroke = Stroke {
        width: (size / 7.0).max(1.0),
        line_cap: LineCap::Round,
        line_join: LineJoin::Round,
        ..Stroke::default()
    };
    pixmap.stroke_path(&path, &paint, &stroke, Transform::identity(), None);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_glyph_parses_and_text_stays_in_its_box() {
        for c in (0u8..128).map(char::from) {
            for stroke in glyph(c).split('|').filter(|s| !s.is_empty()) {
                for pt in stroke.split(' ') {
                    let b = pt.as_bytes();
                    assert!(
                        b.len() == 2
                            && (b'0'..=b'4').contains(&b[0])
                            && (b'0'..=b'6').contains(&b[1]),
                        "glyph {c:?}: {pt:?}"
                    );
                }
            }
        }
        let mut pixmap = Pixmap::new(80, 30).unwrap();
        draw_text(&mut pixmap, "E1", 10.0, 10.0, 12.0, Color::BLACK);
        let w = text_width("E1", 12.0);
        assert_eq!(w, 20.0);
        let ink = |x: u32, y: u32| pixmap.pixel(x, y).map_or(0, |p| p.alpha());
        // The E's spine at x = 10 and its top bar are inked; far outside the box is not.
        assert!(ink(10, 16) > 128 && ink(14, 10) > 128);
        for y in 0..30 {
            for x in 0..80 {
                let inside = (8..=32).contains(&x) && (8..=24).contains(&y);
                assert!(inside || ink(x, y) == 0, "ink at {x},{y}");
            }
        }
    }
}
