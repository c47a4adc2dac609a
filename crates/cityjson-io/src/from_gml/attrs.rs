//! The attributes of one CityGML feature, read from its own bytes: simple-valued properties
//! (`gml:name`, `core:creationDate`, `bldg:measuredHeight`, ...) by local name and generic
//! attributes (CityGML 1.0/2.0 `gen:stringAttribute`, 3.0 `core:genericAttribute`) by their
//! name. Everything else a feature holds that the model does not map (an address, an external
//! reference, a terrain intersection curve) is reported, not dropped silently
//! (docs/decisions.md#cityjson-attributes).

use quick_xml::events::{BytesStart, Event};
use quick_xml::Reader;
use serde_json::{Map, Number, Value};

use crate::report::Report;

/// Child elements handled elsewhere: geometry the model reads, nested features it walks.
fn handled_elsewhere(local: &str) -> bool {
    const STRUCTURE: &[&str] = &[
        "boundedBy",
        "consistsOfBuildingPart",
        "buildingPart",
        "outerBuildingInstallation",
        "interiorBuildingInstallation",
        "buildingInstallation",
        "interiorRoom",
        "buildingRoom",
        "opening",
        "fillingSurface",
        "boundary",
    ];
    if STRUCTURE.contains(&local) {
        return true;
    }
    let Some(rest) = local
        .strip_prefix("lod")
        .and_then(|r| r.get(1..))
        .filter(|_| local.as_bytes().get(3).is_some_and(u8::is_ascii_digit))
    else {
        return false;
    };
    matches!(rest, "Solid" | "MultiSurface" | "Geometry" | "FootPrint" | "RoofEdge")
}

fn local(e: &BytesStart<'_>) -> String {
    String::from_utf8_lossy(e.local_name().as_ref()).into_owned()
}

fn qname(e: &BytesStart<'_>) -> String {
    String::from_utf8_lossy(e.name().as_ref()).into_owned()
}

/// A simple property's JSON value: numbers where CityJSON has numbers.
fn typed(key: &str, text: &str) -> Value {
    let number = match key {
        "measuredHeight" => text.trim().parse::<f64>().ok().and_then(Number::from_f64),
        "storeysAboveGround" | "storeysBelowGround" | "yearOfConstruction" | "yearOfDemolition" => {
            text.trim().parse::<i64>().ok().map(Number::from)
        }
        _ => None,
    };
    number.map(Value::Number).unwrap_or_else(|| Value::String(text.to_string()))
}

/// A generic attribute's JSON value by its element name (`intAttribute`, `DoubleAttribute`...).
fn typed_generic(element: &str, text: &str) -> Value {
    let e = element.to_ascii_lowercase();
    let n = if e.starts_with("int") {
        text.trim().parse::<i64>().ok().map(Number::from)
    } else if e.starts_with("double") || e.starts_with("measure") {
        text.trim().parse::<f64>().ok().and_then(Number::from_f64)
    } else {
        None
    };
    n.map(Value::Number).unwrap_or_else(|| Value::String(text.to_string()))
}

/// Reads the attributes of the feature whose element is `bytes` (start tag to end tag).
pub fn scan(bytes: &[u8], object: &str, report: &mut Report) -> Map<String, Value> {
    let mut out = Map::new();
    let mut r = Reader::from_reader(bytes);
    r.config_mut().trim_text(true);
    // The feature's own start tag.
    loop {
        match r.read_event() {
            Ok(Event::Start(_)) => break,
            Ok(Event::Eof) | Err(_) => return out,
            _ => {}
        }
    }
    loop {
        let ev = match r.read_event() {
            Ok(ev) => ev.into_owned(),
            Err(_) => return out,
        };
        match ev {
            Event::Start(e) => child(&mut r, &e, &mut out, object, report),
            Event::Empty(e) if !handled_elsewhere(&local(&e)) => {
                report.add(format!("empty property {} (not mapped)", qname(&e)), Some(object))
            }
            Event::End(_) | Event::Eof => return out,
            _ => {}
        }
    }
}

