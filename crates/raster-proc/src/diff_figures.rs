//! The comparison's figures (spec §4.2): the error-class map framed with a title and a legend
//! (one swatch per class with its bounds and unit, grey and "no value" explained, the maximum
//! named) and the class histogram as a bar chart with axes. Both are what a person looks at;
//! the numbers are in the [`crate::diff::DiffReport`].
//!
//! # Examples
//!
//! ```
//! use raster_io::Raster;
//! use raster_proc::diff::{compare_with_map, DiffOptions};
//! use raster_proc::diff_figures::{error_map, histogram_chart};
//!
//! let a = Raster::from_values(4, 3, [0.0, 1.0, 0.0, 3.0, 0.0, -1.0], None, vec![0.0; 12]).unwrap();
//! let mut b = a.clone();
//! b.data[5] = 0.3;
//! let opts = DiffOptions::default();
//! let (report, classes) = compare_with_map(&a, &b, &opts).unwrap();
//! let map = error_map(&report, &classes, &opts, "m", "A vs B");
//! assert!(map.canvas.width() > 4 && map.map_x > 0);
//! let chart = histogram_chart(&report, "m");
//! assert_eq!(chart.bars.len(), opts.class_bounds.len() + 1);
//! ```

use raster_picture::{with_legend, Bar, BarChart, Canvas, Framed, Legend, LegendEntry};

use crate::diff::{class_colour, class_map_rgba, CellClass, DiffOptions, DiffReport, ErrorClass, ONE_RASTER_ONLY};

/// The error-class map (A's grid, one pixel per cell) under `title`, with its legend.
pub fn error_map(report: &DiffReport, classes: &[CellClass], opts: &DiffOptions, unit: &str, title: &str) -> Framed {
    let n = opts.class_bounds.len() + 1;
    let map = Canvas::from_rgba(report.width, report.height, class_map_rgba(classes, n));
    let mut entries: Vec<LegendEntry> = report
        .histogram
        .iter()
        .enumerate()
        .map(|(k, c)| LegendEntry { colour: class_colour(k, n), label: class_label(c) })
        .collect();
    entries.push(LegendEntry { colour: ONE_RASTER_ONLY, label: "value in one raster only".into() });
    entries.push(LegendEntry { colour: [0, 0, 0, 0], label: "no value".into() });
    let note = report.max_at.map(|[c, r]| format!("max {:.4} {unit} at col {c} row {r}", report.max_abs));
    with_legend(&map, title, &Legend { title: format!("|dz| = |B - A| ({unit})"), entries, note })
}

/// The class histogram: one bar per class, in the map's colours, as % of the compared cells.
pub fn histogram_chart(report: &DiffReport, unit: &str) -> BarChart {
    let n = report.histogram.len();
    let bars = report
        .histogram
        .iter()
        .enumerate()
        .map(|(k, c)| Bar { label: class_label(c), value: 100.0 * c.share, colour: class_colour(k, n) })
        .collect();
    BarChart {
        title: format!("|dz| classes of {} cells", report.cells_compared),
        x_label: format!("|dz| class ({unit})"),
        y_label: "% of compared cells".into(),
        bars,
    }
}

/// "< 0.01", "0.01-0.02", ">= 2": the class' bounds as a reader writes them.
fn class_label(c: &ErrorClass) -> String {
    match c.to {
        Some(t) if c.from == 0.0 => format!("< {t}"),
        Some(t) => format!("{}-{t}", c.from),
        None => format!(">= {}", c.from),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn class(from: f64, to: Option<f64>) -> ErrorClass {
        ErrorClass { from, to, count: 0, share: 0.0 }
    }

    #[test]
    fn labels_name_both_bounds_and_the_open_ends() {
        assert_eq!(class_label(&class(0.0, Some(0.01))), "< 0.01");
        assert_eq!(class_label(&class(0.01, Some(0.02))), "0.01-0.02");
        assert_eq!(class_label(&class(2.0, None)), ">= 2");
    }
}
