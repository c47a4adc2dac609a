//! The terrain data arguments the subcommands share: rasters, point clouds and T-meshes read
//! from a path or stdin and written to `-o`, the raster output options (`-of`, `-co`, `-ot`),
//! `--device`, and the one-line messages of the terrain libraries' errors. Subcommands call these
//! instead of each other (one module per subcommand, none importing another).

use clap::{Args as ClapArgs, ValueEnum};
use raster_io::{read_xyz, PointCloud, PointsError, Raster, RasterError, RasterFormat, SampleType, WriteOptions};
use raster_proc::ProcError;

use crate::config::{Config, Input, Output};
use crate::error::CliError;

mod tmesh;
pub use tmesh::{read_tmesh_arg, select_device, tspline_err};

/// `--device`: where dense evaluations run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Device {
    /// OpenCL when a platform exists and the kernels build, otherwise the CPU (with a notice).
    Auto,
    /// OpenCL or fail.
    Opencl,
    /// Multi-threaded CPU (rayon).
    Cpu,
}

/// `--ot`: the band type of a raster output.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OutType {
    Float32,
    Float64,
}

/// How a raster output is written, with GDAL's option names (`-of`, `-co`, `-ot` are accepted
/// with one dash, as in gdal_translate).
#[derive(ClapArgs, Debug, Clone, Default)]
#[command(next_help_heading = "Raster output (GDAL)")]
pub struct RasterOutArgs {
    /// Output format (`-of` as in gdal_translate): a GDAL driver name (COG, GTiff, AAIGrid,
    /// netCDF, GS7BG, ...); default from the -o extension, and a .tif (or stdout) is a
    /// Cloud-Optimised GeoTIFF (COG).
    #[arg(long = "of", value_name = "FORMAT")]
    pub of: Option<String>,
    /// GDAL creation option KEY=VALUE (`-co`, repeatable); replaces geofit's default for that key
    /// (COG/GTiff: COMPRESS=DEFLATE with the floating-point predictor; AAIGrid: 17 digits).
    #[arg(long = "co", value_name = "KEY=VALUE")]
    pub co: Vec<String>,
    /// Band type of the output (`-ot`; default: the input raster's float type — Float32 for Float32
    /// and 8/16-bit input, else Float64 — and Float64 for points and T-meshes).
    #[arg(long = "ot", value_enum, ignore_case = true)]
    pub ot: Option<OutType>,
}

impl RasterOutArgs {
    /// The write options for an output derived from input of type `input` (`None` = no raster
    /// input: Float64), checked against the driver before the work: refusals are usage errors.
    pub fn checked(&self, output: Option<&str>, input: Option<SampleType>) -> Result<WriteOptions, CliError> {
        let out = Output::from_arg(output);
        let opts = WriteOptions {
            format: self.of.as_deref().map(RasterFormat::from_driver_name),
            creation_options: self.co.clone(),
            sample_type: match self.ot {
                Some(OutType::Float32) => SampleType::Float32,
                Some(OutType::Float64) => SampleType::Float64,
                None => input.unwrap_or_default(),
            },
        };
        raster_io::check_write(out.path(), &opts).map_err(raster_err)?;
        out.check_target()?;
        Ok(opts)
    }
}

/// One line for a raster-io error (its message already names the file).
pub fn raster_err(e: RasterError) -> CliError {
    match e {
        RasterError::Format(_) => CliError::usage(e.to_string()),
        RasterError::Open { .. } | RasterError::Content { .. } | RasterError::TooLarge { .. } => {
            CliError::unreadable(e.to_string())
        }
        RasterError::Write { .. } => CliError::output(e.to_string()),
        RasterError::Invalid(_) => CliError::findings(e.to_string()),
    }
}

/// One line for a point-file error.
pub fn points_err(e: PointsError) -> CliError {
    CliError::unreadable(e.to_string())
}

