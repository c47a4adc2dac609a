//! One module per subcommand (alphabetical).

pub mod implicit;
pub mod info;
pub mod validate;
