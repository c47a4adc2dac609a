//! Mesh outputs shared by `geofit surface` and `geofit export`: the output [`Format`], the
//! T-mesh tessellation options and the glue around `tspline::tessellate` (device, reference
//! raster, writing). Here rather than in either command so that no subcommand imports another.

use std::path::Path;

use clap::{Args as ClapArgs, ValueEnum};
use raster_io::MissingCorners;
use serde::Serialize;
use tspline::format::TMeshFile;
use tspline::tessellate::{Colouring, SampleGrid, TessellateError};
use tspline::PbSpline;

use crate::config::{write_atomic, Config, Output};
use crate::error::{CliError, CmdResult, Exit};
use crate::terrain_io::{read_raster_arg, select_device, tspline_err, Device};

/// Output format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// Binary glTF 2.0.
    Glb,
    /// glTF 2.0 JSON, buffer embedded as base64 (or in OUT.bin with --gltf-bin).
    Gltf,
    /// Wavefront OBJ, materials in OUT.mtl beside it.
    Obj,
}

/// How a T-mesh is tessellated; shared by `geofit surface` and `geofit export` (T-mesh input).
#[derive(ClapArgs, Debug, Clone)]
pub struct SurfaceOptions {
    /// Sample spacing in parameter units (raster cells).
    #[arg(long)]
    pub step: Option<f64>,
    /// Colour vertices by |dz| against this raster instead of by height.
    #[arg(long)]
    pub reference: Option<String>,
    /// Ignore the data mask stored in the mesh.
    #[arg(long)]
    pub no_mask: bool,
    /// Leave out node `tmesh` (the leaf cells' edges draped on the surface): the surface alone,
    /// as 3D Tiles content wants it.
    #[arg(long)]
    pub no_cell_edges: bool,
    /// Height colours run from MIN to MAX (z units) instead of the lowest to the highest sample,
    /// so that the tiles of one area share one colour ramp.
    #[arg(long, num_args = 2, value_names = ["MIN", "MAX"], allow_hyphen_values = true, conflicts_with = "reference")]
    pub height_range: Option<Vec<f64>>,
    /// Where the evaluation runs.
    #[arg(long, value_enum, default_value_t = Device::Auto)]
    pub device: Device,
}

impl SurfaceOptions {
    /// The options a user set (for the error when they are given with CityGML input).
    pub fn given(&self) -> Vec<&'static str> {
        let mut v = Vec::new();
        if self.step.is_some() {
            v.push("--step");
        }
        if self.reference.is_some() {
            v.push("--reference");
        }
        if self.no_mask {
            v.push("--no-mask");
        }
        if self.no_cell_edges {
            v.push("--no-cell-edges");
        }
        if self.height_range.is_some() {
            v.push("--height-range");
        }
        if !matches!(self.device, Device::Auto) {
            v.push("--device");
        }
        v
    }
}

/// Tessellates `file` (read from `name`) and writes it to `output` as `format`.
pub fn tessellate(
    file: TMeshFile,
    name: &str,
    output: &Output,
    format: Format,
    opts: &SurfaceOptions,
    config: &Config,
) -> CmdResult {
    if format == Format::Obj && output.path().is_none() {
        return Err(CliError::usage(
            "OBJ output of a surface needs a file (-o OUT.obj): its materials go to OUT.mtl beside it",
        ));
    }
    let range = height_range(opts)?;
    let grid = SampleGrid::new(file.mesh.bounds(), opts.step).map_err(|e| match e {
        TessellateError::Step(s) => CliError::usage(format!("--step must be positive, got {s}")),
        TessellateError::TooManySamples { ns, nt } => {
            CliError::usage(format!("{ns}×{nt} samples are too many; raise --step"))
        }
        e => CliError::internal(format!("surface: {e}")),
    })?;
    let ocl = select_device(opts.device, config)?;
    let pb = match &ocl {
        Some(o) => o.build_pbspline(&file.mesh).map_err(|e| tspline_err(name, e))?,
        None => PbSpline::build(&file.mesh),
    };
    let z = match &ocl {
        Some(o) => {
            let sp = o.upload(&pb).map_err(|e| tspline_err(name, e))?;
            o.eval_points(&sp, &grid.points).map_err(|e| tspline_err(name, e))?
        }
        None => pb.eval_z(&grid.points, true),
    };
    let reference = match &opts.reference {
        Some(r) => Some(read_raster_arg(r)?.0),
        None => None,
    };
    let sample_reference = |x: f64, y: f64| reference.as_ref().and_then(|r| r.sample(x, y, MissingCorners::Strict));
    let colouring =
        if reference.is_some() { Colouring::ErrorAgainst(&sample_reference) } else { Colouring::Height { range } };
    let mut scene =
        tspline::tessellate::tessellate(&file, &pb, &grid, z, colouring, !opts.no_mask, !opts.no_cell_edges).map_err(
            |e| match e {
                TessellateError::NoPointInMask => CliError::findings(format!("{name}: {e}")),
                e => CliError::internal(format!("surface: {e}")),
            },
        )?;
    scene.generator = Some("geofit surface".into());
    write_scene(&scene, output, format, false, "surface export")?;
    Ok(Exit::Ok)
}

