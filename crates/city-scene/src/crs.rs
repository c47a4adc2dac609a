//! Which frame a CityGML → mesh export writes: mesh coordinates are metres, so a file in a
//! geographic CRS needs a projected target, whose PROJ transformation takes longitude, latitude
//! (the file's declared axis order is swapped where it is latitude first); the source's height
//! system goes along into the recorded CRS
//! (docs/decisions.md#geographic-crss-and-vertical-datums-of-buildings-issue-41).

use citygml_io::crs::{axis_order, vertical_part, AxisOrder};
use citygml_io::frame::geographic_document;
use citygml_io::CityModel;

/// How the export treats the CRS.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportCrs {
    /// The file's (x, y) are latitude, longitude: give PROJ (y, x).
    pub swap_axes: bool,
    /// The CRS the mesh records: the target with the source's height system (`EPSG:4647+7837`),
    /// else the source's srsName.
    pub recorded: Option<String>,
}

/// Why the export cannot be right (one line).
#[derive(Debug, Clone, PartialEq)]
pub enum ExportCrsError {
    /// A choice the user has to make (exit 2).
    Usage(String),
    /// The file contradicts its CRS (exit 3).
    Unreadable(String),
}

/// The CRS plan of an export of `model` (named `name`) with `--s-srs` / `--t-srs`.
pub fn export_crs(
    model: &CityModel,
    name: &str,
    s_srs: Option<&str>,
    t_srs: Option<&str>,
) -> Result<ExportCrs, ExportCrsError> {
    let source = s_srs.map(str::to_string).or_else(|| model.srs_name.clone());
    let geographic = geographic_document(model, s_srs);
    if let Some(g) = &geographic {
        if t_srs.is_none() {
            return Err(ExportCrsError::Usage(format!(
                "{name}: {}: mesh coordinates would be degrees beside metre heights; give a projected target, e.g. --t-srs {}",
                g.what(),
                g.suggestion()
            )));
        }
        if !g.plausible() {
            let (a, b) = g.lon_lat.map(|(lon, lat)| (lat, lon)).unwrap_or_default();
            return Err(ExportCrsError::Unreadable(format!(
                "{name}: {} but its first point ({a}, {b}) has a latitude beyond ±90°: the coordinates are in the other axis order; declare it (CRS84h) or swap the axes",
                g.what()
            )));
        }
    }
    let swap_axes = geographic.as_ref().is_some_and(|g| axis_order(&g.srs) == AxisOrder::LatLon);
    let recorded = match t_srs {
        Some(t) => {
            let vertical = source.as_deref().and_then(vertical_part).and_then(|v| v.epsg);
            Some(match vertical {
                Some(v) if vertical_part(t).is_none() => format!("{t}+{v}"),
                _ => t.to_string(),
            })
        }
        None => source,
    };
    Ok(ExportCrs { swap_axes, recorded })
}
