//! Pictures a person reads rather than a program: an error map with its legend, a histogram
//! with axes, each with a title and units, encoded as PNG; and the world file that puts a map
//! picture where it belongs in GIS viewers (QGIS, GDAL, ArcGIS read `.pgw`).
//!
//! The pictures are drawn on a plain RGBA [`Canvas`] with an 8×8 bitmap font (`font8x8`,
//! Latin and Greek), so they look the same on every machine: no system fonts, no renderer.
//!
//! # Examples
//!
//! ```
//! use raster_picture::{Canvas, Legend, LegendEntry, with_legend};
//!
//! let map = Canvas::filled(40, 30, [0, 160, 40, 255]);
//! let legend = Legend {
//!     title: "|dz| (m)".into(),
//!     entries: vec![LegendEntry { colour: [0, 160, 40, 255], label: "< 0.01".into() }],
//!     note: None,
//! };
//! let picture = with_legend(&map, "Errors", &legend);
//! assert!(picture.canvas.width() > map.width());
//! let png = picture.canvas.to_png().unwrap();
//! assert_eq!(&png[1..4], b"PNG");
//! ```

mod canvas;
mod chart;
mod legend;
mod world;

pub use canvas::{Canvas, Rgba, BLACK, WHITE};
pub use chart::{bar_chart, Bar, BarChart};
pub use legend::{with_legend, Framed, Legend, LegendEntry};
pub use world::{aux_xml, sidecar_paths, world_file};

/// Why a picture could not be made.
#[derive(Debug, thiserror::Error)]
pub enum PictureError {
    #[error("PNG encoding: {0}")]
    Png(#[from] png::EncodingError),
    #[error("picture of {width}×{height} pixels is too large for PNG")]
    TooLarge { width: usize, height: usize },
}
