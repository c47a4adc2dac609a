//! Units of a raster's heights and of its CRS (issue 41, docs/decisions.md#raster-units-bands-and-no-data-issue-41):
//! a band's unit type (GDAL's `GetUnitType`: "m", "metre", "km", "ft", "US survey foot", ...),
//! a compound CRS's vertical unit and the CRS's horizontal unit are read as a [`LengthUnit`] or
//! refused by name. Nothing is guessed: an unknown string is an error naming it.
//!
//! ```
//! use raster_io::units::{parse_length_unit, resolve_z_unit};
//! assert_eq!(parse_length_unit("US survey foot").unwrap().metres, 1200.0 / 3937.0);
//! assert_eq!(parse_length_unit("kilometres").unwrap().name, "km");
//! assert!(parse_length_unit("furlong").is_none());
//! // the band's unit type decides; --z-unit overrides it
//! assert_eq!(resolve_z_unit(Some("km"), None, None).unwrap().unwrap().unit.metres, 1000.0);
//! assert_eq!(resolve_z_unit(Some("km"), None, Some("m")).unwrap().unwrap().unit.metres, 1.0);
//! assert!(resolve_z_unit(Some("furlong"), None, None).is_err());
//! ```

use gdal::spatial_ref::SpatialRef;

/// A unit of length: its short name and its size in metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LengthUnit {
    /// Short name: `m`, `km`, `cm`, `mm`, `dm`, `ft` (international foot), `us-ft` (US survey
    /// foot), `fathom`.
    pub name: &'static str,
    /// Metres per unit.
    pub metres: f64,
}

/// The metre.
pub const METRE: LengthUnit = LengthUnit { name: "m", metres: 1.0 };

/// The names `--z-unit` takes (each also in its long spellings), for messages.
pub const KNOWN_UNITS: &str = "m, km, cm, mm, dm, ft, us-ft, fathom";

/// Reads a unit of length from its usual spellings (case, plural, `_`/`-` as spaces); `None`
/// for anything else.
pub fn parse_length_unit(s: &str) -> Option<LengthUnit> {
    let n: String = s.trim().trim_end_matches('.').to_ascii_lowercase().replace(['_', '-'], " ");
    let n = n.split_whitespace().collect::<Vec<_>>().join(" ");
    let unit = |name, metres| Some(LengthUnit { name, metres });
    match n.as_str() {
        "m" | "metre" | "metres" | "meter" | "meters" => unit("m", 1.0),
        "km" | "kilometre" | "kilometres" | "kilometer" | "kilometers" => unit("km", 1000.0),
        "dm" | "decimetre" | "decimetres" | "decimeter" | "decimeters" => unit("dm", 0.1),
        "cm" | "centimetre" | "centimetres" | "centimeter" | "centimeters" => unit("cm", 0.01),
        "mm" | "millimetre" | "millimetres" | "millimeter" | "millimeters" => unit("mm", 0.001),
        "ft" | "foot" | "feet" | "international foot" | "international feet" | "foot international" | "intl ft" => {
            unit("ft", 0.3048)
        }
        "us ft" | "ftus" | "us survey foot" | "us survey feet" | "survey foot" | "survey feet" | "foot us"
        | "us foot" | "us feet" | "foot us survey" => unit("us-ft", 1200.0 / 3937.0),
        "fathom" | "fathoms" => unit("fathom", 1.8288),
        _ => None,
    }
}

/// Where the unit of the heights was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ZUnitSource {
    /// The user's `--z-unit`.
    Given,
    /// The band's unit type.
    Band,
    /// The vertical part of a compound CRS.
    VerticalCrs,
}

/// The unit of a raster's heights and where it came from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ZUnit {
    pub unit: LengthUnit,
    pub source: ZUnitSource,
}

/// The horizontal unit of a CRS.
#[derive(Debug, Clone, PartialEq)]
pub enum Horizontal {
    /// No CRS, or one GDAL cannot read.
    Unknown,
    /// Geographic: degrees.
    Degrees,
    /// Projected (or local) in this unit; `name` as the CRS spells it.
    Linear { name: String, metres: f64 },
}

