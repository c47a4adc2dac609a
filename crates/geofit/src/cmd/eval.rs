//! `geofit eval`: evaluates a T-mesh's surface on a raster grid (spec §6.4 surface evaluation,
//! §2.2 masking), on OpenCL or the CPU.

use clap::Args as ClapArgs;

use raster_io::{Raster, WriteOptions};
use tspline::format::DataMask;
use tspline::format::TMeshFile;
use tspline::PbSpline;
use tspline_raster::layout::{EvalGrid, Footprint, Params};

use crate::config::Config;
use crate::error::{CliError, CmdResult, Exit};
use crate::terrain_io::{gdal_notices, read_raster_arg_band, write_raster_arg, Band, RasterOutArgs};
use crate::terrain_io::{read_tmesh_arg, select_device, tspline_err, Device};

const EXAMPLE: &str = "\
Example:
  $ geofit fit bathy.tif -o bathy.tmesh --max-error 0.5
  $ geofit eval bathy.tmesh -o surface.tif            # the fitted raster's grid, masked by its data
  $ geofit eval bathy.tmesh -o full.tif --no-mask     # also the holes and survey gaps
  $ geofit eval bathy.tmesh -o on-b.tif --like other.tif          # other.tif's grid and no-data cells
  $ geofit eval bathy.tmesh -o filled.tif --like other.tif --fill   # also other.tif's no-data cells
  $ geofit diff bathy.tif surface.tif --tolerance 0.5

Without --like the grid is the one the mesh was fitted on (stored in the .tmesh with its data
mask), cells without data stay nodata unless --no-mask; without a stored mask the grid covers the
mesh domain at the parameter spacing. --like takes size, geotransform, CRS and the no-data cells
from a raster (band 1): its no-data cells stay no data, with its nodata marker, unless --fill
(or --no-mask). --mask keeps only cells valid in a raster of the output's size. Outside the mesh
domain: nodata. Heights are in the unit of the raster the mesh was fitted on.";

#[derive(ClapArgs, Debug)]
#[command(about = "Evaluate a T-mesh surface on a raster grid (GeoTIFF, netCDF, ASCII grid)", after_help = EXAMPLE)]
pub struct Args {
    /// T-mesh file (`-` = stdin).
    pub mesh: String,
    /// Output raster (format from the extension; `-` or none = GeoTIFF on stdout).
    #[arg(short, long)]
    pub output: Option<String>,
    /// Take the output grid (size, geotransform, CRS) from this raster.
    #[arg(long)]
    pub like: Option<String>,
    /// Keep only cells that have a value in this raster (same size as the output).
    #[arg(long)]
    pub mask: Option<String>,
    /// Do not apply the data mask stored in the T-mesh (with --like: as --fill).
    #[arg(long)]
    pub no_mask: bool,
    /// With --like: evaluate its no-data cells too (by default they stay no data).
    #[arg(long, requires = "like")]
    pub fill: bool,
    /// Where the evaluation runs.
    #[arg(long, value_enum, default_value_t = Device::Auto)]
    pub device: Device,
    /// Print the evaluation throughput (points/s, flops per point) on stderr.
    #[arg(long)]
    pub timing: bool,
    #[command(flatten)]
    pub raster_out: RasterOutArgs,
}

