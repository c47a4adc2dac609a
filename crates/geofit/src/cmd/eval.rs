//! `geofit eval`: evaluates a T-mesh's surface on a raster grid (spec §6.4 surface evaluation,
//! §2.2 masking), on OpenCL or the CPU.

use clap::Args as ClapArgs;

use raster_io::Raster;
use tspline::{GridSpec, PbSpline};

use crate::terrain_io::{read_tmesh_arg, select_device, tspline_err, Device};
use crate::terrain_io::{read_raster_arg, read_raster_arg_typed, write_raster_arg, RasterOutArgs};
use crate::config::Config;
use crate::error::{CliError, CmdResult, Exit};

const EXAMPLE: &str = "\
Example:
  $ geofit fit bathy.tif -o bathy.tmesh --max-error 0.5
  $ geofit eval bathy.tmesh -o surface.tif            # the fitted raster's grid, masked by its data
  $ geofit eval bathy.tmesh -o full.tif --no-mask     # also the holes and survey gaps
  $ geofit eval bathy.tmesh -o on-b.tif --like other.tif --mask other.tif
  $ geofit diff bathy.tif surface.tif --tolerance 0.5

Without --like the grid is the one the mesh was fitted on (stored in the .tmesh with its data
mask), cells without data stay nodata unless --no-mask; without a stored mask the grid covers the
mesh domain at the parameter spacing. --like takes size, geotransform and CRS from a raster;
--mask keeps only cells valid in a raster of the output's size. Outside the mesh domain: nodata.";

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
    /// Do not apply the data mask stored in the T-mesh.
    #[arg(long)]
    pub no_mask: bool,
    /// Where the evaluation runs.
    #[arg(long, value_enum, default_value_t = Device::Auto)]
    pub device: Device,
    /// Print the evaluation throughput (points/s, flops per point) on stderr.
    #[arg(long)]
    pub timing: bool,
    #[command(flatten)]
    pub raster_out: RasterOutArgs,
}

/// The parameter pairs of the output cells: a list, or a regular grid (row-major).
enum Params {
    List(Vec<[f64; 2]>),
    Grid(GridSpec),
}

