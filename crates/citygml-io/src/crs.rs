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
//!
//! It also knows which srsNames are geographic (degrees: [`geographic_epsg`], [`axis_order`]) and
//! what a CRS's vertical part is ([`vertical_part`]): the one place every buildings command asks
//! (docs/decisions.md#geographic-crss-and-vertical-datums-of-buildings-issue-41).

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
    // a compound CRS as one code (EPSG:5555) or as `EPSG:h+v`: its horizontal part
    if let Some(&first) = epsg_codes(s).first() {
        if let Some(k) = COMPOUND.iter().find(|k| k.0 == first) {
            return format!("EPSG:{}", k.1);
        }
        if s.contains('+') && s.starts_with("EPSG:") {
            return format!("EPSG:{first}");
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

/// Geographic 2D/3D CRSs met in city models (WGS 84, ETRS89, NAD83, GDA94/2020, JGD2000/2011,
/// CGCS2000, NZGD2000 and their 3D variants). Their ellipsoids are GRS80 or WGS 84 (equal to
/// 0.1 mm), so one ellipsoid serves them all for a local metric frame.
pub const GEOGRAPHIC: &[u32] =
    &[4326, 4979, 4258, 4937, 4269, 4617, 4283, 7843, 7844, 4612, 6668, 4490, 4167, 4959, 6318, 4759];

/// The EPSG code of `srs_name` when it names a geographic CRS (any of the common spellings:
/// `EPSG:4326`, `urn:ogc:def:crs:EPSG::4979`, `http://www.opengis.net/def/crs/EPSG/0/4326`, a
/// compound URN whose horizontal part is geographic), or `CRS84`.
pub fn geographic_epsg(srs_name: &str) -> Option<u32> {
    if srs_name.contains("CRS84") {
        return Some(4326);
    }
    if let Some(rest) = srs_name.trim().strip_prefix("urn:adv:crs:") {
        return rest.starts_with("ETRS89_Lat-Lon").then_some(4258);
    }
    let first = epsg_codes(srs_name).into_iter().next()?;
    GEOGRAPHIC.contains(&first).then_some(first)
}

/// The order of a geographic CRS's first two coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum AxisOrder {
    /// Latitude first: the EPSG definition of every geographic CRS, whatever the spelling
    /// (`EPSG:4326`, its URN or URL), and the order GML 3.1+ asks posList to follow.
    LatLon,
    /// Longitude first: OGC CRS84 / CRS84h.
    LonLat,
}

impl AxisOrder {
    /// A point's longitude and latitude, read in this order.
    pub fn lon_lat(self, p: &[f64; 3]) -> (f64, f64) {
        match self {
            AxisOrder::LatLon => (p[1], p[0]),
            AxisOrder::LonLat => (p[0], p[1]),
        }
    }

    /// The first two axes in words: `latitude, longitude`.
    pub fn describe(self) -> &'static str {
        match self {
            AxisOrder::LatLon => "latitude, longitude",
            AxisOrder::LonLat => "longitude, latitude",
        }
    }
}

/// Whether a longitude and latitude are a position on the globe (|lat| ≤ 90°, |lon| ≤ 180°):
/// a "latitude" beyond 90° is the tell of coordinates in the other axis order.
pub fn is_position(lon: f64, lat: f64) -> bool {
    lat.abs() <= 90.0 && lon.abs() <= 180.0
}

/// The axis order a geographic `srs_name` declares (docs/decisions.md#geographic-crss-and-vertical-datums-of-buildings-issue-41).
pub fn axis_order(srs_name: &str) -> AxisOrder {
    if srs_name.contains("CRS84") {
        AxisOrder::LonLat
    } else {
        AxisOrder::LatLon
    }
}

/// PROJ prints its own errors on stderr (`proj_create: crs not found`) besides the one line geofit
/// prints; a command that asks PROJ about the user's CRSs calls this first, before any PROJ
/// context exists, so they stay silent (`PROJ_DEBUG` set by the user is kept).
pub fn quiet_proj() {
    if std::env::var_os("PROJ_DEBUG").is_none() {
        std::env::set_var("PROJ_DEBUG", "0");
    }
}

/// The WGS 84 UTM zone of a position (EPSG:326zz north, 327zz south): the metric frame a
/// geographic file is checked in, and the `--t-srs` geofit suggests for it.
///
/// ```
/// assert_eq!(citygml_io::crs::utm_epsg(7.07, 51.4), 32632);
/// assert_eq!(citygml_io::crs::utm_epsg(151.2, -33.9), 32756);
/// ```
pub fn utm_epsg(lon: f64, lat: f64) -> u32 {
    let zone = (((lon + 180.0) / 6.0).floor() as i64).rem_euclid(60) as u32 + 1;
    if lat < 0.0 {
        32700 + zone
    } else {
        32600 + zone
    }
}

