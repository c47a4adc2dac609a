//! CityGML buildings → one popa3d model, building by building (spec §3, §8.2 steps 1 and 5): what
//! `geofit citygml2popa3d` runs, here so that the command only parses options, makes one call and
//! writes what comes back, and so that a rejected building never stops the others.

use crate::citygml;
use crate::conditions::{self, ConditionCounts, ConditionOptions, Ranges};
use crate::{Counts, Notice, Rejection, Tolerances};
use citygml_io::{CityModel, CityObject};
use popa3d_model::{Popa3d, SourceDocument};
use serde::Serialize;

/// A `--id` that names no Building or BuildingPart with geometry of its own.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("no building or building part with gml:id `{0}` and geometry")]
pub struct UnknownBuilding(pub String);

/// The Buildings and BuildingParts with geometry of their own, in document order; with `ids`
/// only those, each of which must be there (a mistyped id is an error, not an empty result).
pub fn select_buildings<'a>(city: &'a CityModel, ids: &[String]) -> Result<Vec<&'a CityObject>, UnknownBuilding> {
    let mut units: Vec<&CityObject> =
        citygml::buildings(city).into_iter().filter(|b| citygml::has_own_geometry(b)).collect();
    if !ids.is_empty() {
        if let Some(id) = ids.iter().find(|id| !units.iter().any(|b| b.id.as_deref() == Some(id.as_str()))) {
            return Err(UnknownBuilding(id.clone()));
        }
        units.retain(|b| b.id.as_ref().is_some_and(|i| ids.contains(i)));
    }
    Ok(units)
}

/// The empty model the buildings of `city` go into: coordinates reduced to the local origin
/// ([`citygml::local_origin`]), the CRS and the source file (`file`) recorded.
pub fn model_for(city: &CityModel, file: &str) -> Popa3d {
    let mut model = Popa3d::new(citygml::local_origin(city));
    model.srs_name = city.srs_name.clone();
    model.source = Some(SourceDocument { format: "citygml".into(), file: file.to_string() });
    model
}

/// How buildings are converted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BuildingOptions {
    /// Highest LoD read (the best solid ≤ this LoD is used).
    pub lod: u8,
    pub tolerances: Tolerances,
    /// The generated conditions; `None` writes topology and geometry only.
    pub conditions: Option<ConditionOptions>,
}

/// What one converted building contributed: its normalization counts, the conditions generated
/// for it and the notices (the per-building part of the `citygml2popa3d` report).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BuildingReport {
    pub id: String,
    pub counts: Counts,
    pub conditions: ConditionCounts,
    pub notices: Vec<Notice>,
}

/// The buildings converted into the model, in input order, and the rejected ones.
#[derive(Debug, Clone, PartialEq)]
pub struct Conversion {
    pub buildings: Vec<BuildingReport>,
    pub rejected: Vec<Rejection>,
}

/// Converts each building of `units` into `model`; one that cannot be converted is rejected,
/// named by its gml:id, and the others still go in. Conditions are generated once all buildings
/// are in, so the incidence and node positions are built once. `progress(i, id)` is called as
/// building `i` starts.
pub fn convert_buildings(
    model: &mut Popa3d,
    units: &[&CityObject],
    o: &BuildingOptions,
    progress: &dyn Fn(usize, &str),
) -> Conversion {
    let mut conversion = Conversion { buildings: Vec::new(), rejected: Vec::new() };
    let mut ranges = Vec::new();
    for (i, b) in units.iter().enumerate() {
        let id = citygml::building_id(b);
        progress(i, &id);
        match convert_building(model, b, &id, o) {
            Ok((report, r)) => {
                conversion.buildings.push(report);
                ranges.push(r);
            }
            Err(r) => conversion.rejected.push(r),
        }
    }
    if let Some(copt) = &o.conditions {
        for (r, cc) in conversion.buildings.iter_mut().zip(conditions::semantic_many(model, &ranges, copt)) {
            r.conditions = cc;
        }
    }
    conversion
}

/// One building normalized into the model: its report (conditions still to come) and the
/// elements it added.
fn convert_building(
    model: &mut Popa3d,
    b: &CityObject,
    id: &str,
    o: &BuildingOptions,
) -> Result<(BuildingReport, Ranges), Rejection> {
    let soup = citygml::building_soup(b, o.lod).map_err(|r| with_building(r, id))?;
    let before = Ranges::whole(model);
    let n = crate::normalize_into(model, &soup, &o.tolerances).map_err(|r| with_building(r, id))?;
    let report = BuildingReport {
        id: id.to_string(),
        counts: n.counts,
        conditions: ConditionCounts::default(),
        notices: n.notices,
    };
    Ok((report, Ranges::since(model, &before)))
}

