//! JSON reports: every report a command writes carries a `schema` key naming what it is and its
//! version (`geofit-fit-report/1`), and a `units` object giving the unit of each quantity by its
//! key (a dotted path for nested keys, `[]` for every element of an array), so a script reading a
//! report months later knows what a number means (docs/decisions.md#report-schema-and-units).
//!
//! Heights of terrain inputs are in the unit of the input's z values, which a raster rarely
//! declares: their unit reads `"z unit of the input"`, or the unit given with `--z-unit`.

use std::io::Write;

use serde::ser::{Serialize, SerializeMap, Serializer};

use crate::config::Output;
use crate::error::CliError;

/// A report's schema name and the units of its quantities.
#[derive(Debug, Clone, Copy)]
pub struct ReportKind {
    /// `geofit-<command>-report/<version>`; the version changes when a key changes meaning.
    pub schema: &'static str,
    /// (key, unit) pairs; keys name fields of the report (dotted paths, `[]` for arrays).
    pub units: &'static [(&'static str, &'static str)],
}

/// The unit of heights read from a raster or point file that does not declare one.
pub const Z_UNIT: &str = "z unit of the input";

/// A report with its schema and units in front (what every JSON report and JSON line holds).
#[derive(serde::Serialize)]
pub struct Tagged<'a, T: Serialize> {
    schema: &'static str,
    units: Units<'a>,
    #[serde(flatten)]
    body: &'a T,
}

pub struct Units<'a>(&'a [(&'a str, &'a str)]);

impl Serialize for Units<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut m = s.serialize_map(Some(self.0.len()))?;
        for (k, v) in self.0 {
            m.serialize_entry(k, v)?;
        }
        m.end()
    }
}

/// `report` with `kind`'s schema and `units` in front, for a JSON line.
pub fn tagged<'a, T: Serialize>(kind: &ReportKind, units: &'a [(&'a str, &'a str)], report: &'a T) -> Tagged<'a, T> {
    Tagged { schema: kind.schema, units: Units(units), body: report }
}

/// Writes the report of `kind` to `path` atomically (`--report PATH`), or to stdout for `-`.
pub fn write_json_report<T: Serialize>(path: &str, kind: &ReportKind, report: &T) -> Result<(), CliError> {
    write_tagged(path, kind.schema, kind.units, report)
}

/// [`write_json_report`] with units known only at run time (a `--z-unit` option).
pub fn write_json_report_with_units<T: Serialize>(
    path: &str,
    kind: &ReportKind,
    units: &[(&str, &str)],
    report: &T,
) -> Result<(), CliError> {
    write_tagged(path, kind.schema, units, report)
}

fn write_tagged<T: Serialize>(
    path: &str,
    schema: &'static str,
    units: &[(&str, &str)],
    report: &T,
) -> Result<(), CliError> {
    Output::from_arg(Some(path)).write_with(|w| write_json(w, &Tagged { schema, units: Units(units), body: report }))
}

/// The report of a report-only command on stdout: as JSON of `kind` with `--json`, else as the
/// text `text` writes.
pub fn print_report<T: Serialize>(
    json: bool,
    kind: &ReportKind,
    report: &T,
    text: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<(), CliError> {
    print_report_with_units(json, kind, kind.units, report, text)
}

/// [`print_report`] with units known only at run time.
pub fn print_report_with_units<T: Serialize>(
    json: bool,
    kind: &ReportKind,
    units: &[(&str, &str)],
    report: &T,
    text: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<(), CliError> {
    Output::Stdout.write_with(|w| {
        if json {
            write_json(w, &Tagged { schema: kind.schema, units: Units(units), body: report })
        } else {
            text(w).map_err(CliError::io_out)
        }
    })
}

fn write_json<T: Serialize>(w: &mut dyn Write, report: &T) -> Result<(), CliError> {
    serde_json::to_writer_pretty(&mut *w, report).map_err(|e| CliError::internal(e.to_string()))?;
    w.write_all(b"\n").map_err(CliError::io_out)
}

/// `units` with every `Z_UNIT` replaced by `z_unit` (for commands with `--z-unit`).
pub fn with_z_unit<'a>(units: &'a [(&'a str, &'a str)], z_unit: &'a str) -> Vec<(&'a str, &'a str)> {
    units.iter().map(|&(k, u)| (k, if u == Z_UNIT { z_unit } else { u })).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(serde::Serialize)]
    struct R {
        max: f64,
        inner: Inner,
    }
    #[derive(serde::Serialize)]
    struct Inner {
        area: f64,
    }

    #[test]
    fn schema_and_units_come_first_and_the_fields_stay() {
        let units = [("max", "m"), ("inner.area", "m2")];
        let t = Tagged {
            schema: "geofit-x-report/1",
            units: Units(&units),
            body: &R { max: 1.5, inner: Inner { area: 2.0 } },
        };
        let s = serde_json::to_string(&t).unwrap();
        assert_eq!(
            s,
            r#"{"schema":"geofit-x-report/1","units":{"max":"m","inner.area":"m2"},"max":1.5,"inner":{"area":2.0}}"#
        );
    }

    #[test]
    fn the_z_unit_replaces_only_the_placeholder() {
        let u = with_z_unit(&[("a", Z_UNIT), ("t", "s")], "ft");
        assert_eq!(u, [("a", "ft"), ("t", "s")]);
    }
}
