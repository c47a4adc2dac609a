//! `geofit implicit iso`: iso-surfaces of a saved model by marching tetrahedra.

use clap::{Args as ClapArgs, ValueEnum};
use serde::Serialize;

use super::{iso_parts, read_model, write_surfaces, LENGTH};
use crate::config::Config;
use crate::error::{CliError, CmdResult, Exit};
use crate::report::{write_json_report, ReportKind};

#[derive(ClapArgs)]
pub struct IsoArgs {
    /// Saved model (`.gfim`).
    pub model: String,
    /// Iso-value(s) (default: 0, or each distinct constraint value up to 16).
    #[arg(long = "value", value_name = "V")]
    pub values: Vec<f64>,
    /// Output (.obj or .glb; stdout = OBJ).
    #[arg(short, long)]
    pub output: Option<String>,
    /// Vertex colours: from the model's attribute (`auto`: when it has one), from φ, or none.
    #[arg(long, value_enum, default_value_t = Colour::Auto)]
    pub colour: Colour,
    /// Write a JSON report (triangles per iso-value, area) to PATH (`-` = stdout).
    #[arg(long, value_name = "PATH")]
    pub report: Option<String>,
}

#[derive(Copy, Clone, PartialEq, Eq, ValueEnum)]
pub enum Colour {
    Auto,
    Attribute,
    Phi,
    None,
}

/// `implicit iso --report`.
const ISO_REPORT: ReportKind = ReportKind {
    schema: "geofit-implicit-iso-report/1",
    units: &[("value", LENGTH), ("area", "CRS units squared"), ("volume", "CRS units cubed")],
};

#[derive(Serialize)]
struct IsoReport {
    value: f64,
    triangles: usize,
    vertices: usize,
    area: f64,
    closed: bool,
    volume: Option<f64>,
}

pub(super) fn run(a: IsoArgs, config: &Config) -> CmdResult {
    let m = read_model(&a.model)?;
    if a.colour == Colour::Attribute && m.attribute.is_none() {
        return Err(CliError::usage(format!(
            "--colour attribute: {} has no attribute (interpolate with --attribute FILE)",
            a.model
        )));
    }
    let values = if a.values.is_empty() { m.default_iso_values() } else { a.values.clone() };
    let parts = iso_parts(&m, &values, a.colour);
    write_surfaces(&a.output, &parts, config)?;
    if let Some(p) = &a.report {
        let r: Vec<IsoReport> = parts
            .iter()
            .zip(&values)
            .map(|((_, s), &v)| {
                let closed = s.is_closed();
                IsoReport {
                    value: v,
                    triangles: s.tris.len(),
                    vertices: s.positions.len(),
                    area: s.area(),
                    closed,
                    volume: closed.then(|| s.volume().abs()),
                }
            })
            .collect();
        write_json_report(p, &ISO_REPORT, &r)?;
    }
    Ok(Exit::Ok)
}
