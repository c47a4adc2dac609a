//! One module per subcommand (alphabetical).

pub mod info;
pub mod validate;
