//! Scale-out support: what one tile of a big job is, and how the per-tile results come together.
//!
//! geofit does not schedule anything: a workflow engine (Snakemake, make, a Slurm array, GNU
//! parallel) runs one `geofit` command per tile. This crate gives those commands their inputs
//! and merges their outputs:
//! - [`buildings::plan`]: every building-owning top-level object of a set of CityGML files goes
//!   to exactly one tile of a regular grid, by its footprint centroid; the grid size is the
//!   largest power of two (metres) that keeps every tile at or under a building budget.
//! - [`raster::plan`]: core, fit and halo windows (pixels and georeferenced) of a raster, cut
//!   along the whole fit's knot lattice; tiles without a valid cell marked (work 0).
//! - [`extract::extract`]: a tile's buildings as one CityGML document, member bytes copied.
//! - [`report::merge`]: per-tile `validate --json` and `heal --report` outputs summed.
//! - [`tileset::tileset`]: a 3D Tiles 1.1 `tileset.json` over per-tile glb.
//!
//! The rules (centroid assignment, halo buildings read-only, what a cut building does) are in
//! docs/decisions.md#scale-out-tiles-and-workflows.
//!
//! # Examples
//!
//! A 1000×600 raster cut into core windows of about 400 px along the whole fit's knot lattice
//! (cells of 32 px): adjacent cores, fit windows reaching the neighbour's first column,
//! 8-neighbourhoods, and the plan written as the JSON lines a workflow reads.
//!
//! ```
//! use tiling::plan::{write_plan, PlanFormat};
//! use tiling::raster::{fit_window, plan_grid, RasterTiling};
//! let gt = [500_000.0, 1.0, 0.0, 5_800_000.0, 0.0, -1.0];
//! let opts = RasterTiling { tile_pixels: Some(400), cells_per_tile: 0, halo: 2 };
//! let tiles = plan_grid("dem.tif", 1000, 600, gt, &opts).unwrap();
//! assert_eq!(tiles.len(), 3 * 2);
//! let cells: usize = tiles.iter().map(|t| t.work).sum();
//! assert_eq!(cells, 1000 * 600); // every cell in exactly one core
//! let first = &tiles[0];
//! let core = first.core.pixels.unwrap();
//! assert_eq!((core[0], core[1]), (0, 0));
//! assert!(core[2].abs_diff(400) <= 16); // the lattice line nearest 400 px
//! let fit = fit_window(&tiles, first).unwrap();
//! assert_eq!(fit.pixels[0] + fit.pixels[2], core[2] + 1); // the east seam's column, shared
//! assert_eq!(first.neighbours.len(), 3);
//! assert_eq!(write_plan(&tiles, PlanFormat::JsonLines).lines().count(), 6);
//! ```

pub mod buildings;
pub mod extract;
pub mod plan;
pub mod raster;
pub mod report;
pub mod tileset;

pub use plan::{Tile, TileKind, Window};

/// Why a plan, an extract, a report or a tileset cannot be made.
#[derive(Debug, thiserror::Error)]
pub enum TilingError {
    /// Options or a plan that do not fit together (exit 2 in the CLI).
    #[error("{0}")]
    Usage(String),
    /// An input that cannot be read or understood (exit 3).
    #[error("{name}: {message}")]
    Unreadable { name: String, message: String },
}

impl TilingError {
    pub(crate) fn unreadable(name: impl Into<String>, message: impl std::fmt::Display) -> Self {
        TilingError::Unreadable { name: name.into(), message: message.to_string() }
    }
}
