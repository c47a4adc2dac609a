//! `geofit`: composable Unix-style subcommands for GIS and CAD data conversion.
//!
//! One file per subcommand under `cmd/`, each with its usage text, an `Args` struct and a `run`.
//! The algorithms live in the library crates; this crate parses arguments, opens inputs,
//! writes outputs atomically and maps errors to exit codes (see `error::Exit`).

mod cmd;
mod config;
mod error;
mod mesh_output;
mod process_stats;
mod report;
mod terrain_io;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
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

    /// Write the outputs of a step that fails with exit 1 anyway (a fit that stopped short of
    /// --max-error, `diff --check` over its tolerance). Without it such a step writes no data
    /// file (its report still), so `make` does not take a failed result for a finished one; a
    /// file already at -o is left as it was.
    #[arg(long, global = true)]
    keep_partial: bool,

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
    /// Print shell completions (bash, zsh, fish, elvish, powershell).
    Completions(cmd::completions::Args),
    /// Convert buildings between CityGML (1.0, 2.0, 3.0) and CityJSON 2.0 / CityJSONSeq.
    Convert(cmd::convert::Args),
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
    /// Print the man page (roff) of geofit or of one subcommand.
    Man(cmd::completions::ManArgs),
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

/// GDAL spells multi-letter options with one dash (`-of GTiff -co COMPRESS=ZSTD -ot Float32`);
/// geofit accepts those three as GDAL users type them (clap would read `-of` as `-o f`).
fn gdal_style_options(args: impl Iterator<Item = std::ffi::OsString>) -> Vec<std::ffi::OsString> {
    args.map(|a| match a.to_str() {
        Some("-of") => "--of".into(),
        Some("-co") => "--co".into(),
        Some("-ot") => "--ot".into(),
        _ => a,
    })
    .collect()
}

/// `geofit --version`: the program's version and the libraries it runs on (GDAL and PROJ as
/// loaded at run time, the OpenCL platforms the ICD loader finds).
fn long_version() -> String {
    let gdal = raster_io::gdal_io::gdal_version();
    let proj = {
        use proj::Info;
        proj::ProjBuilder::new()
            .info()
            .map(|i| format!("PROJ {}", i.version))
            .unwrap_or_else(|_| "PROJ (unknown)".into())
    };
    let opencl = match ocl::core::get_platform_ids() {
        Ok(ids) if !ids.is_empty() => ids
            .iter()
            .map(|p| {
                let name = ocl::core::get_platform_info(p, ocl::core::PlatformInfo::Name)
                    .map(|i| i.to_string())
                    .unwrap_or_default();
                let version = ocl::core::get_platform_info(p, ocl::core::PlatformInfo::Version)
                    .map(|i| i.to_string())
                    .unwrap_or_default();
                format!("{name} ({version})")
            })
            .collect::<Vec<_>>()
            .join("; "),
        _ => "no platform found (CPU evaluation)".into(),
    };
    format!("{}\n{gdal}\n{proj}\nOpenCL: {opencl}", env!("CARGO_PKG_VERSION"))
}

fn main() -> ExitCode {
    // A file-size limit (`ulimit -f`) makes the kernel send SIGXFSZ, which kills the process
    // silently and leaves its temporary file; ignored, the write fails with EFBIG and takes the
    // ordinary error path (message, exit 4, temporary file removed).
    // SAFETY: installs SIG_IGN for one signal before any thread starts.
    unsafe {
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
    }
    let args = gdal_style_options(std::env::args_os());
    let mut command = Cli::command();
    // The library versions are looked up only when asked for (OpenCL start-up is not free).
    if args.iter().any(|a| a == "--version") {
        command = command.long_version(long_version());
    }
    let matches = match command.clone().try_get_matches_from(&args) {
        Ok(m) => m,
        Err(e) => e.exit(),
    };
    let cli = match Cli::from_arg_matches(&matches) {
        Ok(cli) => cli,
        Err(e) => e.exit(),
    };
    if let Err(e) = config::check_output_args(&matches) {
        crate::say!("geofit: error: {}", e.message);
        return e.exit.into();
    }
    let config = Config { quiet: cli.quiet, keep_partial: cli.keep_partial };
    let result = match cli.command {
        Command::Completions(a) => cmd::completions::run(a, Cli::command()),
        Command::Man(a) => cmd::completions::run_man(a, Cli::command()),
        Command::Implicit(a) => cmd::implicit::run(a, &config),
        Command::Heal(a) => cmd::heal::run(a, &config),
        Command::Convert(a) => cmd::convert::run(a, &config),
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
    // Every file output is renamed into place here, together, or not at all.
    let result = result.and_then(|exit| config::commit_outputs().map(|()| exit));
    if result.is_err() {
        config::discard_outputs();
    }
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
