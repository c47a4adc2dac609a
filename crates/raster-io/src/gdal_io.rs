//! Reading and writing [`Raster`]s through GDAL.
//!
//! Reading: band 1 (or a chosen band) of anything GDAL opens, converted to f64. A cell is
//! invalid when it equals the band's nodata value (compared at the band's own precision, so a
//! Float32 `-3.4e38` marker matches), is NaN/±inf, or is masked by the band's GDAL mask
//! (netCDF `_FillValue`, GeoTIFF internal masks). Scale/offset declared on the band are applied
//! after the nodata test, as GDAL's own tools do.
//!
//! Writing: Float64, format from the extension (`.tif/.tiff` GeoTIFF with DEFLATE, `.asc` ESRI
//! ASCII grid, `.nc` netCDF, otherwise the driver GDAL associates with the extension). Never
//! writes NaN: invalid cells get a finite nodata marker that no valid value uses. Writes are
//! atomic (temporary directory beside the target, then rename), which also covers side files
//! such as the `.prj` of an ASCII grid.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use gdal::errors::GdalError;
use gdal::raster::{GdalDataType, RasterCreationOptions};
use gdal::{Dataset, DriverManager, Metadata};

use crate::error::RasterError;
use crate::raster::{check_geotransform, Raster};

/// Output formats with known creation options; anything else goes by GDAL driver name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RasterFormat {
    GeoTiff,
    AsciiGrid,
    NetCdf,
    /// Any GDAL raster driver by short name (e.g. `"GS7BG"`).
    Driver(String),
}

impl RasterFormat {
    /// The format for a path's extension (`None` when GDAL knows no driver for it).
    pub fn from_path(path: &Path) -> Option<RasterFormat> {
        let ext = path.extension()?.to_string_lossy().to_ascii_lowercase();
        match ext.as_str() {
            "tif" | "tiff" | "gtiff" => Some(RasterFormat::GeoTiff),
            "asc" => Some(RasterFormat::AsciiGrid),
            "nc" | "nc4" => Some(RasterFormat::NetCdf),
            _ => DriverManager::get_output_driver_for_dataset_name(path, gdal::DriverType::Raster)
                .map(|d| RasterFormat::Driver(d.short_name())),
        }
    }

    fn driver_name(&self) -> &str {
        match self {
            RasterFormat::GeoTiff => "GTiff",
            RasterFormat::AsciiGrid => "AAIGrid",
            RasterFormat::NetCdf => "netCDF",
            RasterFormat::Driver(s) => s,
        }
    }

    fn creation_options(&self) -> Vec<&'static str> {
        match self {
            // PREDICTOR=3 is the floating-point predictor: much better DEFLATE ratios on terrain.
            RasterFormat::GeoTiff => vec!["COMPRESS=DEFLATE", "PREDICTOR=3"],
            // Round-trip precision for f64 (17 significant digits).
            RasterFormat::AsciiGrid => vec!["SIGNIFICANT_DIGITS=17"],
            _ => vec![],
        }
    }
}

/// Options for [`write_raster`].
#[derive(Debug, Clone, Default)]
pub struct WriteOptions {
    /// Output format; `None` = from the path's extension.
    pub format: Option<RasterFormat>,
}

/// One clean line out of a GDAL error (its CPL message, without the Rust wrapper).
fn gdal_msg(e: &GdalError) -> String {
    match e {
        GdalError::CplError { msg, .. } => msg.trim().to_string(),
        GdalError::NullPointer { method_name, msg } => {
            if msg.trim().is_empty() {
                format!("GDAL call {method_name} failed")
            } else {
                msg.trim().to_string()
            }
        }
        other => other.to_string(),
    }
}

/// Routes GDAL's warnings (e.g. netCDF "dimension is not a Longitude/X dimension") to `sink`
/// instead of GDAL's default stderr printer, so a CLI can show them as its own notices (or
/// not, under `--quiet`). Errors still reach the Rust error values.
pub fn route_gdal_warnings<F: Fn(&str) + Send + Sync + 'static>(sink: F) {
    gdal::config::set_error_handler(move |class, _no, msg| {
        if class == gdal::errors::CplErrType::Warning {
            sink(msg.trim());
        }
    });
}

/// Reads band 1 of a raster file (see the module docs for what counts as nodata).
pub fn read_raster(path: &Path) -> Result<Raster, RasterError> {
    read_raster_band(path, 1)
}

