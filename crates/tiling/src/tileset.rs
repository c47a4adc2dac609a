//! A 3D Tiles 1.1 `tileset.json` over per-tile glb written by `geofit export`.
//!
//! Frames (docs/decisions.md#scale-out-tiles-and-workflows): `geofit export` writes vertex data in
//! the source CRS minus an origin (`extras.origin` of the root node), Z-up, under a root node
//! whose matrix turns it Y-up. 3D Tiles turns glTF content from Y-up back to Z-up, so the content
//! sits in the tile frame as (E − E₀, N − N₀, h − h₀). Each tile's `transform` maps that frame to
//! ECEF (EPSG:4978) as the affine map tangent to CRS → geographic → ECEF at the origin: columns
//! ∂ECEF/∂E and ∂ECEF/∂N by central differences (±1 m) through PROJ, ∂ECEF/∂h the ellipsoid
//! normal. Off the origin the map is first-order (≈ d²/2R: 2 cm at 500 m). Heights become
//! ellipsoidal as [`Heights`] says: a CRS with a vertical part (NRW's DHHN2016 normal heights, a
//! compound CRS) gets the geoid undulation of its grid at each tile origin through PROJ, or the
//! user's `--height-offset` / `--heights-as-is`; without a grid and without a choice the tileset
//! is refused (docs/decisions.md#geographic-crss-and-vertical-datums-of-buildings-issue-41).
//! What was done is recorded in `asset.extras.heights` and each tile's `extras`. Each tile's
//! bounding box is the box of its vertices in the tile frame; the root's is the ECEF axis-aligned
//! box around the children's boxes.

use std::path::Path;

use serde_json::{json, Value};

use crate::TilingError;

/// What the tileset needs from one glb: origin, CRS and the box of its vertices in the tile frame.
#[derive(Debug, Clone, PartialEq)]
pub struct GlbExtent {
    pub origin: [f64; 3],
    pub crs: Option<String>,
    /// Box of all POSITION accessors' min/max corners through the node matrices below the root
    /// node, in the Z-up frame of the vertex data (source CRS minus origin).
    pub min: [f64; 3],
    pub max: [f64; 3],
}

/// Reads the JSON chunk of a glb.
pub fn glb_json(bytes: &[u8], name: &str) -> Result<Value, TilingError> {
    let bad = |m: &str| TilingError::unreadable(name, format!("not a glb: {m}"));
    if bytes.len() < 20 || &bytes[0..4] != b"glTF" {
        return Err(bad("no glTF magic"));
    }
    let u32_at = |i: usize| u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]) as usize;
    if u32_at(4) != 2 {
        return Err(bad("glTF version is not 2"));
    }
    let (len, kind) = (u32_at(12), u32_at(16));
    if kind != 0x4E4F534A || 20 + len > bytes.len() {
        return Err(bad("the first chunk is not JSON"));
    }
    serde_json::from_slice(&bytes[20..20 + len]).map_err(|e| bad(&e.to_string()))
}

type M4 = [f64; 16]; // column-major

fn mul(a: &M4, b: &M4) -> M4 {
    let mut m = [0.0; 16];
    for c in 0..4 {
        for r in 0..4 {
            m[c * 4 + r] = (0..4).map(|k| a[k * 4 + r] * b[c * 4 + k]).sum();
        }
    }
    m
}

fn apply(m: &M4, p: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|r| m[r] * p[0] + m[4 + r] * p[1] + m[8 + r] * p[2] + m[12 + r])
}

const IDENTITY: M4 = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0];

/// A node's local matrix (matrix, or translation and scale; rotations are refused: geofit's
/// writer never uses them below the root).
fn node_matrix(n: &Value, name: &str) -> Result<M4, TilingError> {
    let nums =
        |k: &str| n.get(k).and_then(Value::as_array).map(|a| a.iter().filter_map(Value::as_f64).collect::<Vec<_>>());
    if let Some(m) = nums("matrix") {
        return m.try_into().map_err(|_| TilingError::unreadable(name, "node matrix without 16 numbers"));
    }
    if n.get("rotation").is_some() {
        return Err(TilingError::unreadable(name, "node rotations below the root node are not supported"));
    }
    let mut m = IDENTITY;
    if let Some(s) = nums("scale").filter(|s| s.len() == 3) {
        (m[0], m[5], m[10]) = (s[0], s[1], s[2]);
    }
    if let Some(t) = nums("translation").filter(|t| t.len() == 3) {
        (m[12], m[13], m[14]) = (t[0], t[1], t[2]);
    }
    Ok(m)
}