/// `--height-range MIN MAX` as a pair; MIN < MAX, both finite.
fn height_range(opts: &SurfaceOptions) -> Result<Option<(f64, f64)>, CliError> {
    match opts.height_range.as_deref() {
        None => Ok(None),
        Some(&[lo, hi]) if lo.is_finite() && hi.is_finite() && lo < hi => Ok(Some((lo, hi))),
        Some(r) => Err(CliError::usage(format!("--height-range needs MIN < MAX, both finite; got {r:?}"))),
    }
}

/// Writes a scene as `format` to `output`: glb; glTF with the buffer embedded or, with
/// `external_bin`, in OUT.bin beside it; OBJ with its MTL beside a file output (on stdout the OBJ
/// alone). Side files are written atomically before the main file. `what` prefixes the message
/// of a failure of the writer itself.
pub fn write_scene(
    scene: &mesh_export::Scene,
    output: &Output,
    format: Format,
    external_bin: bool,
    what: &str,
) -> Result<(), CliError> {
    let export_err = |e: mesh_export::ExportError| match e {
        mesh_export::ExportError::Io(e) => CliError::io_out(e),
        e => CliError::internal(format!("{what}: {e}")),
    };
    match (format, output.path()) {
        (Format::Glb, _) => output.write_with(|w| mesh_export::write_glb(scene, w).map_err(export_err))?,
        (Format::Gltf, Some(path)) if external_bin => {
            let bin_path = path.with_extension("bin");
            let uri = file_name(&bin_path)?;
            let (mut json, mut bin) = (Vec::new(), Vec::new());
            mesh_export::write_gltf(scene, &mut json, mesh_export::GltfBuffer::External { uri: &uri, bin: &mut bin })
                .map_err(export_err)?;
            write_atomic(&bin_path, |w| w.write_all(&bin).map_err(CliError::io_out))?;
            output.write_bytes(&json)?;
        }
        (Format::Gltf, _) => output
            .write_with(|w| mesh_export::write_gltf(scene, w, mesh_export::GltfBuffer::Embedded).map_err(export_err))?,
        (Format::Obj, Some(path)) => {
            let mtl_path = path.with_extension("mtl");
            let mtl_name = file_name(&mtl_path)?;
            let (mut obj, mut mtl) = (Vec::new(), Vec::new());
            mesh_export::write_obj(scene, &mut obj, Some((&mtl_name, &mut mtl))).map_err(export_err)?;
            write_atomic(&mtl_path, |w| w.write_all(&mtl).map_err(CliError::io_out))?;
            output.write_bytes(&obj)?;
        }
        (Format::Obj, None) => output.write_with(|w| mesh_export::write_obj(scene, w, None).map_err(export_err))?,
    }
    Ok(())
}

/// The last component of `p` (the name an OBJ's `mtllib` or a glTF's buffer `uri` refers to).
pub fn file_name(p: &Path) -> Result<String, CliError> {
    p.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .ok_or_else(|| CliError::usage(format!("{}: not a file name", p.display())))
}
