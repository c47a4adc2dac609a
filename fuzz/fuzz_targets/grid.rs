//! Raster grids through raster-io's GDAL path (ESRI ASCII grid by name; GDAL sniffs others):
//! the cell budget is checked against what the header claims before a band is read.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // gdal's create_mem_file hands the Vec's buffer to GDAL, which frees it on unlink: an empty
    // Vec has no buffer to free (the harness, not raster-io, would crash)
    if data.is_empty() {
        return;
    }
    let path = format!("/vsimem/fuzz-{}.asc", std::process::id());
    if gdal::vsi::create_mem_file(&path, data.to_vec()).is_err() {
        return;
    }
    let _ = raster_io::read_raster_band(std::path::Path::new(&path), 1);
    let _ = gdal::vsi::unlink_mem_file(&path);
});
