//! Placeholder: filled by the issue work of this session.

mod common;
