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
pub mod measure;
pub mod repair;
mod unit;

use citygml_io::{CityModel, CityObject, Edit};
use measure::Measures;
use normalize::conditions::ConditionOptions;
use normalize::citygml::unit_name;
use normalize::to_citygml::{BackOptions, BackReport, Template};
use rayon::prelude::*;
use serde::Serialize;
use std::sync::atomic::{AtomicUsize, Ordering};

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
            conditions: ConditionOptions { parallel_deg: 0.0, orthogonal_deg: 0.0, epsilon: 0.0, ..ConditionOptions::default() },
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
    pub healed: usize,
    /// Buildings that keep their original geometry, with the reason.
    pub kept: Vec<Kept>,
    /// Surface area of all buildings before and after (m²; buildings whose area is not finite
    /// are left out of both).
    pub area_before_m2: f64,
    pub area_after_m2: f64,
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

fn measure_all(units: &[&CityObject], which: &[usize], opts: &citygml_validate::Options) -> Vec<Measures> {
    which.par_iter().map(|&i| measure::measure(&normalize::citygml::own_objects(units[i]), opts)).collect()
}

/// Heals every building of a CityGML document (see the crate documentation). `progress` is
/// called with the number of buildings adjusted so far.
pub fn heal(original: &[u8], opts: &HealOptions, progress: &(dyn Fn(usize) + Sync)) -> Result<Healed, HealError> {
    let (bytes, city, bad) = parse_tolerant(original).map_err(|e| HealError::Unreadable(e.to_string()))?;
    let bytes = bytes.as_slice();
    if let Some(srs) = &city.srs_name {
        if let Some(epsg) = crs::geographic_epsg(srs) {
            return Err(HealError::Geographic { srs: srs.clone(), epsg });
        }
    }
    let units = units(&city);
    if units.is_empty() {
        return Err(HealError::NoBuildings);
    }
    let template = Template::new(bytes, &city);
    let done = AtomicUsize::new(0);
    let (results, records): (Vec<Result<(Vec<Edit>, BackReport), String>>, Vec<_>) = units
        .par_iter()
        .map(|b| {
            let r = unit::heal_or_repair(b, bytes, &template, opts);
            progress(done.fetch_add(1, Ordering::Relaxed) + 1);
            r
        })
        .unzip();
    let mut kept: Vec<Option<String>> = results.iter().map(|r| r.as_ref().err().cloned()).collect();
    let mut with_bad_numbers = Vec::new();
    for b in &bad {
        // the innermost unit holding the bad number keeps its geometry
        if let Some(i) = (0..units.len()).filter(|&i| units[i].span.bytes.contains(&b.byte)).max_by_key(|&i| units[i].span.bytes.start) {
            kept[i] = Some(format!("non-finite coordinate '{}' at line {}, column {}", b.token, b.line, b.column));
            with_bad_numbers.push(i);
        }
    }
    reject_overlaps(&units, &results, &mut kept);
    let all: Vec<usize> = (0..units.len()).collect();
    let mut before = measure_all(&units, &all, &opts.validation);
    for &i in &with_bad_numbers {
        before[i].area = f64::NAN; // measured on the stand-in numbers: left out of the totals
    }
    let touched_by = touch_map(&units, &results);
    let verifier = Verifier { original, units: &units, results: &results, touched_by: &touched_by, with_bad_numbers: &with_bad_numbers, opts };
    let (document, after, rounds) = verifier.run(&mut kept, &before)?;
    let mut back = BackReport::default();
    for (r, k) in results.iter().zip(&kept) {
        if let (Ok((_, rep)), None) = (r, k) {
            add_back(&mut back, rep);
        }
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
    let mut report = HealReport {
        repairs: Default::default(),
        buildings: units.len(),
        healed: kept.iter().filter(|k| k.is_none()).count(),
        kept: units.iter().zip(&kept).filter_map(|(b, k)| k.as_ref().map(|r| Kept { building: unit_name(b), reason: r.clone() })).collect(),
        area_before_m2: finite_sum(before.iter().zip(&after).map(|(b, a)| (b.area, a.area)), |x| x.0),
        area_after_m2: finite_sum(before.iter().zip(&after).map(|(b, a)| (b.area, a.area)), |x| x.1),
        findings_before: sum_codes(&before),
        findings_after: sum_codes(&after),
        rounds,
        back,
    };
    report.repairs = repair::records(&units, records, &report.kept);
    let defects = Defects {
        bad_numbers: bad.iter().map(|b| format!("{}:{}: non-finite coordinate '{}'", b.line, b.column, b.token)).collect(),
        unresolved_xlinks: city.unresolved_xlinks.iter().map(|x| format!("{}:{}: {}", x.span.line, x.span.column, input_limits::quote(&x.reason()))).collect(),
    };
    Ok(Healed { document, report, defects })
}

/// The verify-after-write loop of [`heal`]: apply the edits of the buildings not kept, read the
/// document back, measure what can have changed, keep every building the guard rejects (and the
/// buildings whose edits reach it); repeat until a round keeps nothing new.
struct Verifier<'a> {
    original: &'a [u8],
    units: &'a [&'a CityObject],
    results: &'a [Result<(Vec<Edit>, BackReport), String>],
    touched_by: &'a [std::collections::BTreeSet<usize>],
    with_bad_numbers: &'a [usize],
    opts: &'a HealOptions,
}