/// The output grid: --like's, the original raster of an indirect mesh, or the fitted raster's.
fn output_grid(args: &Args, file: &TMeshFile, write_opts: &mut WriteOptions) -> Result<EvalGrid, CliError> {
    let g = &file.georef;
    // Indirect meshes: output cells are mapped forward through the stored field (spec §2.3.3)
    // and the default grid is the original raster's, masked by its footprint.
    let field = match &file.warp {
        Some(json) => Some(
            raster_proc::warp::WarpField::from_json(json)
                .map_err(|e| CliError::unreadable(format!("{}: <warp>: {e}", args.mesh)))?,
        ),
        None => None,
    };
    let mapper = field.as_ref().map(|f| f.mapper());
    let to_param = |x: f64, y: f64| match &mapper {
        Some(m) => {
            let q = m.forward([x, y]);
            g.param(q[0], q[1])
        }
        None => g.param(x, y),
    };
    let crs = if g.crs.is_empty() { None } else { Some(g.crs.clone()) };
    if let Some(like) = &args.like {
        let (r, name, like_type) = read_raster_arg_band(like, Band::First)?;
        // The output's band type follows --like (a Float32 grid gets a Float32 surface).
        *write_opts = args.raster_out.checked(args.output.as_deref(), Some(like_type))?;
        let mut grid = EvalGrid::like(&r, crs, to_param).map_err(|e| CliError::unreadable(format!("{name}: {e}")))?;
        // No-data cells of --like stay no data, with its marker (no phantom shoals), unless --fill.
        grid.raster.nodata = r.nodata;
        if !(args.fill || args.no_mask) {
            let mask = DataMask { width: r.width, height: r.height, bits: r.valid_mask() };
            grid.mask = Some(Footprint { mask, rows_from_bottom: false });
        }
        return Ok(grid);
    }
    if let Some(src) = field.as_ref().and_then(|f| f.source.as_ref()) {
        return EvalGrid::of_warp_source(src, crs, to_param)
            .map_err(|e| CliError::unreadable(format!("{}: <warp> source grid: {e}", args.mesh)));
    }
    match &file.mask {
        Some(m) => Ok(EvalGrid::of_mask(g, m)),
        None => {
            let b = file.mesh.bounds();
            EvalGrid::of_domain(g, b.s_min, b.s_max, b.t_min, b.t_max)
                .map_err(|e| CliError::usage(format!("{}: {e}; pass --like", args.mesh)))
        }
    }
}

/// --mask: a raster of the output's size whose cells without a value stay empty.
fn extra_mask(args: &Args, out: &Raster) -> Result<Option<Raster>, CliError> {
    let Some(m) = &args.mask else { return Ok(None) };
    let (r, name, _) = read_raster_arg_band(m, Band::First)?;
    if r.width != out.width || r.height != out.height {
        return Err(CliError::usage(format!(
            "--mask {name} is {}×{}, the output grid is {}×{}",
            r.width, r.height, out.width, out.height
        )));
    }
    Ok(Some(r))
}

fn evaluate(args: &Args, config: &Config, file: &TMeshFile, params: &Params) -> Result<Vec<f64>, CliError> {
    let ocl = select_device(args.device, config)?;
    let pb = match &ocl {
        Some(o) => o.build_pbspline(&file.mesh).map_err(|e| tspline_err(&args.mesh, e))?,
        None => PbSpline::build(&file.mesh),
    };
    let t0 = std::time::Instant::now();
    let parallel = tspline::worker_threads() > 1;
    let z = match &ocl {
        Some(o) => {
            let sp = o.upload(&pb).map_err(|e| tspline_err(&args.mesh, e))?;
            match params {
                Params::List(st) => o.eval_points(&sp, st),
                Params::Grid(gs) => o.eval_grid(&sp, gs),
            }
            .map_err(|e| tspline_err(&args.mesh, e))?
        }
        None => match params {
            Params::List(st) => pb.eval_z(st, parallel),
            Params::Grid(gs) => pb.eval_grid(gs, parallel),
        },
    };
    if args.timing {
        let secs = t0.elapsed().as_secs_f64();
        let st = params.list();
        let dev = match &ocl {
            Some(o) => format!("opencl {}", o.device_name()),
            None => format!("cpu, {} thread(s)", tspline::worker_threads()),
        };
        crate::say!(
            "geofit: timing: {} points in {:.3} s = {:.2} M points/s, {:.0} flops/point ({}; {} control points, degree {})",
            st.len(),
            secs,
            st.len() as f64 / secs / 1e6,
            pb.flops_estimate(&st),
            dev,
            pb.point_ids.len(),
            pb.degree.k()
        );
    }
    Ok(z)
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    gdal_notices(config);
    let mut write_opts = args.raster_out.checked(args.output.as_deref(), None)?;
    let file = read_tmesh_arg(&args.mesh)?;
    let grid = output_grid(&args, &file, &mut write_opts)?;
    let extra = extra_mask(&args, &grid.raster)?;
    let z = evaluate(&args, config, &file, &grid.params)?;
    let out = grid.fill(z, args.no_mask, extra.as_ref());
    write_raster_arg(&out, args.output.as_deref(), &write_opts)?;
    Ok(Exit::Ok)
}