/// One line for a processing error, prefixed with what was being processed.
pub fn proc_err(what: &str, e: ProcError) -> CliError {
    match e {
        ProcError::Raster(r) => raster_err(r),
        ProcError::Input(m) => CliError::findings(format!("{what}: {m}")),
        ProcError::FoldOver(_) => CliError::findings(format!("{what}: {e}")),
        ProcError::TooLarge { .. } | ProcError::TinTooLarge { .. } => CliError::unreadable(format!("{what}: {e}")),
        ProcError::Field(_) => CliError::unreadable(format!("{what}: {e}")),
    }
}

/// Shows GDAL's warnings as geofit notices (one line each, silent under `--quiet`) instead of
/// GDAL's own "Warning 1: ..." lines.
pub fn gdal_notices(config: &Config) {
    let quiet = config.quiet;
    raster_io::gdal_io::route_gdal_warnings(move |m| {
        if !quiet {
            crate::say!("geofit: GDAL: {m}");
        }
    });
}

/// Reads a raster from a path argument (GDAL needs a path; stdin is spooled to a temp file).
/// GDAL's virtual paths (`/vsigzip/x.tif.gz`, `/vsizip/a.zip/x.tif`) are read as GDAL reads them.
pub fn read_raster_arg(arg: &str) -> Result<(Raster, String), CliError> {
    read_raster_arg_typed(arg).map(|(r, name, _)| (r, name))
}

/// [`read_raster_arg`] with the float type that holds the raster's values (kept on output).
pub fn read_raster_arg_typed(arg: &str) -> Result<(Raster, String, SampleType), CliError> {
    read_raster_arg_band(arg, Band::Only)
}

/// Which band of a raster input a command reads (docs/decisions.md#raster-units-bands-and-no-data-issue-41).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Band {
    /// The only band, or band 1 of a survey whose bands say so (see [`choose_band`]).
    Only,
    /// `-b N` (1-based, as GDAL counts).
    Given(usize),
    /// Band 1 whatever the count (`--like`: the grid and its no-data cells).
    First,
    /// Band 1 of two when band 2 is read as its uncertainty (`--max-error-from-uncertainty`).
    ElevationOfSurvey,
}

/// The band `choice` picks in the file at `path`: a multi-band file without `-b` is refused
/// (a 4-band Terrain-RGB PNG is not its red band, a grey + alpha PNG not surely its grey),
/// unless band 1 is a survey's elevation (a BAG: bands "elevation" and "uncertainty", or two
/// bands read with `--max-error-from-uncertainty`).
pub fn choose_band(path: &std::path::Path, name: &str, choice: Band) -> Result<usize, CliError> {
    let bands = raster_io::bands(path).map_err(raster_err)?;
    let n = bands.len();
    let survey = bands.first().is_some_and(|b| b.description.eq_ignore_ascii_case("elevation"))
        || bands.iter().any(|b| b.description.eq_ignore_ascii_case("uncertainty"));
    match choice {
        Band::Given(b) if b == 0 || b > n => Err(CliError::usage(format!("-b {b}: {name} has {n} band(s) (1 to {n})"))),
        Band::Given(b) => Ok(b),
        Band::First => Ok(1),
        _ if n <= 1 || survey || (choice == Band::ElevationOfSurvey && n == 2) => Ok(1),
        _ => {
            let what: Vec<String> = bands
                .iter()
                .map(|b| if b.description.is_empty() { b.color.clone() } else { b.description.clone() })
                .collect();
            Err(CliError::usage(format!(
                "{name} has {n} bands ({}): choose the heights with -b N (GDAL's band number)",
                what.join(", ")
            )))
        }
    }
}

