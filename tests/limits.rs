//! Issue 40: limits.

mod common;
