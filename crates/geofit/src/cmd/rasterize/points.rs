//! The points of `geofit rasterize` read and gridded: streamed twice for Gauss splatting of a
//! file, held once for TIN and for stdin.

use std::path::Path;

use raster_io::crs::Crs;
use raster_io::point_batches::BoundsXy;
use raster_io::Raster;
use raster_proc::grid::GridSpec;
use raster_proc::point_input::{open_file, read_file, read_text, TextFacts};
use raster_proc::splat::{splat_points, SplatAccumulator, SplatKernel};
use raster_proc::tin::{tin_points, TinOptions, TinStats};
use raster_proc::ProcError;

use super::{check_cell_units, crs_plan, reproject, Args};
use crate::config::{Config, Input};
use crate::error::CliError;
use crate::terrain_io::{points_err, proc_err};

/// Gauss splatting of a point file in two passes over it (bounds and count, then the splat),
/// holding one batch of points and the 16-byte-a-cell accumulators, never the cloud
/// (docs/decisions.md#streaming-points).
pub(super) fn splat_streamed(
    args: &Args,
    path: &Path,
    kernel: SplatKernel,
    config: &Config,
) -> Result<(BoundsXy, Raster, Option<TinStats>), CliError> {
    let open = || open_file(path, args.class, args.sep.as_deref(), args.decimal.as_deref()).map_err(points_err);
    let mut first_pass = open()?;
    let file_crs = first_pass.crs().map(str::to_string);
    let plan = crs_plan(args, file_crs.as_deref())?;
    let mut seen = BoundsXy::default();
    for b in first_pass.by_ref() {
        let mut b = b.map_err(points_err)?;
        reproject(&plan, &mut b)?;
        seen.extend(&b);
    }
    let grid = plan_grid(args, &seen, plan.grid.as_ref(), &TextFacts::of(&first_pass), config)?;
    let mut acc = SplatAccumulator::new(grid.width, grid.height, kernel).map_err(|e| proc_err(&args.input, e))?;
    for b in open()? {
        let mut b = b.map_err(points_err)?;
        reproject(&plan, &mut b)?;
        acc.add_points(&grid, &b);
    }
    let crs = plan.grid.map(|c| c.wkt).or(file_crs);
    Ok((seen, acc.into_raster(&grid, crs).map_err(|e| proc_err(&args.input, e))?, None))
}

/// TIN, and Gauss on stdin (which cannot be read twice): the whole cloud in memory, within the
/// point budget.
pub(super) fn rasterize_held(
    args: &Args,
    kernel: Option<SplatKernel>,
    config: &Config,
) -> Result<(BoundsXy, Raster, Option<TinStats>), CliError> {
    let (sep, decimal) = (args.sep.as_deref(), args.decimal.as_deref());
    let input = Input::from_arg(&args.input);
    let (mut cloud, facts) = match input.path() {
        Some(p) => read_file(p, args.class, sep, decimal),
        None if args.class.is_some() => return Err(CliError::usage("--class needs a LAS/LAZ file, not stdin")),
        None => read_text(input.open()?, "<stdin>", sep, decimal),
    }
    .map_err(points_err)?;
    let plan = crs_plan(args, cloud.crs.as_deref())?;
    reproject(&plan, &mut cloud.points)?;
    let mut seen = BoundsXy::default();
    seen.extend(&cloud.points);
    let grid = plan_grid(args, &seen, plan.grid.as_ref(), &facts, config)?;
    let crs = plan.grid.map(|c| c.wkt).or_else(|| cloud.crs.clone());
    let fail = |e| proc_err(&args.input, e);
    Ok(match kernel {
        Some(k) => (seen, splat_points(&cloud, &grid, k, crs).map_err(fail)?, None),
        None => {
            let (r, s) = tin_points(&cloud, &grid, &TinOptions { max_edge: args.max_edge }, crs).map_err(fail)?;
            (seen, r, Some(s))
        }
    })
}

/// The grid: `--bounds` exactly, else the cells on multiples of `--cell` covering the points;
/// says how many points were read first, and how a text was read.
fn plan_grid(
    args: &Args,
    seen: &BoundsXy,
    crs: Option<&Crs>,
    facts: &TextFacts,
    config: &Config,
) -> Result<GridSpec, CliError> {
    config.notice(&format!(
        "read {} points from {}{}{}",
        seen.count,
        args.input,
        args.class.map(|c| format!(" (class {c})")).unwrap_or_default(),
        facts.read_as.as_ref().map(|f| format!(" ({f})")).unwrap_or_default()
    ));
    let bounds = seen.get().ok_or_else(|| CliError::unreadable(format!("{}: no points", args.input)))?;
    let cell = raster_io::units::length_in_crs_units(
        "--cell",
        args.cell,
        args.cell_unit.as_deref(),
        crs.map(|c| c.wkt.as_str()),
    );
    let args = &Args { cell: cell.map_err(CliError::usage)?, ..args.clone() };
    let grid = match &args.bounds {
        Some(b) => GridSpec::from_edges(b[0], b[1], b[2], b[3], args.cell),
        None => GridSpec::covering(bounds, args.cell),
    }
    .map_err(|e| match e {
        ProcError::Input(m) => CliError::usage(m),
        e @ ProcError::TooLarge { .. } => CliError::usage(format!("--cell {}: {e}", args.cell)),
        other => proc_err(&args.input, other),
    })?;
    if args.bounds.is_none() {
        check_cell_units(args, seen, crs, facts.geographic, &grid)?;
    }
    Ok(grid)
}
