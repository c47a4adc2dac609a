//! `geofit observe`: attach measurements to a popa3d model (spec P20, the incremental workflow of
//! the first use case: sketch → measure → adjust → measure more → adjust again).

use clap::Args as ClapArgs;

use crate::config::{Config, Input, Output};
use crate::error::{CliError, CmdResult, Exit};

const AFTER_HELP: &str = "\
Example:
  geofit obj2popa3d rooms.obj -o rooms.popa3d
  geofit observe rooms.popa3d --add tape.csv -o rooms.popa3d
  geofit adjust rooms.popa3d -o rooms.popa3d --report rooms.json   # starts from the last solution

CSV: one measurement per line, `type,a,b,value,sigma` (`#` comments, optional header). `type` is
`distance` or a typed distance class (DistanceFaceFace, DistanceFaceEdge, ...); a primitive is
face:ID, edge:ID, node:ID, v:N (OBJ vertex), or a source polygon id (CityGML gml:id). Each
measurement is checked against the topology (unknown ids and wrong primitive kinds are errors
naming the CSV line); face-face, face-edge and edge-edge distances add their induced parallelism
constraint unless parallelism holds by construction. Polar pointings are not read from
CSV yet.";

#[derive(ClapArgs, Debug)]
#[command(after_help = AFTER_HELP)]
pub struct Args {
    /// popa3d document, `-` for stdin.
    pub input: String,
    /// CSV file(s) of measurements to add (repeatable).
    #[arg(long = "add", required = true)]
    pub add: Vec<String>,
    /// Output popa3d document (stdout when missing or `-`).
    #[arg(short, long)]
    pub output: Option<String>,
    /// σ of the induced angle constraints (cosine units).
    #[arg(long, default_value_t = 1e-4)]
    pub sigma_induced: f64,
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    if !(args.sigma_induced.is_finite() && args.sigma_induced > 0.0) {
        return Err(CliError::usage(format!("--sigma-induced must be a positive number, got {}", args.sigma_induced)));
    }
    let input = Input::from_arg(&args.input);
    let name = input.display_name();
    let bytes = input.read_all()?;
    let mut model = popa3d_model::read(&bytes).map_err(|e| CliError::unreadable(format!("{name}: {e}")))?;
    let mut added = 0usize;
    let mut induced = 0usize;
    for csv in &args.add {
        let cin = Input::from_arg(csv);
        let cname = cin.display_name();
        let text =
            String::from_utf8(cin.read_all()?).map_err(|e| CliError::unreadable(format!("{cname}: not UTF-8: {e}")))?;
        let obs = popa3d_model::csv::parse_distances(&text, &model)
            .map_err(|e| CliError::findings(format!("{cname}: {e}")))?;
        for o in obs {
            let ids = normalize::conditions::add_distance(&mut model, o, args.sigma_induced);
            added += 1;
            induced += ids.len().saturating_sub(1);
        }
    }
    if !config.quiet {
        crate::say!(
            "observe: {added} measurement(s) added, {induced} induced constraint(s); {} observations in total",
            model.observations.len()
        );
    }
    Output::from_arg(args.output.as_deref())
        .write_with(|w| popa3d_model::write(&model, w).map_err(|e| CliError::internal(e.to_string())))?;
    Ok(Exit::Ok)
}
