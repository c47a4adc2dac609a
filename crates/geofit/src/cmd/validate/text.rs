//! The text form of a validation report: one located line per finding (`FILE:LINE:COL: …`),
//! then one verdict line per check, as compilers and val3dity print them.

use std::io::Write;
use std::path::Path;

use citygml_validate::document::Report;
use citygml_validate::xsd::XsdErrorKind;

pub(super) fn write(w: &mut dyn Write, r: &Report) -> std::io::Result<()> {
    let f = &r.file;
    writeln!(w, "{f}: CityGML {}", r.version.as_deref().unwrap_or("(version unknown)"))?;
    if let Some(v) = &r.heights {
        writeln!(w, "{f}: heights: {v}")?;
    }
    if let Some(frame) = &r.geometry.frame {
        writeln!(w, "{f}: frame: {frame}")?;
    }
    let schema_name = r
        .xsd
        .schema
        .as_deref()
        .map(|s| Path::new(s).file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default());
    if r.xsd.checked {
        let sn = schema_name.unwrap_or_default();
        if r.xsd.errors.is_empty() {
            writeln!(w, "{f}: XSD ({sn}): valid")?;
        } else {
            for e in &r.xsd.errors {
                let what = if e.kind == XsdErrorKind::NotWellFormed { "not well-formed" } else { "XSD" };
                writeln!(w, "{f}:{}:{}: {what}: {}", e.line, e.column, e.message)?;
            }
            writeln!(
                w,
                "{f}: XSD ({sn}): {} error{}",
                r.xsd.errors.len(),
                if r.xsd.errors.len() == 1 { "" } else { "s" }
            )?;
        }
    } else {
        writeln!(w, "{f}: XSD: not checked ({})", r.xsd.reason.as_deref().unwrap_or(""))?;
    }
    let g = &r.geometry;
    if g.checked {
        for x in &g.findings {
            let mut ids = String::new();
            if let Some(id) = &x.feature {
                ids.push_str(&format!(" feature={id}"));
            } else {
                ids.push_str(&format!(" feature=({})", x.feature_type));
            }
            if let Some(p) = &x.primitive {
                ids.push_str(&format!(" primitive={p}"));
            }
            writeln!(w, "{f}:{}:{}: {} {}{} [{}]: {}", x.line, x.column, x.code, x.name, ids, x.geometry, x.detail)?;
        }
        let o = &g.options;
        let n = g.findings.len();
        writeln!(
            w,
            "{f}: geometry: {} in {} feature{} (snap {} m, planarity {} m, normals {}°)",
            if n == 0 { "valid".to_string() } else { format!("{n} error{}", if n == 1 { "" } else { "s" }) },
            g.features,
            if g.features == 1 { "" } else { "s" },
            o.snap_tol,
            o.planarity_tol,
            o.normals_tol_deg
        )?;
    } else {
        writeln!(w, "{f}: geometry: not checked (--no-geometry)")?;
    }
    writeln!(w, "{f}: {}", if r.valid { "VALID" } else { "INVALID" })
}
