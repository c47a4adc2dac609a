//! T-mesh reader (XML exchange format and the compact .tmb, chosen by magic bytes).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = tspline::format::read(data);
});
