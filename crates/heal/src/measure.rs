//! What the guard compares for one building before and after healing: its validation findings
//! per code and its surface area. Both are computed from the parsed document, so the "after"
//! side measures what was really written, not what the adjustment believed it wrote.

use citygml_io::{CityObject, Polygon};
use citygml_validate::{validate_objects_only, Options};
use std::collections::BTreeMap;

/// One building's measures.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Measures {
    /// Number of validation findings per val3dity code.
    pub codes: BTreeMap<u16, usize>,
    /// Total area of its polygons (exterior minus holes, m²); each polygon once (XLink copies
    /// skipped).
    pub area: f64,
    /// After a write-back: the Hausdorff distance between the surface before and after (m, see
    /// [`crate::hausdorff`]); 0 before.
    pub moved: f64,
}

/// The objects of a unit and their own polygons (not those reached by XLink).
pub(crate) fn own_polygons<'a>(objects: &[&'a CityObject]) -> Vec<&'a Polygon> {
    objects
        .iter()
        .flat_map(|o| o.geometries.iter())
        .flat_map(|g| g.polygons())
        .filter(|p| p.via_xlink.is_none())
        .collect()
}

/// Measures one unit (its own objects, see `normalize::citygml::own_objects`).
pub fn measure(objects: &[&CityObject], opts: &Options) -> Measures {
    let mut codes = BTreeMap::new();
    for f in validate_objects_only(objects, opts) {
        *codes.entry(f.code).or_insert(0) += 1;
    }
    let area = own_polygons(objects).into_iter().map(polygon_area).sum();
    Measures { codes, area, moved: 0.0 }
}

/// The surface of a unit (its own polygons) for [`crate::hausdorff`].
pub fn surface(objects: &[&CityObject]) -> crate::hausdorff::Surface {
    crate::hausdorff::Surface::new(
        own_polygons(objects)
            .into_iter()
            .map(|p| std::iter::once(&p.exterior).chain(p.interiors.iter()).map(|r| r.points.clone()).collect())
            .collect(),
    )
}

/// Vector area of a closed ring (Newell), m².
fn ring_area(pts: &[[f64; 3]]) -> f64 {
    let n = popa3d_model::topology::newell(pts);
    0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
}

/// Exterior area minus the areas of the holes.
pub fn polygon_area(p: &Polygon) -> f64 {
    ring_area(&p.exterior.points) - p.interiors.iter().map(|r| ring_area(&r.points)).sum::<f64>()
}

/// The reference point of a unit: the centre of its polygons' bounding box, rounded down to
/// whole metres, so the unit's local coordinates (and with them the adjustment) are the same
/// wherever the building sits: alone in a file, inside a tile, or shifted by whole metres.
/// Errs when a coordinate is not finite, the unit spans more than [`MAX_EXTENT`] or it has no
/// polygons.
pub fn reference_point(objects: &[&CityObject]) -> Result<[f64; 3], String> {
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in own_polygons(objects) {
        for r in std::iter::once(&p.exterior).chain(p.interiors.iter()) {
            for q in &r.points {
                for k in 0..3 {
                    if !q[k].is_finite() {
                        return Err(format!(
                            "a coordinate of polygon {} is not finite",
                            p.id.as_deref().unwrap_or("without gml:id")
                        ));
                    }
                    lo[k] = lo[k].min(q[k]);
                    hi[k] = hi[k].max(q[k]);
                }
            }
        }
    }
    if lo[0] > hi[0] {
        return Err("no polygons".into());
    }
    if (0..3).any(|k| (hi[k] - lo[k]).partial_cmp(&MAX_EXTENT) != Some(std::cmp::Ordering::Less)) {
        return Err(format!("its coordinates span more than {MAX_EXTENT} m (a coordinate is out of range)"));
    }
    Ok([0, 1, 2].map(|k| (lo[k] / 2.0 + hi[k] / 2.0).floor()))
}

/// The largest extent of one building that heal accepts (m): no building is 100 km long, so a
/// larger one holds a bad coordinate.
pub const MAX_EXTENT: f64 = 1e5;

/// The codes whose count grew from `before` to `after`, as `code ×before→after` texts.
pub fn new_findings(before: &Measures, after: &Measures) -> Vec<String> {
    after
        .codes
        .iter()
        .filter(|(c, n)| before.codes.get(c).copied().unwrap_or(0) < **n)
        .map(|(c, n)| format!("{c} ×{}→{n}", before.codes.get(c).copied().unwrap_or(0)))
        .collect()
}
