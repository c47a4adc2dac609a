//! `geofit`: composable Unix-style subcommands for GIS and CAD data conversion.
//!
//! One file per subcommand under `cmd/`, each with its usage text, an `Args` struct and a `run`.
//! The algorithms live in the library crates; this crate parses arguments, opens inputs,
//! writes outputs atomically and maps errors to exit codes (see `error::Exit`).

mod cmd;
mod config;
mod error;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

use config::Config;
use error::Exit;

#[derive(Parser)]
#[command(
    name = "geofit",
    version,
    about = "Composable subcommands for CityGML buildings, T-spline terrain and implicit surfaces",
    long_about = "geofit: composable subcommands for CityGML buildings (popa3d adjustment), \
T-spline terrain reduction and implicit surfaces.\n\nEvery command reads a path or `-` (stdin) and \
writes to `-o PATH` (stdout when `-o` is missing or `-`).\n\nExit codes: 0 success, 1 findings in the \
input (listed), 2 usage error, 3 unreadable input, 4 internal failure."
)]
struct Cli {
    /// No progress bars or stage lines on stderr.
    #[arg(long, short, global = true)]
    quiet: bool,

    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    // One line per subcommand; keep alphabetical. Each `cmd::<name>` module has `Args` and `run`.
    /// Least-squares adjustment of a popa3d model: Gauss–Helmert, datum, statistics, blunders.
    Adjust(cmd::adjust::Args),
    /// CityGML buildings to a normalized popa3d model with conditions from their semantics.
    Citygml2popa3d(cmd::citygml2popa3d::Args),
    /// Compare two rasters: |dz| statistics, error classes, error-class map PNG.
    Diff(cmd::diff::Args),
    /// Evaluate a T-mesh surface on a raster grid (GeoTIFF, netCDF, ASCII grid).
    Eval(cmd::eval::Args),
    /// Export CityGML buildings (or a T-mesh surface) as triangle meshes: glb, glTF or OBJ (+MTL).
    Export(cmd::export::Args),
    /// Fit a T-spline surface (T-mesh) to a raster within a maximum error.
    Fit(cmd::fit::Args),
    /// CityGML → popa3d → adjustment → CityGML in one step, for buildings that fail planarity.
    Heal(cmd::heal::Args),
    /// Implicit surfaces by DSI on adaptive tetrahedral meshes.
    Implicit(cmd::implicit::Args),
    /// Summarise a CityGML file (or a T-mesh, raster or point file): counts, extent, CRS.
    Info(cmd::info::Args),
    /// An OBJ sketch of rooms to a popa3d model with sketch priors, plus measured distances (CSV).
    Obj2popa3d(cmd::obj2popa3d::Args),
    /// Attach measured distances (CSV) to a popa3d model, for the next adjustment.
    Observe(cmd::observe::Args),
    /// Write an (adjusted) popa3d model back into the original CityGML file.
    Popa3d2citygml(cmd::popa3d2citygml::Args),
    /// Grid scattered points (XYZ/CSV, LAS/LAZ) into a raster: Gauss splat or TIN-linear.
    Rasterize(cmd::rasterize::Args),
    /// Tessellate a T-mesh surface to glb/gltf/obj (height or error colours, T-mesh lines).
    Surface(cmd::surface::Args),
    /// Scale-out: tile plans, per-tile extracts, merged reports and a 3D Tiles tileset.
    Tile(cmd::tile::Args),
    /// Map a warped raster back onto its original grid (field read from the raster itself).
    Unwarp(cmd::unwarp::Args),
    /// Validate CityGML: XSD schema (libxml2) and geometry (val3dity/QIE codes).
    Validate(cmd::validate::Args),
    /// Rotate and warp a raster to fill a rectangle (indirect reduction); the field travels inside it.
    Warp(cmd::warp::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let config = Config { quiet: cli.quiet };
    let result = match cli.command {
        Command::Implicit(a) => cmd::implicit::run(a, &config),
        Command::Heal(a) => cmd::heal::run(a, &config),
        Command::Observe(a) => cmd::observe::run(a, &config),
        Command::Popa3d2citygml(a) => cmd::popa3d2citygml::run(a, &config),
        Command::Adjust(a) => cmd::adjust::run(a, &config),
        Command::Diff(a) => cmd::diff::run(a, &config),
        Command::Eval(a) => cmd::eval::run(a, &config),
        Command::Export(a) => cmd::export::run(a, &config),
        Command::Fit(a) => cmd::fit::run(a, &config),
        Command::Surface(a) => cmd::surface::run(a, &config),
        Command::Citygml2popa3d(a) => cmd::citygml2popa3d::run(a, &config),
        Command::Info(a) => cmd::info::run(a, &config),
        Command::Obj2popa3d(a) => cmd::obj2popa3d::run(a, &config),
        Command::Rasterize(a) => cmd::rasterize::run(a, &config),
        Command::Tile(a) => cmd::tile::run(a, &config),
        Command::Unwarp(a) => cmd::unwarp::run(a, &config),
        Command::Validate(a) => cmd::validate::run(a, &config),
        Command::Warp(a) => cmd::warp::run(a, &config),
    };
    match result {
        Ok(exit) => exit.into(),
        Err(e) => {
            // A closed stdout (e.g. `geofit ... | head`) is not an error worth a message.
            if e.message.contains("Broken pipe") {
                return Exit::Ok.into();
            }
            crate::say!("geofit: error: {}", e.message);
            e.exit.into()
        }
    }
}
