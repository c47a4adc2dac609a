//! Heal CityGML buildings without making any of them worse.
//!
//! `heal` makes the faces of LoD2/LoD3 buildings exactly planar by the popa3d pipe (spec §8.2:
//! CityGML → plane-parameterised model → Gauss–Helmert adjustment → plane intersections written
//! back), one building at a time, each about its own reference point so the result does not
//! depend on where the building sits in its file. It then verifies what it wrote: the healed
//! document is parsed again and every building is validated and measured. A building that would
//! get a validation finding it did not have (for example a shell that was closed and is now
//! open), or whose surface area would change by more than `max_area_change`, or whose vertices
//! would move further than `max_move`, keeps its original geometry, and the report says why.
//! The output is therefore never worse than the input by geofit's own validation.
//!
//! # Examples
//! ```
//! let gml = br#"<?xml version="1.0"?>
//! <core:CityModel xmlns:core="http://www.opengis.net/citygml/2.0" xmlns:gml="http://www.opengis.net/gml"
//!   xmlns:bldg="http://www.opengis.net/citygml/building/2.0">
//! <core:cityObjectMember><bldg:Building gml:id="b1"/></core:cityObjectMember>
//! </core:CityModel>"#;
//! // A building without geometry: nothing to heal.
//! let err = heal::heal(gml, &heal::HealOptions::default(), &|_| {}).err().unwrap();
//! assert!(matches!(err, heal::HealError::NoBuildings));
//! ```

pub mod crs;
pub mod hausdorff;
pub mod measure;
pub mod repair;
mod unit;
mod verify;

use citygml_io::{CityModel, CityObject, Edit};
use measure::Measures;
use normalize::citygml::unit_name;
use normalize::conditions::ConditionOptions;
use normalize::to_citygml::{BackOptions, BackReport, Template};
use rayon::prelude::*;
use serde::Serialize;
use std::sync::atomic::{AtomicUsize, Ordering};
pub use verify::UnitResult;

/// Options of [`heal`].
#[derive(Debug, Clone)]
pub struct HealOptions {
    /// Highest LoD to read.
    pub lod: u8,
    /// Normalization tolerances (snap, planarity, m).
    pub tolerances: normalize::Tolerances,
    /// Generated conditions.
    pub conditions: ConditionOptions,
    /// Write-back (coplanar tolerance, merging, precision).
    pub back: BackOptions,
    /// A building whose vertices would move further than this keeps its geometry (m).
    pub max_move: f64,
    /// A building whose surface area would change by more than this fraction keeps its geometry.
    pub max_area_change: f64,
    /// Validation tolerances of the before/after comparison.
    pub validation: citygml_validate::Options,
}

impl Default for HealOptions {
    fn default() -> Self {
        HealOptions {
            lod: 4,
            tolerances: normalize::Tolerances::default(),
            // Healing makes faces planar with the least change: no squaring (parallel or
            // orthogonal conditions) and no snapping of offset planes (ε = 0).
            conditions: ConditionOptions {
                parallel_deg: 0.0,
                orthogonal_deg: 0.0,
                epsilon: 0.0,
                ..ConditionOptions::default()
            },
            back: BackOptions::default(),
            max_move: 0.05,
            max_area_change: 0.005,
            validation: citygml_validate::Options::default(),
        }
    }
}

/// A building left as it was, and why.
#[derive(Debug, Clone, Serialize)]
pub struct Kept {
    pub building: String,
    pub reason: String,
}

/// What [`heal`] did.
#[derive(Debug, Clone, Serialize)]
pub struct HealReport {
    /// Buildings and building parts with geometry of their own.
    pub buildings: usize,
    /// Buildings whose geometry was rewritten and whose validation findings fell.
    pub healed: usize,
    /// Buildings whose geometry was rewritten (healed or only made planar).
    pub changed: usize,
    /// Buildings without any validation finding, before and after.
    pub valid_before: usize,
    pub valid_after: usize,
    /// Buildings that keep their original geometry, with the reason.
    pub kept: Vec<Kept>,
    /// Surface area of all buildings before and after (m²; buildings whose area is not finite
    /// are left out of both).
    pub area_before_m2: f64,
    pub area_after_m2: f64,
    /// Per rewritten building, the Hausdorff distance between its surface before and after (m):
    /// the largest distance of an input vertex from the output surface or of an output vertex
    /// from the input surface; and the largest of them.
    pub moved_by_building_m: std::collections::BTreeMap<String, f64>,
    pub max_moved_m: f64,
    /// Validation findings per code, all buildings, before and after.
    pub findings_before: std::collections::BTreeMap<u16, usize>,
    pub findings_after: std::collections::BTreeMap<u16, usize>,
    /// Verification rounds (each round writes, re-reads and re-validates).
    pub rounds: usize,
    /// The write-back of the healed buildings, summed.
    pub back: BackReport,
    /// Per building with findings the repairs beyond planarity act on (by name): the repairs
    /// written and how often, the codes left alone, or why the repairs were not written.
    pub repairs: std::collections::BTreeMap<String, repair::RepairRecord>,
}