/// The EPSG codes named in `s`, in order: after each `EPSG`, the last all-digit part of its
/// `:`/`/`-separated segment (so versions such as `/0/` or `:6.12:` are skipped); `EPSG:a+b`
/// names both.
pub fn epsg_codes(s: &str) -> Vec<u32> {
    let mut codes = Vec::new();
    for seg in s.split("EPSG").skip(1) {
        let seg = seg.split([',', '&', '?', ' ', '"', ']']).next().unwrap_or("");
        let (seg, plus) = match seg.split_once('+') {
            Some((a, b)) => (a, b.parse::<u32>().ok()),
            None => (seg, None),
        };
        let code = seg.split([':', '/']).rfind(|t| !t.is_empty() && t.bytes().all(|c| c.is_ascii_digit()));
        if let Some(c) = code.and_then(|c| c.parse().ok()) {
            codes.push(c);
            codes.extend(plus);
        }
    }
    codes
}

/// What the heights of a CRS with a vertical part are, and which geoid grid turns them into
/// ellipsoidal heights (h = H + N, N the grid's value).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct VerticalDatum {
    /// The vertical CRS's name (`DHHN2016 height`).
    pub name: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub epsg: Option<u32>,
    /// `normal`, `orthometric`, `geoid model` or `unknown` heights.
    pub kind: &'static str,
    /// Metres per height unit (0.3048 for feet).
    pub unit_m: f64,
    /// File names of the geoid grid PROJ would use, in the order looked for (PROJ-data names
    /// first, then the older proj-datumgrid ones); empty where no public grid is known.
    pub grids: Vec<&'static str>,
}

impl std::fmt::Display for VerticalDatum {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.epsg {
            Some(c) => write!(f, "{} (EPSG:{c}, {} heights)", self.name, self.kind),
            None => write!(f, "{} ({} heights)", self.name, self.kind),
        }
    }
}

/// Vertical CRSs: EPSG code, name, kind of height, metres per unit, geoid grids.
const VERTICAL: &[(u32, &str, &str, f64, &[&str])] = &[
    (7837, "DHHN2016 height", "normal", 1.0, &["de_bkg_gcg2016.tif", "GCG2016.tif", "GCG2016.gtx"]),
    (5783, "DHHN92 height", "normal", 1.0, &["de_bkg_gcg2011.tif", "GCG2011.gtx"]),
    (5784, "DHHN85 height", "normal-orthometric", 1.0, &[]),
    (5785, "SNN76 height", "normal", 1.0, &[]),
    (5703, "NAVD88 height", "orthometric", 1.0, &["us_noaa_g2018u0.tif", "g2018u0.gtx"]),
    (8228, "NAVD88 height (ft)", "orthometric", 0.3048, &["us_noaa_g2018u0.tif", "g2018u0.gtx"]),
    (6360, "NAVD88 height (ftUS)", "orthometric", 1200.0 / 3937.0, &["us_noaa_g2018u0.tif", "g2018u0.gtx"]),
    (5773, "EGM96 height", "geoid model", 1.0, &["us_nga_egm96_15.tif", "egm96_15.gtx"]),
    (3855, "EGM2008 height", "geoid model", 1.0, &["us_nga_egm08_25.tif", "egm08_25.gtx"]),
    (5709, "NAP height", "normal-orthometric", 1.0, &["nl_nsgi_nlgeo2018.tif", "nlgeo2018.gtx"]),
    (5701, "ODN height", "orthometric", 1.0, &["uk_os_OSGM15_GB.tif"]),
    (5941, "NN2000 height", "normal", 1.0, &["no_kv_HREF2018B_NN2000_EUREF89.tif"]),
    (5799, "DVR90 height", "orthometric", 1.0, &["dk_sdfe_dvr90.tif"]),
    (5728, "LN02 height", "orthometric", 1.0, &[]),
    (5730, "EVRF2000 height", "normal", 1.0, &[]),
    (5621, "EVRF2007 height", "normal", 1.0, &[]),
    (9389, "EVRF2019 height", "normal", 1.0, &[]),
    (5714, "MSL height", "orthometric", 1.0, &[]),
    (5705, "Baltic 1977 height", "normal", 1.0, &[]),
    (3900, "N2000 height", "normal", 1.0, &["fi_nls_n2000.tif"]),
    (5613, "RH2000 height", "normal", 1.0, &["se_lantmateriet_SWEN17_RH2000.tif"]),
    (5711, "AHD height", "orthometric", 1.0, &["au_ga_AUSGeoid2020_20180201.tif"]),
    (7839, "NZVD2016 height", "normal-orthometric", 1.0, &["nz_linz_nzgeoid2016.tif"]),
    (6647, "CGVD2013(CGG2013) height", "orthometric", 1.0, &["ca_nrc_CGG2013an83.tif"]),
    (6695, "JGD2011 (vertical) height", "orthometric", 1.0, &["jp_gsi_gsigeo2011.tif"]),
];

