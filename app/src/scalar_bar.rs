//! # Scalar bars composited into images
//!
//! A vertical colour bar per coloured field ([`ScalarBar`]): the colormap from max (top) to
//! min, tick labels at max, middle and min to its right and the field's name above, on a
//! dimmed panel at the right edge of the image. The viewer draws the same bar as an egui
//! overlay ([`tick_labels`] is shared); screenshots and `isoscope render`/`movie` images get
//! it here, drawn with a tiny built-in 5×7 bitmap font (digits, `.`, `-`, `+`, `e`, ASCII
//! letters shown as capitals, a few signs; anything else as `?`), so no font dependency.

use crate::coloring::ScalarBar;

/// 5×7 glyphs, one row per byte from the top, bit 4 the leftmost pixel.
const GLYPHS: &[(char, [u8; 7])] = &[
    (
        '0',
        [
            0b01110, 0b10001, 0b10011, 0b10101, 0b11001, 0b10001, 0b01110,
        ],
    ),
    (
        '1',
        [
            0b00100, 0b01100, 0b00100, 0b00100, 0b00100, 0b00100, 0b01110,
        ],
    ),
    (
        '2',
        [
            0b01110, 0b10001, 0b00001, 0b00010, 0b00100, 0b01000, 0b11111,
        ],
    ),
    (
        '3',
        [
            0b11111, 0b00010, 0b00100, 0b00010, 0b00001, 0b10001, 0b01110,
        ],
    ),
    (
        '4',
        [
            0b00010, 0b00110, 0b01010, 0b10010, 0b11111, 0b00010, 0b00010,
        ],
    ),
    (
        '5',
        [
            0b11111, 0b10000, 0b11110, 0b00001, 0b00001, 0b10001, 0b01110,
        ],
    ),
    (
        '6',
        [
            0b00110, 0b01000, 0b10000, 0b11110, 0b10001, 0b10001, 0b01110,
        ],
    ),
    (
        '7',
        [
            0b11111, 0b00001, 0b00010, 0b00100, 0b01000, 0b01000, 0b01000,
        ],
    ),
    (
        '8',
        [
            0b01110, 0b10001, 0b10001, 0b01110, 0b10001, 0b10001, 0b01110,
        ],
    ),
    (
        '9',
        [
            0b01110, 0b10001, 0b10001, 0b01111, 0b00001, 0b00010, 0b01100,
        ],
    ),
    (
        'A',
        [
            0b01110, 0b10001, 0b10001, 0b11111, 0b10001, 0b10001, 0b10001,
        ],
    ),
    (
        'B',
        [
            0b11110, 0b10001, 0b10001, 0b11110, 0b10001, 0b10001, 0b11110,
        ],
    ),
    (
        'C',
        [
            0b01110, 0b10001, 0b10000, 0b10000, 0b10000, 0b10001, 0b01110,
        ],
    ),
    (
        'D',
        [
            0b11100, 0b10010, 0b10001, 0b10001, 0b10001, 0b10010, 0b11100,
        ],
    ),
    (
        'E',
        [
            0b11111, 0b10000, 0b10000, 0b11110, 0b10000, 0b10000, 0b11111,
        ],
    ),
    (
        'F',
        [
            0b11111, 0b10000, 0b10000, 0b11110, 0b10000, 0b10000, 0b10000,
        ],
    ),
    (
        'G',
        [
            0b01110, 0b10001, 0b10000, 0b10111, 0b10001, 0b10001, 0b01111,
        ],
    ),
    (
        'H',
        [
            0b10001, 0b10001, 0b10001, 0b11111, 0b10001, 0b10001, 0b10001,
        ],
    ),
    (
        'I',
        [
            0b01110, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b01110,
        ],
    ),
    (
        'J',
        [
            0b00111, 0b00010, 0b00010, 0b00010, 0b00010, 0b10010, 0b01100,
        ],
    ),
    (
        'K',
        [
            0b10001, 0b10010, 0b10100, 0b11000, 0b10100, 0b10010, 0b10001,
        ],
    ),
    (
        'L',
        [
            0b10000, 0b10000, 0b10000, 0b10000, 0b10000, 0b10000, 0b11111,
        ],
    ),
    (
        'M',
        [
            0b10001, 0b11011, 0b10101, 0b10101, 0b10001, 0b10001, 0b10001,
        ],
    ),
    (
        'N',
        [
            0b10001, 0b10001, 0b11001, 0b10101, 0b10011, 0b10001, 0b10001,
        ],
    ),
    (
        'O',
        [
            0b01110, 0b10001, 0b10001, 0b10001, 0b10001, 0b10001, 0b01110,
        ],
    ),
    (
        'P',
        [
            0b11110, 0b10001, 0b10001, 0b11110, 0b10000, 0b10000, 0b10000,
        ],
    ),
    (
        'Q',
        [
            0b01110, 0b10001, 0b10001, 0b10001, 0b10101, 0b10010, 0b01101,
        ],
    ),
    (
        'R',
        [
            0b11110, 0b10001, 0b10001, 0b11110, 0b10100, 0b10010, 0b10001,
        ],
    ),
    (
        'S',
        [
            0b01111, 0b10000, 0b10000, 0b01110, 0b00001, 0b00001, 0b11110,
        ],
    ),
    (
        'T',
        [
            0b11111, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100,
        ],
    ),
    (
        'U',
        [
            0b10001, 0b10001, 0b10001, 0b10001, 0b10001, 0b10001, 0b01110,
        ],
    ),
    (
        'V',
        [
            0b10001, 0b10001, 0b10001, 0b10001, 0b10001, 0b01010, 0b00100,
        ],
    ),
    (
        'W',
        [
            0b10001, 0b10001, 0b10001, 0b10101, 0b10101, 0b10101, 0b01010,
        ],
    ),
    (
        'X',
        [
            0b10001, 0b10001, 0b01010, 0b00100, 0b01010, 0b10001, 0b10001,
        ],
    ),
    (
        'Y',
        [
            0b10001, 0b10001, 0b10001, 0b01010, 0b00100, 0b00100, 0b00100,
        ],
    ),
    (
        'Z',
        [
            0b11111, 0b00001, 0b00010, 0b00100, 0b01000, 0b10000, 0b11111,
        ],
    ),
    (
        'e',
        [
            0b00000, 0b00000, 0b01110, 0b10001, 0b11111, 0b10000, 0b01110,
        ],
    ),
    (
        '.',
        [
            0b00000, 0b00000, 0b00000, 0b00000, 0b00000, 0b01100, 0b01100,
        ],
    ),
    (
        '-',
        [
            0b00000, 0b00000, 0b00000, 0b11111, 0b00000, 0b00000, 0b00000,
        ],
    ),
    (
        '+',
        [
            0b00000, 0b00100, 0b00100, 0b11111, 0b00100, 0b00100, 0b00000,
        ],
    ),
    (' ', [0; 7]),
    (
        '_',
        [
            0b00000, 0b00000, 0b00000, 0b00000, 0b00000, 0b00000, 0b11111,
        ],
    ),
    (
        '/',
        [
            0b00000, 0b00001, 0b00010, 0b00100, 0b01000, 0b10000, 0b00000,
        ],
    ),
    (
        '(',
        [
            0b00010, 0b00100, 0b01000, 0b01000, 0b01000, 0b00100, 0b00010,
        ],
    ),
    (
        ')',
        [
            0b01000, 0b00100, 0b00010, 0b00010, 0b00010, 0b00100, 0b01000,
        ],
    ),
    (
        ':',
        [
            0b00000, 0b01100, 0b01100, 0b00000, 0b01100, 0b01100, 0b00000,
        ],
    ),
    (
        '?',
        [
            0b01110, 0b10001, 0b00001, 0b00010, 0b00100, 0b00000, 0b00100,
        ],
    ),
];

