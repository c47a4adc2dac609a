//! popa3d XML reader: a model or an XmlError; a model that reads writes back and reads again.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(m) = popa3d_model::read(data) {
        let bytes = popa3d_model::write_to_vec(&m).expect("a model that was read can be written");
        let _ = popa3d_model::read(&bytes);
    }
});