impl Params {
    /// The pairs as a list (the timing's flop estimate samples them).
    fn list(&self) -> std::borrow::Cow<'_, [[f64; 2]]> {
        match self {
            Params::List(v) => std::borrow::Cow::Borrowed(v),
            Params::Grid(g) => (0..g.ns * g.nt).map(|q| [g.s0 + (q % g.ns) as f64 * g.ds, g.t0 + (q / g.ns) as f64 * g.dt]).collect(),
        }
    }
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    // The output's band type follows --like (a Float32 grid gets a Float32 surface).
    let mut write_opts = args.raster_out.checked(args.output.as_deref(), None)?;
    let file = read_tmesh_arg(&args.mesh)?;
    let g = &file.georef;
    // Indirect meshes: output cells are mapped forward through the stored field (spec §2.3.3)
    // and the default grid is the original raster's, masked by its footprint.
    let field = match &file.warp {
        Some(json) => Some(
            raster_proc::warp::WarpField::from_json(json).map_err(|e| CliError::unreadable(format!("{}: <warp>: {e}", args.mesh)))?,
        ),
        None => None,
    };
    let mapper = field.as_ref().map(|f| f.mapper());
    let to_param = |x: f64, y: f64| -> (f64, f64) {
        match &mapper {
            Some(m) => {
                let q = m.forward([x, y]);
                g.param(q[0], q[1])
            }
            None => g.param(x, y),
        }
    };
    let crs = if g.crs.is_empty() { None } else { Some(g.crs.clone()) };
    // Output grid and the parameter pair of each output cell.
    let (mut out, st, stored_mask): (Raster, Params, Option<Vec<bool>>) = if let Some(like) = &args.like {
        let (r, name, like_type) = read_raster_arg_typed(like)?;
        write_opts = args.raster_out.checked(args.output.as_deref(), Some(like_type))?;
        let gt = r.geotransform;
        if gt[2] != 0.0 || gt[4] != 0.0 {
            return Err(CliError::findings(format!("{name}: rotated rasters are not supported")));
        }
        let mut st = Vec::with_capacity(r.width * r.height);
        for row in 0..r.height {
            for col in 0..r.width {
                let (x, y) = r.cell_centre(col, row);
                let (s, t) = to_param(x, y);
                st.push([s, t]);
            }
        }
        let out = Raster::new_empty(r.width, r.height, gt, r.crs.clone().or(crs));
        (out, Params::List(st), None)
    } else if let Some(src) = field.as_ref().and_then(|f| f.source.as_ref()) {
        let out = Raster::new_empty(src.width, src.height, src.geotransform, src.crs.clone().or(crs));
        let mut st = Vec::with_capacity(src.width * src.height);
        for row in 0..src.height {
            for col in 0..src.width {
                let (x, y) = out.cell_centre(col, row);
                let (s, t) = to_param(x, y);
                st.push([s, t]);
            }
        }
        let mask = src.mask().map_err(|e| CliError::unreadable(format!("{}: <warp> source grid: {e}", args.mesh)))?;
        (out, Params::List(st), Some(mask))
    } else {
        let (w, h, s0, t0) = match &file.mask {
            Some(m) => (m.width, m.height, 0.0, 0.0),
            None => {
                let b = file.mesh.bounds();
                let s0 = b.s_min.ceil();
                let t0 = b.t_min.ceil();
                ((b.s_max.floor() - s0) as usize + 1, (b.t_max.floor() - t0) as usize + 1, s0, t0)
            }
        };
        if w.saturating_mul(h) > 2_000_000_000 {
            return Err(CliError::usage(format!("{}: the output grid {w}×{h} is too large; pass --like", args.mesh)));
        }
        // North-up output: row r holds t = t0 + h − 1 − r. A regular grid: evaluated
        // separably (rows of basis values reused, no per-cell parameter list).
        let (x0, ytop) = g.world(s0, t0 + (h as f64 - 1.0));
        let gt = Raster::geotransform_from_centres(x0, ytop, g.dx, -g.dy);
        let st = Params::Grid(GridSpec { s0, t0: t0 + (h as f64 - 1.0), ds: 1.0, dt: -1.0, ns: w, nt: h });
        let mask = file.mask.as_ref().map(|m| {
            let mut v = vec![false; w * h];
            for row in 0..h {
                for col in 0..w {
                    v[row * w + col] = m.get(col, h - 1 - row);
                }
            }
            v
        });
        (Raster::new_empty(w, h, gt, crs), st, mask)
    };
    let extra_mask = match &args.mask {
        Some(m) => {
            let (r, name) = read_raster_arg(m)?;
            if r.width != out.width || r.height != out.height {
                return Err(CliError::usage(format!(
                    "--mask {name} is {}×{}, the output grid is {}×{}",
                    r.width, r.height, out.width, out.height
                )));
            }
            Some(r.valid)
        }
        None => None,
    };
    let ocl = select_device(args.device, config)?;
    let pb = match &ocl {
        Some(o) => o.build_pbspline(&file.mesh).map_err(|e| tspline_err(&args.mesh, e))?,
        None => PbSpline::build(&file.mesh),
    };
    let t0 = std::time::Instant::now();
    let parallel = tspline::worker_threads() > 1;
    let z = match (&ocl, &st) {
        (Some(o), _) => {
            let sp = o.upload(&pb).map_err(|e| tspline_err(&args.mesh, e))?;
            match &st {
                Params::List(st) => o.eval_points(&sp, st),
                Params::Grid(gs) => o.eval_grid(&sp, gs),
            }
            .map_err(|e| tspline_err(&args.mesh, e))?
        }
        (None, Params::List(st)) => pb.eval_z(st, parallel),
        (None, Params::Grid(gs)) => pb.eval_grid(gs, parallel),
    };
    if args.timing {
        let secs = t0.elapsed().as_secs_f64();
        let st = st.list();
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
    for (q, v) in z.into_iter().enumerate() {
        let keep = v.is_finite()
            && (args.no_mask || stored_mask.as_ref().map(|m| m[q]).unwrap_or(true))
            && extra_mask.as_ref().map(|m| m[q]).unwrap_or(true);
        if keep {
            out.data[q] = v;
            out.valid[q] = true;
        }
    }
    write_raster_arg(&out, args.output.as_deref(), &write_opts)?;
    Ok(Exit::Ok)
}
