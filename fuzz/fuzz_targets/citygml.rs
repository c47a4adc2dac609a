//! CityGML reader (citygml_io::parse): any bytes give a model or a ReadError, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = citygml_io::parse(data);
});
