//! LAS/LAZ reader (issue 40): the header and LASzip VLR checks of input-limits, then the `las`
//! and `laz` crates decoding every point. Seeds: fuzz/corpus/las (a LAS 1.2 and a layered
//! LAS 1.4 LAZ); regressions: a POINT10 item size of 1 (a panic in laz), layer sizes of 0xFF
//! (4.2 GB allocated).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(mut las) = point_io::las::LasPoints::from_bytes(data.to_vec(), None) {
        while let Ok(batch) = las.next_batch() {
            if batch.is_empty() {
                let _ = las.check_end();
                break;
            }
        }
    }
});