/// The healed document and the report.
pub struct Healed {
    pub document: Vec<u8>,
    pub report: HealReport,
    /// What the input holds that other commands refuse, in file order, each as
    /// "line:column: why": non-finite coordinates (the reader's error, exit 3 elsewhere) and
    /// XLinks to nothing (a finding elsewhere). heal keeps the buildings they are in as they
    /// were; the command refuses the input when no building is left to heal.
    pub defects: Defects,
}

/// See [`Healed::defects`].
#[derive(Debug, Clone, Default)]
pub struct Defects {
    pub bad_numbers: Vec<String>,
    pub unresolved_xlinks: Vec<String>,
}

/// Why a document cannot be healed at all (a building that cannot be healed is not an error:
/// it is kept and reported).
#[derive(Debug, thiserror::Error)]
pub enum HealError {
    #[error("{0}")]
    Unreadable(String),
    #[error("no Building or BuildingPart with geometry")]
    NoBuildings,
    #[error("the CRS `{srs}` is geographic (EPSG:{epsg}, degrees) but heal's tolerances are metres; reproject the file to a projected CRS (e.g. its UTM zone) first")]
    Geographic { srs: String, epsg: u32 },
    #[error("internal: {0}")]
    Internal(String),
}

/// The conversion units of a document: every Building / BuildingPart with geometry of its own.
fn units(city: &CityModel) -> Vec<&CityObject> {
    normalize::citygml::buildings(city).into_iter().filter(|b| normalize::citygml::has_own_geometry(b)).collect()
}

/// Heals every building of a CityGML document (see the crate documentation). `progress` is
/// called with the number of buildings adjusted so far.
pub fn heal(original: &[u8], opts: &HealOptions, progress: &(dyn Fn(usize) + Sync)) -> Result<Healed, HealError> {
    let doc = Document::read(original, false)?;
    let units = units(&doc.city);
    if units.is_empty() {
        return Err(HealError::NoBuildings);
    }
    let template = Template::new(&doc.bytes, &doc.city);
    let done = AtomicUsize::new(0);
    let (results, records): (Vec<UnitResult>, Vec<_>) = units
        .par_iter()
        .map(|b| {
            let r = unit::heal_or_repair(b, &doc.bytes, &template, opts);
            progress(done.fetch_add(1, Ordering::Relaxed) + 1);
            r
        })
        .unzip();
    let mut healed = verified(original, &doc, &units, results, Vec::new(), opts)?;
    healed.report.repairs = repair::records(&units, records, &healed.report.kept);
    Ok(healed)
}

/// Writes an adjusted popa3d model back into its template (`popa3d2citygml`) through the same
/// verification as [`heal`]: the edits are split by building, and a building that would get a
/// new validation code, change its area by more than `opts.max_area_change` or move further than
/// `opts.max_move` (Hausdorff) keeps its original geometry and is named in `report.kept`.
/// Returns the verified document and the summed write-back report of the whole model.
pub fn write_back(
    model: &popa3d_model::Popa3d,
    original: &[u8],
    back: &BackOptions,
    opts: &HealOptions,
) -> Result<(Healed, BackReport), WriteBackError> {
    let doc = Document::read(original, true)?;
    let units = units(&doc.city);
    if units.is_empty() {
        return Err(HealError::NoBuildings.into());
    }
    let template = Template::new(&doc.bytes, &doc.city);
    let (edits, report) = normalize::to_citygml::back_edits(model, &template, back)?;
    let (per_unit, always) = split_by_unit(&units, edits);
    let results = per_unit.into_iter().map(|e| Ok((e, BackReport::default()))).collect();
    let mut healed = verified(original, &doc, &units, results, always, opts)?;
    healed.report.back = report.clone();
    Ok((healed, report))
}

