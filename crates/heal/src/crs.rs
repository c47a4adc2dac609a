//! Is a CRS geographic (degrees)? Heal's tolerances (snap, planarity, `--max-move`) are metres,
//! so a file in degrees is refused with its CRS named rather than "healed" with a 1 mm snap that
//! is ~100 m on the ground.
//!
//! # Examples
//! ```
//! use heal::crs::geographic_epsg;
//! assert_eq!(geographic_epsg("urn:ogc:def:crs:EPSG::4979"), Some(4979));
//! assert_eq!(geographic_epsg("http://www.opengis.net/def/crs/EPSG/0/4326"), Some(4326));
//! assert_eq!(geographic_epsg("urn:ogc:def:crs,crs:EPSG::25832,crs:EPSG::5783"), None);
//! ```

/// Geographic 2D/3D CRSs met in city models (WGS 84, ETRS89, NAD83, GDA94/2020, JGD2000/2011,
/// CGCS2000, NZGD2000 and their 3D variants).
const GEOGRAPHIC: &[u32] = &[4326, 4979, 4258, 4937, 4269, 4617, 4283, 7843, 7844, 4612, 6668, 4490, 4167, 4959, 6318, 4759];

/// The EPSG code of `srs_name` when it names a geographic CRS (any of the common spellings:
/// `EPSG:4326`, `urn:ogc:def:crs:EPSG::4979`, `http://www.opengis.net/def/crs/EPSG/0/4326`, a
/// compound URN whose horizontal part is geographic), or `CRS84`.
pub fn geographic_epsg(srs_name: &str) -> Option<u32> {
    if srs_name.contains("CRS84") {
        return Some(4326);
    }
    let first = epsg_codes(srs_name).into_iter().next()?;
    GEOGRAPHIC.contains(&first).then_some(first)
}

/// The EPSG codes named in `s`, in order: after each `EPSG`, the last all-digit part of its
/// `:`/`/`-separated segment (so versions such as `/0/` or `:6.12:` are skipped).
fn epsg_codes(s: &str) -> Vec<u32> {
    s.split("EPSG")
        .skip(1)
        .filter_map(|seg| {
            let seg = seg.split(',').next().unwrap_or("");
            seg.split([':', '/']).rfind(|t| !t.is_empty() && t.bytes().all(|c| c.is_ascii_digit()))?.parse().ok()
        })
        .collect()
}
