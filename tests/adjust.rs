//! End-to-end tests of `geofit adjust`, `observe`, `popa3d2citygml` and `heal`.
mod common;

use common::{code, run};

fn stdout(o: &std::process::Output) -> Vec<u8> {
    o.stdout.clone()
}

/// The pipe's first two steps on the project's three-storey fixture: the adjustment converges and
/// writes a valid popa3d document.
#[test]
fn adjust_three_storey_building() {
    let gml = common::repo_root().join("fixtures/citygml/three_storey.gml");
    let a = run(&["citygml2popa3d", gml.to_str().unwrap()], None);
    assert_eq!(code(&a), 0, "{}", String::from_utf8_lossy(&a.stderr));
    let b = run(&["adjust", "-", "--report", "-"], Some(&stdout(&a)));
    assert_eq!(code(&b), 0, "{}", String::from_utf8_lossy(&b.stderr));
}
