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
use std::sync::{Mutex, Once};

use gdal::errors::{CplErrType, GdalError};
use gdal::raster::{GdalDataType, RasterCreationOptions};
use gdal::{Dataset, DriverManager, Metadata};

use crate::error::RasterError;
use crate::raster::{check_geotransform, Raster};

/// Output formats with known creation options; anything else goes by GDAL driver name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RasterFormat {
    /// Cloud-optimised GeoTIFF (GDAL's COG driver): the default for `.tif`.
    Cog,
    /// Plain GeoTIFF (`-of GTiff`): striped, DEFLATE with the floating-point predictor.
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
            "tif" | "tiff" | "gtiff" => Some(RasterFormat::Cog),
            "asc" => Some(RasterFormat::AsciiGrid),
            "nc" | "nc4" => Some(RasterFormat::NetCdf),
            _ => DriverManager::get_output_driver_for_dataset_name(path, gdal::DriverType::Raster)
                .map(|d| RasterFormat::from_driver_name(&d.short_name())),
        }
    }

    /// The format for a GDAL driver short name as `-of` takes it (case-insensitive for the ones
    /// with their own defaults; any other name is checked by [`check_write`]).
    pub fn from_driver_name(name: &str) -> RasterFormat {
        match name.to_ascii_lowercase().as_str() {
            "cog" => RasterFormat::Cog,
            "gtiff" => RasterFormat::GeoTiff,
            "aaigrid" => RasterFormat::AsciiGrid,
            "netcdf" => RasterFormat::NetCdf,
            _ => RasterFormat::Driver(name.to_string()),
        }
    }

    pub fn driver_name(&self) -> &str {
        match self {
            RasterFormat::Cog => "COG",
            RasterFormat::GeoTiff => "GTiff",
            RasterFormat::AsciiGrid => "AAIGrid",
            RasterFormat::NetCdf => "netCDF",
            RasterFormat::Driver(s) => s,
        }
    }

    /// geofit's defaults for the format; `-co` options replace them key by key.
    fn default_creation_options(&self) -> Vec<&'static str> {
        match self {
            // DEFLATE with the predictor GDAL picks for the type (floating-point for floats):
            // much better ratios on terrain than COG's default LZW without predictor.
            RasterFormat::Cog => vec!["COMPRESS=DEFLATE", "PREDICTOR=YES"],
            // PREDICTOR=3 is the floating-point predictor.
            RasterFormat::GeoTiff => vec!["COMPRESS=DEFLATE", "PREDICTOR=3"],
            // Round-trip precision for f64 (17 significant digits).
            RasterFormat::AsciiGrid => vec!["SIGNIFICANT_DIGITS=17"],
            _ => vec![],
        }
    }

    /// The defaults merged with the user's `KEY=VALUE` options (a user key replaces the default).
    fn creation_options(&self, user: &[String]) -> Vec<String> {
        let key = |o: &str| o.split_once('=').map(|(k, _)| k.trim().to_ascii_uppercase()).unwrap_or_default();
        let mut out: Vec<String> = self
            .default_creation_options()
            .into_iter()
            .filter(|d| !user.iter().any(|u| key(u) == key(d)))
            .map(String::from)
            .collect();
        out.extend(user.iter().cloned());
        out
    }

    /// Extension for a temporary in-memory file of this format.
    fn extension(&self) -> &str {
        match self {
            RasterFormat::Cog | RasterFormat::GeoTiff => "tif",
            RasterFormat::AsciiGrid => "asc",
            RasterFormat::NetCdf => "nc",
            RasterFormat::Driver(_) => "dat",
        }
    }
}

/// The band type written: a float type, so no value is cut to an integer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SampleType {
    Float32,
    #[default]
    Float64,
}

impl SampleType {
    /// GDAL's name of the type (`Float32`, `Float64`).
    pub fn gdal_name(self) -> &'static str {
        match self {
            SampleType::Float32 => "Float32",
            SampleType::Float64 => "Float64",
        }
    }

    /// The smaller float type that holds every value of a GDAL band type exactly: Float32 for
    /// Float32 and integers up to 16 bits (24-bit mantissa), Float64 for the rest
    /// (docs/decisions.md#raster-outputs-by-driver).
    pub fn holding(t: GdalDataType) -> SampleType {
        match t {
            GdalDataType::Float32 | GdalDataType::UInt8 | GdalDataType::UInt16 | GdalDataType::Int16 => {
                SampleType::Float32
            }
            _ => SampleType::Float64,
        }
    }

    /// A value as stored at this precision.
    fn round(self, v: f64) -> f64 {
        match self {
            SampleType::Float32 => v as f32 as f64,
            SampleType::Float64 => v,
        }
    }
}

