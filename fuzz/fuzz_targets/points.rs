//! XYZ/CSV point reader (rasterize's and implicit's text input).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = raster_io::points::read_xyz(std::io::Cursor::new(data), "fuzz.xyz");
});
