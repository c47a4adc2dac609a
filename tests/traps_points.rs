//! Traps (issue 41): traps_points.

mod common;