/// Origin, CRS and vertex box of a glb written by `geofit export` (root node `origin`).
pub fn glb_extent(bytes: &[u8], name: &str) -> Result<GlbExtent, TilingError> {
    let j = glb_json(bytes, name)?;
    let scene = j.get("scene").and_then(Value::as_u64).unwrap_or(0) as usize;
    let roots = j["scenes"][scene]["nodes"].as_array().cloned().unwrap_or_default();
    let [root] = roots.as_slice() else {
        return Err(TilingError::unreadable(name, "expected one root node (geofit export's `origin` node)"));
    };
    let root = &j["nodes"][root.as_u64().unwrap_or(u64::MAX) as usize];
    let origin: Vec<f64> =
        root["extras"]["origin"].as_array().map(|a| a.iter().filter_map(Value::as_f64).collect()).unwrap_or_default();
    let origin: [f64; 3] = origin
        .try_into()
        .map_err(|_| TilingError::unreadable(name, "root node has no extras.origin (not written by geofit export)"))?;
    let crs = root["extras"]["crs"].as_str().map(str::to_string);
    let (mut min, mut max) = ([f64::MAX; 3], [f64::MIN; 3]);
    let mut stack: Vec<(usize, M4)> = root["children"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(Value::as_u64)
        .map(|c| (c as usize, IDENTITY))
        .collect();
    while let Some((i, parent)) = stack.pop() {
        let n = &j["nodes"][i];
        let m = mul(&parent, &node_matrix(n, name)?);
        if let Some(mesh) = n.get("mesh").and_then(Value::as_u64) {
            for prim in j["meshes"][mesh as usize]["primitives"].as_array().into_iter().flatten() {
                let Some(acc) = prim["attributes"]["POSITION"].as_u64() else { continue };
                let acc = &j["accessors"][acc as usize];
                let v = |k: &str| acc[k].as_array().map(|a| a.iter().filter_map(Value::as_f64).collect::<Vec<_>>());
                let (Some(lo), Some(hi)) = (v("min"), v("max")) else {
                    return Err(TilingError::unreadable(name, "POSITION accessor without min/max"));
                };
                for k in 0..8 {
                    let p = [0, 1, 2].map(|a| if k >> a & 1 == 0 { lo[a] } else { hi[a] });
                    let q = apply(&m, p);
                    for a in 0..3 {
                        min[a] = min[a].min(q[a]);
                        max[a] = max[a].max(q[a]);
                    }
                }
            }
        }
        for c in n["children"].as_array().into_iter().flatten().filter_map(Value::as_u64) {
            stack.push((c as usize, m));
        }
    }
    if min[0] > max[0] {
        return Err(TilingError::unreadable(name, "no triangles"));
    }
    Ok(GlbExtent { origin, crs, min, max })
}

/// GRS80 (ETRS89) / WGS84 share a and differ in f by 1e-11: GRS80 is used.
fn geodetic_to_ecef(lon_deg: f64, lat_deg: f64, h: f64) -> [f64; 3] {
    let (a, f) = (6_378_137.0, 1.0 / 298.257_222_101);
    let e2 = f * (2.0 - f);
    let (lon, lat) = (lon_deg.to_radians(), lat_deg.to_radians());
    let n = a / (1.0 - e2 * lat.sin().powi(2)).sqrt();
    [(n + h) * lat.cos() * lon.cos(), (n + h) * lat.cos() * lon.sin(), (n * (1.0 - e2) + h) * lat.sin()]
}

/// How the glb heights become ellipsoidal heights (h = H + offset).
#[derive(Debug, Clone, PartialEq)]
pub enum Heights {
    /// The geoid grid PROJ has for the CRS's height system; refused where there is none. A CRS
    /// without a vertical part keeps its heights (taken as ellipsoidal).
    Auto,
    /// `--geoid GRID`: this grid's undulation N at each tile origin (h = H + N).
    Geoid(String),
    /// `--height-offset M`: h = H + M everywhere.
    Offset(f64),
    /// `--heights-as-is`: h = H, whatever the CRS says.
    AsIs,
}

/// The geoid undulation of `grid` at a position in degrees, by a PROJ pipeline (vgridshift adds
/// the grid value to a zero height: h = H + N). Fails when PROJ cannot open the grid.
pub fn geoid_undulation(grid: &str, lon: f64, lat: f64) -> Result<f64, String> {
    let def = format!(
        "+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad +step +proj=vgridshift +grids={grid} +multiplier=1 +step +proj=axisswap +order=3,2,1"
    );
    let p = proj::Proj::new(&def).map_err(|e| format!("PROJ cannot open the geoid grid '{grid}': {e}"))?;
    let (n, _) =
        p.convert((lon, lat)).map_err(|e| format!("geoid grid '{grid}' has no value at ({lon}, {lat}): {e}"))?;
    if !n.is_finite() || n.abs() > 200.0 {
        return Err(format!("geoid grid '{grid}' gives {n} m at ({lon}, {lat}): not a geoid undulation"));
    }
    Ok(n)
}

/// The offset (m) that makes the heights of `crs` ellipsoidal at the tile origin (longitude,
/// latitude), and what was done, for the tileset's `extras`.
fn height_offset(
    heights: &Heights,
    crs_names: &[&str],
    uri: &str,
    lon: f64,
    lat: f64,
) -> Result<(f64, Value), TilingError> {
    let vertical = crs_names.iter().find_map(|c| citygml_io::crs::vertical_part(c));
    let named = vertical.as_ref().map(|v| v.to_string());
    match heights {
        Heights::Offset(m) => Ok((*m, json!({"method": "offset", "offset_m": m, "vertical": named}))),
        Heights::AsIs => Ok((0.0, json!({"method": "as-is", "vertical": named}))),
        Heights::Geoid(grid) => {
            let n = geoid_undulation(grid, lon, lat).map_err(|e| TilingError::Usage(format!("--geoid: {e}")))?;
            Ok((n, json!({"method": "geoid", "grid": grid, "undulation_m": n, "vertical": named})))
        }
        Heights::Auto => {
            let Some(v) = vertical else {
                return Ok((
                    0.0,
                    json!({"method": "as-is", "vertical": null, "why": "the CRS names no height system: heights taken as ellipsoidal"}),
                ));
            };
            let choose = "give --geoid GRID (a PROJ geoid grid file), --height-offset M (h = H + M, e.g. the geoid undulation) or --heights-as-is";
            if v.unit_m != 1.0 {
                return Err(TilingError::Usage(format!(
                    "{uri}: heights are {v}, not metres: convert them first, or {choose}"
                )));
            }
            let mut tried = Vec::new();
            for grid in &v.grids {
                match geoid_undulation(grid, lon, lat) {
                    Ok(n) => {
                        return Ok((
                            n,
                            json!({"method": "geoid", "grid": grid, "undulation_m": n, "vertical": v.to_string()}),
                        ))
                    }
                    Err(_) => tried.push(*grid),
                }
            }
            let looked = if tried.is_empty() {
                "no public geoid grid is known to geofit for it".to_string()
            } else {
                format!("no geoid grid for it is installed ({} not found by PROJ)", tried.join(", "))
            };
            Err(TilingError::Usage(format!(
                "{uri}: heights are {v} (CRS {}), not ellipsoidal; {looked}: {choose}",
                crs_names[crs_names.len() - 1]
            )))
        }
    }
}

/// The tile-frame → ECEF affine map at `origin` (column-major 4×4).
pub fn enu_like_transform(crs: &str, origin: [f64; 3], height_offset: f64) -> Result<M4, TilingError> {
    let p = proj::Proj::new_known_crs(crs, "EPSG:4326", None)
        .map_err(|e| TilingError::Usage(format!("cannot transform from '{crs}' to geographic coordinates: {e}")))?;
    let h = origin[2] + height_offset;
    let ecef = |e: f64, n: f64| -> Result<[f64; 3], TilingError> {
        let (lon, lat) = p
            .convert((e, n))
            .map_err(|err| TilingError::Usage(format!("'{crs}': ({e}, {n}) has no geographic position: {err}")))?;
        Ok(geodetic_to_ecef(lon, lat, h))
    };
    let (e0, n0) = (origin[0], origin[1]);
    let c = ecef(e0, n0)?;
    let de = [ecef(e0 + 1.0, n0)?, ecef(e0 - 1.0, n0)?];
    let dn = [ecef(e0, n0 + 1.0)?, ecef(e0, n0 - 1.0)?];
    let (lon, lat) = p.convert((e0, n0)).map_err(|err| TilingError::Usage(format!("'{crs}': {err}")))?;
    let (lo, la) = (lon.to_radians(), lat.to_radians());
    let up = [la.cos() * lo.cos(), la.cos() * lo.sin(), la.sin()];
    let col = |d: &[[f64; 3]; 2]| [0, 1, 2].map(|k| (d[0][k] - d[1][k]) / 2.0);
    let (ce, cn) = (col(&de), col(&dn));
    Ok([ce[0], ce[1], ce[2], 0.0, cn[0], cn[1], cn[2], 0.0, up[0], up[1], up[2], 0.0, c[0], c[1], c[2], 1.0])
}

/// One content tile: where its glb is (relative to the tileset) and its extent.
pub struct ContentTile {
    pub uri: String,
    pub extent: GlbExtent,
}

/// Longitude, latitude (degrees) of a point of `crs` (PROJ's spelling).
fn lon_lat(crs: &str, e: f64, n: f64) -> Result<(f64, f64), TilingError> {
    let p = proj::Proj::new_known_crs(crs, "EPSG:4326", None)
        .map_err(|err| TilingError::Usage(format!("PROJ cannot transform from CRS '{crs}' to geographic coordinates ({err}): give the CRS the glb are in, e.g. --crs EPSG:25832")))?;
    p.convert((e, n))
        .map_err(|err| TilingError::Usage(format!("'{crs}': ({e}, {n}) has no geographic position: {err}")))
}

/// The tileset: a root with one leaf per content tile (refine ADD: every building is in exactly
/// one tile), geometric error 0 at the leaves and the root box diagonal at the root.
pub fn tileset(
    tiles: &[ContentTile],
    crs_override: Option<&str>,
    heights: &Heights,
    generator: &str,
) -> Result<Value, TilingError> {
    if tiles.is_empty() {
        return Err(TilingError::Usage("no glb content to put in a tileset".into()));
    }
    let (mut lo, mut hi) = ([f64::MAX; 3], [f64::MIN; 3]);
    let mut children = Vec::new();
    let mut record: Option<Value> = None;
    for t in tiles {
        // the glb records the source's srsName (an AdV URN for German data): PROJ's spelling of it
        let crs = crs_override.or(t.extent.crs.as_deref()).map(citygml_io::crs::proj_crs).ok_or_else(|| {
            TilingError::Usage(format!("{}: the glb records no CRS; give one (e.g. EPSG:25832)", t.uri))
        })?;
        // the height system: --crs's when it names one, else the one the glb records
        let names: Vec<&str> = crs_override.into_iter().chain(t.extent.crs.as_deref()).collect();
        let (lon, lat) = lon_lat(&crs, t.extent.origin[0], t.extent.origin[1])?;
        let (offset, how) = height_offset(heights, &names, &t.uri, lon, lat)?;
        if record.is_none() {
            record = Some(how);
        }
        let m = enu_like_transform(&crs, t.extent.origin, offset)?;
        let (a, b) = (t.extent.min, t.extent.max);
        let centre = [0, 1, 2].map(|k| (a[k] + b[k]) / 2.0);
        let half = [0, 1, 2].map(|k| (b[k] - a[k]) / 2.0);
        for k in 0..8 {
            let q = apply(&m, [0, 1, 2].map(|ax| if k >> ax & 1 == 0 { a[ax] } else { b[ax] }));
            for ax in 0..3 {
                lo[ax] = lo[ax].min(q[ax]);
                hi[ax] = hi[ax].max(q[ax]);
            }
        }
        let id = Path::new(&t.uri)
            .file_name()
            .map(|f| f.to_string_lossy().split('.').next().unwrap_or_default().to_string());
        children.push(json!({
            "boundingVolume": {"box": [centre[0], centre[1], centre[2], half[0], 0.0, 0.0, 0.0, half[1], 0.0, 0.0, 0.0, half[2]]},
            "transform": m,
            "geometricError": 0.0,
            "content": {"uri": t.uri},
            "extras": {"tile": id, "origin": t.extent.origin, "crs": crs, "height_offset_m": offset},
        }));
    }
    let centre = [0, 1, 2].map(|k| (lo[k] + hi[k]) / 2.0);
    let half = [0, 1, 2].map(|k| (hi[k] - lo[k]) / 2.0);
    let diagonal = 2.0 * half.iter().map(|h| h * h).sum::<f64>().sqrt();
    Ok(json!({
        "asset": {"version": "1.1", "generator": generator, "extras": {"heights": record}},
        "geometricError": diagonal,
        "root": {
            "boundingVolume": {"box": [centre[0], centre[1], centre[2], half[0], 0.0, 0.0, 0.0, half[1], 0.0, 0.0, 0.0, half[2]]},
            "geometricError": diagonal,
            "refine": "ADD",
            "children": children,
        }
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ecef_of_known_points() {
        let p = geodetic_to_ecef(0.0, 0.0, 0.0);
        assert!((p[0] - 6_378_137.0).abs() < 1e-6 && p[1].abs() < 1e-6 && p[2].abs() < 1e-6);
        let pole = geodetic_to_ecef(0.0, 90.0, 0.0);
        assert!((pole[2] - 6_356_752.314_140).abs() < 1e-3, "{pole:?}");
    }

    #[test]
    fn utm_tangent_map_is_nearly_orthonormal_and_right_handed() {
        let m = enu_like_transform("EPSG:25832", [332_500.0, 5_729_500.0, 50.0], 0.0).unwrap();
        let col = |c: usize| [m[c * 4], m[c * 4 + 1], m[c * 4 + 2]];
        let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let (e, n, u) = (col(0), col(1), col(2));
        // UTM scale factor near x = 332 km: 0.9996·(1 + x'²/2R²) ≈ 0.99995, so |∂ECEF/∂E| ≈ 1/k
        assert!((dot(e, e).sqrt() - 1.0).abs() < 2e-4 && (dot(n, n).sqrt() - 1.0).abs() < 2e-4);
        assert!(dot(e, n).abs() < 1e-3 && dot(e, u).abs() < 1e-6 && dot(n, u).abs() < 1e-6);
        let cross = [e[1] * n[2] - e[2] * n[1], e[2] * n[0] - e[0] * n[2], e[0] * n[1] - e[1] * n[0]];
        assert!(dot(cross, u) > 0.99);
        // the origin lies on the ellipsoid + 50 m: |p| between polar and equatorial radius
        let r = dot([m[12], m[13], m[14]], [m[12], m[13], m[14]]).sqrt();
        assert!(r > 6_356_752.0 && r < 6_378_188.0, "{r}");
    }

    #[test]
    fn heights_follow_the_choice_or_are_refused() {
        let nrw = ["urn:adv:crs:ETRS89_UTM32*DE_DHHN2016_NH*GCG2016"];
        let (o, how) = height_offset(&Heights::Offset(46.5), &nrw, "t.glb", 6.46, 51.69).unwrap();
        assert_eq!((o, how["method"].as_str()), (46.5, Some("offset")));
        assert!(how["vertical"].as_str().unwrap().starts_with("DHHN2016 height"));
        assert_eq!(height_offset(&Heights::AsIs, &nrw, "t.glb", 6.46, 51.69).unwrap().0, 0.0);
        // no height system named: kept
        let (o, how) = height_offset(&Heights::Auto, &["EPSG:25832"], "t.glb", 6.46, 51.69).unwrap();
        assert_eq!((o, how["method"].as_str()), (0.0, Some("as-is")));
        // DHHN2016 without its grid (not in PROJ-data): refused, naming the choices
        if let Err(e) = height_offset(&Heights::Auto, &nrw, "t.glb", 6.46, 51.69) {
            let m = e.to_string();
            assert!(m.contains("DHHN2016") && m.contains("--height-offset") && m.contains("--heights-as-is"), "{m}");
        }
        // feet are not metres
        assert!(height_offset(&Heights::Auto, &["EPSG:2230+6360"], "t.glb", -117.0, 33.0).is_err());
    }

    #[test]
    fn egm96_undulation_where_the_grid_is_installed() {
        // EGM96 at 51.69° N, 6.46° E is about +44.5 m (h = H + N); Debian's proj-data ships it
        match geoid_undulation("egm96_15.gtx", 6.46, 51.69) {
            Ok(n) => assert!((n - 44.47).abs() < 0.1, "{n}"),
            Err(e) => eprintln!("SKIP: {e}"),
        }
        assert!(geoid_undulation("no_such_grid.tif", 6.46, 51.69).is_err());
    }

    #[test]
    fn matrices_compose_column_major() {
        let mut t = IDENTITY;
        (t[12], t[13], t[14]) = (1.0, 2.0, 3.0);
        let mut s = IDENTITY;
        s[0] = 2.0;
        assert_eq!(apply(&mul(&t, &s), [1.0, 1.0, 1.0]), [3.0, 3.0, 4.0]);
    }
}
