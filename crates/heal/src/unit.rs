//! One building through the popa3d pipe on its own: polygons → plane model about the building's
//! own reference point → generated conditions → adjustment → edits for the document.

use crate::{measure, HealOptions};
use adjust::popa3d::{adjust_model, DatumChoice, ModelOptions};
use citygml_io::{CityObject, Edit};
use normalize::conditions::{self, Ranges};
use normalize::to_citygml::{back_edits, BackReport, Template};
use popa3d_model::Popa3d;

/// The adjustment as heal runs it: soft datum (the generated identity observations keep every
/// plane near its measured place), no statistics (nothing is tested, only made planar).
fn model_options() -> ModelOptions {
    let mut mo = ModelOptions { datum: DatumChoice::Soft, ..ModelOptions::default() };
    mo.engine.statistics = false;
    mo.engine.unknown_sigmas = false;
    mo
}

/// The edits that heal one building, or why it is left as it is.
pub fn heal_unit(b: &CityObject, tpl: &Template, opts: &HealOptions) -> Result<(Vec<Edit>, BackReport), String> {
    let objects = normalize::citygml::own_objects(b);
    let origin = measure::reference_point(&objects)?;
    let mut m = Popa3d::new(origin);
    let soup = normalize::citygml::building_soup(b, opts.lod).map_err(|r| r.to_string())?;
    normalize::normalize_into(&mut m, &soup, &opts.tolerances).map_err(|r| r.to_string())?;
    let all = Ranges::whole(&m);
    conditions::semantic(&mut m, &all, &opts.conditions);
    adjust_model(&mut m, &model_options()).map_err(|e| format!("adjustment: {e}"))?;
    let (edits, report) = back_edits(&m, tpl, &opts.back).map_err(|e| e.to_string())?;
    if report.max_move > opts.max_move {
        return Err(format!("a vertex would move {:.3} m (more than --max-move {} m)", report.max_move, opts.max_move));
    }
    Ok((edits, report))
}

/// One building healed: the repairs beyond planarity first where it has findings they act on
/// (`crate::repair`), else (or when they are refused) the planarity heal. The record says what
/// the repairs did, for buildings with such findings.
pub fn heal_or_repair(
    b: &CityObject,
    doc: &[u8],
    tpl: &Template,
    opts: &HealOptions,
) -> (Result<(Vec<Edit>, BackReport), String>, Option<crate::repair::RepairRecord>) {
    let ro = crate::repair::RepairOptions {
        validation: opts.validation,
        max_move: opts.max_move,
        max_area_change: opts.max_area_change,
    };
    let (edits, record) = crate::repair::repair_unit(b, doc, &ro);
    if let Some(edits) = edits {
        // the repairs replace the planarity heal for this building: both rewrite its rings
        // (docs/decisions.md#issue-35-repairs-verified-before-writing-instead-of-the-planarity-heal)
        return (Ok((edits, BackReport::default())), record);
    }
    (heal_unit(b, tpl, opts), record)
}
