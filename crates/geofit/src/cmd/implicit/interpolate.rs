//! `geofit implicit interpolate`: interpolate φ on an adaptive mesh and save the model.

use clap::Args as ClapArgs;

use super::build::{build_model, write_report, BuildArgs};
use super::write_vtk;
use crate::config::{Config, Output};
use crate::error::{CmdResult, Exit};

#[derive(ClapArgs)]
pub struct InterpolateArgs {
    #[command(flatten)]
    pub build: BuildArgs,
    /// Output model file (`.gfim`: mesh, constraints and solution, read by update/iso/section/csg).
    #[arg(short, long, value_name = "MODEL")]
    pub output: Option<String>,
}

pub(super) fn run(a: InterpolateArgs, config: &Config) -> CmdResult {
    let (m, rep, secs) = build_model(&a.build, config)?;
    Output::from_arg(a.output.as_deref()).write_bytes(&m.to_bytes())?;
    write_vtk(&a.build.vtk, &m)?;
    write_report(&a.build.report, &rep, secs)?;
    Ok(Exit::Ok)
}
