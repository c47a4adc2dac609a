//! `geofit surface`: a T-mesh's surface as a triangle mesh (glb / gltf / obj) with vertex colours
//! by height or by error against a reference raster, and the T-mesh cell edges as a separate
//! line node. The tessellation is `tspline::tessellate`'s; the options and the writing are shared
//! with `geofit export` (which takes T-mesh input too) through [`crate::mesh_output`].

use clap::Args as ClapArgs;

use crate::config::{Config, Output};
use crate::error::{CliError, CmdResult};
use crate::mesh_output::{tessellate, Format, SurfaceOptions};
use crate::terrain_io::read_tmesh_arg;

const EXAMPLE: &str = "\
Example:
  $ geofit fit bathy.tif -o bathy.tmesh --max-error 0.5
  $ geofit surface bathy.tmesh -o bathy.glb                          # colours by height
  $ geofit surface bathy.tmesh -o err.glb --reference bathy.tif      # colours by |dz| class
  $ geofit surface bathy.tmesh -o bathy.obj --step 4                 # also writes bathy.mtl

The surface is sampled every --step parameter units (raster cells; default: about 512 samples
along the longer side), masked by the data mask stored in the mesh unless --no-mask; a grid quad
becomes two triangles when its four corners have values. Node `surface` holds the triangles,
node `tmesh` the leaf-cell edges draped on the surface. Error colours: green < 0.1, yellow < 0.5,
orange < 1, red >= 1 (raster units), grey where the reference has no value.";

#[derive(ClapArgs, Debug)]
#[command(about = "Tessellate a T-mesh surface to glb/gltf/obj (height or error colours, T-mesh lines)", after_help = EXAMPLE)]
pub struct Args {
    /// T-mesh file (`-` = stdin).
    pub mesh: String,
    /// Output (.glb, .gltf or .obj; `-` or none = glb on stdout).
    #[arg(short, long)]
    pub output: Option<String>,
    #[command(flatten)]
    pub opts: SurfaceOptions,
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    let output = Output::from_arg(args.output.as_deref());
    let format = match output.extension().as_deref() {
        Some("obj") => Format::Obj,
        Some("gltf") => Format::Gltf,
        Some("glb") | None => Format::Glb,
        Some(other) => {
            return Err(CliError::usage(format!("unknown output format .{other} (use .glb, .gltf or .obj)")))
        }
    };
    let file = read_tmesh_arg(&args.mesh)?;
    tessellate(file, &args.mesh, &output, format, &args.opts, config)
}
