//! A bar chart with a title, a y axis with round tick values and its unit, a label under each
//! bar and the value above it — the histogram figure of a comparison report.
//!
//! # Examples
//!
//! ```
//! use raster_picture::{bar_chart, Bar, BarChart};
//!
//! let chart = BarChart {
//!     title: "Cells per |dz| class".into(),
//!     x_label: "|dz| class (m)".into(),
//!     y_label: "% of cells".into(),
//!     bars: vec![
//!         Bar { label: "<0.1".into(), value: 80.0, colour: [0, 200, 40, 255] },
//!         Bar { label: ">=0.1".into(), value: 20.0, colour: [255, 0, 40, 255] },
//!     ],
//! };
//! let c = bar_chart(&chart);
//! assert!(c.width() > 2 * 40 && c.height() > 200);
//! ```

use crate::canvas::{Canvas, Rgba, BLACK, WHITE};

/// One bar: its label under the axis, its value (in the y axis' unit) and colour.
#[derive(Debug, Clone, PartialEq)]
pub struct Bar {
    pub label: String,
    pub value: f64,
    pub colour: Rgba,
}

#[derive(Debug, Clone, PartialEq)]
pub struct BarChart {
    pub title: String,
    pub x_label: String,
    /// The y axis' quantity and unit, e.g. "% of cells".
    pub y_label: String,
    pub bars: Vec<Bar>,
}

const MARGIN: usize = 10;
const PLOT_H: usize = 240;
const GRID: Rgba = [220, 220, 220, 255];

/// Draws the chart; bars are at least 40 px wide and wide enough for their labels.
pub fn bar_chart(chart: &BarChart) -> Canvas {
    let max = chart.bars.iter().map(|b| b.value).filter(|v| v.is_finite()).fold(0.0, f64::max);
    let (step, top) = nice_axis(max);
    let ticks: Vec<String> = (0..=((top / step).round() as usize)).map(|k| format_tick(k as f64 * step)).collect();
    let axis_w = ticks.iter().map(|t| Canvas::text_width(t, 1)).max().unwrap_or(8) + 6;
    let bar_w = chart.bars.iter().map(|b| Canvas::text_width(&b.label, 1) + 4).max().unwrap_or(0).max(40);
    let gap = 8;
    let plot_w = chart.bars.len() * (bar_w + gap) + gap;
    let title_h = Canvas::line_height(2) + 4;
    let (x0, y0) = (MARGIN + axis_w, MARGIN + title_h + Canvas::line_height(1) + 6);
    let width = (x0 + plot_w + MARGIN).max(2 * MARGIN + Canvas::text_width(&chart.title, 2));
    let height = y0 + PLOT_H + 2 * Canvas::line_height(1) + 8 + MARGIN;
    let mut c = Canvas::filled(width, height, WHITE);
    c.text(MARGIN, MARGIN, &chart.title, BLACK, 2);
    c.text(MARGIN, MARGIN + title_h, &chart.y_label, BLACK, 1);
    let y_of = |v: f64| y0 + PLOT_H - ((v / top).clamp(0.0, 1.0) * PLOT_H as f64).round() as usize;
    for (k, t) in ticks.iter().enumerate() {
        let y = y_of(k as f64 * step);
        c.fill_rect(x0, y, plot_w, 1, GRID);
        c.fill_rect(x0 - 4, y, 4, 1, BLACK);
        c.text(x0 - 6 - Canvas::text_width(t, 1), y.saturating_sub(4), t, BLACK, 1);
    }
    for (k, b) in chart.bars.iter().enumerate() {
        let x = x0 + gap + k * (bar_w + gap);
        let y = if b.value.is_finite() { y_of(b.value) } else { y0 + PLOT_H };
        c.fill_rect(x, y, bar_w, y0 + PLOT_H - y, b.colour);
        let value = format_tick(b.value);
        c.text(x + (bar_w.saturating_sub(Canvas::text_width(&value, 1))) / 2, y.saturating_sub(10), &value, BLACK, 1);
        c.text(x + (bar_w.saturating_sub(Canvas::text_width(&b.label, 1))) / 2, y0 + PLOT_H + 4, &b.label, BLACK, 1);
    }
    c.fill_rect(x0, y0, 1, PLOT_H + 1, BLACK);
    c.fill_rect(x0, y0 + PLOT_H, plot_w, 1, BLACK);
    let xl = &chart.x_label;
    c.text(
        x0 + plot_w.saturating_sub(Canvas::text_width(xl, 1)) / 2,
        y0 + PLOT_H + 4 + Canvas::line_height(1) + 4,
        xl,
        BLACK,
        1,
    );
    c
}

/// A tick step of 1, 2 or 5 × 10ⁿ giving 4–10 intervals, and the axis top (a multiple of it).
fn nice_axis(max: f64) -> (f64, f64) {
    if max.is_nan() || max <= 0.0 {
        return (1.0, 1.0);
    }
    let raw = max / 5.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0].iter().map(|m| m * mag).find(|s| *s >= raw).unwrap_or(10.0 * mag);
    (step, (max / step).ceil() * step)
}

fn format_tick(v: f64) -> String {
    let s = format!("{:.2}", v);
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".into()
    } else {
        s.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_steps_are_round_and_cover_the_maximum() {
        assert_eq!(nice_axis(61.2), (20.0, 80.0));
        assert_eq!(nice_axis(100.0), (20.0, 100.0));
        assert_eq!(nice_axis(0.37), (0.1, 0.4));
        assert_eq!(nice_axis(0.0), (1.0, 1.0));
    }

    #[test]
    fn bar_heights_are_proportional_to_values() {
        let bar = |v: f64, c: Rgba| Bar { label: "x".into(), value: v, colour: c };
        let chart = BarChart {
            title: "t".into(),
            x_label: "x".into(),
            y_label: "%".into(),
            bars: vec![bar(50.0, [255, 0, 0, 255]), bar(25.0, [0, 0, 255, 255])],
        };
        let c = bar_chart(&chart);
        let count = |col: Rgba| c.pixels().chunks(4).filter(|p| *p == col).count();
        let (red, blue) = (count([255, 0, 0, 255]), count([0, 0, 255, 255]));
        assert!((red as f64 / blue as f64 - 2.0).abs() < 0.05, "{red} vs {blue}");
    }

    #[test]
    fn ticks_print_without_trailing_zeros() {
        assert_eq!(format_tick(20.0), "20");
        assert_eq!(format_tick(0.25), "0.25");
        assert_eq!(format_tick(-0.0), "0");
    }
}
