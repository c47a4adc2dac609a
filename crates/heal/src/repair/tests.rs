//! Whole-building repairs on hand-built unit cubes: each defect is made by hand, the repair's
//! name and count and the validation codes after are the analytic expectation.

use super::{repair_unit, RepairOptions};

/// The six faces of the unit cube, outwards, as posList texts (closing point included).
const CUBE: [&str; 6] = [
    "0 0 0 0 1 0 1 1 0 1 0 0 0 0 0",
    "0 0 1 1 0 1 1 1 1 0 1 1 0 0 1",
    "0 0 0 1 0 0 1 0 1 0 0 1 0 0 0",
    "1 0 0 1 1 0 1 1 1 1 0 1 1 0 0",
    "1 1 0 0 1 0 0 1 1 1 1 1 1 1 0",
    "0 1 0 0 0 0 0 0 1 0 1 1 0 1 0",
];

fn document(faces: &[String]) -> String {
    let members: String = faces
        .iter()
        .map(|p| format!("<gml:surfaceMember><gml:Polygon><gml:exterior><gml:LinearRing><gml:posList>{p}</gml:posList></gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember>"))
        .collect();
    format!(
        r#"<core:CityModel xmlns:core="http://www.opengis.net/citygml/2.0" xmlns:gml="http://www.opengis.net/gml" xmlns:bldg="http://www.opengis.net/citygml/building/2.0"><core:cityObjectMember><bldg:Building gml:id="b"><bldg:lod1Solid><gml:Solid><gml:exterior><gml:CompositeSurface>{members}</gml:CompositeSurface></gml:exterior></gml:Solid></bldg:lod1Solid></bldg:Building></core:cityObjectMember></core:CityModel>"#
    )
}

/// Repairs the cube with `faces`, writes the edits and validates the result: (record, codes
/// before, codes after).
fn repair(faces: &[String]) -> (super::RepairRecord, Vec<u16>, Vec<u16>) {
    let gml = document(faces);
    let city = citygml_io::parse(gml.as_bytes()).unwrap();
    let opts = RepairOptions { validation: Default::default(), max_move: 0.05, max_area_change: 0.005 };
    let codes = |c: &citygml_io::CityModel| {
        citygml_validate::validate_model(c, &opts.validation).iter().map(|f| f.code).collect::<Vec<_>>()
    };
    let before = codes(&city);
    let (edits, record) = repair_unit(&city.objects[0], gml.as_bytes(), &opts);
    let mut out = Vec::new();
    citygml_io::write_with_edits(gml.as_bytes(), &edits.unwrap_or_default(), &mut out).unwrap();
    let after = codes(&citygml_io::parse(&out).unwrap());
    (record.expect("a record for a building with findings"), before, after)
}

fn cube() -> Vec<String> {
    CUBE.iter().map(|s| s.to_string()).collect()
}

#[test]
fn one_face_turned_inwards_is_turned_back() {
    let mut f = cube();
    f[3] = "1 0 0 1 0 1 1 1 1 1 1 0 1 0 0".into(); // the x = 1 face, reversed
    let (r, before, after) = repair(&f);
    assert_eq!(before, vec![307]);
    assert_eq!(r.repairs.get("orient_faces"), Some(&1), "{r:?}");
    assert!(after.is_empty(), "{after:?}");
}

#[test]
fn a_repeated_corner_is_dropped() {
    let mut f = cube();
    f[1] = "0 0 1 1 0 1 1 1 1 1.0004 1 1 0 1 1 0 0 1".into(); // (1, 1, 1) twice, 0.4 mm apart
    let (r, before, after) = repair(&f);
    assert_eq!(before, vec![102]);
    assert_eq!(r.repairs.get("drop_duplicate_points"), Some(&1), "{r:?}");
    assert!(after.is_empty(), "{after:?}");
}

#[test]
fn a_long_spike_is_left_and_reported() {
    let mut f = cube();
    // the top face runs from (1, 1, 1) out to (1.5, 1, 1) and back: a 0.5 m spike whose tip
    // would end 0.5 m from the repaired surface, more than --max-move: refused
    f[1] = "0 0 1 1 0 1 1 1 1 1.5 1 1 1 1 1 0 1 1 0 0 1".into();
    let (r, before, after) = repair(&f);
    assert_eq!(before, vec![104]);
    assert!(r.repairs.is_empty(), "{r:?}");
    assert!(r.refused.as_deref().unwrap_or("").contains("--max-move"), "{r:?}");
    assert_eq!(after, before);
}

#[test]
fn a_short_spike_is_removed() {
    let mut f = cube();
    f[1] = "0 0 1 1 0 1 1 1 1 1.03 1 1 0 1 1 0 0 1".into(); // folds back from (1.03, 1, 1) to (0, 1, 1)
    let (r, before, after) = repair(&f);
    assert_eq!(before, vec![104]);
    assert_eq!(r.repairs.get("remove_spike"), Some(&1), "{r:?}");
    assert!(after.is_empty(), "{after:?}");
}
