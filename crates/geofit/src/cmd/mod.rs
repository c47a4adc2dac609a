//! One module per subcommand (alphabetical), plus `args`: option groups and checks they share.

pub mod args;

pub mod adjust;
pub mod citygml2popa3d;
pub mod completions;
pub mod convert;
pub mod diff;
pub mod eval;
pub mod export;
pub mod fit;
pub mod heal;
pub mod implicit;
pub mod info;
pub mod obj2popa3d;
pub mod observe;
pub mod popa3d2citygml;
pub mod rasterize;
pub mod surface;
pub mod tile;
pub mod unwarp;
pub mod validate;
pub mod warp;