/// The horizontal unit of a CRS given as WKT.
pub fn horizontal_unit(wkt: Option<&str>) -> Horizontal {
    let Some(srs) = wkt.filter(|w| !w.trim().is_empty()).and_then(|w| SpatialRef::from_wkt(w).ok()) else {
        return Horizontal::Unknown;
    };
    if srs.is_geographic() {
        return Horizontal::Degrees;
    }
    Horizontal::Linear {
        name: srs.linear_units_name().unwrap_or_else(|| "unnamed unit".into()),
        metres: srs.linear_units(),
    }
}

/// The unit of the vertical part of a compound CRS (`None` when it has none).
fn vertical_unit_name(wkt: &str) -> Option<(String, f64)> {
    let srs = SpatialRef::from_wkt(wkt).ok()?;
    if !srs.is_compound() {
        return None;
    }
    let key = std::ffi::CString::new("VERT_CS").ok()?;
    let mut name: *mut std::os::raw::c_char = std::ptr::null_mut();
    // SAFETY: `srs` is a live handle; GDAL returns a pointer to a string it owns (not freed here).
    let metres = unsafe { gdal_sys::OSRGetTargetLinearUnits(srs.to_c_hsrs(), key.as_ptr(), &mut name) };
    let name = if name.is_null() {
        String::new()
    } else {
        unsafe { std::ffi::CStr::from_ptr(name) }.to_string_lossy().into_owned()
    };
    (metres > 0.0).then_some((name, metres))
}

/// The unit of the heights: `given` (`--z-unit`) when there is one, else the band's unit type,
/// else a compound CRS's vertical unit; `Ok(None)` when nothing declares one (the heights are
/// then taken as they are, in metres as ever). Refused, with a one-line reason naming the string
/// and `--z-unit`: a unit string geofit does not know, and a CRS whose x/y are in feet (or any
/// unit but the metre) when the band says nothing: its heights may be in either.
pub fn resolve_z_unit(
    band_unit: Option<&str>,
    crs_wkt: Option<&str>,
    given: Option<&str>,
) -> Result<Option<ZUnit>, String> {
    if let Some(g) = given {
        let unit =
            parse_length_unit(g).ok_or_else(|| format!("--z-unit '{g}' is not a unit geofit knows ({KNOWN_UNITS})"))?;
        return Ok(Some(ZUnit { unit, source: ZUnitSource::Given }));
    }
    if let Some(b) = band_unit.map(str::trim).filter(|b| !b.is_empty()) {
        let unit = parse_length_unit(b).ok_or_else(|| {
            format!("the band's unit type is '{b}', not a unit of length geofit knows ({KNOWN_UNITS}): give --z-unit UNIT to say what the heights are in")
        })?;
        return Ok(Some(ZUnit { unit, source: ZUnitSource::Band }));
    }
    let wkt = crs_wkt.filter(|w| !w.trim().is_empty());
    if let Some((name, metres)) = wkt.and_then(vertical_unit_name) {
        let unit = parse_length_unit(&name).or_else(|| known_by_size(metres)).ok_or_else(|| {
            format!("the CRS's vertical unit is '{name}' ({metres} m), not one geofit knows ({KNOWN_UNITS}): give --z-unit UNIT")
        })?;
        return Ok(Some(ZUnit { unit, source: ZUnitSource::VerticalCrs }));
    }
    if let Horizontal::Linear { name, metres } = horizontal_unit(wkt) {
        if (metres - 1.0).abs() > 1e-12 {
            return Err(format!(
                "x/y are in {name} (the CRS) and the band declares no unit for the heights: give --z-unit UNIT ({KNOWN_UNITS}) to say what they are in"
            ));
        }
    }
    Ok(None)
}

/// A unit recognised by its size in metres (a CRS that names its unit oddly).
fn known_by_size(metres: f64) -> Option<LengthUnit> {
    ["m", "km", "cm", "mm", "dm", "ft", "us-ft", "fathom"]
        .iter()
        .filter_map(|n| parse_length_unit(n))
        .find(|u| (u.metres - metres).abs() <= 1e-9 * u.metres)
}

