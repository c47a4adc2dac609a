//! `geofit implicit csg`: union, intersection or difference of two saved models.

use clap::{Args as ClapArgs, ValueEnum};
use implicit::contour::{self, CsgOp};
use serde::Serialize;

use super::{read_model, write_surfaces};
use crate::config::{Config, Output};
use crate::error::{CliError, CmdResult, Exit};
use crate::report::{write_json_report, ReportKind};

#[derive(ClapArgs)]
pub struct CsgArgs {
    /// First saved model (`.gfim`).
    pub a: String,
    /// Second saved model (`.gfim`); both fields are sampled on a common mesh one level finer than either.
    pub b: String,
    /// The operation: union (min φ), intersection (max φ) or difference (max(φa, −φb)).
    #[arg(long, value_enum)]
    pub op: Op,
    /// Output surface of the combined φ = 0 (.obj or .glb; stdout = OBJ).
    #[arg(short, long)]
    pub output: Option<String>,
    /// Also write the combined field as a VTK unstructured grid (legacy ASCII).
    #[arg(long, value_name = "PATH")]
    pub vtk: Option<String>,
    /// Write a JSON report (triangles, area) to PATH (`-` = stdout).
    #[arg(long, value_name = "PATH")]
    pub report: Option<String>,
}

#[derive(Copy, Clone, PartialEq, Eq, ValueEnum)]
pub enum Op {
    Union,
    Intersection,
    Difference,
}

/// `implicit csg --report`.
const CSG_REPORT: ReportKind = ReportKind {
    schema: "geofit-implicit-csg-report/1",
    units: &[("area", "CRS units squared"), ("volume", "CRS units cubed")],
};

#[derive(Serialize)]
struct CsgReport {
    op: &'static str,
    triangles: usize,
    closed: bool,
    volume: f64,
    area: f64,
}

pub(super) fn run(a: CsgArgs, config: &Config) -> CmdResult {
    let ma = read_model(&a.a)?;
    let mb = read_model(&a.b)?;
    let (op, name) = match a.op {
        Op::Union => (CsgOp::Union, "union"),
        Op::Intersection => (CsgOp::Intersection, "intersection"),
        Op::Difference => (CsgOp::Difference, "difference"),
    };
    let (s, mesh, field) = contour::csg(&ma, &mb, op);
    let closed = s.is_closed();
    let volume = s.volume().abs();
    config.notice(&format!("{name}: {} triangles, closed {closed}, volume {volume:.6}", s.tris.len()));
    if let Some(p) = &a.vtk {
        Output::from_arg(Some(p)).write_with(|w| {
            implicit::vtk::write_vtk(w, &mesh, ma.origin, &[("phi", &field)]).map_err(CliError::io_out)
        })?;
    }
    if let Some(p) = &a.report {
        write_json_report(
            p,
            &CSG_REPORT,
            &CsgReport { op: name, triangles: s.tris.len(), closed, volume, area: s.area() },
        )?;
    }
    write_surfaces(&a.output, &[(name.to_string(), s)], config)?;
    Ok(Exit::Ok)
}
