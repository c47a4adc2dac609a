//! `metadata.referenceSystem` (an OGC CRS URL) ⇄ CityGML `srsName`, the vertical part kept:
//! a compound CRS is an OGC `crs-compound` URL one way and a compound URN the other.
//!
//! # Examples
//! ```
//! use cityjson_io::crs::{to_srs_name, to_reference_system};
//! assert_eq!(to_srs_name("https://www.opengis.net/def/crs/EPSG/0/7415"), "urn:ogc:def:crs:EPSG::7415");
//! let compound = to_reference_system("urn:ogc:def:crs,crs:EPSG::25832,crs:EPSG::5783").unwrap();
//! assert_eq!(compound, "https://www.opengis.net/def/crs-compound?1=https://www.opengis.net/def/crs/EPSG/0/25832&2=https://www.opengis.net/def/crs/EPSG/0/5783");
//! assert_eq!(to_srs_name(&compound), "urn:ogc:def:crs,crs:EPSG::25832,crs:EPSG::5783");
//! ```

const EPSG_URL: &str = "https://www.opengis.net/def/crs/EPSG/0/";

/// The EPSG code at the end of an OGC CRS URL (`http` or `https`, any version segment).
fn url_code(url: &str) -> Option<u32> {
    let rest = url.trim().strip_prefix("https://").or_else(|| url.trim().strip_prefix("http://"))?;
    let rest = rest.strip_prefix("www.opengis.net/def/crs/EPSG/")?;
    rest.rsplit('/').next()?.parse().ok()
}

/// A CityGML srsName for a CityJSON `referenceSystem` (kept as written when not an EPSG URL).
pub fn to_srs_name(reference_system: &str) -> String {
    if let Some(code) = url_code(reference_system) {
        return format!("urn:ogc:def:crs:EPSG::{code}");
    }
    if let Some(q) = reference_system.split_once("crs-compound?").map(|(_, q)| q) {
        let codes: Option<Vec<u32>> =
            q.split('&').map(|kv| kv.split_once('=').and_then(|(_, u)| url_code(u))).collect();
        if let Some(codes) = codes.filter(|c| !c.is_empty()) {
            let parts: Vec<String> = codes.iter().map(|c| format!("crs:EPSG::{c}")).collect();
            return format!("urn:ogc:def:crs,{}", parts.join(","));
        }
    }
    reference_system.to_string()
}

/// A CityJSON `referenceSystem` for a CityGML srsName: one EPSG code → its URL, a compound
/// (horizontal + vertical) → a `crs-compound` URL. `None` when no EPSG code can be named.
pub fn to_reference_system(srs_name: &str) -> Option<String> {
    let mut codes = citygml_io::crs::epsg_codes(srs_name);
    if codes.is_empty() {
        let proj = citygml_io::crs::proj_crs(srs_name);
        codes = proj.strip_prefix("EPSG:").and_then(|c| c.parse().ok()).into_iter().collect();
        if let Some(v) = citygml_io::crs::vertical_part(srs_name).and_then(|v| v.epsg) {
            codes.push(v);
        }
    }
    match codes[..] {
        [] => None,
        [one] => Some(format!("{EPSG_URL}{one}")),
        _ => {
            let parts: Vec<String> =
                codes.iter().enumerate().map(|(i, c)| format!("{}={EPSG_URL}{c}", i + 1)).collect();
            Some(format!("https://www.opengis.net/def/crs-compound?{}", parts.join("&")))
        }
    }
}