/// A horizontal length a user gave (`rasterize --cell`) in the unit of the grid's CRS (WKT).
/// The length is in metres unless `unit` says otherwise (`crs` for the CRS's own unit); a CRS
/// whose x/y are in another linear unit than the metre (US survey feet, feet) needs `unit`,
/// since either reading is common there: refused, naming both (docs/decisions.md#cell-sizes-in-a-crs-of-feet-issue-41).
/// Geographic and unknown CRSs keep the length as given (their own checks apply).
///
/// ```
/// use raster_io::units::length_in_crs_units;
/// let ft_us = r#"PROJCS["x",GEOGCS["NAD83",DATUM["North_American_Datum_1983",SPHEROID["GRS 1980",6378137,298.257222101]],PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433]],PROJECTION["Transverse_Mercator"],UNIT["US survey foot",0.304800609601219]]"#;
/// assert!(length_in_crs_units("--cell", 10.0, None, Some(ft_us)).is_err());
/// assert_eq!(length_in_crs_units("--cell", 10.0, Some("crs"), Some(ft_us)).unwrap(), 10.0);
/// let ft = length_in_crs_units("--cell", 10.0, Some("m"), Some(ft_us)).unwrap();
/// assert!((ft - 32.808333).abs() < 1e-5);
/// assert_eq!(length_in_crs_units("--cell", 2.0, None, None).unwrap(), 2.0);
/// ```
pub fn length_in_crs_units(
    option: &str,
    length: f64,
    unit: Option<&str>,
    crs_wkt: Option<&str>,
) -> Result<f64, String> {
    let given = match unit {
        None | Some("crs") => None,
        Some(u) => Some(
            parse_length_unit(u)
                .ok_or_else(|| format!("{option}-unit {u}: not a unit geofit knows ({KNOWN_UNITS}, or crs)"))?,
        ),
    };
    match (horizontal_unit(crs_wkt), given) {
        (Horizontal::Linear { metres, .. }, Some(u)) => Ok(length * u.metres / metres),
        (Horizontal::Linear { name, metres }, None) if unit.is_none() && (metres - 1.0).abs() > 1e-12 => Err(format!(
            "{option} {length}: the grid's CRS has x/y in {name}; say which unit {option} is in: \
             {option}-unit crs ({length} {name}) or {option}-unit m ({:.6} {name})",
            length / metres
        )),
        (_, Some(u)) if (u.metres - 1.0).abs() > 1e-12 => {
            Err(format!("{option}-unit {}: the grid's CRS is not in a linear unit to convert into", u.name))
        }
        _ => Ok(length),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spellings_gdal_and_netcdf_use() {
        for (s, name) in [
            ("metre", "m"),
            ("Meters", "m"),
            ("KM", "km"),
            ("feet", "ft"),
            ("US survey foot", "us-ft"),
            ("US_survey_feet", "us-ft"),
            ("ftUS", "us-ft"),
            ("cm", "cm"),
            ("centimetres", "cm"),
        ] {
            assert_eq!(parse_length_unit(s).map(|u| u.name), Some(name), "{s}");
        }
        for s in ["", "degrees", "m/s", "furlong", "kft"] {
            assert!(parse_length_unit(s).is_none(), "{s}");
        }
    }

    #[test]
    fn a_feet_crs_without_a_band_unit_is_refused_and_metres_pass() {
        let ft = SpatialRef::from_epsg(2240).unwrap().to_wkt().unwrap(); // Georgia West, US survey feet
        let e = resolve_z_unit(None, Some(&ft), None).unwrap_err();
        assert!(e.contains("--z-unit"), "{e}");
        assert_eq!(resolve_z_unit(None, Some(&ft), Some("us-ft")).unwrap().unwrap().unit.name, "us-ft");
        let utm = SpatialRef::from_epsg(25832).unwrap().to_wkt().unwrap();
        assert_eq!(resolve_z_unit(None, Some(&utm), None).unwrap(), None);
        let geo = SpatialRef::from_epsg(4326).unwrap().to_wkt().unwrap();
        assert_eq!(horizontal_unit(Some(&geo)), Horizontal::Degrees);
        assert_eq!(resolve_z_unit(None, Some(&geo), None).unwrap(), None);
    }
}
