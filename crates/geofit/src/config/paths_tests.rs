//! Unit tests of `config/paths.rs`.

use super::*;

#[test]
fn every_kind_that_is_refused_names_a_way_out_or_what_it_is() {
    let kinds =
        [FileKind::CityGml, FileKind::Popa3d, FileKind::TMesh, FileKind::Raster("PNG"), FileKind::Las, FileKind::Obj];
    for k in kinds {
        assert!(hint(&k, "x").starts_with(" (read it with geofit "), "{k:?}");
    }
    assert!(hint(&FileKind::CityJson, "x").contains("convert"));
}

#[test]
fn readers_keep_what_they_judge_themselves() {
    let p = Path::new("x");
    assert!(accepts(Takes::Raster, &FileKind::Xml("VRTDataset".into()), p));
    assert!(accepts(Takes::Raster, &FileKind::PointText, p));
    assert!(accepts(Takes::CityGml, &FileKind::Unknown, p));
    assert!(!accepts(Takes::Raster, &FileKind::CityGml, p));
    assert!(!accepts(Takes::Points, &FileKind::CityGml, p));
    assert!(!accepts(Takes::TMesh, &FileKind::Raster("TIFF/GeoTIFF"), p));
    assert!(accepts(Takes::CityGml, &FileKind::CityJson, p));
    assert!(!accepts(Takes::Popa3d, &FileKind::CityJson, p));
}