/// Compound CRSs as one EPSG code: (compound, horizontal, vertical).
const COMPOUND: &[(u32, u32, u32)] = &[
    (5554, 25831, 5783),
    (5555, 25832, 5783),
    (5556, 25833, 5783),
    (7415, 28992, 5709),
    (9286, 4258, 5709),
    (5972, 25832, 5941),
    (7416, 25832, 5799),
    (7409, 4258, 5730),
    (6697, 6668, 6695),
    (3901, 2393, 3900),
];

fn vertical_epsg(code: u32) -> Option<VerticalDatum> {
    let &(epsg, name, kind, unit_m, grids) = VERTICAL.iter().find(|v| v.0 == code)?;
    Some(VerticalDatum { name: name.to_string(), epsg: Some(epsg), kind, unit_m, grids: grids.to_vec() })
}

/// The vertical part of `srs_name`, where it has one: an AdV URN's height system
/// (`urn:adv:crs:ETRS89_UTM32*DE_DHHN2016_NH*GCG2016` → DHHN2016 normal heights), a compound
/// URN/URL or `EPSG:h+v` whose later component is a vertical CRS, a compound EPSG code
/// (EPSG:5555 = UTM 32N + DHHN92), a WKT with a VERTCRS. `None`: the CRS names no height system
/// (a 2D CRS, or a 3D geographic one whose heights are ellipsoidal).
///
/// ```
/// use citygml_io::crs::vertical_part;
/// let v = vertical_part("urn:adv:crs:ETRS89_UTM32*DE_DHHN2016_NH*GCG2016").unwrap();
/// assert_eq!((v.name.as_str(), v.epsg, v.kind), ("DHHN2016 height", Some(7837), "normal"));
/// assert_eq!(vertical_part("urn:ogc:def:crs,crs:EPSG::25832,crs:EPSG::5783").unwrap().epsg, Some(5783));
/// assert_eq!(vertical_part("EPSG:25832+5773").unwrap().name, "EGM96 height");
/// assert!(vertical_part("urn:ogc:def:crs:EPSG::25832").is_none());
/// assert!(vertical_part("urn:ogc:def:crs:EPSG::4979").is_none());
/// ```
pub fn vertical_part(srs_name: &str) -> Option<VerticalDatum> {
    let s = srs_name.trim();
    if let Some(rest) = s.strip_prefix("urn:adv:crs:") {
        let height = rest.split('*').nth(1)?;
        let system = height.trim_start_matches("DE_");
        let (system, suffix) = system.rsplit_once('_').unwrap_or((system, ""));
        let code = match system {
            "DHHN2016" => Some(7837),
            "DHHN92" => Some(5783),
            "DHHN85" => Some(5784),
            "SNN76" => Some(5785),
            _ => None,
        };
        if let Some(v) = code.and_then(vertical_epsg) {
            return Some(v);
        }
        let kind = match suffix {
            "NH" => "normal",
            "NOH" => "normal-orthometric",
            "OH" => "orthometric",
            _ => "unknown",
        };
        return Some(VerticalDatum { name: format!("{system} height"), epsg: None, kind, unit_m: 1.0, grids: vec![] });
    }
    for wkt_key in ["VERTCRS[\"", "VERT_CS[\"", "VERTICALCRS[\""] {
        if let Some(i) = s.find(wkt_key) {
            let name = s[i + wkt_key.len()..].split('"').next().unwrap_or("").to_string();
            let known = VERTICAL.iter().find(|v| v.1 == name).and_then(|v| vertical_epsg(v.0));
            return Some(known.unwrap_or(VerticalDatum {
                name,
                epsg: None,
                kind: "unknown",
                unit_m: 1.0,
                grids: vec![],
            }));
        }
    }
    let codes = epsg_codes(s);
    if let Some(&(_, _, v)) = codes.first().and_then(|c| COMPOUND.iter().find(|k| k.0 == *c)) {
        return vertical_epsg(v);
    }
    codes.iter().skip(1).find_map(|&c| {
        vertical_epsg(c).or(Some(VerticalDatum {
            name: format!("EPSG:{c}"),
            epsg: Some(c),
            kind: "unknown",
            unit_m: 1.0,
            grids: vec![],
        }))
    })
}

