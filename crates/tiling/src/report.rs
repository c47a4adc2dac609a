//! The merge step for buildings: per-tile `geofit validate --json` and `geofit heal --report`
//! outputs summed into one report. Counts and areas are sums over tiles; the largest vertex move
//! is the maximum; kept buildings are listed with their tile and reason.

use std::collections::BTreeMap;

use serde::Serialize;
use serde_json::Value;

use crate::TilingError;

/// One per-tile report as read: its tile id (file name up to the first `.`) and JSON.
pub struct TileReport {
    pub tile: String,
    pub json: Value,
}

impl TileReport {
    /// Reads the report `text` of file `path`.
    pub fn parse(path: &str, text: &str) -> Result<TileReport, TilingError> {
        let json: Value =
            serde_json::from_str(text).map_err(|e| TilingError::unreadable(path, format!("not JSON: {e}")))?;
        let file = std::path::Path::new(path).file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default();
        let tile = file.split('.').next().unwrap_or_default().to_string();
        if tile.is_empty() {
            return Err(TilingError::Usage(format!(
                "{path}: no tile id in the file name (expected <tile>.<anything>.json)"
            )));
        }
        Ok(TileReport { tile, json })
    }

    fn is_heal(&self) -> bool {
        self.json.get("schema").and_then(Value::as_str).is_some_and(|s| s.starts_with("geofit-heal-report/"))
    }

    fn is_validate(&self) -> bool {
        self.json.get("geometry").is_some() && self.json.get("xsd").is_some()
    }
}

#[derive(Debug, Default, Serialize, PartialEq)]
pub struct ValidateSum {
    pub reports: usize,
    pub valid: usize,
    pub features: u64,
    pub xsd_errors: u64,
    pub findings: u64,
    pub findings_by_code: BTreeMap<String, u64>,
}

#[derive(Debug, Serialize, PartialEq)]
pub struct KeptBuilding {
    pub tile: String,
    pub building: String,
    pub reason: String,
}

#[derive(Debug, Default, Serialize, PartialEq)]
pub struct HealSum {
    pub reports: usize,
    pub buildings: u64,
    pub healed: u64,
    pub kept: Vec<KeptBuilding>,
    pub area_before_m2: f64,
    pub area_after_m2: f64,
    pub findings_before: BTreeMap<String, u64>,
    pub findings_after: BTreeMap<String, u64>,
    pub max_move_m: f64,
    pub vertices_written: u64,
}

#[derive(Debug, Serialize, PartialEq)]
pub struct TileLine {
    pub tile: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub validate_findings: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub buildings: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub healed: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kept: Option<usize>,
}

/// The units of the merged report's measures; the other numbers are counts.
const UNITS: &[(&str, &str)] = &[("heal.area_before_m2", "m²"), ("heal.area_after_m2", "m²"), ("heal.max_move_m", "m")];

/// The merged report.
#[derive(Debug, Serialize, PartialEq)]
pub struct MergedReport {
    pub schema: &'static str,
    /// The unit of each measure (key → unit), as every geofit report states them.
    pub units: BTreeMap<&'static str, &'static str>,
    pub tiles: usize,
    pub validate: ValidateSum,
    pub heal: HealSum,
    pub per_tile: Vec<TileLine>,
}

fn count(v: &Value, key: &str) -> u64 {
    v.get(key).and_then(Value::as_u64).unwrap_or(0)
}

fn add_codes(into: &mut BTreeMap<String, u64>, codes: Option<&Value>) {
    for (k, n) in codes.and_then(Value::as_object).into_iter().flatten() {
        *into.entry(k.clone()).or_default() += n.as_u64().unwrap_or(0);
    }
}