/// Options for [`write_raster`].
#[derive(Debug, Clone, Default)]
pub struct WriteOptions {
    /// Output format; `None` = from the path's extension (COG for stdout).
    pub format: Option<RasterFormat>,
    /// GDAL creation options `KEY=VALUE` (`-co`); each replaces geofit's default for its key.
    pub creation_options: Vec<String>,
    /// Band type of the output.
    pub sample_type: SampleType,
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

type WarningSink = Box<dyn Fn(&str) + Send + Sync>;

/// Where GDAL warnings go ([`route_gdal_warnings`]); none = dropped.
static WARNING_SINK: Mutex<Option<WarningSink>> = Mutex::new(None);
/// How many CE_Failure/CE_Fatal messages GDAL has emitted, and the first one since the last
/// [`gdal_checked`] began: a write is failed when this count moved during it, even if a later
/// warning replaced GDAL's "last error" (and the first message is the cause: "No space left
/// on device", not the "IO error writing directory" that follows it).
static FAILURES: AtomicU64 = AtomicU64::new(0);
static FIRST_FAILURE: Mutex<String> = Mutex::new(String::new());
static HANDLER: Once = Once::new();

/// Installs geofit's GDAL error handler once: failures are counted (see [`FAILURES`]), warnings
/// go to the sink.
fn install_error_handler() {
    HANDLER.call_once(|| {
        gdal::config::set_error_handler(|class, _no, msg| match class {
            CplErrType::Failure | CplErrType::Fatal => {
                if let Ok(mut first) = FIRST_FAILURE.lock() {
                    if first.is_empty() {
                        *first = msg.trim().to_string();
                    }
                }
                FAILURES.fetch_add(1, Ordering::SeqCst);
            }
            CplErrType::Warning => {
                if let Ok(sink) = WARNING_SINK.lock() {
                    if let Some(s) = sink.as_ref() {
                        s(msg.trim());
                    }
                }
            }
            _ => {}
        });
    });
}

/// Routes GDAL's warnings (e.g. netCDF "dimension is not a Longitude/X dimension") to `sink`
/// instead of GDAL's default stderr printer, so a CLI can show them as its own notices (or
/// not, under `--quiet`). Errors still reach the Rust error values.
pub fn route_gdal_warnings<F: Fn(&str) + Send + Sync + 'static>(sink: F) {
    if let Ok(mut s) = WARNING_SINK.lock() {
        *s = Some(Box::new(sink));
    }
    install_error_handler();
}

/// Runs the GDAL calls of `f` and fails when GDAL reported a failure during them, even one the
/// call itself did not return: GDAL before 3.7 returns nothing from `GDALFlushCache` and
/// `GDALClose`, and a strip that could not be written (full disk, `ulimit -f`) is only a
/// CPLError (docs/decisions.md#raster-outputs-by-driver).
fn gdal_checked<T>(f: impl FnOnce() -> Result<T, GdalError>) -> Result<T, String> {
    install_error_handler();
    if let Ok(mut first) = FIRST_FAILURE.lock() {
        first.clear();
    }
    let before = FAILURES.load(Ordering::SeqCst);
    // SAFETY: resets this thread's CPL error state; no pointers involved.
    unsafe { gdal_sys::CPLErrorReset() };
    let value = f();
    let first = FIRST_FAILURE.lock().map(|s| s.clone()).unwrap_or_default();
    match value {
        Err(e) if first.is_empty() => Err(gdal_msg(&e)),
        Err(_) => Err(first),
        Ok(_) if FAILURES.load(Ordering::SeqCst) != before => {
            Err(if first.is_empty() { "GDAL reported a write failure".into() } else { first })
        }
        Ok(v) => Ok(v),
    }
}

/// The GDAL library loaded at run time, as `gdalinfo --version` says it ("GDAL 3.6.2, released
/// 2023/01/02").
pub fn gdal_version() -> String {
    gdal::version::VersionInfo::version_summary()
}

