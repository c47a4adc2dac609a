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
    let mut units: Vec<&CityObject> = citygml::buildings(city).into_iter().filter(|b| citygml::has_own_geometry(b)).collect();
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
pub fn convert_buildings(model: &mut Popa3d, units: &[&CityObject], o: &BuildingOptions, progress: &dyn Fn(usize, &str)) -> Conversion {
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
fn convert_building(model: &mut Popa3d, b: &CityObject, id: &str, o: &BuildingOptions) -> Result<(BuildingReport, Ranges), Rejection> {
    let soup = citygml::building_soup(b, o.lod).map_err(|r| with_building(r, id))?;
    let before = Ranges::whole(model);
    let n = crate::normalize_into(model, &soup, &o.tolerances).map_err(|r| with_building(r, id))?;
    let report = BuildingReport { id: id.to_string(), counts: n.counts, conditions: ConditionCounts::default(), notices: n.notices };
    Ok((report, Ranges::since(model, &before)))
}

/// Puts the building's gml:id in front of the element when the rejection names a polygon.
fn with_building(mut r: Rejection, bid: &str) -> Rejection {
    if r.element != bid {
        r.element = format!("{bid}: {}", r.element);
    }
    r
}
