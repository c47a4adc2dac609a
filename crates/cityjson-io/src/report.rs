//! What a conversion could not carry into its target, counted by kind, with the first object
//! it happened in: a conversion never drops content silently
//! (docs/decisions.md#cityjson-what-a-conversion-cannot-carry).

use std::collections::BTreeMap;

use serde::Serialize;

/// One kind of content the target cannot hold.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Loss {
    /// How many times it occurred.
    pub count: usize,
    /// The first object (id) it occurred in, if any.
    pub first_object: Option<String>,
}

/// The report of one conversion: what was not carried over (or carried in a changed form).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct Report {
    /// Kind of content (a sentence) → how often and where first.
    pub not_carried: BTreeMap<String, Loss>,
}

impl Report {
    /// Records one occurrence of `what` in object `object`.
    pub fn add(&mut self, what: impl Into<String>, object: Option<&str>) {
        let e = self.not_carried.entry(what.into()).or_insert(Loss { count: 0, first_object: None });
        e.count += 1;
        if e.first_object.is_none() {
            e.first_object = object.map(str::to_string);
        }
    }

    /// Adds every entry of another report.
    pub fn merge(&mut self, other: Report) {
        for (what, loss) in other.not_carried {
            let e = self.not_carried.entry(what).or_insert(Loss { count: 0, first_object: None });
            e.count += loss.count;
            if e.first_object.is_none() {
                e.first_object = loss.first_object;
            }
        }
    }

    pub fn is_empty(&self) -> bool {
        self.not_carried.is_empty()
    }

    /// One line per kind: `3 × bldg:address (not mapped) (first in object B1)`.
    pub fn lines(&self) -> Vec<String> {
        self.not_carried
            .iter()
            .map(|(what, l)| match &l.first_object {
                Some(o) => format!("{} × {what} (first: {o})", l.count),
                None => format!("{} × {what}", l.count),
            })
            .collect()
    }
}