/// Reads band 1 of a raster file (see the module docs for what counts as nodata).
pub fn read_raster(path: &Path) -> Result<Raster, RasterError> {
    read_raster_band(path, 1)
}

/// Reads band `band` (1-based, GDAL numbering) of a raster file.
pub fn read_raster_band(path: &Path, band: usize) -> Result<Raster, RasterError> {
    read_raster_band_typed(path, band).map(|(r, _)| r)
}

/// GDAL's virtual file systems (`/vsigzip/`, `/vsizip/`, `/vsicurl/`, ...): paths that exist
/// for GDAL only, so no local existence check applies to them.
/// Opens a dataset with GDAL after checking what a netCDF classic header claims against the
/// file (`input_limits::netcdf`): libnetcdf sizes allocations by header counts first, and one
/// flipped attribute count in a 10 KB grid made it take 16 GB (docs/decisions.md#input-limits).
pub fn open_dataset(path: &Path, options: gdal::DatasetOptions<'_>) -> Result<Dataset, RasterError> {
    let open_err = |message: String| RasterError::Open { path: path.to_path_buf(), message };
    if !is_gdal_virtual_path(path) {
        input_limits::netcdf::check_file(path).map_err(|e| open_err(e.to_string()))?;
    }
    if !is_gdal_virtual_path(path) {
        if let Some(what) = not_a_raster(path) {
            return Err(open_err(what));
        }
    }
    Dataset::open_ex(path, options).map_err(|e| open_err(what_it_is(path).unwrap_or_else(|| gdal_msg(&e))))
}

/// A directory or an empty file: said before GDAL tries (its answer is "GDALOpenEx failed").
fn not_a_raster(path: &Path) -> Option<String> {
    let meta = std::fs::metadata(path).ok()?;
    if meta.is_dir() {
        return Some("is a directory, not a raster file (give one raster: GeoTIFF, netCDF, ASCII grid, ...)".into());
    }
    (meta.is_file() && meta.len() == 0).then(|| "is an empty file (0 bytes), not a raster".into())
}

/// What a file GDAL cannot open as a raster is, when its first bytes show one of the other
/// kinds geofit reads (the `file-kind` crate), with the command that takes it (issue 41:
/// wrong file kinds name the fix).
pub fn what_it_is(path: &Path) -> Option<String> {
    use file_kind::FileKind as K;
    let kind = file_kind::sniff_path(path).ok()?;
    let takes = match kind {
        K::TMesh => " (`geofit eval` makes a raster of it)",
        K::Las | K::PointText => " (`geofit rasterize --cell S` makes a raster of it)",
        K::CityGml => " (`geofit info`, `validate`, `heal`, `export` take it)",
        K::Popa3d => " (`geofit adjust` takes it)",
        K::CityJson | K::Xml(_) | K::Obj | K::Gltf => "",
        _ => return None,
    };
    Some(format!("is {}{takes}, not a raster GDAL reads", kind.describe()))
}

pub fn is_gdal_virtual_path(path: &Path) -> bool {
    path.to_str().is_some_and(|s| s.starts_with("/vsi"))
}

/// Reads band `band` like [`read_raster_band`], with the float type that holds its values
/// exactly (what an output derived from it is written as).
pub fn read_raster_band_typed(path: &Path, band: usize) -> Result<(Raster, SampleType), RasterError> {
    read_raster_window_typed(path, band, None)
}

