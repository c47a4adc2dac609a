//! The product a T-mesh competes with (issue 37): GDAL's LERC_ZSTD GeoTIFF at the same
//! maximum error also guarantees every cell within E, is read by every GIS and encodes in
//! milliseconds. `fit` encodes the raster so, in memory (/vsimem/), and states its size beside
//! its own, so that a user sees when the T-mesh is the wrong product
//! (docs/decisions.md#lerc-beside-the-t-mesh-issue-37).

use raster_io::gdal_io::raster_to_bytes;
use raster_io::{Raster, RasterFormat, SampleType, WriteOptions};
use tspline::fit::{Heights, Samples};

/// Bytes of `gdal_translate -co COMPRESS=LERC_ZSTD -co MAX_Z_ERROR=e` of the samples (a
/// striped GeoTIFF of the raster's float type without georeference, a few hundred bytes less
/// than the file of the same raster with it), or None when GDAL cannot encode it.
pub(super) fn lerc_zstd_bytes(s: &Samples, e: f64) -> Option<usize> {
    let (w, h) = (s.width, s.height);
    // the samples run from the bottom row; a GeoTIFF from the top
    let data: Vec<f64> = (0..h).rev().flat_map(|j| (0..w).map(move |i| s.z.get(j * w + i))).collect();
    let r = Raster::from_values(w, h, [0.0, 1.0, 0.0, h as f64, 0.0, -1.0], None, data).ok()?;
    let sample_type = match s.z {
        Heights::F32(_) => SampleType::Float32,
        Heights::F64(_) => SampleType::Float64,
    };
    let opts = WriteOptions {
        format: Some(RasterFormat::GeoTiff),
        creation_options: vec!["COMPRESS=LERC_ZSTD".into(), format!("MAX_Z_ERROR={e}"), "PREDICTOR=1".into()],
        sample_type,
    };
    raster_to_bytes(&r, &opts).ok().map(|b| b.len())
}

/// The stderr line that puts the two sizes side by side, and says which product is smaller.
pub(super) fn line(name: &str, tmb: usize, lerc: usize, e: &str) -> String {
    let ratio = tmb as f64 / lerc as f64;
    let verdict = if ratio > 1.0 {
        format!(
            "the LERC GeoTIFF is the smaller product here (gdal_translate -co COMPRESS=LERC_ZSTD -co MAX_Z_ERROR={e})"
        )
    } else {
        "the T-mesh is the smaller product".to_string()
    };
    format!("{name}: T-mesh {tmb} bytes, LERC_ZSTD GeoTIFF at the same max error {lerc} bytes ({ratio:.2}×): {verdict}")
}