impl Verifier<'_> {
    /// The written document, the measures after, and the number of rounds.
    fn run(&self, kept: &mut [Option<String>], before: &[Measures]) -> Result<(Vec<u8>, Vec<Measures>, usize), HealError> {
        for rounds in 1.. {
            let (doc, after) = self.round(kept, before)?;
            if !self.keep_the_worse(kept, before, &after) {
                return Ok((doc, after, rounds));
            }
        }
        unreachable!("every round that does not end keeps one more building")
    }

    /// Applies the edits of the buildings not kept and measures what they can have changed.
    fn round(&self, kept: &[Option<String>], before: &[Measures]) -> Result<(Vec<u8>, Vec<Measures>), HealError> {
        let (original, units, results, touched_by, opts) = (self.original, self.units, self.results, self.touched_by, self.opts);
        let edits: Vec<Edit> = results.iter().zip(kept).filter(|(_, k)| k.is_none()).flat_map(|(r, _)| r.as_ref().map(|x| x.0.clone()).unwrap_or_default()).collect();
        // the edits go into the original bytes (the tolerant copy differs only inside bad numbers)
        let mut doc = Vec::with_capacity(original.len());
        citygml_io::write_with_edits(original, &edits, &mut doc).map_err(|e| HealError::Internal(e.to_string()))?;
        let (_, city2, _) = parse_tolerant(&doc).map_err(|e| HealError::Internal(format!("the healed document cannot be read back: {e}")))?;
        let units2 = self::units(&city2);
        if units2.len() != units.len() || units2.iter().zip(units).any(|(a, b)| a.id != b.id) {
            return Err(HealError::Internal("the healed document does not hold the same buildings".into()));
        }
        // Only what the applied edits can have changed is measured again: a building being
        // healed, or one that another healed building's edits reach.
        let changed: Vec<usize> = (0..units.len()).filter(|&i| kept[i].is_none() || touched_by[i].iter().any(|&j| kept[j].is_none())).collect();
        let mut after = before.to_vec();
        for (i, m) in changed.iter().zip(measure_all(&units2, &changed, &opts.validation)) {
            after[*i] = m;
        }
        for &i in self.with_bad_numbers {
            after[i].area = f64::NAN;
        }
        Ok((doc, after))
    }

    /// Keeps every building the guard rejects, and the buildings whose edits reach it. Returns
    /// whether anything was kept (then another round is needed).
    fn keep_the_worse(&self, kept: &mut [Option<String>], before: &[Measures], after: &[Measures]) -> bool {
        let mut failed = false;
        for i in 0..self.units.len() {
            let touching: Vec<usize> = self.touched_by[i].iter().copied().filter(|&j| kept[j].is_none()).collect();
            if kept[i].is_some() && touching.is_empty() {
                continue; // left as it was, and no other building's edit reaches it
            }
            let Some(why) = guard(&before[i], &after[i], self.opts) else { continue };
            failed = true;
            if kept[i].is_none() {
                kept[i] = Some(why.clone());
            }
            for j in touching {
                kept[j] = Some(format!("its write-back changes {} too, which would then get worse: {why}", unit_name(self.units[i])));
            }
        }
        failed
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
                let len = copy[e.byte..].iter().position(|c| c.is_ascii_whitespace() || *c == b'<' || *c == b',').unwrap_or(copy.len() - e.byte);
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

/// Why a healed building must keep its original geometry, if it must.
fn guard(before: &Measures, after: &Measures, opts: &HealOptions) -> Option<String> {
    let new = measure::new_findings(before, after);
    if !new.is_empty() {
        return Some(format!("healing would add validation findings ({})", new.join(", ")));
    }
    if before.area > 0.0 && before.area.is_finite() {
        let change = after.area / before.area - 1.0;
        if change.abs().partial_cmp(&opts.max_area_change) != Some(std::cmp::Ordering::Less) {
            return Some(format!(
                "healing would change its surface area by {:+.2} % ({:.2} → {:.2} m², limit ±{} %)",
                100.0 * change,
                before.area,
                after.area,
                100.0 * opts.max_area_change
            ));
        }
    }
    None
}

/// The bytes a unit's geometry is read from: its element and every polygon its geometries hold
/// (polygons reached by XLink are defined elsewhere).
fn footprint(b: &CityObject) -> Vec<std::ops::Range<usize>> {
    let mut v = vec![b.span.bytes.clone()];
    for o in normalize::citygml::own_objects(b) {
        for g in &o.geometries {
            v.extend(g.polygons().into_iter().map(|p| p.span.bytes.clone()));
        }
    }
    v
}

/// For every unit, the other units whose edits touch its footprint (an XLink'd polygon, a
/// nested part). Footprints sorted by start and searched in a window as long as the longest
/// one, so the map costs about (edits × polygons near each edit), not units².
fn touch_map(units: &[&CityObject], results: &[Result<(Vec<Edit>, BackReport), String>]) -> Vec<std::collections::BTreeSet<usize>> {
    let mut fp: Vec<(std::ops::Range<usize>, usize)> = units.iter().enumerate().flat_map(|(i, b)| footprint(b).into_iter().map(move |r| (r, i))).collect();
    fp.sort_by_key(|f| (f.0.start, f.0.end));
    let longest = fp.iter().map(|f| f.0.len()).max().unwrap_or(0);
    let mut out = vec![std::collections::BTreeSet::new(); units.len()];
    for (j, r) in results.iter().enumerate() {
        let Ok((edits, _)) = r else { continue };
        for e in edits {
            let from = fp.partition_point(|f| f.0.start < e.bytes.start.saturating_sub(longest));
            for (f, i) in fp[from..].iter().take_while(|f| f.0.start <= e.bytes.end) {
                if *i != j && touches(&e.bytes, f) {
                    out[*i].insert(j);
                }
            }
        }
    }
    out
}

/// Does an edit (a replaced range, or an insertion point when empty) touch the range `f`?
fn touches(e: &std::ops::Range<usize>, f: &std::ops::Range<usize>) -> bool {
    if e.is_empty() {
        f.start <= e.start && e.start < f.end
    } else {
        e.start < f.end && f.start < e.end
    }
}

/// Two buildings whose edits touch the same bytes (a polygon shared through an XLink and mapped
/// by both): the later one keeps its geometry.
fn reject_overlaps(units: &[&CityObject], results: &[Result<(Vec<Edit>, BackReport), String>], kept: &mut [Option<String>]) {
    let mut spans: Vec<(usize, usize, usize)> = Vec::new();
    for (u, r) in results.iter().enumerate() {
        if let Ok((edits, _)) = r {
            spans.extend(edits.iter().filter(|e| !e.bytes.is_empty()).map(|e| (e.bytes.start, e.bytes.end, u)));
        }
    }
    spans.sort();
    let mut reach: Option<(usize, usize)> = None;
    for (s, e, u) in spans {
        if let Some((end, owner)) = reach {
            if s < end && owner != u && kept[u].is_none() && kept[owner].is_none() {
                kept[u] = Some(format!("its geometry is shared with {} (XLink), which is healed instead", unit_name(units[owner])));
                continue;
            }
        }
        if reach.is_none_or(|(end, _)| e > end) {
            reach = Some((e, u));
        }
    }
}

fn add_back(t: &mut BackReport, r: &BackReport) {
    t.polygons_mapped += r.polygons_mapped;
    t.removed_degenerate.extend(r.removed_degenerate.iter().cloned());
    t.merged.extend(r.merged.iter().cloned());
    t.removed_surfaces.extend(r.removed_surfaces.iter().cloned());
    t.moved_openings.extend(r.moved_openings.iter().cloned());
    t.mean_move = (t.mean_move * t.vertices_written as f64 + r.mean_move * r.vertices_written as f64) / (t.vertices_written + r.vertices_written).max(1) as f64;
    t.vertices_written += r.vertices_written;
    t.max_move = t.max_move.max(r.max_move);
    t.vertices_dropped += r.vertices_dropped;
    t.max_move_by_building.extend(r.max_move_by_building.iter().map(|(k, v)| (k.clone(), *v)));
}
