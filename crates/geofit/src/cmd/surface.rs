//! `geofit surface`: a T-mesh's surface as a triangle mesh (glb / gltf / obj) with vertex colours
//! by height or by error against a reference raster, and the T-mesh cell edges as a separate
//! line node. `geofit export MESH.tmesh` lands here too (the issue's spelling): export sniffs the
//! root element and hands T-mesh input to [`tessellate`].

use std::path::Path;

use clap::Args as ClapArgs;

use mesh_export::{LineSet, Material, MeshNode, Scene, TriangleMesh};
use raster_io::MissingCorners;
use tspline::format::TMeshFile;
use tspline::PbSpline;

use super::export::Format;
use crate::terrain_io::{read_tmesh_arg, select_device, tspline_err, Device};
use crate::terrain_io::read_raster_arg;
use crate::config::{write_atomic, Config, Output};
use crate::error::{CliError, CmdResult, Exit};

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

/// How a T-mesh is tessellated; shared with `geofit export`, which takes T-mesh input too.
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
        if !matches!(self.device, Device::Auto) {
            v.push("--device");
        }
        v
    }
}

fn ramp(f: f64) -> [f32; 4] {
    // blue (deep) → cyan → green → brown (high)
    let f = f.clamp(0.0, 1.0) as f32;
    let stops = [[0.05, 0.15, 0.55], [0.1, 0.6, 0.8], [0.2, 0.65, 0.25], [0.55, 0.4, 0.2]];
    let x = f * 3.0;
    let i = (x.floor() as usize).min(2);
    let t = x - i as f32;
    let (a, b) = (stops[i], stops[i + 1]);
    [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t, a[2] + (b[2] - a[2]) * t, 1.0]
}

fn error_colour(e: f64) -> [f32; 4] {
    if !e.is_finite() {
        [0.5, 0.5, 0.5, 1.0]
    } else if e < 0.1 {
        [0.1, 0.7, 0.2, 1.0]
    } else if e < 0.5 {
        [0.9, 0.85, 0.1, 1.0]
    } else if e < 1.0 {
        [0.95, 0.5, 0.1, 1.0]
    } else {
        [0.85, 0.1, 0.1, 1.0]
    }
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    let output = Output::from_arg(args.output.as_deref());
    let format = match output.extension().as_deref() {
        Some("obj") => Format::Obj,
        Some("gltf") => Format::Gltf,
        Some("glb") | None => Format::Glb,
        Some(other) => return Err(CliError::usage(format!("unknown output format .{other} (use .glb, .gltf or .obj)"))),
    };
    let file = read_tmesh_arg(&args.mesh)?;
    tessellate(file, &args.mesh, &output, format, &args.opts, config)
}

