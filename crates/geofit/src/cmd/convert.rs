//! `geofit convert`: CityGML 1.0/2.0/3.0 ⇄ CityJSON 2.0 / CityJSONSeq (issue 38). The mapping
//! lives in the cityjson-io crate; this file parses arguments, makes the one call and reports
//! what the target cannot hold (never dropped silently).

use clap::Args as ClapArgs;
use serde::Serialize;

use crate::config::encoding::{self, Encoding};
use crate::config::{Config, Input, Output};
use crate::error::{CliError, CmdResult, Exit};
use crate::report::{write_json_report, ReportKind};

const AFTER_HELP: &str = "\
Example:
  $ geofit convert building.gml -o building.city.json
  convert: building.gml (CityGML 2.0) -> building.city.json (CityJSON 2.0): 1 feature
  convert: not carried: 1 x bldg:address (not mapped to CityJSON) (first: BLDG_1)
  $ geofit convert building.city.json -o back.gml
  $ geofit convert tile.gml -o tile.city.jsonl --precision 0.01
  $ geofit convert big.city.jsonl --to citygml | geofit validate -

The input's encoding is read from its content (CityGML, CityJSON 2.0 or 1.1, CityJSONSeq), the
output's from the extension of -o (.gml/.xml/.citygml, .json, .jsonl) or --to. CityJSON is
written with quantised vertices (--precision, the transform's scale); CityGML is written as 2.0,
one geometry per LoD property as the schema has it. Boundary surfaces and openings become
semantic surfaces (their gml:id kept as the surface's id), parts, installations and rooms become
children, attributes keep their names (generic ones their types). What the target cannot hold
(addresses, appearances, a second lod1 geometry, ...) is listed on stderr and in --report, with
the first object it occurred in.

Exit codes: 0 written; 2 bad options; 3 unreadable input (naming file and line or object id);
4 internal.";

#[derive(ClapArgs, Debug)]
#[command(after_help = AFTER_HELP)]
pub struct Args {
    /// CityGML, CityJSON or CityJSONSeq input, `-` for stdin.
    pub input: String,
    /// Output file (stdout when missing or `-`); its extension names the encoding.
    #[arg(short, long)]
    pub output: Option<String>,
    /// Encoding to write (default: from -o's extension, else CityJSON for CityGML input and CityGML for CityJSON input).
    #[arg(long, value_parser = ["citygml", "cityjson", "cityjsonseq"])]
    pub to: Option<String>,
    /// Precision of CityJSON's quantised vertices, the transform's scale (CRS units).
    #[arg(long, default_value_t = 0.001)]
    pub precision: f64,
    /// Write a JSON report (what was not carried) to this path (`-` = stdout).
    #[arg(long)]
    pub report: Option<String>,
}

const REPORT: ReportKind = ReportKind { schema: "geofit-convert/1", units: &[("precision", "CRS units")] };

#[derive(Serialize)]
struct Report<'a> {
    input: String,
    from: &'static str,
    to: &'static str,
    precision: f64,
    #[serde(flatten)]
    report: &'a cityjson_io::Report,
}

fn target(args: &Args, from: Encoding) -> Encoding {
    match args.to.as_deref() {
        Some("citygml") => Encoding::CityGml,
        Some("cityjson") => Encoding::CityJson,
        Some("cityjsonseq") => Encoding::CityJsonSeq,
        _ => args
            .output
            .as_deref()
            .and_then(|o| Encoding::of_path(std::path::Path::new(o)))
            .unwrap_or(if from == Encoding::CityGml { Encoding::CityJson } else { Encoding::CityGml }),
    }
}

pub fn run(args: Args, config: &Config) -> CmdResult {
    if !(args.precision.is_finite() && args.precision > 0.0) {
        return Err(CliError::usage(format!("convert: --precision {} must be a positive number", args.precision)));
    }
    let output = Output::from_arg(args.output.as_deref());
    output.check_target()?;
    crate::config::check_report_target(args.report.as_deref(), args.output.as_deref())?;
    let input = Input::from_arg(&args.input);
    let name = input.display_name();
    let raw = input.map_or_read_raw()?;
    let from = Encoding::of_bytes(&raw);
    let to = target(&args, from);
    let (bytes, report) = encoding::convert(&name, &raw, from, to, args.precision)?;
    output.write_bytes(&bytes)?;
    if !config.quiet {
        let out = args.output.as_deref().unwrap_or("stdout");
        crate::say!("convert: {name} ({}) -> {out} ({})", from.describe(), to.describe());
        for line in report.lines() {
            crate::say!("convert: not carried: {line}");
        }
    }
    if let Some(p) = &args.report {
        let r = Report {
            input: name,
            from: from.describe(),
            to: to.describe(),
            precision: args.precision,
            report: &report,
        };
        write_json_report(p, &REPORT, &r)?;
    }
    Ok(Exit::Ok)
}
