//! CRS names as PROJ reads them.
//!
//! CityGML names its CRS in `srsName`, in spellings PROJ does not all accept: the AdV URNs of
//! German state data, compound OGC URNs. Every command that hands a srsName to PROJ (export's
//! reprojection, the 3D Tiles tileset's frame) maps it here once.
//!
//! # Examples
//! ```
//! use citygml_io::crs::proj_crs;
//! assert_eq!(proj_crs("urn:adv:crs:ETRS89_UTM32*DE_DHHN2016_NH*GCG2016"), "EPSG:25832");
//! assert_eq!(proj_crs("urn:ogc:def:crs,crs:EPSG::25832,crs:EPSG::5783"), "EPSG:25832");
//! assert_eq!(proj_crs("urn:ogc:def:crs:EPSG::25832"), "EPSG:25832");
//! assert_eq!(proj_crs("#local-CRS-1"), "#local-CRS-1");
//! ```

/// A srsName as PROJ understands it. PROJ reads `EPSG:n`, OGC URNs and URLs itself; the AdV
/// URNs of German state data (`urn:adv:crs:ETRS89_UTM32*DE_DHHN2016_NH*GCG2016`) are mapped to
/// their horizontal EPSG code, and compound URNs to their first (horizontal) component, since
/// only x and y are transformed.
pub fn proj_crs(srs_name: &str) -> String {
    let s = srs_name.trim();
    if let Some(rest) = s.strip_prefix("urn:adv:crs:") {
        let horizontal = rest.split('*').next().unwrap_or(rest);
        let code = match horizontal {
            "ETRS89_UTM32" => Some(25832),
            "ETRS89_UTM33" => Some(25833),
            "ETRS89_Lat-Lon" | "ETRS89_Lat-Lon-h" => Some(4258),
            "DE_DHDN_3GK2" => Some(31466),
            "DE_DHDN_3GK3" => Some(31467),
            "DE_DHDN_3GK4" => Some(31468),
            "DE_DHDN_3GK5" => Some(31469),
            _ => None,
        };
        if let Some(c) = code {
            return format!("EPSG:{c}");
        }
    }
    // urn:ogc:def:crs,crs:EPSG::25832,crs:EPSG::5783 → its first component.
    if let Some(rest) = s.strip_prefix("urn:ogc:def:crs,") {
        if let Some(first) = rest.split(',').next() {
            let first = first.strip_prefix("crs:").unwrap_or(first);
            let parts: Vec<&str> = first.split(':').collect();
            if parts.len() >= 2 && parts[0].eq_ignore_ascii_case("EPSG") {
                if let Some(code) = parts.last() {
                    return format!("EPSG:{code}");
                }
            }
        }
    }
    // urn:ogc:def:crs:EPSG:6.12:3068 / urn:ogc:def:crs:EPSG::25832 → EPSG:code
    if let Some(rest) = s.strip_prefix("urn:ogc:def:crs:EPSG:") {
        if let Some(code) = rest.rsplit(':').next() {
            if code.chars().all(|c| c.is_ascii_digit()) && !code.is_empty() {
                return format!("EPSG:{code}");
            }
        }
    }
    s.to_string()
}

#[cfg(test)]
mod tests {
    use super::proj_crs;

    #[test]
    fn crs_names_for_proj() {
        assert_eq!(proj_crs("urn:adv:crs:ETRS89_UTM32*DE_DHHN2016_NH*GCG2016"), "EPSG:25832");
        assert_eq!(proj_crs("urn:adv:crs:ETRS89_UTM32*DE_DHHN92_NH"), "EPSG:25832");
        assert_eq!(proj_crs("urn:ogc:def:crs,crs:EPSG::25832,crs:EPSG::5783"), "EPSG:25832");
        assert_eq!(proj_crs("urn:ogc:def:crs,crs:EPSG:6.12:3068,crs:EPSG:6.12:5783"), "EPSG:3068");
        assert_eq!(proj_crs("urn:ogc:def:crs:EPSG::25832"), "EPSG:25832");
        assert_eq!(proj_crs("EPSG:25832"), "EPSG:25832");
        assert_eq!(proj_crs("#local-CRS-1"), "#local-CRS-1");
    }
}
