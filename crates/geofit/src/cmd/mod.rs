//! One module per subcommand (alphabetical).

pub mod export;
pub mod implicit;
pub mod citygml2popa3d;
pub mod info;
pub mod obj2popa3d;
pub mod validate;