/// One child of the feature (its start tag read).
fn child(r: &mut Reader<&[u8]>, e: &BytesStart<'_>, out: &mut Map<String, Value>, object: &str, report: &mut Report) {
    let name = local(e);
    if handled_elsewhere(&name) {
        let _ = r.read_to_end(e.name());
        return;
    }
    if name.ends_with("Attribute") && name != "genericAttribute" {
        let key =
            e.try_get_attribute("name").ok().flatten().and_then(|a| a.unescape_value().ok()).map(|s| s.into_owned());
        let value = element_texts(r, e).into_iter().find(|(k, _)| k == "value").map(|(_, v)| v);
        return generic(out, &name, key, value, object, report);
    }
    if name == "genericAttribute" {
        let texts = element_texts(r, e);
        let element = texts.iter().find(|(k, _)| k.ends_with("Attribute")).map(|(k, _)| k.clone()).unwrap_or_default();
        let key = texts.iter().find(|(k, _)| k == "name").map(|(_, v)| v.clone());
        let value = texts.iter().find(|(k, _)| k == "value").map(|(_, v)| v.clone());
        return generic(out, &element, key, value, object, report);
    }
    let q = qname(e);
    let has_xml_attrs =
        e.attributes().flatten().any(|a| !(name == "measuredHeight" && a.key.local_name().as_ref() == b"uom"));
    let texts = element_texts(r, e);
    match &texts[..] {
        [(k, text)] if *k == name => {
            if has_xml_attrs {
                report.add(format!("XML attributes of {q} (codeSpace, uom: not carried)"), Some(object));
            }
            let key = name.clone();
            if out.contains_key(&key) {
                report.add(format!("repeated {q} (CityJSON keeps the first)"), Some(object));
            } else {
                out.insert(key.clone(), typed(&key, text));
            }
        }
        _ => report.add(format!("{q} (not mapped to CityJSON)"), Some(object)),
    }
}

fn generic(
    out: &mut Map<String, Value>,
    element: &str,
    key: Option<String>,
    value: Option<String>,
    object: &str,
    report: &mut Report,
) {
    match (key, value) {
        (Some(k), Some(v)) if !element.to_ascii_lowercase().starts_with("genericattributeset") => {
            if element.to_ascii_lowercase().starts_with("measure") {
                report.add("uom of a measure attribute (the number is kept)", Some(object));
            }
            out.insert(k, typed_generic(element, &v));
        }
        _ => report
            .add(format!("generic attribute {element} without name and value, or a set (not mapped)"), Some(object)),
    }
}

/// Reads to the end of `e`: (local name, text) of every element inside holding text, and of
/// `e` itself if it holds text directly; nested structure flattened.
fn element_texts(r: &mut Reader<&[u8]>, e: &BytesStart<'_>) -> Vec<(String, String)> {
    let mut stack = vec![local(e)];
    let mut out = Vec::new();
    let mut text = String::new();
    loop {
        match r.read_event() {
            Ok(Event::Start(s)) => {
                stack.push(local(&s));
                text.clear();
            }
            Ok(Event::Text(t)) => text.push_str(&t.decode().map(|s| unescape(&s)).unwrap_or_default()),
            Ok(Event::GeneralRef(g)) => text.push_str(&general_ref(&g.decode().unwrap_or_default())),
            Ok(Event::CData(c)) => text.push_str(&String::from_utf8_lossy(&c)),
            Ok(Event::End(_)) => {
                let name = stack.pop().unwrap_or_default();
                if !text.is_empty() {
                    out.push((name, std::mem::take(&mut text)));
                }
                if stack.is_empty() {
                    return out;
                }
            }
            Ok(Event::Eof) | Err(_) => return out,
            _ => {}
        }
    }
}

/// Entities resolved and line ends normalised as an XML parser must (`\r\n`, `\r` → `\n`).
fn unescape(s: &str) -> String {
    let s = s.replace("\r\n", "\n").replace('\r', "\n");
    quick_xml::escape::unescape(&s).map(|c| c.into_owned()).unwrap_or(s)
}

/// `&amp;` and friends, which quick-xml 0.38 reports as their own events.
fn general_ref(name: &str) -> String {
    match name {
        "amp" => "&".into(),
        "lt" => "<".into(),
        "gt" => ">".into(),
        "quot" => "\"".into(),
        "apos" => "'".into(),
        n => n
            .strip_prefix("#x")
            .and_then(|h| u32::from_str_radix(h, 16).ok())
            .or_else(|| n.strip_prefix('#').and_then(|d| d.parse().ok()))
            .and_then(char::from_u32)
            .map(String::from)
            .unwrap_or_else(|| format!("&{n};")),
    }
}
