//! `metadata.referenceSystem` (an OGC CRS URL) ⇄ CityGML `srsName`, the vertical part kept:
//! a compound CRS is an OGC `crs-compound` URL one way and a compound URN the other.
//!
//! # Examples
//! ```
//! use cityjson_io::crs::{to_srs_name, to_reference_system};
//! assert_eq!(to_srs_name("https://www.opengis.net/def/crs/EPSG/0/7415"), "urn:ogc:def:crs:EPSG::7415");
//! // The CityJSON schema takes one CRS URL: a compound without an EPSG code of its own keeps
//! // its horizontal part, and the vertical one is reported.
//! let (url, dropped) = to_reference_system("urn:ogc:def:crs,crs:EPSG::25832,crs:EPSG::5783").unwrap();
//! assert_eq!((url.as_str(), dropped), ("https://www.opengis.net/def/crs/EPSG/0/25832", Some(5783)));
//! let (url, dropped) = to_reference_system("urn:ogc:def:crs,crs:EPSG::28992,crs:EPSG::5709").unwrap();
//! assert_eq!((url.as_str(), dropped), ("https://www.opengis.net/def/crs/EPSG/0/7415", None));
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

/// Compound EPSG codes for a horizontal + vertical pair (the CityJSON schema takes one URL).
const COMPOUND: &[(u32, u32, u32)] = &[(28992, 5709, 7415)];

/// A CityJSON `referenceSystem` for a CityGML srsName and the vertical EPSG code it could not
/// name: one code → its URL; a known compound pair → the compound's URL; another pair → the
/// horizontal URL (the vertical part reported by the caller). `None`: no EPSG code.
pub fn to_reference_system(srs_name: &str) -> Option<(String, Option<u32>)> {
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
        [one] => Some((format!("{EPSG_URL}{one}"), None)),
        [h, v, ..] => match COMPOUND.iter().find(|c| c.0 == h && c.1 == v) {
            Some(c) => Some((format!("{EPSG_URL}{}", c.2), None)),
            None => Some((format!("{EPSG_URL}{h}"), Some(v))),
        },
    }
}
