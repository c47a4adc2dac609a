//! Sidecar files that georeference a PNG: the ESRI world file (`.pgw`: six lines, pixel size and
//! the centre of the top-left pixel) and GDAL's PAM `.aux.xml` carrying the CRS, which GDAL,
//! QGIS and ArcGIS read next to the picture.
//!
//! # Examples
//!
//! ```
//! use raster_picture::world_file;
//!
//! // 2 m cells, top-left corner at (1000, 5000), the map 8 px right and 30 px down in the picture
//! let pgw = world_file([1000.0, 2.0, 0.0, 5000.0, 0.0, -2.0], 8, 30);
//! assert_eq!(pgw.lines().collect::<Vec<_>>(), ["2", "0", "0", "-2", "985", "5059"]);
//! ```

use std::path::{Path, PathBuf};

/// World-file text for a picture whose pixel (`map_x`, `map_y`) is the top-left cell of a map
/// with GDAL geotransform `gt` (pixel-corner based). The world file names the centre of the
/// picture's top-left pixel.
pub fn world_file(gt: [f64; 6], map_x: usize, map_y: usize) -> String {
    let (col, row) = (0.5 - map_x as f64, 0.5 - map_y as f64);
    let x = gt[0] + col * gt[1] + row * gt[2];
    let y = gt[3] + col * gt[4] + row * gt[5];
    [gt[1], gt[4], gt[2], gt[5], x, y].iter().map(|v| format!("{}\n", v + 0.0)).collect()
}

/// GDAL PAM sidecar (`NAME.png.aux.xml`) holding the CRS as WKT.
pub fn aux_xml(wkt: &str) -> String {
    let escaped = wkt.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;");
    format!("<PAMDataset>\n  <SRS dataAxisToSRSAxisMapping=\"1,2\">{escaped}</SRS>\n</PAMDataset>\n")
}

/// The world file and PAM sidecar paths GDAL looks for next to `picture`
/// (`errors.png` → `errors.pgw`, `errors.png.aux.xml`).
pub fn sidecar_paths(picture: &Path) -> (PathBuf, PathBuf) {
    let ext = picture.extension().and_then(|e| e.to_str()).unwrap_or("png");
    let mut chars = ext.chars();
    let world_ext = match (chars.next(), chars.last()) {
        (Some(a), Some(b)) => format!("{a}{b}w"),
        _ => "wld".to_string(),
    };
    let mut aux = picture.as_os_str().to_owned();
    aux.push(".aux.xml");
    (picture.with_extension(world_ext), PathBuf::from(aux))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sidecars_follow_gdal_naming() {
        let (w, a) = sidecar_paths(Path::new("out/errors.png"));
        assert_eq!(w, Path::new("out/errors.pgw"));
        assert_eq!(a, Path::new("out/errors.png.aux.xml"));
    }

    #[test]
    fn the_aux_file_escapes_wkt_quotes() {
        let x = aux_xml("PROJCS[\"a<b\"]");
        assert!(x.contains("PROJCS[&quot;a&lt;b&quot;]"));
    }
}
