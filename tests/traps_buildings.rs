//! Traps (issue 41): traps_buildings.

mod common;
