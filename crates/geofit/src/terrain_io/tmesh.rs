//! T-meshes at the CLI's edge: reading a `.tmesh`/`.tmb` argument, the evaluation device, and
//! the T-spline library's errors as one line each.

use tspline::format::TMeshFile;
use tspline::ocl_eval::OclEvaluator;
use tspline::TsplineError;

use super::Device;
use crate::config::{Config, Input};
use crate::error::CliError;

/// One line per T-spline library error.
pub fn tspline_err(what: &str, e: TsplineError) -> CliError {
    match e {
        TsplineError::Format { .. } | TsplineError::InvalidMesh(_) | TsplineError::ValueRange { .. } => {
            CliError::unreadable(format!("{what}: {e}"))
        }
        TsplineError::Fit(_) => CliError::findings(format!("{what}: {e}")),
        TsplineError::OpenCl(_) | TsplineError::Io(_) => CliError::internal(format!("{what}: {e}")),
    }
}

/// The OpenCL evaluator per `--device`: `auto` falls back to the CPU with one notice when no
/// platform exists (checked first, never a panic) or the kernels do not build.
pub fn select_device(device: Device, config: &Config) -> Result<Option<OclEvaluator>, CliError> {
    match device {
        Device::Cpu => Ok(None),
        Device::Opencl => {
            OclEvaluator::new().map(Some).map_err(|e| CliError::internal(format!("--device opencl: {e}")))
        }
        Device::Auto => {
            let has_platform = ocl::core::get_platform_ids().map(|v| !v.is_empty()).unwrap_or(false);
            if !has_platform {
                config.notice("notice: no OpenCL platform found; evaluating on the CPU");
                return Ok(None);
            }
            match OclEvaluator::new() {
                Ok(o) => Ok(Some(o)),
                Err(e) => {
                    config.notice(&format!("notice: {e}; evaluating on the CPU"));
                    Ok(None)
                }
            }
        }
    }
}

/// Reads a `.tmesh` argument.
pub fn read_tmesh_arg(arg: &str) -> Result<TMeshFile, CliError> {
    let input = Input::from_arg(arg);
    let bytes = input.read_all()?;
    let name = input.display_name();
    if !tspline::format::is_tmesh_document(&bytes) {
        if let Some(what) = input.path().and_then(not_a_tmesh) {
            return Err(CliError::unreadable(format!("{name}: {what}")));
        }
    }
    let file = tspline::format::read(&bytes).map_err(|e| CliError::unreadable(format!("{name}: {e}")))?;
    // The CRS goes to GDAL as a C string: a NUL byte in it (a binary T-mesh can hold one) is the
    // input's fault, not an internal error ("FfiNulError", exit 4).
    if file.georef.crs.contains('\0') {
        return Err(CliError::unreadable(format!(
            "{name}: the CRS \"{}\" holds a NUL byte",
            input_limits::quote(&file.georef.crs.replace('\0', "\\0"))
        )));
    }
    Ok(file)
}

/// What a file given as a T-mesh is instead, when it is a kind geofit reads elsewhere (a raster:
/// `fit` makes a T-mesh of it; points: `rasterize`; CityGML), with the command that takes it.
fn not_a_tmesh(path: &std::path::Path) -> Option<String> {
    use file_kind::FileKind as K;
    match file_kind::sniff_path(path).ok()? {
        K::TMesh | K::Xml(_) | K::Empty => None,
        K::Raster(_) | K::Unknown | K::Binary if raster_io::bands(path).is_ok_and(|b| !b.is_empty()) => Some(
            "is a raster, not a T-mesh: `geofit fit RASTER --max-error E -o MESH.tmesh` makes the T-mesh this command takes".to_string(),
        ),
        K::Unknown | K::Binary => None,
        k => Some(format!("is {}, not a T-mesh", k.describe())),
    }
}
