//! Repairs beyond planarity (issue 35): each one named, counted per building and verified like
//! the planarity heal.
//!
//! A building with findings among [`TARGETS`] gets, in this order, on a working copy of its
//! polygons (every polygon once, however many geometries reach it by XLink):
//!
//! 1. `drop_duplicate_points` (102): consecutive points that snap to one vertex become one;
//!    `remove_spike` (104): a vertex whose two edges fold back onto each other goes;
//!    `remove_collapsed_ring` / `remove_collapsed_polygon` (101): a ring left with fewer than 3
//!    vertices has no area and goes (a polygon only where nothing refers to it).
//! 2. `insert_t_junction` (302): a vertex of the shell lying on an edge used by one face only is
//!    inserted into that edge; `snap_gap` (302): a border vertex within `max_move` of another
//!    moves onto it, where that closes border edges (docs/decisions.md#issue-35-repairs-gap-snap-bound).
//! 3. `cut_keyhole` / `split_pinch` / `remove_fold` (104): a ring that passes twice through a
//!    vertex is split into an outer ring, holes (a keyhole's cut dropped), lobes (new polygons)
//!    and zero-area loops (dropped).
//! 4. `orient_faces` (307) / `orient_shell` (405): the faces of a shell are turned to agree
//!    along every edge, then all of them outwards by the signed volume.
//!
//! The result is validated and measured before anything is written ([`verify`],
//! docs/decisions.md#issue-35-repairs-verified-before-writing-instead-of-the-planarity-heal); the
//! codes the building still has are reported as left alone. Vertex identity is the validator's
//! (its snapper, `--snap-tol`), so a repair sees exactly the vertices the finding was about
//! (docs/decisions.md#issue-35-repairs-vertex-identity-is-the-validators).
//!
//! # Examples
//! ```
//! // a unit cube whose faces all point inwards (QIE 308, val3dity 405)
//! let face = |p: &str| format!("<gml:surfaceMember><gml:Polygon><gml:exterior><gml:LinearRing><gml:posList>{p}</gml:posList></gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember>");
//! let faces = [
//!     "0 0 0 1 0 0 1 1 0 0 1 0 0 0 0", "0 0 1 0 1 1 1 1 1 1 0 1 0 0 1", "0 0 0 0 0 1 1 0 1 1 0 0 0 0 0",
//!     "1 0 0 1 0 1 1 1 1 1 1 0 1 0 0", "1 1 0 1 1 1 0 1 1 0 1 0 1 1 0", "0 0 0 0 1 0 0 1 1 0 0 1 0 0 0",
//! ];
//! let gml = format!(r#"<core:CityModel xmlns:core="http://www.opengis.net/citygml/2.0" xmlns:gml="http://www.opengis.net/gml"
//!   xmlns:bldg="http://www.opengis.net/citygml/building/2.0"><core:cityObjectMember><bldg:Building gml:id="b">
//!   <bldg:lod1Solid><gml:Solid><gml:exterior><gml:CompositeSurface>{}</gml:CompositeSurface></gml:exterior></gml:Solid></bldg:lod1Solid>
//!   </bldg:Building></core:cityObjectMember></core:CityModel>"#, faces.map(|f| face(f)).concat());
//! let city = citygml_io::parse(gml.as_bytes()).unwrap();
//! let opts = heal::repair::RepairOptions { validation: Default::default(), max_move: 0.05, max_area_change: 0.005 };
//! let (edits, record) = heal::repair::repair_unit(&city.objects[0], gml.as_bytes(), &opts);
//! let record = record.unwrap();
//! assert_eq!(record.repairs.get("orient_shell"), Some(&1));
//! assert!(record.left_alone.is_empty());
//! assert_eq!(edits.unwrap().len(), 6); // every face runs the other way
//! ```

pub mod ring;
pub mod rings;
mod screen;
pub mod shell;
#[cfg(test)]
mod tests;
pub mod verify;
pub mod work;
mod write;

use citygml_io::{CityObject, Edit};
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
use work::Work;