/// Puts the building's gml:id in front of the element when the rejection names a polygon.
fn with_building(mut r: Rejection, bid: &str) -> Rejection {
    if r.element != bid {
        r.element = format!("{bid}: {}", r.element);
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::RefCell;

    /// A CityGML 2.0 document of boxes (x0, y0, width, depth, height), building `b{i}` each, as
    /// closed lod1Solids with outward faces.
    fn boxes(list: &[[f64; 5]]) -> String {
        let mut members = String::new();
        for (i, [x, y, w, d, h]) in list.iter().enumerate() {
            // corner k: bit 0 → +width, bit 1 → +depth, bit 2 → +height
            let c = |k: usize| [x + w * (k & 1) as f64, y + d * (k >> 1 & 1) as f64, h * (k >> 2 & 1) as f64];
            let faces = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [1, 3, 7, 5], [3, 2, 6, 7], [2, 0, 4, 6]];
            let mut shell = String::new();
            for f in faces {
                let ring: Vec<String> =
                    f.iter().chain(&f[..1]).map(|&k| c(k).map(|v| v.to_string()).join(" ")).collect();
                shell += &format!("<gml:surfaceMember><gml:Polygon><gml:exterior><gml:LinearRing><gml:posList>{}</gml:posList></gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember>", ring.join(" "));
            }
            members += &format!(
                "<core:cityObjectMember><bldg:Building gml:id=\"b{i}\"><bldg:lod1Solid><gml:Solid><gml:exterior><gml:CompositeSurface>{shell}</gml:CompositeSurface></gml:exterior></gml:Solid></bldg:lod1Solid></bldg:Building></core:cityObjectMember>\n"
            );
        }
        format!(
            "<?xml version=\"1.0\"?>\n<core:CityModel xmlns:core=\"http://www.opengis.net/citygml/2.0\" xmlns:bldg=\"http://www.opengis.net/citygml/building/2.0\" xmlns:gml=\"http://www.opengis.net/gml\">\n{members}</core:CityModel>\n"
        )
    }

    #[test]
    fn a_mistyped_id_is_an_error_and_ids_select_in_document_order() {
        let city = citygml_io::parse(
            boxes(&[[0.0, 0.0, 4.0, 3.0, 2.5], [10.0, 0.0, 5.0, 5.0, 3.0], [20.0, 0.0, 2.0, 2.0, 6.0]]).as_bytes(),
        )
        .unwrap();
        assert_eq!(select_buildings(&city, &["b7".into()]).err(), Some(UnknownBuilding("b7".into())));
        let picked = select_buildings(&city, &["b2".into(), "b0".into()]).unwrap();
        assert_eq!(picked.iter().map(|b| b.id.clone().unwrap()).collect::<Vec<_>>(), ["b0", "b2"]);
        assert_eq!(select_buildings(&city, &[]).unwrap().len(), 3);
    }

    #[test]
    fn every_box_becomes_eight_nodes_on_six_planes_of_its_own() {
        let city =
            citygml_io::parse(boxes(&[[0.0, 0.0, 4.0, 3.0, 2.5], [10.0, 0.0, 5.0, 5.0, 3.0]]).as_bytes()).unwrap();
        let units = select_buildings(&city, &[]).unwrap();
        let mut model = model_for(&city, "boxes.gml");
        let seen = RefCell::new(Vec::new());
        let o = BuildingOptions { lod: 2, tolerances: Tolerances::default(), conditions: None };
        let done = convert_buildings(&mut model, &units, &o, &|i, id| seen.borrow_mut().push((i, id.to_string())));
        assert_eq!(*seen.borrow(), [(0, "b0".to_string()), (1, "b1".to_string())]);
        assert!(done.rejected.is_empty(), "{:?}", done.rejected);
        for r in &done.buildings {
            let last = r.counts.last();
            assert_eq!((last.nodes, last.faces, last.planes), (8, 6, 6), "{}", r.id);
            assert_eq!(r.conditions, ConditionCounts::default(), "no conditions asked for");
        }
        assert_eq!((model.nodes.len(), model.faces.len()), (16, 12), "the two boxes share nothing");
        assert_eq!(model.source.as_ref().map(|s| s.file.as_str()), Some("boxes.gml"));
    }
}