/// Why [`write_back`] failed: the model does not fit its template, or the document cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum WriteBackError {
    #[error(transparent)]
    Back(#[from] normalize::to_citygml::BackError),
    #[error(transparent)]
    Heal(#[from] HealError),
}

/// Each edit goes to the innermost unit whose element holds it; edits outside every unit (none
/// the write-back makes today) are returned apart and applied whatever is kept.
fn split_by_unit(units: &[&CityObject], edits: Vec<Edit>) -> (Vec<Vec<Edit>>, Vec<Edit>) {
    let mut per_unit = vec![Vec::new(); units.len()];
    let mut always = Vec::new();
    for e in edits {
        let holder = (0..units.len())
            .filter(|&i| units[i].span.bytes.start <= e.bytes.start && e.bytes.end <= units[i].span.bytes.end)
            .max_by_key(|&i| units[i].span.bytes.start);
        match holder {
            Some(i) => per_unit[i].push(e),
            None => always.push(e),
        }
    }
    (per_unit, always)
}

/// A document read for healing: the tolerant copy of its bytes, its model and its bad numbers.
struct Document {
    bytes: Vec<u8>,
    city: CityModel,
    bad: Vec<BadNumber>,
}

impl Document {
    /// `geographic_ok`: a CRS in degrees is accepted (the write-back of a model adjusted
    /// elsewhere), else refused (heal's tolerances are metres).
    fn read(original: &[u8], geographic_ok: bool) -> Result<Document, HealError> {
        let (bytes, city, bad) = parse_tolerant(original).map_err(|e| HealError::Unreadable(e.to_string()))?;
        if let Some(srs) = city.srs_name.as_ref().filter(|_| !geographic_ok) {
            if let Some(epsg) = crs::geographic_epsg(srs) {
                return Err(HealError::Geographic { srs: srs.clone(), epsg });
            }
        }
        Ok(Document { bytes, city, bad })
    }
}

/// The verification of the units' edits (see [`verify`]) and the report.
fn verified(
    original: &[u8],
    doc: &Document,
    units: &[&CityObject],
    results: Vec<UnitResult>,
    always: Vec<Edit>,
    opts: &HealOptions,
) -> Result<Healed, HealError> {
    let bad = &doc.bad;
    let mut kept: Vec<Option<String>> = results.iter().map(|r| r.as_ref().err().cloned()).collect();
    let mut with_bad_numbers = Vec::new();
    for b in bad {
        // the innermost unit holding the bad number keeps its geometry
        if let Some(i) = (0..units.len())
            .filter(|&i| units[i].span.bytes.contains(&b.byte))
            .max_by_key(|&i| units[i].span.bytes.start)
        {
            kept[i] = Some(format!("non-finite coordinate '{}' at line {}, column {}", b.token, b.line, b.column));
            with_bad_numbers.push(i);
        }
    }
    verify::reject_overlaps(units, &results, &mut kept);
    let all: Vec<usize> = (0..units.len()).collect();
    let mut before = verify::measure_all(units, &all, None, &opts.validation);
    for &i in &with_bad_numbers {
        before[i].area = f64::NAN; // measured on the stand-in numbers: left out of the totals
    }
    let touched_by = verify::touch_map(units, &results);
    let verifier = verify::Verifier {
        original,
        units,
        results: &results,
        always: &always,
        touched_by: &touched_by,
        with_bad_numbers: &with_bad_numbers,
        opts,
    };
    let (document, after, rounds) = verifier.run(&mut kept, &before)?;
    let report = summary(original, units, &results, &kept, &before, &after, rounds);
    let defects = Defects {
        bad_numbers: bad
            .iter()
            .map(|b| format!("{}:{}: non-finite coordinate '{}'", b.line, b.column, b.token))
            .collect(),
        unresolved_xlinks: doc
            .city
            .unresolved_xlinks
            .iter()
            .map(|x| format!("{}:{}: {}", x.span.line, x.span.column, input_limits::quote(&x.reason())))
            .collect(),
    };
    Ok(Healed { document, report, defects })
}

/// Whether a unit's edits change any byte of the document (an edit may write the same text).
fn changes_bytes(original: &[u8], edits: &[Edit]) -> bool {
    edits.iter().any(|e| original.get(e.bytes.clone()).is_none_or(|old| old != e.replacement.as_slice()))
}

/// The report of a verified write-back. "Healed" is honest: the unit's geometry was rewritten
/// (its bytes changed) and its validation findings fell (docs/decisions.md#honest-heal-summaries).
fn summary(
    original: &[u8],
    units: &[&CityObject],
    results: &[UnitResult],
    kept: &[Option<String>],
    before: &[Measures],
    after: &[Measures],
    rounds: usize,
) -> HealReport {
    let mut back = BackReport::default();
    let (mut healed, mut changed) = (0, 0);
    let mut moved_m = std::collections::BTreeMap::new();
    for (i, (r, k)) in results.iter().zip(kept).enumerate() {
        let (Ok((edits, rep)), None) = (r, k) else { continue };
        add_back(&mut back, rep);
        if !changes_bytes(original, edits) {
            continue;
        }
        changed += 1;
        let total = |m: &Measures| m.codes.values().sum::<usize>();
        if total(&after[i]) < total(&before[i]) {
            healed += 1;
        }
        moved_m.insert(unit_name(units[i]), after[i].moved);
    }
    let sum_codes = |m: &[Measures]| {
        let mut t = std::collections::BTreeMap::new();
        for x in m {
            for (c, n) in &x.codes {
                *t.entry(*c).or_insert(0) += n;
            }
        }
        t
    };
    let pairs = || before.iter().zip(after).map(|(b, a)| (b.area, a.area));
    HealReport {
        repairs: Default::default(),
        buildings: units.len(),
        healed,
        changed,
        valid_before: before.iter().filter(|m| m.codes.is_empty()).count(),
        valid_after: after.iter().filter(|m| m.codes.is_empty()).count(),
        kept: units
            .iter()
            .zip(kept)
            .filter_map(|(b, k)| k.as_ref().map(|r| Kept { building: unit_name(b), reason: r.clone() }))
            .collect(),
        area_before_m2: finite_sum(pairs(), |x| x.0),
        area_after_m2: finite_sum(pairs(), |x| x.1),
        max_moved_m: moved_m.values().cloned().fold(0.0, f64::max),
        moved_by_building_m: moved_m,
        findings_before: sum_codes(before),
        findings_after: sum_codes(after),
        rounds,
        back,
    }
}

/// A non-finite coordinate token (NaN, inf) found by [`parse_tolerant`].
struct BadNumber {
    byte: usize,
    line: usize,
    column: usize,
    token: String,
}

/// Parses `bytes`, replacing every non-finite coordinate (which the reader rejects: it cannot be
/// a position) by a finite number of the same length, so one bad number keeps only its building
/// from being healed instead of the whole file. Same length: byte offsets, and so the edits of
/// the other buildings, are those of the original. Returns the parsed copy and the bad numbers.
fn parse_tolerant(bytes: &[u8]) -> Result<(Vec<u8>, CityModel, Vec<BadNumber>), citygml_io::ReadError> {
    let mut copy = bytes.to_vec();
    let mut bad = Vec::new();
    loop {
        match citygml_io::parse(&copy) {
            Ok(city) => return Ok((copy, city, bad)),
            Err(e) if e.message.contains("non-finite coordinate") && bad.len() < 10_000 && e.byte < copy.len() => {
                let len = copy[e.byte..]
                    .iter()
                    .position(|c| c.is_ascii_whitespace() || *c == b'<' || *c == b',')
                    .unwrap_or(copy.len() - e.byte);
                if len == 0 {
                    return Err(e);
                }
                let token = input_limits::quote_bytes(&copy[e.byte..e.byte + len]);
                bad.push(BadNumber { byte: e.byte, line: e.line, column: e.column, token });
                let nines = if copy[e.byte] == b'-' { 1 } else { 0 };
                for c in &mut copy[e.byte + nines..e.byte + len] {
                    *c = b'9';
                }
            }
            Err(e) => return Err(e),
        }
    }
}

/// Sum over the buildings whose area before and after is finite (a building with an absurd
/// coordinate is kept and reported, and must not turn the totals into inf or NaN).
fn finite_sum(pairs: impl Iterator<Item = (f64, f64)>, pick: impl Fn((f64, f64)) -> f64) -> f64 {
    pairs.filter(|p| p.0.is_finite() && p.1.is_finite()).map(pick).sum()
}

fn add_back(t: &mut BackReport, r: &BackReport) {
    t.polygons_mapped += r.polygons_mapped;
    t.removed_degenerate.extend(r.removed_degenerate.iter().cloned());
    t.merged.extend(r.merged.iter().cloned());
    t.removed_surfaces.extend(r.removed_surfaces.iter().cloned());
    t.moved_openings.extend(r.moved_openings.iter().cloned());
    t.mean_move = (t.mean_move * t.vertices_written as f64 + r.mean_move * r.vertices_written as f64)
        / (t.vertices_written + r.vertices_written).max(1) as f64;
    t.vertices_written += r.vertices_written;
    t.max_move = t.max_move.max(r.max_move);
    t.vertices_dropped += r.vertices_dropped;
    t.max_move_by_building.extend(r.max_move_by_building.iter().map(|(k, v)| (k.clone(), *v)));
}
