//! The verification every write-back goes through, `heal`'s and `popa3d2citygml`'s alike: the
//! edits of every building are applied, the document is read back, and every building is
//! validated and measured again (new validation codes, area, Hausdorff move); a building the
//! guard rejects keeps its original geometry, as do the buildings whose edits reach it
//! (docs/decisions.md#one-verifier-for-every-write-back).

use crate::{measure, parse_tolerant, HealError, HealOptions};
use citygml_io::{CityObject, Edit};
use measure::Measures;
use normalize::citygml::unit_name;
use normalize::to_citygml::BackReport;
use rayon::prelude::*;

/// The edits of one unit and what its write-back did, or why it is left as it is.
pub type UnitResult = Result<(Vec<Edit>, BackReport), String>;

/// Measures units `which` of `units` (after a write-back: with the Hausdorff distance to the
/// same unit of `before_units`).
pub(crate) fn measure_all(
    units: &[&CityObject],
    which: &[usize],
    before_units: Option<&[&CityObject]>,
    opts: &citygml_validate::Options,
) -> Vec<Measures> {
    which
        .par_iter()
        .map(|&i| {
            let objects = normalize::citygml::own_objects(units[i]);
            let mut m = measure::measure(&objects, opts);
            if let Some(b) = before_units {
                let before = measure::surface(&normalize::citygml::own_objects(b[i]));
                m.moved = crate::hausdorff::hausdorff(&before, &measure::surface(&objects));
            }
            m
        })
        .collect()
}

/// The verify-after-write loop of [`heal`]: apply the edits of the buildings not kept, read the
/// document back, measure what can have changed, keep every building the guard rejects (and the
/// buildings whose edits reach it); repeat until a round keeps nothing new.
pub(crate) struct Verifier<'a> {
    pub original: &'a [u8],
    pub units: &'a [&'a CityObject],
    pub results: &'a [UnitResult],
    /// Edits outside every unit, applied whatever is kept.
    pub always: &'a [Edit],
    pub touched_by: &'a [std::collections::BTreeSet<usize>],
    pub with_bad_numbers: &'a [usize],
    pub opts: &'a HealOptions,
}

impl Verifier<'_> {
    /// The written document, the measures after, and the number of rounds.
    pub fn run(
        &self,
        kept: &mut [Option<String>],
        before: &[Measures],
    ) -> Result<(Vec<u8>, Vec<Measures>, usize), HealError> {
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
        let (original, units, results, touched_by, opts) =
            (self.original, self.units, self.results, self.touched_by, self.opts);
        let mut edits: Vec<Edit> = results
            .iter()
            .zip(kept)
            .filter(|(_, k)| k.is_none())
            .flat_map(|(r, _)| r.as_ref().map(|x| x.0.clone()).unwrap_or_default())
            .collect();
        edits.extend(self.always.iter().cloned());
        // the edits go into the original bytes (the tolerant copy differs only inside bad numbers)
        let mut doc = Vec::with_capacity(original.len());
        citygml_io::write_with_edits(original, &edits, &mut doc).map_err(|e| HealError::Internal(e.to_string()))?;
        let (_, city2, _) = parse_tolerant(&doc)
            .map_err(|e| HealError::Internal(format!("the healed document cannot be read back: {e}")))?;
        let units2 = crate::units(&city2);
        if units2.len() != units.len() || units2.iter().zip(units).any(|(a, b)| a.id != b.id) {
            return Err(HealError::Internal("the healed document does not hold the same buildings".into()));
        }
        // Only what the applied edits can have changed is measured again: a building being
        // healed, or one that another healed building's edits reach.
        let changed: Vec<usize> = (0..units.len())
            .filter(|&i| kept[i].is_none() || touched_by[i].iter().any(|&j| kept[j].is_none()))
            .collect();
        let mut after = before.to_vec();
        for (i, m) in changed.iter().zip(measure_all(&units2, &changed, Some(units), &opts.validation)) {
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
                kept[j] = Some(format!(
                    "its write-back changes {} too, which would then get worse: {why}",
                    unit_name(self.units[i])
                ));
            }
        }
        failed
    }
}

/// Why a healed building must keep its original geometry, if it must.
pub(crate) fn guard(before: &Measures, after: &Measures, opts: &HealOptions) -> Option<String> {
    let new = measure::new_findings(before, after);
    if !new.is_empty() {
        return Some(format!("the new geometry would add validation findings ({})", new.join(", ")));
    }
    if after.moved > opts.max_move {
        return Some(format!(
            "an input vertex would end {:.3} m from the healed surface, or a healed vertex that far from the input (Hausdorff distance; limit --max-move {} m)",
            after.moved, opts.max_move
        ));
    }
    if before.area > 0.0 && before.area.is_finite() {
        let change = after.area / before.area - 1.0;
        if change.abs().partial_cmp(&opts.max_area_change) != Some(std::cmp::Ordering::Less) {
            return Some(format!(
                "the new geometry would change its surface area by {:+.2} % ({:.2} → {:.2} m², limit ±{} %)",
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
pub(crate) fn touch_map(units: &[&CityObject], results: &[UnitResult]) -> Vec<std::collections::BTreeSet<usize>> {
    let mut fp: Vec<(std::ops::Range<usize>, usize)> =
        units.iter().enumerate().flat_map(|(i, b)| footprint(b).into_iter().map(move |r| (r, i))).collect();
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
pub(crate) fn reject_overlaps(units: &[&CityObject], results: &[UnitResult], kept: &mut [Option<String>]) {
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
                let (a, b) = (unit_name(units[u]), unit_name(units[owner]));
                kept[u] = Some(if a == b {
                    // two buildings with one gml:id: their polygon ids are ambiguous too
                    format!("duplicate gml:id {a}: another building has the same id and is healed instead")
                } else {
                    format!("its geometry is shared with {b} (XLink), which is healed instead")
                });
                continue;
            }
        }
        if reach.is_none_or(|(end, _)| e > end) {
            reach = Some((e, u));
        }
    }
}
