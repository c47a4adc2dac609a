//! End-to-end tests of `geofit validate` (filled in below).
mod common;
