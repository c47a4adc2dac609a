//! `geofit implicit run POINTS -o SURFACE` (also the bare `geofit implicit POINTS`): interpolate
//! and write the iso-surfaces in one step.

use clap::Args as ClapArgs;

use super::build::{build_model, write_report, BuildArgs};
use super::{iso_parts, write_surfaces, write_vtk, Colour};
use crate::config::{Config, Output};
use crate::error::{CliError, CmdResult, Exit};

#[derive(ClapArgs, Clone)]
pub struct RunArgs {
    #[command(flatten)]
    pub build: BuildArgs,
    /// Output surface (.obj or .glb; stdout = OBJ).
    #[arg(short, long, value_name = "SURFACE")]
    pub output: Option<String>,
    /// Iso-value(s) to extract (default: 0, or each distinct data value up to 16 of them).
    #[arg(long = "iso", value_name = "V")]
    pub iso: Vec<f64>,
    /// Also save the model.
    #[arg(long, value_name = "PATH")]
    pub model: Option<String>,
}

pub(super) fn run(a: RunArgs, config: &Config) -> CmdResult {
    if a.build.points.is_none() {
        return Err(CliError::usage("missing POINTS (see `geofit implicit --help`)"));
    }
    let ext = Output::from_arg(a.output.as_deref()).extension();
    if !matches!(ext.as_deref(), None | Some("obj") | Some("glb")) {
        return Err(CliError::usage(format!(
            "-o: unknown surface format `.{}`: use .obj or .glb",
            ext.unwrap_or_default()
        )));
    }
    let (m, rep, secs) = build_model(&a.build, config)?;
    let isos = if a.iso.is_empty() { m.default_iso_values() } else { a.iso.clone() };
    let parts = iso_parts(&m, &isos, Colour::Auto);
    write_surfaces(&a.output, &parts, config)?;
    if let Some(p) = &a.model {
        Output::from_arg(Some(p)).write_bytes(&m.to_bytes())?;
    }
    write_vtk(&a.build.vtk, &m)?;
    write_report(&a.build.report, &rep, secs)?;
    Ok(Exit::Ok)
}
