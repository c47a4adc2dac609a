//! End-to-end tests of the T-spline commands (`geofit fit`, `geofit eval`).
mod common;
