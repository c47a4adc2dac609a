//! The netCDF classic header check that runs before GDAL opens a file (input_limits::netcdf).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = input_limits::netcdf::check(&mut &data[..], data.len() as u64);
});
