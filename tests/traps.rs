//! Traps (issue 41): traps.

mod common;
