//! End-to-end tests of the popa3d conversion commands (placeholder filled below).
mod common;
