//! A map picture framed with a title above and a legend to its right: a swatch and a label per
//! colour, the legend's title carrying the unit.
//!
//! The map keeps its pixels one to one (no resampling), so a world file written with
//! [`Framed::map_x`]/[`Framed::map_y`] as offset puts every map pixel where it belongs; the title
//! and the legend lie outside the map's footprint.
//!
//! # Examples
//!
//! ```
//! use raster_picture::{Canvas, Legend, LegendEntry, with_legend};
//!
//! let map = Canvas::filled(50, 40, [200, 40, 40, 255]);
//! let legend = Legend {
//!     title: "|dz| (m)".into(),
//!     entries: vec![LegendEntry { colour: [200, 40, 40, 255], label: ">= 2".into() }],
//!     note: Some("max 2.31 m".into()),
//! };
//! let framed = with_legend(&map, "Error classes", &legend);
//! assert_eq!(framed.canvas.get(framed.map_x, framed.map_y), [200, 40, 40, 255]);
//! ```

use crate::canvas::{Canvas, Rgba, BLACK, WHITE};

/// One colour of a legend and what it means.
#[derive(Debug, Clone, PartialEq)]
pub struct LegendEntry {
    pub colour: Rgba,
    pub label: String,
}

/// A legend: its title (with the unit), entries top to bottom, an optional line below.
#[derive(Debug, Clone, PartialEq)]
pub struct Legend {
    pub title: String,
    pub entries: Vec<LegendEntry>,
    pub note: Option<String>,
}

/// A framed map and where the map's top-left pixel landed in it.
#[derive(Debug, Clone, PartialEq)]
pub struct Framed {
    pub canvas: Canvas,
    pub map_x: usize,
    pub map_y: usize,
}

const MARGIN: usize = 8;
const SWATCH: [usize; 2] = [18, 12];
const GAP: usize = 12;
const TITLE_SCALE: usize = 2;
/// Checkerboard behind the map: shows "no value" (transparent) cells in any viewer.
const CHECKER: [Rgba; 2] = [[235, 235, 235, 255], [210, 210, 210, 255]];

/// The map under `title`, with `legend` to its right, on white.
pub fn with_legend(map: &Canvas, title: &str, legend: &Legend) -> Framed {
    let row = Canvas::line_height(1).max(SWATCH[1] + 4);
    let legend_w = legend_width(legend);
    let legend_h =
        Canvas::line_height(1) + 4 + legend.entries.len() * row + legend.note.as_ref().map_or(0, |_| row + 4);
    let title_h = Canvas::line_height(TITLE_SCALE) + MARGIN;
    let width =
        (MARGIN + map.width() + GAP + legend_w + MARGIN).max(2 * MARGIN + Canvas::text_width(title, TITLE_SCALE));
    let height = title_h + map.height().max(legend_h) + 2 * MARGIN;
    let mut c = Canvas::filled(width, height, WHITE);
    c.text(MARGIN, MARGIN, title, BLACK, TITLE_SCALE);
    let (map_x, map_y) = (MARGIN, title_h + MARGIN);
    draw_map(&mut c, map, map_x, map_y);
    draw_legend(&mut c, legend, map_x + map.width() + GAP, map_y, row);
    Framed { canvas: c, map_x, map_y }
}

fn legend_width(legend: &Legend) -> usize {
    let labels = legend.entries.iter().map(|e| SWATCH[0] + 6 + Canvas::text_width(&e.label, 1));
    let lines = [Canvas::text_width(&legend.title, 1), legend.note.as_deref().map_or(0, |n| Canvas::text_width(n, 1))];
    labels.chain(lines).max().unwrap_or(0)
}

/// Map pixels over a checkerboard, alpha-blended, so transparent cells stay recognisable.
fn draw_map(c: &mut Canvas, map: &Canvas, x0: usize, y0: usize) {
    for y in 0..map.height() {
        for x in 0..map.width() {
            let back = CHECKER[((x / 8) + (y / 8)) % 2];
            c.put(x0 + x, y0 + y, blend(map.get(x, y), back));
        }
    }
}

fn blend(top: Rgba, back: Rgba) -> Rgba {
    let a = top[3] as u32;
    let mix = |t: u8, b: u8| ((t as u32 * a + b as u32 * (255 - a) + 127) / 255) as u8;
    [mix(top[0], back[0]), mix(top[1], back[1]), mix(top[2], back[2]), 255]
}

fn draw_legend(c: &mut Canvas, legend: &Legend, x: usize, y: usize, row: usize) {
    c.text(x, y, &legend.title, BLACK, 1);
    let mut yy = y + Canvas::line_height(1) + 4;
    for e in &legend.entries {
        c.fill_rect(x, yy, SWATCH[0], SWATCH[1], blend(e.colour, CHECKER[0]));
        c.stroke_rect(x, yy, SWATCH[0], SWATCH[1], BLACK);
        c.text(x + SWATCH[0] + 6, yy + (SWATCH[1].saturating_sub(8)) / 2, &e.label, BLACK, 1);
        yy += row;
    }
    if let Some(n) = &legend.note {
        c.text(x, yy + 4, n, BLACK, 1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn legend(n: usize) -> Legend {
        let entries =
            (0..n).map(|k| LegendEntry { colour: [k as u8 * 20, 100, 40, 255], label: format!("class {k}") }).collect();
        Legend { title: "t (m)".into(), entries, note: None }
    }

    #[test]
    fn the_map_is_copied_one_to_one_at_its_offset() {
        let mut map = Canvas::filled(13, 9, [1, 2, 3, 255]);
        map.put(12, 8, [9, 8, 7, 255]);
        let f = with_legend(&map, "T", &legend(3));
        assert_eq!(f.canvas.get(f.map_x, f.map_y), [1, 2, 3, 255]);
        assert_eq!(f.canvas.get(f.map_x + 12, f.map_y + 8), [9, 8, 7, 255]);
    }

    #[test]
    fn every_entry_colour_appears_as_a_swatch_right_of_the_map() {
        let map = Canvas::filled(20, 5, [0, 0, 0, 0]);
        let l = legend(6);
        let f = with_legend(&map, "T", &l);
        for e in &l.entries {
            let found = (0..f.canvas.height())
                .any(|y| (f.map_x + 20..f.canvas.width()).any(|x| f.canvas.get(x, y) == e.colour));
            assert!(found, "swatch {:?}", e.colour);
        }
        // a tall legend makes the picture taller than the map
        assert!(f.canvas.height() > 6 * 14);
    }

    #[test]
    fn transparent_map_cells_show_the_checkerboard() {
        let map = Canvas::filled(16, 16, [0, 0, 0, 0]);
        let f = with_legend(&map, "T", &legend(1));
        assert_eq!(f.canvas.get(f.map_x, f.map_y), CHECKER[0]);
        assert_eq!(f.canvas.get(f.map_x + 8, f.map_y), CHECKER[1]);
    }
}