/// The names of the repairs, as the heal report counts them.
pub mod names {
    pub const DUPLICATE_POINTS: &str = "drop_duplicate_points";
    pub const SPIKE: &str = "remove_spike";
    pub const COLLAPSED_RING: &str = "remove_collapsed_ring";
    pub const COLLAPSED_POLYGON: &str = "remove_collapsed_polygon";
    pub const T_JUNCTION: &str = "insert_t_junction";
    pub const GAP: &str = "snap_gap";
    pub const KEYHOLE: &str = "cut_keyhole";
    pub const PINCH: &str = "split_pinch";
    pub const FOLD: &str = "remove_fold";
    pub const FACE_ORIENTATION: &str = "orient_faces";
    pub const SHELL_ORIENTATION: &str = "orient_shell";
}

/// The validation codes the repairs act on (val3dity numbering).
pub const TARGETS: [u16; 6] = [101, 102, 104, 302, 307, 405];

/// Repair name → how many times it was applied.
pub type Counts = BTreeMap<&'static str, usize>;

/// What the repairs did to one building.
#[derive(Debug, Clone, Default, Serialize)]
pub struct RepairRecord {
    /// The repairs written (empty when they were refused).
    pub repairs: Counts,
    /// Findings per code the building still has: the codes the repairs leave alone.
    pub left_alone: BTreeMap<u16, usize>,
    /// Why the repairs found were not written, when they were not.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refused: Option<String>,
}

/// Tolerances of the repairs and of their verification.
#[derive(Debug, Clone)]
pub struct RepairOptions {
    /// Snap tolerance, planarity and normals tolerances of the validation.
    pub validation: citygml_validate::Options,
    /// No input vertex may end further than this from the output surface (m); also the widest
    /// gap closed by moving a vertex.
    pub max_move: f64,
    /// No thematic surface type's area may change by this fraction or more.
    pub max_area_change: f64,
}

fn code_totals(f: &verify::Findings) -> BTreeMap<u16, usize> {
    let mut m = BTreeMap::new();
    for ((_, c), n) in f {
        *m.entry(*c).or_insert(0) += n;
    }
    m
}

/// How far from an edge (in snap tolerances) a shell vertex may lie and still be inserted into
/// it as a T-junction: coordinates written to the millimetre put a vertex that lies on the edge
/// up to 1 mm and a rounding error off it, just beyond one snap tolerance (NRW tile
/// 338_5724: 1.0000002 mm). See docs/decisions.md#issue-35-repairs-t-junction-reach.
pub const T_JUNCTION_REACH: f64 = 2.0;

/// Runs the repair steps on the working copy.
fn run_steps(w: &mut Work, opts: &RepairOptions) -> Counts {
    let tol = opts.validation.snap_tol;
    let mut counts = Counts::new();
    rings::fix_points(w, tol, &mut counts);
    // T-junctions first: a gap snap may then collapse a short border edge the insertion made
    shell::insert_t_junctions(w, tol, T_JUNCTION_REACH * tol, &mut counts);
    if shell::snap_gaps(w, tol, opts.max_move, &mut counts) > 0 {
        rings::fix_points(w, tol, &mut counts);
        shell::insert_t_junctions(w, tol, T_JUNCTION_REACH * tol, &mut counts);
    }
    rings::split_rings(w, tol, &mut counts);
    shell::orient_shells(w, tol, &mut counts);
    counts
}