/// The glyph of `c`: lowercase letters other than `e` as capitals, unknown characters as `?`.
fn glyph(c: char) -> [u8; 7] {
    let find = |c: char| GLYPHS.iter().find(|(g, _)| *g == c).map(|(_, rows)| *rows);
    find(c)
        .or_else(|| find(c.to_ascii_uppercase()))
        .unwrap_or_else(|| find('?').expect("a '?' glyph"))
}

/// A tick value as at most 4 significant digits, plain for magnitudes in `[1e-3, 1e5)` and
/// in exponent form (`1.5e-7`) otherwise.
pub fn tick_label(v: f32) -> String {
    if v == 0.0 || !v.is_finite() {
        return if v.is_nan() {
            "nan".into()
        } else if v == 0.0 {
            "0".into()
        } else {
            format!("{v}")
        };
    }
    let a = v.abs();
    let trim = |s: String| -> String {
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_owned()
        } else {
            s
        }
    };
    if (1e-3..1e5).contains(&a) {
        let decimals = (3 - a.log10().floor() as i32).clamp(0, 6) as usize;
        trim(format!("{v:.decimals$}"))
    } else {
        let s = format!("{v:.3e}");
        let (mantissa, exponent) = s.split_once('e').unwrap_or((&s, "0"));
        format!("{}e{exponent}", trim(mantissa.to_owned()))
    }
}

