//! OBJ sketch reader (obj2popa3d's input).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = normalize::obj::read_sketch(data, "fuzz.obj");
});