/// Repairs one building (a conversion unit: its own objects, not its parts). Returns the edits
/// (`None` when nothing is written) and the record (`None` when the building has no finding
/// the repairs act on).
pub fn repair_unit(b: &CityObject, doc: &[u8], opts: &RepairOptions) -> (Option<Vec<Edit>>, Option<RepairRecord>) {
    let objects = normalize::citygml::own_objects(b);
    let mut w = Work::new(&objects);
    if !screen::suspect(&w, opts.validation.snap_tol) {
        return (None, None);
    }
    let before = verify::findings(&objects, &opts.validation);
    let totals = code_totals(&before);
    if !TARGETS.iter().any(|c| totals.contains_key(c)) {
        return (None, None);
    }
    let mut record = RepairRecord { left_alone: totals.clone(), ..RepairRecord::default() };
    let counts = run_steps(&mut w, opts);
    let changed: HashMap<(usize, usize), &work::WPoly> = w
        .polys
        .iter()
        .filter(|p| !p.frozen && p.changed())
        .map(|p| ((p.src.span.bytes.start, p.src.span.bytes.end), p))
        .collect();
    if changed.is_empty() {
        record.refused = Some("no repair applies to its findings".into());
        return (None, Some(record));
    }
    let mut copy = b.clone();
    verify::apply(&mut copy, &changed);
    let after_objects = normalize::citygml::own_objects(&copy);
    let after = verify::findings(&after_objects, &opts.validation);
    if let Some(why) = refuse(&objects, &after_objects, &before, &after, opts) {
        record.refused = Some(why);
        return (None, Some(record));
    }
    let mut edits = Vec::new();
    for p in changed.values() {
        match write::polygon_edits(doc, p) {
            Ok(e) => edits.extend(e),
            Err(why) => {
                record.refused = Some(format!("polygon {}: {why}", p.src.id.as_deref().unwrap_or("without gml:id")));
                return (None, Some(record));
            }
        }
    }
    edits.sort_by_key(|e| (e.bytes.start, e.bytes.end));
    record.repairs = counts;
    record.left_alone = code_totals(&after);
    (Some(edits), Some(record))
}

/// Why the repaired building must not be written, if it must not.
fn refuse(
    before_objects: &[&CityObject],
    after_objects: &[&CityObject],
    before: &verify::Findings,
    after: &verify::Findings,
    opts: &RepairOptions,
) -> Option<String> {
    let grown: Vec<String> = after
        .iter()
        .filter(|(k, n)| before.get(k).copied().unwrap_or(0) < **n)
        .map(|((f, c), n)| {
            format!(
                "{c} ×{}→{n} in {}",
                before.get(&(f.clone(), *c)).copied().unwrap_or(0),
                f.as_deref().unwrap_or("(no id)")
            )
        })
        .collect();
    if !grown.is_empty() {
        return Some(format!("the repairs would add validation findings ({})", grown.join(", ")));
    }
    let (tb, ta) = (code_totals(before), code_totals(after));
    let fixed: usize =
        TARGETS.iter().map(|c| tb.get(c).copied().unwrap_or(0).saturating_sub(ta.get(c).copied().unwrap_or(0))).sum();
    if fixed == 0 {
        return Some("the repairs would remove no finding".into());
    }
    let (ab, aa) = (verify::areas(before_objects), verify::areas(after_objects));
    for (t, a0) in &ab {
        let a1 = aa.get(t).copied().unwrap_or(0.0);
        if *a0 > 0.0 && ((a1 / a0 - 1.0).abs() >= opts.max_area_change || !a1.is_finite()) {
            let name = t.map_or("untyped", |t| t.local_name());
            return Some(format!("the repairs would change the {name} area by {:+.2} %", 100.0 * (a1 / a0 - 1.0)));
        }
    }
    let d = verify::max_vertex_distance(before_objects, after_objects);
    if !(d <= opts.max_move) {
        return Some(format!(
            "an input vertex would end {d:.3} m from the repaired surface (more than --max-move {} m)",
            opts.max_move
        ));
    }
    None
}

/// The heal report's per-building records (by building name): a building the heal's own
/// verification kept has its repairs undone, and says why.
pub fn records(
    units: &[&CityObject],
    records: Vec<Option<RepairRecord>>,
    kept: &[crate::Kept],
) -> BTreeMap<String, RepairRecord> {
    let why: HashMap<&str, &str> = kept.iter().map(|k| (k.building.as_str(), k.reason.as_str())).collect();
    let mut out = BTreeMap::new();
    for (b, r) in units.iter().zip(records) {
        let Some(mut r) = r else { continue };
        let name = normalize::citygml::unit_name(b);
        if let (Some(reason), false) = (why.get(name.as_str()), r.repairs.is_empty()) {
            r.repairs.clear();
            r.refused = Some(reason.to_string());
        }
        out.insert(name, r);
    }
    out
}
