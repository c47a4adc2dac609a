//! Issue 40: crashes.

mod common;
