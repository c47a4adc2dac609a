//! The checks of `geofit export`'s options that need no input (format, origin, CRSs), so usage
//! errors come before the input is read.

use citygml_io::crs::proj_crs;

use super::Args;
use crate::config::Output;
use crate::error::CliError;
use crate::mesh_output::Format;

/// The output format (from --format or the extension) and the fixed origin, after the option
/// checks that need no input: usage errors come before the input is read.
pub(super) fn checked_options(args: &Args, output: &Output) -> Result<(Format, Option<[f64; 3]>), CliError> {
    let format = match (args.format, output.extension().as_deref()) {
        (Some(f), _) => f,
        (None, Some("glb")) => Format::Glb,
        (None, Some("gltf")) => Format::Gltf,
        (None, Some("obj")) => Format::Obj,
        (None, Some(e)) => {
            return Err(CliError::usage(format!(
                "unknown output extension '.{e}': use .glb, .gltf or .obj, or --format"
            )))
        }
        (None, None) => return Err(CliError::usage("writing to stdout: say which format with --format glb|gltf|obj")),
    };
    if args.gltf_bin && (format != Format::Gltf || output.path().is_none()) {
        return Err(CliError::usage("--gltf-bin needs a .gltf output file (-o OUT.gltf)"));
    }
    let fixed_origin = parse_origin(&args.origin)?;
    // A CRS string GDAL does not know is refused as gdalsrsinfo refuses it (PROJ alone read
    // `--t-srs foo` as a Bessel longlat).
    for (opt, crs) in [("--t-srs", args.t_srs.as_deref()), ("--s-srs", args.s_srs.as_deref().map(proj_crs).as_deref())]
    {
        if let Some(c) = crs {
            let parsed = raster_io::crs::Crs::parse(c).map_err(|e| CliError::usage(format!("{opt}: {e}")))?;
            if opt == "--t-srs" && parsed.geographic {
                return Err(CliError::usage(format!(
                    "--t-srs {c} is geographic (degrees): mesh coordinates must be metres (heights are); use a projected CRS, e.g. the UTM zone EPSG:326zz / 327zz"
                )));
            }
        }
    }
    Ok((format, fixed_origin))
}

fn parse_origin(s: &str) -> Result<Option<[f64; 3]>, CliError> {
    match s {
        "auto" => Ok(None),
        "none" => Ok(Some([0.0; 3])),
        _ => {
            let v: Vec<f64> = s
                .split(',')
                .map(|t| t.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|_| CliError::usage(format!("--origin '{s}': expected auto, none or x,y,z")))?;
            if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
                return Err(CliError::usage(format!(
                    "--origin '{s}': expected auto, none or three finite numbers x,y,z"
                )));
            }
            Ok(Some([v[0], v[1], v[2]]))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn origin_option() {
        assert_eq!(parse_origin("auto").unwrap(), None);
        assert_eq!(parse_origin("none").unwrap(), Some([0.0; 3]));
        assert_eq!(parse_origin("1,2.5,-3").unwrap(), Some([1.0, 2.5, -3.0]));
        assert!(parse_origin("1,2").is_err());
        assert!(parse_origin("1,2,nan").is_err());
    }
}
