//! Implicit model files (`.gfim`, issue 40): the reader, and for a small model the solver of
//! `implicit update` (constraint 0 moved onto itself), which a NaN or 1e300 weight made run
//! forever. Seeds: fuzz/corpus/gfim; regressions: value weights of NaN and 1e300.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(mut m) = implicit::model::Model::from_bytes(data) else { return };
    if m.mesh.verts.len() > 2000 || m.params.max_iter > 5000 || m.params.rounds > 8 {
        return;
    }
    let Some(c) = m.constraints.first() else { return };
    let p = [0, 1, 2].map(|k| c.pos[k] + m.origin[k]);
    let _ = m.update(&[], &[(0, p)], false, &mut |_| {});
});
