//! Traps (issue 41): traps_raster.

mod common;