/// Merges the reports; they are taken in tile-id order (then file order), so the float sums do
/// not depend on the order the engine finished the jobs in.
pub fn merge(mut reports: Vec<TileReport>) -> Result<MergedReport, TilingError> {
    reports.sort_by(|a, b| a.tile.cmp(&b.tile));
    let (mut v, mut h) = (ValidateSum::default(), HealSum::default());
    let mut lines: BTreeMap<String, TileLine> = BTreeMap::new();
    for r in &reports {
        let line = lines.entry(r.tile.clone()).or_insert_with(|| TileLine {
            tile: r.tile.clone(),
            validate_findings: None,
            buildings: None,
            healed: None,
            kept: None,
        });
        if r.is_heal() {
            let j = &r.json;
            h.reports += 1;
            h.buildings += count(j, "buildings");
            h.healed += count(j, "healed");
            let kept = j.get("kept").and_then(Value::as_array).cloned().unwrap_or_default();
            for k in &kept {
                let s = |key| k.get(key).and_then(Value::as_str).unwrap_or_default().to_string();
                h.kept.push(KeptBuilding { tile: r.tile.clone(), building: s("building"), reason: s("reason") });
            }
            h.area_before_m2 += j.get("area_before_m2").and_then(Value::as_f64).unwrap_or(0.0);
            h.area_after_m2 += j.get("area_after_m2").and_then(Value::as_f64).unwrap_or(0.0);
            add_codes(&mut h.findings_before, j.get("findings_before"));
            add_codes(&mut h.findings_after, j.get("findings_after"));
            let back = j.get("back");
            h.max_move_m =
                h.max_move_m.max(back.and_then(|b| b.get("max_move")).and_then(Value::as_f64).unwrap_or(0.0));
            h.vertices_written += back.map(|b| count(b, "vertices_written")).unwrap_or(0);
            line.buildings = Some(line.buildings.unwrap_or(0) + count(j, "buildings"));
            line.healed = Some(line.healed.unwrap_or(0) + count(j, "healed"));
            line.kept = Some(line.kept.unwrap_or(0) + kept.len());
        } else if r.is_validate() {
            let j = &r.json;
            v.reports += 1;
            v.valid += usize::from(j.get("valid").and_then(Value::as_bool) == Some(true));
            let g = &j["geometry"];
            v.features += count(g, "features");
            v.xsd_errors += j["xsd"].get("errors").and_then(Value::as_array).map_or(0, |e| e.len() as u64);
            let findings = g.get("findings").and_then(Value::as_array).cloned().unwrap_or_default();
            for f in &findings {
                let code = f.get("code").and_then(Value::as_u64).map(|c| c.to_string()).unwrap_or_else(|| "?".into());
                *v.findings_by_code.entry(code).or_default() += 1;
            }
            v.findings += findings.len() as u64;
            line.validate_findings = Some(line.validate_findings.unwrap_or(0) + findings.len() as u64);
        } else {
            return Err(TilingError::Usage(format!(
                "tile {}: a report that is neither `geofit heal --report` nor `geofit validate --json` output",
                r.tile
            )));
        }
    }
    Ok(MergedReport {
        schema: "geofit-tile-report/1",
        units: UNITS.iter().copied().collect(),
        tiles: lines.len(),
        validate: v,
        heal: h,
        per_tile: lines.into_values().collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sums_counts_codes_and_kept() {
        let heal = |b: u64, kept: &str| {
            format!(
                r#"{{"schema":"geofit-heal-report/1","buildings":{b},"healed":{},"kept":[{kept}],"area_before_m2":1.5,"area_after_m2":1.25,"findings_before":{{"203":2}},"findings_after":{{}},"back":{{"max_move":0.01,"vertices_written":7}}}}"#,
                b - 1
            )
        };
        let val = r#"{"file":"t","valid":false,"xsd":{"checked":false,"errors":[]},"geometry":{"features":3,"findings":[{"code":203},{"code":104}]}}"#;
        let reports = vec![
            TileReport::parse("out/x1_y0.heal.json", &heal(3, r#"{"building":"b","reason":"r"}"#)).unwrap(),
            TileReport::parse("out/x0_y0.heal.json", &heal(2, r#"{"building":"a","reason":"q"}"#)).unwrap(),
            TileReport::parse("out/x0_y0.validate.json", val).unwrap(),
        ];
        let m = merge(reports).unwrap();
        assert_eq!(m.tiles, 2);
        assert_eq!((m.heal.buildings, m.heal.healed, m.heal.vertices_written), (5, 3, 14));
        assert_eq!(m.heal.kept[0].tile, "x0_y0");
        assert_eq!(m.heal.findings_before["203"], 4);
        assert_eq!(m.validate.findings_by_code["104"], 1);
        assert_eq!(m.heal.area_before_m2, 3.0);
        assert_eq!(m.units["heal.area_before_m2"], "m²", "the units are stated");
        assert!(merge(vec![TileReport::parse("x.json", "{}").unwrap()]).is_err());
    }
}
