//! `geofit tile report`: per-tile heal and validate reports summed into one.

use clap::Args as ClapArgs;

use super::{read_text, tiling_error};
use crate::config::{Config, Output};
use crate::error::{CliError, CmdResult, Exit};

#[derive(ClapArgs, Debug)]
pub struct ReportArgs {
    /// Per-tile reports named `<tile>.<anything>.json`.
    #[arg(required = true)]
    pub reports: Vec<String>,
    #[arg(short, long)]
    pub output: Option<String>,
}

pub(super) fn run(a: ReportArgs, _config: &Config) -> CmdResult {
    let output = Output::from_arg(a.output.as_deref());
    output.check_target()?;
    let reports = a
        .reports
        .iter()
        .map(|p| tiling::report::TileReport::parse(p, &read_text(p)?).map_err(tiling_error))
        .collect::<Result<Vec<_>, _>>()?;
    let merged = tiling::report::merge(reports).map_err(tiling_error)?;
    let text = serde_json::to_string_pretty(&merged).map_err(|e| CliError::internal(format!("report: {e}")))? + "\n";
    output.write_bytes(text.as_bytes())?;
    Ok(Exit::Ok)
}