/// The labels of a bar's max, middle and min ticks, top to bottom.
pub fn tick_labels([lo, hi]: [f32; 2]) -> [String; 3] {
    [
        tick_label(hi),
        tick_label(lo + 0.5 * (hi - lo)),
        tick_label(lo),
    ]
}

/// An RGBA8 image to draw into.
struct Canvas<'a> {
    rgba: &'a mut [u8],
    width: i64,
    height: i64,
}

impl Canvas<'_> {
    fn put(&mut self, x: i64, y: i64, rgb: [u8; 3]) {
        if (0..self.width).contains(&x) && (0..self.height).contains(&y) {
            let p = 4 * (y * self.width + x) as usize;
            self.rgba[p..p + 3].copy_from_slice(&rgb);
            self.rgba[p + 3] = 255;
        }
    }

    /// Darkens the rectangle `[x0, x1) × [y0, y1)` to 40 % (the panel under the bar).
    fn dim(&mut self, x0: i64, y0: i64, x1: i64, y1: i64) {
        for y in y0.max(0)..y1.min(self.height) {
            for x in x0.max(0)..x1.min(self.width) {
                let p = 4 * (y * self.width + x) as usize;
                for c in &mut self.rgba[p..p + 3] {
                    *c = (u16::from(*c) * 2 / 5) as u8;
                }
            }
        }
    }

    fn fill(&mut self, x0: i64, y0: i64, x1: i64, y1: i64, rgb: [u8; 3]) {
        for y in y0..y1 {
            for x in x0..x1 {
                self.put(x, y, rgb);
            }
        }
    }

    /// `text` with its top-left corner at `(x, y)`, each font pixel `scale` pixels.
    fn text(&mut self, x: i64, y: i64, scale: i64, text: &str, rgb: [u8; 3]) {
        for (i, c) in text.chars().enumerate() {
            let rows = glyph(c);
            let gx = x + i as i64 * 6 * scale;
            for (r, bits) in rows.iter().enumerate() {
                for col in 0..5 {
                    if bits >> (4 - col) & 1 == 1 {
                        let px = gx + col * scale;
                        let py = y + r as i64 * scale;
                        self.fill(px, py, px + scale, py + scale, rgb);
                    }
                }
            }
        }
    }
}