/// Tessellates `file` (read from `name`) and writes it to `output` as `format`.
pub fn tessellate(file: TMeshFile, name: &str, output: &Output, format: Format, opts: &SurfaceOptions, config: &Config) -> CmdResult {
    if format == Format::Obj && output.path().is_none() {
        return Err(CliError::usage("OBJ output of a surface needs a file (-o OUT.obj): its materials go to OUT.mtl beside it"));
    }
    let g = file.georef.clone();
    let b = file.mesh.bounds();
    let step = match opts.step {
        Some(s) if s > 0.0 && s.is_finite() => s,
        Some(s) => return Err(CliError::usage(format!("--step must be positive, got {s}"))),
        None => (b.width().max(b.height()) / 512.0).max(1.0),
    };
    let ns = (b.width() / step).floor() as usize + 1;
    let nt = (b.height() / step).floor() as usize + 1;
    if ns.saturating_mul(nt) > 50_000_000 {
        return Err(CliError::usage(format!("{ns}×{nt} samples are too many; raise --step")));
    }
    let st: Vec<[f64; 2]> = (0..nt).flat_map(|j| (0..ns).map(move |i| [b.s_min + i as f64 * step, b.t_min + j as f64 * step])).collect();
    let ocl = select_device(opts.device, config)?;
    let pb = match &ocl {
        Some(o) => o.build_pbspline(&file.mesh).map_err(|e| tspline_err(name, e))?,
        None => PbSpline::build(&file.mesh),
    };
    let mut z = match &ocl {
        Some(o) => {
            let sp = o.upload(&pb).map_err(|e| tspline_err(name, e))?;
            o.eval_points(&sp, &st).map_err(|e| tspline_err(name, e))?
        }
        None => pb.eval_z(&st, true),
    };
    if let (Some(m), false) = (&file.mask, opts.no_mask) {
        for (q, p) in st.iter().enumerate() {
            let (i, j) = (p[0].round(), p[1].round());
            let inside = i >= 0.0 && j >= 0.0 && (i as usize) < m.width && (j as usize) < m.height && m.get(i as usize, j as usize);
            if !inside {
                z[q] = f64::NAN;
            }
        }
    }
    let reference = match &opts.reference {
        Some(r) => Some(read_raster_arg(r)?.0),
        None => None,
    };
    let (zmin, zmax) = z.iter().filter(|v| v.is_finite()).fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
    if !zmin.is_finite() {
        return Err(CliError::findings(format!("{name}: the surface has no point inside the mask")));
    }
    let mut mesh = TriangleMesh::new(Some(0));
    let mut colours = Vec::new();
    let mut vid = vec![u32::MAX; z.len()];
    for (q, p) in st.iter().enumerate() {
        if !z[q].is_finite() {
            continue;
        }
        let (x, y) = g.world(p[0], p[1]);
        vid[q] = mesh.push_vertex([x, y, z[q]]);
        colours.push(match &reference {
            Some(r) => error_colour(r.sample(x, y, MissingCorners::Strict).map(|v| (v - z[q]).abs()).unwrap_or(f64::NAN)),
            None => ramp((z[q] - zmin) / (zmax - zmin).max(1e-300)),
        });
    }
    for j in 0..nt.saturating_sub(1) {
        for i in 0..ns.saturating_sub(1) {
            let (a, bq, c, d) = (j * ns + i, j * ns + i + 1, (j + 1) * ns + i, (j + 1) * ns + i + 1);
            if [a, bq, c, d].iter().all(|&q| vid[q] != u32::MAX) {
                mesh.indices.extend_from_slice(&[vid[a], vid[bq], vid[d], vid[a], vid[d], vid[c]]);
            }
        }
    }
    mesh.colors = Some(colours);
    // T-mesh lines: every leaf edge, draped on the surface (8 segments per edge).
    let mut lines = LineSet { material: Some(1), ..Default::default() };
    for c in file.mesh.cells.iter().filter(|c| c.is_leaf()) {
        let r = c.rect;
        // all four sides (edges shared by two leaves are drawn twice)
        for (s0, t0, s1, t1) in [(r.s_min, r.t_min, r.s_max, r.t_min), (r.s_min, r.t_min, r.s_min, r.t_max), (r.s_min, r.t_max, r.s_max, r.t_max), (r.s_max, r.t_min, r.s_max, r.t_max)] {
            let mut prev: Option<u32> = None;
            for k in 0..=8 {
                let f = k as f64 / 8.0;
                let (s, t) = (s0 + (s1 - s0) * f, t0 + (t1 - t0) * f);
                let zz = pb.point(s, t)[2];
                let masked = match (&file.mask, opts.no_mask) {
                    (Some(m), false) => {
                        let (i, j) = (s.round(), t.round());
                        !(i >= 0.0 && j >= 0.0 && (i as usize) < m.width && (j as usize) < m.height && m.get(i as usize, j as usize))
                    }
                    _ => false,
                };
                if !zz.is_finite() || masked {
                    prev = None;
                    continue;
                }
                let (x, y) = g.world(s, t);
                lines.positions.push([x, y, zz]);
                let id = (lines.positions.len() - 1) as u32;
                if let Some(p) = prev {
                    lines.indices.extend_from_slice(&[p, id]);
                }
                prev = Some(id);
            }
        }
    }
    let mut surface = MeshNode::new("surface");
    surface.meshes.push(mesh);
    let mut tnode = MeshNode::new("tmesh");
    if !lines.indices.is_empty() {
        tnode.lines.push(lines);
    }
    let mut scene = Scene {
        materials: vec![Material::new("surface", [1.0, 1.0, 1.0, 1.0]), Material::new("tmesh-edges", [0.05, 0.05, 0.05, 1.0])],
        crs: if g.crs.is_empty() { None } else { Some(g.crs.clone()) },
        generator: Some("geofit surface".into()),
        ..Default::default()
    };
    scene.nodes.push(surface);
    scene.nodes.push(tnode);
    scene.origin = scene.auto_origin();
    let export_err = |e: mesh_export::ExportError| match e {
        mesh_export::ExportError::Io(e) => CliError::io_out(e),
        e => CliError::internal(format!("surface export: {e}")),
    };
    match format {
        Format::Obj => {
            let path = output.path().expect("checked above: OBJ goes to a file");
            let mtl_path = path.with_extension("mtl");
            let mtl_name = file_name(&mtl_path)?;
            let (mut obj, mut mtl) = (Vec::new(), Vec::new());
            mesh_export::write_obj(&scene, &mut obj, Some((&mtl_name, &mut mtl))).map_err(export_err)?;
            write_atomic(&mtl_path, |w| w.write_all(&mtl).map_err(CliError::io_out))?;
            output.write_bytes(&obj)?;
        }
        Format::Gltf => output.write_with(|w| mesh_export::write_gltf(&scene, w, mesh_export::GltfBuffer::Embedded).map_err(export_err))?,
        Format::Glb => output.write_with(|w| mesh_export::write_glb(&scene, w).map_err(export_err))?,
    }
    Ok(Exit::Ok)
}

fn file_name(p: &Path) -> Result<String, CliError> {
    p.file_name().map(|n| n.to_string_lossy().into_owned()).ok_or_else(|| CliError::usage(format!("{}: not a file name", p.display())))
}