/// Reads band `band` (1-based, GDAL numbering) of a raster file.
pub fn read_raster_band(path: &Path, band: usize) -> Result<Raster, RasterError> {
    let open_err = |message: String| RasterError::Open { path: path.to_path_buf(), message };
    let content_err = |message: String| RasterError::Content { path: path.to_path_buf(), message };
    if !path.exists() {
        return Err(open_err("no such file".into()));
    }
    // ESRI ASCII grids are opened as Float32 by default; ask for Float64 so written grids
    // round-trip exactly.
    let is_asc = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("asc"));
    let ds = if is_asc {
        let opts = gdal::DatasetOptions { open_options: Some(&["DATATYPE=Float64"]), ..Default::default() };
        Dataset::open_ex(path, opts)
    } else {
        Dataset::open(path)
    }
    .map_err(|e| open_err(gdal_msg(&e)))?;
    let count = ds.raster_count();
    if count == 0 {
        let subs = ds.metadata_domain("SUBDATASETS").unwrap_or_default();
        let names: Vec<&str> = subs
            .iter()
            .filter(|s| s.contains("_NAME="))
            .filter_map(|s| s.split_once('=').map(|(_, v)| v))
            .collect();
        return Err(content_err(if names.is_empty() {
            "no raster band (not a raster file?)".into()
        } else {
            format!("no raster band; open one of its subdatasets instead: {}", names.join(", "))
        }));
    }
    if band == 0 || band > count {
        return Err(content_err(format!("band {band} requested but the file has {count} band(s)")));
    }
    let (width, height) = ds.raster_size();
    if width == 0 || height == 0 {
        return Err(content_err(format!("raster size {width}×{height} has no cells")));
    }
    // The size is the header's claim: check it before GDAL or Vec allocate for it.
    let budget = crate::limits::CellBudget::for_cost(crate::limits::READ_BYTES_PER_CELL);
    if !budget.allows(width, height) {
        let bytes = (width as u128 * height as u128 * 8).min(u64::MAX as u128) as u64;
        return Err(RasterError::TooLarge {
            path: path.to_path_buf(),
            width,
            height,
            size: crate::limits::gib(bytes),
            limit: budget.describe(),
        });
    }
    // GDAL reports a missing geotransform as an error with the default identity-like transform;
    // pixel coordinates (origin top-left, unit cells, y down) are then the honest fallback.
    let geotransform = ds.geo_transform().unwrap_or([0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
    check_geotransform(&geotransform).map_err(|e| content_err(e.to_string()))?;
    let wkt = ds.projection();
    let crs = if wkt.trim().is_empty() { None } else { Some(wkt) };

    let rb = ds.rasterband(band).map_err(|e| content_err(gdal_msg(&e)))?;
    let band_type = rb.band_type();
    let nodata = rb.no_data_value();
    let buf = rb
        .read_as::<f64>((0, 0), (width, height), (width, height), None)
        .map_err(|e| content_err(format!("cannot read band {band}: {}", gdal_msg(&e))))?;
    let (_, mut data) = buf.into_shape_and_vec();

    // The per-band mask (GMF_ALL_VALID when there is none, then it is skipped).
    let mut mask: Option<Vec<u8>> = None;
    if let Ok(flags) = rb.mask_flags() {
        if !flags.is_all_valid() && !flags.is_nodata() {
            if let Ok(mb) = rb.open_mask_band() {
                if let Ok(m) = mb.read_as::<u8>((0, 0), (width, height), (width, height), None) {
                    mask = Some(m.into_shape_and_vec().1);
                }
            }
        }
    }

    let is_f32 = band_type == GdalDataType::Float32;
    let scale = rb.scale().unwrap_or(1.0);
    let offset = rb.offset().unwrap_or(0.0);
    let mut valid = vec![false; data.len()];
    for (i, v) in data.iter_mut().enumerate() {
        let is_nodata = match nodata {
            Some(nd) if nd.is_nan() => v.is_nan(),
            Some(nd) if is_f32 => (*v as f32) == (nd as f32),
            Some(nd) => *v == nd,
            None => false,
        };
        let masked = mask.as_ref().is_some_and(|m| m[i] == 0);
        if is_nodata || masked || !v.is_finite() {
            *v = f64::NAN;
        } else {
            *v = *v * scale + offset;
            valid[i] = v.is_finite();
            if !valid[i] {
                *v = f64::NAN;
            }
        }
    }
    let mut metadata = std::collections::BTreeMap::new();
    for item in ds.metadata() {
        if item.is_default_domain() {
            metadata.insert(item.key, item.value);
        }
    }
    Ok(Raster { width, height, geotransform, crs, data, valid, nodata, metadata })
}

/// A finite nodata marker that no valid cell uses: the raster's own marker when possible,
/// else the first free one of the usual conventions.
pub fn choose_nodata(r: &Raster) -> f64 {
    let used = |c: f64| r.data.iter().zip(&r.valid).any(|(d, v)| *v && *d == c);
    let mut candidates: Vec<f64> = Vec::new();
    if let Some(nd) = r.nodata.filter(|v| v.is_finite()) {
        candidates.push(nd);
    }
    candidates.extend([-9999.0, -99999.0, -999999.0, -32768.0, -3.0e38]);
    for c in candidates {
        if !used(c) {
            return c;
        }
    }
    // All conventions taken (pathological): one below the minimum, rounded to an integer.
    r.min_max().map(|(lo, _)| (lo - 1.0).floor()).unwrap_or(-9999.0)
}

static TMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Builds the in-memory GDAL dataset for `r`.
fn to_mem_dataset(r: &Raster, nodata: f64) -> Result<Dataset, String> {
    let mem = DriverManager::get_driver_by_name("MEM").map_err(|e| gdal_msg(&e))?;
    let mut ds = mem
        .create_with_band_type::<f64, _>("", r.width, r.height, 1)
        .map_err(|e| gdal_msg(&e))?;
    ds.set_geo_transform(&r.geotransform).map_err(|e| gdal_msg(&e))?;
    if let Some(wkt) = &r.crs {
        ds.set_projection(wkt).map_err(|e| gdal_msg(&e))?;
    }
    for (k, v) in &r.metadata {
        ds.set_metadata_item(k, v, "").map_err(|e| gdal_msg(&e))?;
    }
    {
        let mut band = ds.rasterband(1).map_err(|e| gdal_msg(&e))?;
        band.set_no_data_value(Some(nodata)).map_err(|e| gdal_msg(&e))?;
        let data: Vec<f64> = r.data.iter().zip(&r.valid).map(|(d, v)| if *v { *d } else { nodata }).collect();
        let mut buf = gdal::raster::Buffer::new((r.width, r.height), data);
        band.write((0, 0), (r.width, r.height), &mut buf).map_err(|e| gdal_msg(&e))?;
    }
    Ok(ds)
}

/// Writes `r` to `path` atomically (see the module docs).
pub fn write_raster(r: &Raster, path: &Path, opts: &WriteOptions) -> Result<(), RasterError> {
    let werr = |message: String| RasterError::Write { path: path.to_path_buf(), message };
    r.validate()?;
    let format = match &opts.format {
        Some(f) => f.clone(),
        None => RasterFormat::from_path(path).ok_or_else(|| {
            werr("unknown raster format for this extension (use .tif, .asc or .nc)".into())
        })?,
    };
    let driver = DriverManager::get_driver_by_name(format.driver_name()).map_err(|e| werr(gdal_msg(&e)))?;
    let nodata = choose_nodata(r);
    let mem = to_mem_dataset(r, nodata).map_err(werr)?;

    let file_name = path.file_name().ok_or_else(|| werr("not a file path".into()))?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let n = TMP_COUNTER.fetch_add(1, Ordering::Relaxed);
    let tmp_dir = dir.join(format!(".geofit-raster-{}-{n}.tmp", std::process::id()));
    std::fs::create_dir(&tmp_dir).map_err(|e| werr(format!("cannot create {}: {e}", tmp_dir.display())))?;
    let result = (|| -> Result<(), String> {
        let tmp_path = tmp_dir.join(file_name);
        let mut co = RasterCreationOptions::new();
        for o in format.creation_options() {
            co.add_string(o).map_err(|e| gdal_msg(&e))?;
        }
        let out = mem.create_copy(&driver, &tmp_path, &co).map_err(|e| gdal_msg(&e))?;
        out.close().map_err(|e| gdal_msg(&e))?;
        // Move the main file last so a reader never sees it without its side files.
        let mut entries: Vec<PathBuf> = std::fs::read_dir(&tmp_dir)
            .map_err(|e| e.to_string())?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .collect();
        entries.sort_by_key(|p| p.file_name() == Some(file_name));
        for p in entries {
            let name = p.file_name().map(|s| s.to_os_string()).unwrap_or_default();
            std::fs::rename(&p, dir.join(&name)).map_err(|e| format!("cannot move {}: {e}", p.display()))?;
        }
        Ok(())
    })();
    let _ = std::fs::remove_dir_all(&tmp_dir);
    result.map_err(werr)
}

/// Encodes `r` in `format` and returns the main file's bytes (for writing to stdout); side
/// files (e.g. an ASCII grid's `.prj`) are dropped.
pub fn raster_to_bytes(r: &Raster, format: &RasterFormat) -> Result<Vec<u8>, RasterError> {
    let werr = |message: String| RasterError::Write { path: PathBuf::from("<stdout>"), message };
    r.validate()?;
    let driver = DriverManager::get_driver_by_name(format.driver_name()).map_err(|e| werr(gdal_msg(&e)))?;
    let nodata = choose_nodata(r);
    let mem = to_mem_dataset(r, nodata).map_err(werr)?;
    let ext = match format {
        RasterFormat::GeoTiff => "tif",
        RasterFormat::AsciiGrid => "asc",
        RasterFormat::NetCdf => "nc",
        RasterFormat::Driver(_) => "dat",
    };
    let n = TMP_COUNTER.fetch_add(1, Ordering::Relaxed);
    let dir = format!("/vsimem/geofit-{}-{n}", std::process::id());
    let vpath = PathBuf::from(format!("{dir}/out.{ext}"));
    let mut co = RasterCreationOptions::new();
    for o in format.creation_options() {
        co.add_string(o).map_err(|e| werr(gdal_msg(&e)))?;
    }
    let out = mem.create_copy(&driver, &vpath, &co).map_err(|e| werr(gdal_msg(&e)))?;
    out.close().map_err(|e| werr(gdal_msg(&e)))?;
    let bytes = gdal::vsi::get_vsi_mem_file_bytes_owned(&vpath).map_err(|e| werr(gdal_msg(&e)))?;
    if let Ok(files) = gdal::vsi::read_dir(&dir, true) {
        for f in files {
            let _ = gdal::vsi::unlink_mem_file(Path::new(&dir).join(f));
        }
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Raster {
        let gt = Raster::geotransform_from_centres(500000.5, 5_700_000.5, 1.0, -1.0);
        let mut r = Raster::from_values(4, 3, gt, None, (0..12).map(|i| i as f64 * 0.125 - 0.3).collect()).unwrap();
        r.set(2, 1, f64::NAN);
        r.metadata.insert("GEOFIT_TEST".into(), "{\"a\":1}".into());
        r
    }

    #[test]
    fn geotiff_round_trip_is_exact() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.tif");
        let r = sample();
        write_raster(&r, &p, &WriteOptions::default()).unwrap();
        let back = read_raster(&p).unwrap();
        assert_eq!(back.width, 4);
        assert_eq!(back.geotransform, r.geotransform);
        assert_eq!(back.valid, r.valid);
        for (a, b) in back.data.iter().zip(&r.data) {
            assert!(a == b || (a.is_nan() && b.is_nan()));
        }
        assert_eq!(back.metadata.get("GEOFIT_TEST").map(String::as_str), Some("{\"a\":1}"));
        assert_eq!(back.nodata, Some(-9999.0));
        // only the target file is left behind
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names.len(), 1, "{names:?}");
    }

    #[test]
    fn ascii_grid_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.asc");
        let r = sample();
        write_raster(&r, &p, &WriteOptions::default()).unwrap();
        let back = read_raster(&p).unwrap();
        assert_eq!(back.valid, r.valid);
        for (a, b) in back.data.iter().zip(&r.data).filter(|(a, _)| a.is_finite()) {
            assert_eq!(a, b);
        }
    }

    #[test]
    fn nodata_marker_avoids_valid_values() {
        let mut r = sample();
        r.set(0, 0, -9999.0);
        assert_eq!(choose_nodata(&r), -99999.0);
    }

    #[test]
    fn bytes_for_stdout() {
        let b = raster_to_bytes(&sample(), &RasterFormat::GeoTiff).unwrap();
        assert!(b.starts_with(b"II*\0") || b.starts_with(b"MM\0*"));
    }

    #[test]
    fn garbage_file_is_a_clear_error() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.tif");
        std::fs::write(&p, b"this is not a tiff").unwrap();
        let e = read_raster(&p).unwrap_err().to_string();
        assert!(e.contains("x.tif"), "{e}");
        let e = read_raster(&dir.path().join("missing.tif")).unwrap_err().to_string();
        assert!(e.contains("no such file"), "{e}");
    }
}