fn to_u8(c: f32) -> u8 {
    (c.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// Width in pixels of `text` in the bitmap font at `scale`.
fn text_width(text: &str, scale: i64) -> i64 {
    (text.chars().count() as i64 * 6 - 1).max(0) * scale
}

/// Draws `bars` into the row-major RGBA8 image (`width × height`), right to left from the
/// right edge, vertically centred. Images too small to hold a bar are left as they are.
pub fn composite(rgba: &mut [u8], width: u32, height: u32, bars: &[ScalarBar]) {
    if bars.is_empty()
        || width < 80
        || height < 80
        || rgba.len() != 4 * width as usize * height as usize
    {
        return;
    }
    let mut canvas = Canvas {
        rgba,
        width: i64::from(width),
        height: i64::from(height),
    };
    let scale = (i64::from(height) / 400).max(1);
    let (bar_w, pad, gap) = (10 * scale, 6 * scale, 4 * scale);
    let bar_h = (i64::from(height) / 2).max(40);
    let line = 9 * scale;
    let mut right = canvas.width - pad;
    let white = [255, 255, 255];
    for bar in bars {
        let labels = tick_labels(bar.range);
        let labels_w = labels
            .iter()
            .map(|l| text_width(l, scale))
            .max()
            .unwrap_or(0);
        let body_w = bar_w + gap + 3 * scale + labels_w;
        // A name wider than the image is cut (the panel stays inside the image).
        let max_chars = ((right - 2 * pad) / (6 * scale)).max(1) as usize;
        let title: String = bar.label.chars().take(max_chars).collect();
        let title_w = text_width(&title, scale);
        let panel_w = body_w.max(title_w) + 2 * pad;
        let left = right - panel_w;
        let top = (canvas.height - bar_h) / 2;
        let panel_top = top - line - pad - 4 * scale;
        canvas.dim(left, panel_top, right, top + bar_h + pad + 4 * scale);
        canvas.text(left + pad, panel_top + pad, scale, &title, white);
        let x0 = left + pad;
        for y in 0..bar_h {
            let t = 1.0 - y as f32 / (bar_h - 1) as f32;
            let rgb = bar.colormap.at(t).map(to_u8);
            canvas.fill(x0, top + y, x0 + bar_w, top + y + 1, rgb);
        }
        for (k, label) in labels.iter().enumerate() {
            let y = top + (bar_h - 1) * k as i64 / 2;
            // A tick mark, then the label centred on it.
            canvas.fill(x0 + bar_w, y, x0 + bar_w + 3 * scale, y + scale, white);
            let ty = (y - 3 * scale).clamp(0, canvas.height - 7 * scale);
            canvas.text(x0 + bar_w + gap + 3 * scale, ty, scale, label, white);
        }
        right = left - pad;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use volume_core::render::Colormap;

    #[test]
    fn tick_labels_read_as_short_numbers() {
        assert_eq!(tick_label(0.0), "0");
        assert_eq!(tick_label(1.5), "1.5");
        assert_eq!(tick_label(-2.0), "-2");
        assert_eq!(tick_label(1234.5678), "1235");
        assert_eq!(tick_label(0.012_345), "0.01235");
        assert_eq!(tick_label(1.5e-7), "1.5e-7");
        assert_eq!(tick_label(-2.5e9), "-2.5e9");
        assert_eq!(tick_labels([-1.0, 3.0]), ["3", "1", "-1"].map(String::from));
        // Every character of a label has a glyph of its own (none falls back to '?').
        for s in ["0123456789", "-1.5e+7", "e"] {
            for c in s.chars() {
                assert!(GLYPHS.iter().any(|(g, _)| *g == c), "{c}");
            }
        }
        assert_eq!(glyph('x'), glyph('X'));
        assert_eq!(glyph('€'), glyph('?'));
    }

    #[test]
    fn the_bar_shows_the_colormap_from_max_at_the_top_to_min() {
        let (w, h) = (200u32, 120u32);
        let bg = [10u8, 200, 30, 255];
        let mut img: Vec<u8> = bg.repeat((w * h) as usize);
        let bar = ScalarBar {
            label: "x".into(),
            colormap: Colormap::Coolwarm,
            range: [0.0, 1.0],
        };
        composite(&mut img, w, h, std::slice::from_ref(&bar));
        let px = |x: u32, y: u32| {
            let p = 4 * (y * w + x) as usize;
            [img[p], img[p + 1], img[p + 2]]
        };
        // Find the bar: the column whose top and bottom are coolwarm's ends.
        let top_rgb = Colormap::Coolwarm.at(1.0).map(to_u8);
        let bottom_rgb = Colormap::Coolwarm.at(0.0).map(to_u8);
        let bar_h = 60;
        let top = (h - bar_h) / 2;
        let column = (0..w)
            .find(|&x| px(x, top) == top_rgb && px(x, top + bar_h - 1) == bottom_rgb)
            .expect("a bar column");
        assert!(column > w / 2, "the bar sits on the right: {column}");
        let mid = Colormap::Coolwarm.at(1.0 - 30.0 / 59.0).map(to_u8);
        assert_eq!(px(column, top + 30), mid);
        // Away from the panel the image is untouched; on it, dimmed or drawn.
        assert_eq!(px(5, 5), [10, 200, 30]);
        assert_ne!(px(column - 2, top + 30), [10, 200, 30]);
        // Too small an image: nothing drawn.
        let mut tiny = bg.repeat(50 * 50);
        composite(&mut tiny, 50, 50, &[bar]);
        assert!(tiny.chunks(4).all(|p| p == bg));
    }
}