/// [`read_raster_arg_typed`] of the band `choice` picks.
pub fn read_raster_arg_band(arg: &str, choice: Band) -> Result<(Raster, String, SampleType), CliError> {
    let input = Input::from_arg(arg);
    let name = input.display_name();
    match input.path() {
        Some(p) => {
            let band = choose_band(p, &name, choice)?;
            let (r, t) = raster_io::read_raster_band_typed(p, band).map_err(raster_err)?;
            Ok((r, name, t))
        }
        None => {
            let (r, t) = raster_from_stdin_bytes_typed(&input.read_all()?, choice)?;
            Ok((r, name, t))
        }
    }
}

/// The unit of `r`'s heights (`--z-unit` first, then what the file declares); `None` when
/// nothing declares one. An unknown unit is refused in one line naming it and `--z-unit`.
pub fn z_unit_of(r: &Raster, name: &str, given: Option<&str>) -> Result<Option<raster_io::units::ZUnit>, CliError> {
    raster_io::units::resolve_z_unit(r.z_unit.as_deref(), r.crs.as_deref(), given).map_err(|m| match given {
        Some(_) => CliError::usage(m),
        None => CliError::unreadable(format!("{name}: {m}")),
    })
}

/// A raster from bytes read on stdin: GDAL opens paths, so they are spooled to a temporary file
/// (errors name `<stdin>`, not the spool file).
pub fn raster_from_stdin_bytes(bytes: &[u8]) -> Result<Raster, CliError> {
    raster_from_stdin_bytes_typed(bytes, Band::First).map(|(r, _)| r)
}

/// [`raster_from_stdin_bytes`] with the raster's float type.
fn raster_from_stdin_bytes_typed(bytes: &[u8], choice: Band) -> Result<(Raster, SampleType), CliError> {
    let dir = tempfile::tempdir().map_err(|e| CliError::internal(format!("temporary directory: {e}")))?;
    let p = dir.path().join("stdin.raster");
    std::fs::write(&p, bytes).map_err(|e| CliError::internal(format!("temporary file: {e}")))?;
    let spool = p.display().to_string();
    let band = choose_band(&p, "<stdin>", choice).map_err(|mut e| {
        e.message = e.message.replace(&spool, "<stdin>");
        e
    })?;
    raster_io::read_raster_band_typed(&p, band)
        .map_err(|e| CliError::unreadable(e.to_string().replace(&spool, "<stdin>")))
}

/// Writes a raster to `-o` as `opts` says (stdout: the format's bytes, COG by default).
pub fn write_raster_arg(r: &Raster, output: Option<&str>, opts: &WriteOptions) -> Result<(), CliError> {
    let out = Output::from_arg(output);
    match out.path() {
        Some(p) => {
            // raster-io stages into `.geofit-raster-PID-N.tmp` beside the target
            crate::config::clean_stale_temps(
                p.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(std::path::Path::new(".")),
            );
            raster_io::write_raster(r, p, opts).map_err(raster_err)
        }
        None => {
            let bytes = raster_io::gdal_io::raster_to_bytes(r, opts).map_err(raster_err)?;
            out.write_bytes(&bytes)
        }
    }
}

/// Reads a point cloud argument (XYZ/CSV, LAS/LAZ; stdin: XYZ text), LAS points of `class` only.
pub fn read_cloud(arg: &str, class: Option<u8>) -> Result<PointCloud, CliError> {
    let input = Input::from_arg(arg);
    match input.path() {
        Some(p) => raster_io::read_points(p, class).map_err(points_err),
        None => {
            if class.is_some() {
                return Err(CliError::usage("--class needs a LAS/LAZ file, not stdin"));
            }
            read_xyz(input.open()?, "<stdin>").map_err(points_err)
        }
    }
}

/// `r` in the fit's parameter layout (`tspline_raster::layout`), errors naming the input.
pub fn raster_layout(r: Raster, name: &str) -> Result<tspline_raster::layout::Layout, CliError> {
    // a rotated grid is input the fit cannot take (exit 3), not a finding of the fit
    tspline_raster::layout::samples_from_raster(r).map_err(|e| CliError::unreadable(format!("{name}: {e}")))
}