/// One line on a srsName for reports: the horizontal CRS as PROJ gets it, whether it is
/// geographic, and the height system (`heights: DHHN2016 height (EPSG:7837, normal heights)`).
pub fn describe(srs_name: &str) -> String {
    let mut s = format!("{} as {}", srs_name.trim(), proj_crs(srs_name));
    if let Some(epsg) = geographic_epsg(srs_name) {
        s += &format!(", geographic (EPSG:{epsg}, degrees, {})", axis_order(srs_name).describe());
    }
    match vertical_part(srs_name) {
        Some(v) => s += &format!("; heights: {v}"),
        None => s += "; heights: no vertical datum named (ellipsoidal or unknown)",
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crs_names_for_proj() {
        assert_eq!(proj_crs("urn:adv:crs:ETRS89_UTM32*DE_DHHN2016_NH*GCG2016"), "EPSG:25832");
        assert_eq!(proj_crs("urn:adv:crs:ETRS89_UTM32*DE_DHHN92_NH"), "EPSG:25832");
        assert_eq!(proj_crs("urn:ogc:def:crs,crs:EPSG::25832,crs:EPSG::5783"), "EPSG:25832");
        assert_eq!(proj_crs("urn:ogc:def:crs,crs:EPSG:6.12:3068,crs:EPSG:6.12:5783"), "EPSG:3068");
        assert_eq!(proj_crs("urn:ogc:def:crs:EPSG::25832"), "EPSG:25832");
        assert_eq!(proj_crs("EPSG:25832"), "EPSG:25832");
        assert_eq!(proj_crs("#local-CRS-1"), "#local-CRS-1");
        assert_eq!(proj_crs("EPSG:25832+7837"), "EPSG:25832");
        assert_eq!(proj_crs("EPSG:5555"), "EPSG:25832");
    }

    #[test]
    fn geographic_and_axis_order() {
        assert_eq!(geographic_epsg("urn:ogc:def:crs:EPSG::4979"), Some(4979));
        assert_eq!(geographic_epsg("http://www.opengis.net/def/crs/EPSG/0/4326"), Some(4326));
        assert_eq!(geographic_epsg("urn:ogc:def:crs,crs:EPSG::25832,crs:EPSG::5783"), None);
        assert_eq!(geographic_epsg("urn:adv:crs:ETRS89_Lat-Lon-h"), Some(4258));
        assert_eq!(geographic_epsg("urn:adv:crs:ETRS89_UTM32*DE_DHHN2016_NH"), None);
        assert_eq!(axis_order("urn:ogc:def:crs:EPSG::4979"), AxisOrder::LatLon);
        assert_eq!(axis_order("urn:ogc:def:crs:OGC:1.3:CRS84"), AxisOrder::LonLat);
    }

    #[test]
    fn vertical_parts() {
        let v = vertical_part("urn:adv:crs:ETRS89_UTM32*DE_DHHN92_NH").unwrap();
        assert_eq!(v.epsg, Some(5783));
        let v = vertical_part("urn:adv:crs:ETRS89_UTM32*DE_DHHN12_NOH").unwrap();
        assert_eq!((v.name.as_str(), v.kind, v.epsg), ("DHHN12 height", "normal-orthometric", None));
        assert!(vertical_part("urn:adv:crs:ETRS89_UTM32").is_none());
        assert_eq!(vertical_part("EPSG:5555").unwrap().epsg, Some(5783));
        let url = "http://www.opengis.net/def/crs-compound?1=http://www.opengis.net/def/crs/EPSG/0/25832&2=http://www.opengis.net/def/crs/EPSG/0/7837";
        assert_eq!(vertical_part(url).unwrap().epsg, Some(7837));
        assert_eq!(epsg_codes(url), vec![25832, 7837]);
        assert_eq!(vertical_part("urn:ogc:def:crs,crs:EPSG::25832,crs:EPSG::9999").unwrap().kind, "unknown");
        let wkt = r#"COMPOUNDCRS["x",PROJCRS["ETRS89 / UTM zone 32N"],VERTCRS["EGM96 height",VDATUM["EGM96 geoid"]]]"#;
        assert_eq!(vertical_part(wkt).unwrap().epsg, Some(5773));
        assert!(describe("urn:adv:crs:ETRS89_UTM32*DE_DHHN2016_NH*GCG2016")
            .contains("heights: DHHN2016 height (EPSG:7837, normal heights)"));
    }
}