/// Reads the pixel window `[col_off, row_off, width, height]` (GDAL's `-srcwin` convention) of
/// band `band` through a GDAL windowed read: only the window's cells are read and held (a tile of
/// a VRT or COG of any size costs the tile), the geotransform moved to the window's corner.
/// `None`: the whole band.
pub fn read_raster_window_typed(
    path: &Path,
    band: usize,
    window: Option<[usize; 4]>,
) -> Result<(Raster, SampleType), RasterError> {
    let open_err = |message: String| RasterError::Open { path: path.to_path_buf(), message };
    let content_err = |message: String| RasterError::Content { path: path.to_path_buf(), message };
    if !is_gdal_virtual_path(path) && !path.exists() {
        return Err(open_err("no such file".into()));
    }
    // ESRI ASCII grids are opened as Float32 by default; ask for Float64 so written grids
    // round-trip exactly.
    let is_asc = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("asc"));
    let ds = if is_asc {
        let opts = gdal::DatasetOptions { open_options: Some(&["DATATYPE=Float64"]), ..Default::default() };
        open_dataset(path, opts)?
    } else {
        open_dataset(path, Default::default())?
    };
    let count = ds.raster_count();
    if count == 0 {
        return Err(content_err(no_band_message(&ds)));
    }
    if band == 0 || band > count {
        return Err(content_err(format!("band {band} requested but the file has {count} band(s)")));
    }
    let (full_w, full_h) = ds.raster_size();
    if full_w == 0 || full_h == 0 {
        return Err(content_err(format!("raster size {full_w}×{full_h} has no cells")));
    }
    let [xoff, yoff, width, height] = window.unwrap_or([0, 0, full_w, full_h]);
    if width == 0
        || height == 0
        || xoff.checked_add(width).is_none_or(|e| e > full_w)
        || yoff.checked_add(height).is_none_or(|e| e > full_h)
    {
        return Err(content_err(format!("window {xoff} {yoff} {width} {height} (xoff yoff xsize ysize) is not inside the raster's {full_w}×{full_h} pixels")));
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
    let mut geotransform = ds.geo_transform().unwrap_or([0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
    check_geotransform(&geotransform).map_err(|e| content_err(e.to_string()))?;
    if window.is_some() {
        let (c, r) = (xoff as f64, yoff as f64);
        geotransform[0] += c * geotransform[1] + r * geotransform[2];
        geotransform[3] += c * geotransform[4] + r * geotransform[5];
    }
    let wkt = ds.projection();
    let crs = if wkt.trim().is_empty() { None } else { Some(wkt) };

    let rb = ds.rasterband(band).map_err(|e| content_err(gdal_msg(&e)))?;
    let band_type = rb.band_type();
    let nodata = rb.no_data_value();
    let z_unit = Some(rb.unit().trim().to_string()).filter(|u| !u.is_empty());
    let buf = rb
        .read_as::<f64>((xoff as isize, yoff as isize), (width, height), (width, height), None)
        .map_err(|e| content_err(format!("cannot read band {band}: {}", gdal_msg(&e))))?;
    let (_, mut data) = buf.into_shape_and_vec();

    // The per-band mask (GMF_ALL_VALID when there is none, then it is skipped).
    let mut mask: Option<Vec<u8>> = None;
    if let Ok(flags) = rb.mask_flags() {
        if !flags.is_all_valid() && !flags.is_nodata() {
            if let Ok(mb) = rb.open_mask_band() {
                if let Ok(m) = mb.read_as::<u8>((xoff as isize, yoff as isize), (width, height), (width, height), None)
                {
                    mask = Some(m.into_shape_and_vec().1);
                }
            }
        }
    }

    let is_f32 = band_type == GdalDataType::Float32;
    let scale = rb.scale().unwrap_or(1.0);
    let offset = rb.offset().unwrap_or(0.0);
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
            if !v.is_finite() {
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
    Ok((Raster { width, height, geotransform, crs, data, nodata, metadata, z_unit }, SampleType::holding(band_type)))
}

/// Why a dataset without raster bands cannot be read: a container of subdatasets (NetCDF, HDF)
/// names them, so the message can say which to open instead.
fn no_band_message(ds: &gdal::Dataset) -> String {
    let subs = ds.metadata_domain("SUBDATASETS").unwrap_or_default();
    let names: Vec<&str> =
        subs.iter().filter(|s| s.contains("_NAME=")).filter_map(|s| s.split_once('=').map(|(_, v)| v)).collect();
    if names.is_empty() {
        "no raster band (not a raster file?)".into()
    } else {
        format!("no raster band; open one of its subdatasets instead: {}", names.join(", "))
    }
}

/// The uncertainty layer that goes with the elevation in band 1 (issue 19): the band whose
/// description is `uncertainty` (GDAL's BAG driver names band 2 so), else band 2 of a file
/// with two or more bands (e.g. a GeoTIFF of elevation + uncertainty). Read as any band (nodata,
/// masks, scale/offset as in [`read_raster_band`]); the caller checks it matches band 1's grid.
pub fn read_uncertainty(path: &Path) -> Result<(Raster, usize), RasterError> {
    let content_err = |message: String| RasterError::Content { path: path.to_path_buf(), message };
    let ds = open_dataset(path, Default::default())?;
    let count = ds.raster_count();
    let named = (1..=count).find(|&b| {
        ds.rasterband(b).is_ok_and(|rb| rb.description().is_ok_and(|d| d.trim().eq_ignore_ascii_case("uncertainty")))
    });
    let band = match named {
        Some(b) => b,
        None if count >= 2 => 2,
        None => {
            return Err(content_err(format!(
                "no uncertainty layer: {count} band(s), none named \"uncertainty\" (expected as band 2)"
            )))
        }
    };
    drop(ds);
    Ok((read_raster_band(path, band)?, band))
}

/// Heights of a Mapbox Terrain-RGB raster (PNG or WebP tiles of elevation): bands 1-3 hold
/// red, green and blue, and h = -10000 + (R·256² + G·256 + B) · 0.1 metres. A cell is no data
/// where a band has none, or where band 4 (alpha) is 0.
pub fn read_terrain_rgb(path: &Path) -> Result<Raster, RasterError> {
    let content_err = |message: String| RasterError::Content { path: path.to_path_buf(), message };
    let n = bands(path)?.len();
    if n < 3 {
        return Err(content_err(format!("Terrain-RGB needs 3 bands (red, green, blue), the file has {n}")));
    }
    let mut r = read_raster_band(path, 1)?;
    let g = read_raster_band(path, 2)?;
    let b = read_raster_band(path, 3)?;
    let alpha = if n >= 4 { Some(read_raster_band(path, 4)?) } else { None };
    for (q, v) in r.data.iter_mut().enumerate() {
        let transparent = alpha.as_ref().is_some_and(|a| a.data[q] == 0.0 || a.data[q].is_nan());
        *v = if transparent { f64::NAN } else { -10000.0 + (*v * 65536.0 + g.data[q] * 256.0 + b.data[q]) * 0.1 };
    }
    r.nodata = None;
    r.z_unit = Some("m".into());
    Ok(r)
}

/// One band of a raster file as GDAL describes it (for choosing the band to read).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BandInfo {
    /// GDAL's band description ("elevation", "uncertainty", often empty).
    pub description: String,
    /// GDAL's colour interpretation ("Red", "Alpha", "Gray", "Undefined", ...).
    pub color: String,
}

/// The bands of a raster file (1-based in GDAL's numbering: element 0 is band 1).
pub fn bands(path: &Path) -> Result<Vec<BandInfo>, RasterError> {
    let open_err = |message: String| RasterError::Open { path: path.to_path_buf(), message };
    if !is_gdal_virtual_path(path) && !path.exists() {
        return Err(open_err("no such file".into()));
    }
    let ds = open_dataset(path, Default::default())?;
    Ok((1..=ds.raster_count())
        .filter_map(|b| ds.rasterband(b).ok())
        .map(|rb| BandInfo {
            description: rb.description().unwrap_or_default().trim().to_string(),
            color: rb.color_interpretation().name(),
        })
        .collect())
}

/// A finite nodata marker that no valid cell uses: the raster's own marker when possible,
/// else the first free one of the usual conventions.
pub fn choose_nodata(r: &Raster) -> f64 {
    choose_nodata_for(r, SampleType::Float64)
}

/// [`choose_nodata`] for values stored as `t`: a marker is taken only when no valid value
/// equals it at that precision (a Float32 -9999.0001 is -9999).
pub fn choose_nodata_for(r: &Raster, t: SampleType) -> f64 {
    let used = |c: f64| r.data.iter().any(|d| !d.is_nan() && t.round(*d) == t.round(c));
    let mut candidates: Vec<f64> = Vec::new();
    if let Some(nd) = r.nodata.filter(|v| v.is_finite() && t.round(*v).is_finite()) {
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

/// Builds the in-memory GDAL dataset for `r` with bands of type `T`.
fn to_mem_dataset_as<T: gdal::raster::GdalType + Copy>(
    r: &Raster,
    nodata: f64,
    cast: impl Fn(f64) -> T,
) -> Result<Dataset, String> {
    let mem = DriverManager::get_driver_by_name("MEM").map_err(|e| gdal_msg(&e))?;
    let mut ds = mem.create_with_band_type::<T, _>("", r.width, r.height, 1).map_err(|e| gdal_msg(&e))?;
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
        if let Some(unit) = r.z_unit.as_deref().and_then(|u| std::ffi::CString::new(u).ok()) {
            // SAFETY: a live band handle and a NUL-terminated string GDAL copies.
            unsafe { gdal_sys::GDALSetRasterUnitType(band.c_rasterband(), unit.as_ptr()) };
        }
        let data: Vec<T> = r.data.iter().map(|d| cast(if d.is_nan() { nodata } else { *d })).collect();
        let mut buf = gdal::raster::Buffer::new((r.width, r.height), data);
        band.write((0, 0), (r.width, r.height), &mut buf).map_err(|e| gdal_msg(&e))?;
    }
    Ok(ds)
}

/// Builds the in-memory GDAL dataset for `r` at the output's band type.
fn to_mem_dataset(r: &Raster, t: SampleType) -> Result<Dataset, String> {
    let nodata = t.round(choose_nodata_for(r, t));
    match t {
        SampleType::Float32 => to_mem_dataset_as::<f32>(r, nodata, |v| v as f32),
        SampleType::Float64 => to_mem_dataset_as::<f64>(r, nodata, |v| v),
    }
}

/// A GDAL driver's metadata item (`DMD_*`, `DCAP_*`), empty when it has none.
fn driver_item(driver: &gdal::Driver, key: &str) -> String {
    driver.metadata_item(key, "").unwrap_or_default()
}

/// Drivers that write no data of their own: a VRT (or MEM) copy of geofit's in-memory result
/// would reference a dataset that is gone when the process ends.
const VIRTUAL_DRIVERS: [&str; 2] = ["VRT", "MEM"];

/// Checks before any work that `opts` can write a raster to `path` (`None` = stdout): the
/// format is known, writable, stores the band type, accepts the creation options, and (for
/// stdout) can write through GDAL's in-memory files. Returns the resolved format. Every
/// refusal is a [`RasterError::Format`] naming the driver and why.
pub fn check_write(path: Option<&Path>, opts: &WriteOptions) -> Result<RasterFormat, RasterError> {
    let target = path.map_or_else(|| "stdout".to_string(), |p| p.display().to_string());
    let ferr = |m: String| RasterError::Format(format!("-o {target}: {m}"));
    if path.is_some_and(is_gdal_virtual_path) {
        return Err(ferr(
            "writing to a GDAL virtual path is not supported; write a file and compress it afterwards".into(),
        ));
    }
    let format = match (&opts.format, path) {
        (Some(f), _) => f.clone(),
        (None, None) => RasterFormat::Cog,
        (None, Some(p)) => RasterFormat::from_path(p).ok_or_else(|| {
            ferr(
                "GDAL knows no raster format for this extension; use .tif, .asc or .nc, or name a driver with -of"
                    .into(),
            )
        })?,
    };
    let name = format.driver_name().to_string();
    let driver = DriverManager::get_driver_by_name(&name)
        .map_err(|_| ferr(format!("-of {name}: GDAL has no such driver (`gdalinfo --formats` lists them)")))?;
    let name = driver.short_name();
    if driver_item(&driver, "DCAP_RASTER") != "YES" {
        return Err(ferr(format!("{name} is not a raster format")));
    }
    if VIRTUAL_DRIVERS.iter().any(|v| v.eq_ignore_ascii_case(&name)) {
        return Err(ferr(format!(
            "{name} stores references to other files, and geofit's result exists only in memory: write a GeoTIFF and build the {name} on it (gdalbuildvrt)"
        )));
    }
    if driver_item(&driver, "DCAP_CREATECOPY") != "YES" && driver_item(&driver, "DCAP_CREATE") != "YES" {
        return Err(ferr(format!("GDAL's {name} driver reads but cannot write")));
    }
    let types = driver_item(&driver, "DMD_CREATIONDATATYPES");
    let stores = |t: &str| types.split_whitespace().any(|x| x == t);
    let wanted = opts.sample_type.gdal_name();
    // AAIGrid lists Float32 as its widest type but writes Float64 text at 17 digits (and
    // geofit reads it back as Float64): the list is trusted for the other drivers only.
    let own_format = !matches!(format, RasterFormat::Driver(_));
    if !own_format && !types.is_empty() && !stores(wanted) {
        return Err(ferr(if stores("Float32") {
            format!("{name} stores {types}, not {wanted}: add --ot float32 (7 significant digits)")
        } else {
            format!("{name} stores only {types}: elevations would be cut to integers; use GeoTIFF (.tif), .asc or .nc")
        }));
    }
    let list = driver_item(&driver, "DMD_CREATIONOPTIONLIST").to_ascii_uppercase();
    for o in &opts.creation_options {
        let Some(key) = o.split_once('=').map(|(k, _)| k.trim().to_ascii_uppercase()).filter(|k| !k.is_empty()) else {
            return Err(ferr(format!("-co {o}: expected KEY=VALUE")));
        };
        let known = list.contains(&format!("NAME='{key}'")) || list.contains(&format!("NAME=\"{key}\""));
        if !list.is_empty() && !known {
            return Err(ferr(format!(
                "-co {o}: {name} has no creation option {key} (`gdalinfo --format {name}` lists them)"
            )));
        }
    }
    if path.is_none() && driver_item(&driver, "DCAP_VIRTUALIO") != "YES" {
        return Err(ferr(format!("{name} cannot be written to stdout (the driver needs a real file): use -o FILE")));
    }
    Ok(format)
}

/// A raster written into a temporary directory beside its target, moved into place by
/// [`commit`](StagedRaster::commit); dropped uncommitted, it leaves nothing behind.
struct StagedRaster {
    tmp_dir: PathBuf,
    dir: PathBuf,
    file_name: std::ffi::OsString,
}

impl StagedRaster {
    /// Moves every file of the temporary directory next to the target, the main file last so
    /// a reader never sees it without its side files (the `.prj` of an ASCII grid).
    fn commit(&self) -> Result<(), String> {
        let mut entries: Vec<PathBuf> = std::fs::read_dir(&self.tmp_dir)
            .map_err(|e| e.to_string())?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .collect();
        entries.sort_by_key(|p| p.file_name() == Some(self.file_name.as_os_str()));
        for p in &entries {
            // Data the kernel still holds (delayed allocation on a nearly full disk) must reach
            // the disk before the old file is replaced.
            std::fs::File::open(p)
                .and_then(|f| f.sync_all())
                .map_err(|e| format!("cannot write {}: {e}", p.display()))?;
        }
        let target = self.dir.join(&self.file_name);
        if std::fs::metadata(&target).is_ok_and(|m| !m.is_file() && !m.is_dir()) {
            return self.copy_into_device(&target);
        }
        for p in entries {
            let name = p.file_name().map(|s| s.to_os_string()).unwrap_or_default();
            std::fs::rename(&p, self.dir.join(&name)).map_err(|e| format!("cannot move {}: {e}", p.display()))?;
        }
        Ok(())
    }

    /// A target that is a device or FIFO (`-o /dev/null -of GTiff`) gets the main file's bytes
    /// written into it: renaming over it would replace the device node, for every process on
    /// the host when run as root. Side files have no place beside a device and are dropped.
    fn copy_into_device(&self, target: &Path) -> Result<(), String> {
        let main = self.tmp_dir.join(&self.file_name);
        let mut from = std::fs::File::open(&main).map_err(|e| format!("cannot read {}: {e}", main.display()))?;
        let mut to = std::fs::OpenOptions::new()
            .write(true)
            .open(target)
            .map_err(|e| format!("cannot write {}: {e}", target.display()))?;
        std::io::copy(&mut from, &mut to).map(|_| ()).map_err(|e| format!("cannot write {}: {e}", target.display()))
    }
}

impl Drop for StagedRaster {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.tmp_dir);
    }
}

/// Writes `r` to `path` atomically (see the module docs); the format, band type and creation
/// options come from `opts` ([`check_write`] refuses what cannot be written).
pub fn write_raster(r: &Raster, path: &Path, opts: &WriteOptions) -> Result<(), RasterError> {
    let werr = |message: String| RasterError::Write { path: path.to_path_buf(), message };
    r.validate()?;
    let format = check_write(Some(path), opts)?;
    let driver = DriverManager::get_driver_by_name(format.driver_name()).map_err(|e| werr(gdal_msg(&e)))?;
    let mem = to_mem_dataset(r, opts.sample_type).map_err(werr)?;

    let file_name = path.file_name().ok_or_else(|| werr("not a file path".into()))?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let n = TMP_COUNTER.fetch_add(1, Ordering::Relaxed);
    let tmp_dir = dir.join(format!(".geofit-raster-{}-{n}.tmp", std::process::id()));
    std::fs::create_dir(&tmp_dir).map_err(|e| werr(format!("cannot create {}: {e}", tmp_dir.display())))?;
    let staged = StagedRaster { tmp_dir, dir, file_name: file_name.to_os_string() };
    let tmp_path = staged.tmp_dir.join(file_name);
    let co = creation_options(&format, &opts.creation_options).map_err(werr)?;
    // GDAL's messages name the temporary file: say the target instead (it is the one asked for).
    let tmp_name = tmp_path.display().to_string();
    let named = |m: String| werr(m.replace(&tmp_name, &path.display().to_string()));
    gdal_checked(|| {
        let mut out = mem.create_copy(&driver, &tmp_path, &co)?;
        out.flush_cache()?;
        out.close()
    })
    .map_err(named)?;
    staged.commit().map_err(named)
}

fn creation_options(format: &RasterFormat, user: &[String]) -> Result<RasterCreationOptions, String> {
    let mut co = RasterCreationOptions::new();
    for o in format.creation_options(user) {
        co.add_string(&o).map_err(|e| gdal_msg(&e))?;
    }
    Ok(co)
}

/// Encodes `r` as `opts` says (COG by default) and returns the main file's bytes (for writing
/// to stdout); side files (e.g. an ASCII grid's `.prj`) are dropped.
pub fn raster_to_bytes(r: &Raster, opts: &WriteOptions) -> Result<Vec<u8>, RasterError> {
    let werr = |message: String| RasterError::Write { path: PathBuf::from("<stdout>"), message };
    r.validate()?;
    let format = check_write(None, opts)?;
    let driver = DriverManager::get_driver_by_name(format.driver_name()).map_err(|e| werr(gdal_msg(&e)))?;
    let mem = to_mem_dataset(r, opts.sample_type).map_err(werr)?;
    let n = TMP_COUNTER.fetch_add(1, Ordering::Relaxed);
    let dir = format!("/vsimem/geofit-{}-{n}", std::process::id());
    let vpath = PathBuf::from(format!("{dir}/out.{}", format.extension()));
    let co = creation_options(&format, &opts.creation_options).map_err(werr)?;
    let written = gdal_checked(|| {
        let mut out = mem.create_copy(&driver, &vpath, &co)?;
        out.flush_cache()?;
        out.close()?;
        gdal::vsi::get_vsi_mem_file_bytes_owned(&vpath)
    });
    if let Ok(files) = gdal::vsi::read_dir(&dir, true) {
        for f in files {
            let _ = gdal::vsi::unlink_mem_file(Path::new(&dir).join(f));
        }
    }
    written.map_err(werr)
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
        assert_eq!(back.valid_mask(), r.valid_mask());
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
        assert_eq!(back.valid_mask(), r.valid_mask());
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
        let b = raster_to_bytes(&sample(), &WriteOptions::default()).unwrap();
        assert!(b.starts_with(b"II*\0") || b.starts_with(b"MM\0*"));
    }

    /// Band 2 of a two-band GeoTIFF is its uncertainty layer; a one-band file has none.
    #[test]
    fn uncertainty_is_band_two_or_the_named_band() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("two.tif");
        {
            let drv = DriverManager::get_driver_by_name("GTiff").unwrap();
            let mut ds = drv.create_with_band_type::<f32, _>(&p, 3, 2, 2).unwrap();
            ds.set_geo_transform(&[0.0, 1.0, 0.0, 2.0, 0.0, -1.0]).unwrap();
            for (b, v) in [(1, 10.0f32), (2, 0.25f32)] {
                let mut band = ds.rasterband(b).unwrap();
                let mut buf = gdal::raster::Buffer::new((3, 2), vec![v; 6]);
                band.write((0, 0), (3, 2), &mut buf).unwrap();
            }
        }
        let (u, band) = read_uncertainty(&p).unwrap();
        assert_eq!((band, u.width, u.height), (2, 3, 2));
        assert!(u.data.iter().all(|&v| v == 0.25));
        let one = dir.path().join("one.tif");
        write_raster(&sample(), &one, &WriteOptions::default()).unwrap();
        let e = read_uncertainty(&one).unwrap_err().to_string();
        assert!(e.contains("no uncertainty layer") && e.contains("one.tif"), "{e}");
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
