//! An RGBA8 raster to draw on: filled rectangles, lines and text in an 8×8 bitmap font.
//!
//! # Examples
//!
//! ```
//! use raster_picture::{Canvas, BLACK, WHITE};
//!
//! let mut c = Canvas::filled(100, 20, WHITE);
//! c.text(2, 2, "σ = 0.5 m", BLACK, 1);
//! assert_eq!(Canvas::text_width("σ = 0.5 m", 1), 9 * 8);
//! assert!(c.pixels().chunks(4).any(|p| p == BLACK));
//! ```

use font8x8::{UnicodeFonts, BASIC_FONTS, GREEK_FONTS, LATIN_FONTS, MISC_FONTS};

use crate::PictureError;

/// A colour as red, green, blue, alpha bytes.
pub type Rgba = [u8; 4];
pub const BLACK: Rgba = [0, 0, 0, 255];
pub const WHITE: Rgba = [255, 255, 255, 255];

/// Side of one glyph cell in pixels at scale 1.
const GLYPH: usize = 8;

/// RGBA8 pixels, row 0 on top.
#[derive(Debug, Clone, PartialEq)]
pub struct Canvas {
    width: usize,
    height: usize,
    rgba: Vec<u8>,
}

impl Canvas {
    /// A canvas of one colour.
    pub fn filled(width: usize, height: usize, colour: Rgba) -> Canvas {
        Canvas { width, height, rgba: colour.repeat(width * height) }
    }

    /// A canvas over existing pixels (`rgba.len()` must be `4 · width · height`).
    pub fn from_rgba(width: usize, height: usize, rgba: Vec<u8>) -> Canvas {
        assert_eq!(rgba.len(), 4 * width * height, "RGBA buffer size");
        Canvas { width, height, rgba }
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    /// The pixels, RGBA8 row by row.
    pub fn pixels(&self) -> &[u8] {
        &self.rgba
    }

    /// Sets one pixel; outside the canvas nothing happens (drawing is clipped).
    pub fn put(&mut self, x: usize, y: usize, colour: Rgba) {
        if x < self.width && y < self.height {
            let i = 4 * (y * self.width + x);
            self.rgba[i..i + 4].copy_from_slice(&colour);
        }
    }

    /// The pixel at (x, y).
    pub fn get(&self, x: usize, y: usize) -> Rgba {
        let i = 4 * (y * self.width + x);
        [self.rgba[i], self.rgba[i + 1], self.rgba[i + 2], self.rgba[i + 3]]
    }

    /// Fills the rectangle with corner (x, y) and size w × h, clipped to the canvas.
    pub fn fill_rect(&mut self, x: usize, y: usize, w: usize, h: usize, colour: Rgba) {
        for yy in y..(y + h).min(self.height) {
            for xx in x..(x + w).min(self.width) {
                self.put(xx, yy, colour);
            }
        }
    }

    /// A one-pixel outline of the rectangle.
    pub fn stroke_rect(&mut self, x: usize, y: usize, w: usize, h: usize, colour: Rgba) {
        if w == 0 || h == 0 {
            return;
        }
        self.fill_rect(x, y, w, 1, colour);
        self.fill_rect(x, y + h - 1, w, 1, colour);
        self.fill_rect(x, y, 1, h, colour);
        self.fill_rect(x + w - 1, y, 1, h, colour);
    }

    /// Copies `src` with its top-left corner at (x, y), clipped.
    pub fn blit(&mut self, src: &Canvas, x: usize, y: usize) {
        for sy in 0..src.height {
            for sx in 0..src.width {
                self.put(x + sx, y + sy, src.get(sx, sy));
            }
        }
    }

    /// Width in pixels of `text` at `scale` (every glyph is 8 pixels wide at scale 1).
    pub fn text_width(text: &str, scale: usize) -> usize {
        text.chars().count() * GLYPH * scale
    }

    /// Height in pixels of one line of text at `scale`.
    pub fn line_height(scale: usize) -> usize {
        (GLYPH + 2) * scale
    }

    /// Draws `text` with its top-left corner at (x, y). Characters the font lacks are drawn
    /// as '?', so a label never silently loses a character.
    pub fn text(&mut self, x: usize, y: usize, text: &str, colour: Rgba, scale: usize) {
        for (k, ch) in text.chars().enumerate() {
            let glyph = glyph(ch);
            let x0 = x + k * GLYPH * scale;
            for (row, bits) in glyph.iter().enumerate() {
                for col in 0..GLYPH {
                    if bits & (1 << col) != 0 {
                        self.fill_rect(x0 + col * scale, y + row * scale, scale, scale, colour);
                    }
                }
            }
        }
    }

    /// PNG bytes (8-bit RGBA).
    pub fn to_png(&self) -> Result<Vec<u8>, PictureError> {
        let too_large = || PictureError::TooLarge { width: self.width, height: self.height };
        let w = u32::try_from(self.width).map_err(|_| too_large())?;
        let h = u32::try_from(self.height).map_err(|_| too_large())?;
        let mut buf = Vec::new();
        {
            let mut enc = png::Encoder::new(&mut buf, w, h);
            enc.set_color(png::ColorType::Rgba);
            enc.set_depth(png::BitDepth::Eight);
            let mut wr = enc.write_header()?;
            wr.write_image_data(&self.rgba)?;
        }
        Ok(buf)
    }
}

fn glyph(ch: char) -> [u8; 8] {
    BASIC_FONTS
        .get(ch)
        .or_else(|| LATIN_FONTS.get(ch))
        .or_else(|| GREEK_FONTS.get(ch))
        .or_else(|| MISC_FONTS.get(ch))
        .or_else(|| BASIC_FONTS.get('?'))
        .unwrap_or([0; 8])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_sets_the_glyph_pixels_and_nothing_outside_its_box() {
        let mut c = Canvas::filled(30, 12, WHITE);
        c.text(1, 1, "A", BLACK, 1);
        let black: Vec<(usize, usize)> =
            (0..12).flat_map(|y| (0..30).map(move |x| (x, y))).filter(|&(x, y)| c.get(x, y) == BLACK).collect();
        assert!(black.len() > 10);
        assert!(black.iter().all(|&(x, y)| (1..9).contains(&x) && (1..9).contains(&y)));
    }

    #[test]
    fn a_character_the_font_lacks_is_drawn_as_a_question_mark() {
        let (mut a, mut b) = (Canvas::filled(10, 10, WHITE), Canvas::filled(10, 10, WHITE));
        a.text(0, 0, "\u{4e2d}", BLACK, 1);
        b.text(0, 0, "?", BLACK, 1);
        assert_eq!(a, b);
    }

    #[test]
    fn png_round_trips_through_the_decoder() {
        let mut c = Canvas::filled(7, 5, [10, 20, 30, 255]);
        c.put(3, 2, [200, 100, 50, 128]);
        let bytes = c.to_png().unwrap();
        let dec = png::Decoder::new(std::io::Cursor::new(bytes));
        let mut r = dec.read_info().unwrap();
        let mut buf = vec![0; r.output_buffer_size()];
        let info = r.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height), (7, 5));
        assert_eq!(&buf[..info.buffer_size()], c.pixels());
    }
}
