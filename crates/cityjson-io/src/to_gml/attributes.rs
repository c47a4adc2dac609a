//! CityJSON attributes → CityGML 2.0 properties: the CityGML-defined ones by name (`name`,
//! `creationDate`, the building's `measuredHeight`, ...), every other one as a typed generic
//! attribute (docs/decisions.md#cityjson-attributes).

use std::fmt::Write;

use serde_json::{Map, Value};

use crate::report::Report;
use crate::xml::escape;

/// Building-module properties of `_AbstractBuilding` in schema order.
pub const BUILDING_PROPERTIES: &[&str] = &[
    "class",
    "function",
    "usage",
    "yearOfConstruction",
    "yearOfDemolition",
    "roofType",
    "measuredHeight",
    "storeysAboveGround",
    "storeysBelowGround",
];
/// The ones of rooms, installations and generic objects.
pub const OTHER_PROPERTIES: &[&str] = &["class", "function", "usage"];
/// `_CityObject` properties written in the core namespace.
pub const CORE_PROPERTIES: &[&str] = &["creationDate", "terminationDate"];

/// The property text of one object: GML/core properties, generic attributes, module properties
/// (three strings, written in this order between the other parts of the feature).
#[derive(Default)]
pub struct AttributeXml {
    pub gml_core: String,
    pub generic: String,
    pub module: String,
}

/// Maps `attrs`; `module_props` are the names the object's module defines (written as
/// `module_prefix:name`), others become `gen:` attributes.
pub fn attributes(
    attrs: &Map<String, Value>,
    module_prefix: &str,
    module_props: &[&str],
    object: &str,
    report: &mut Report,
) -> AttributeXml {
    let mut x = AttributeXml::default();
    if let Some(v) = attrs.get("description").and_then(Value::as_str) {
        let _ = write!(x.gml_core, "<gml:description>{}</gml:description>", escape(v));
    }
    if let Some(v) = attrs.get("name").and_then(Value::as_str) {
        let _ = write!(x.gml_core, "<gml:name>{}</gml:name>", escape(v));
    }
    for key in CORE_PROPERTIES {
        if let Some(v) = attrs.get(*key).and_then(Value::as_str) {
            let _ = write!(x.gml_core, "<core:{key}>{}</core:{key}>", escape(v));
        }
    }
    for (key, value) in attrs {
        let taken_as_text = matches!(key.as_str(), "description" | "name") || CORE_PROPERTIES.contains(&key.as_str());
        if taken_as_text && value.is_string() {
            continue;
        }
        if module_props.contains(&key.as_str()) && !value.is_object() && !value.is_array() && !value.is_null() {
            continue;
        }
        generic(&mut x.generic, key, value, object, report);
    }
    for key in module_props {
        let Some(v) = attrs.get(*key).filter(|v| !v.is_object() && !v.is_array() && !v.is_null()) else { continue };
        let text = scalar_text(v);
        let uom = if *key == "measuredHeight" { " uom=\"m\"" } else { "" };
        let _ = write!(x.module, "<{module_prefix}:{key}{uom}>{}</{module_prefix}:{key}>", escape(&text));
    }
    x
}

/// One generic attribute, typed by its JSON value.
pub fn generic(out: &mut String, key: &str, value: &Value, object: &str, report: &mut Report) {
    let (element, text) = match value {
        Value::String(s) => ("stringAttribute", s.clone()),
        Value::Number(n) if n.is_i64() || n.is_u64() => ("intAttribute", n.to_string()),
        Value::Number(n) => ("doubleAttribute", n.to_string()),
        Value::Bool(b) => {
            report.add("boolean attribute (written as a gen:stringAttribute \"true\"/\"false\")", Some(object));
            ("stringAttribute", b.to_string())
        }
        Value::Null => {
            report.add("attribute with the value null (left out)", Some(object));
            return;
        }
        Value::Array(_) | Value::Object(_) => {
            report.add(
                "array or object attribute (written as a gen:stringAttribute holding its JSON text)",
                Some(object),
            );
            ("stringAttribute", value.to_string())
        }
    };
    let _ =
        write!(out, "<gen:{element} name=\"{}\"><gen:value>{}</gen:value></gen:{element}>", escape(key), escape(&text));
}

fn scalar_text(v: &Value) -> String {
    match v {
        Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}
