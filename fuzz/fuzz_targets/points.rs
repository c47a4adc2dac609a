//! XYZ/CSV point readers: the terrain dialect (rasterize's input) and the LoopStructural dialect
//! (implicit's input), both in crates/point-io.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = raster_io::points::read_xyz(std::io::Cursor::new(data), "fuzz.xyz");
    let _ = point_io::loop_structural::parse_xyz(data, "fuzz.csv");
});
