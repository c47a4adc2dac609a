//! Where each object id stands in a CityJSON text: the line of its first occurrence as an
//! object key (`"B1": {`), found in one pass over the bytes, so a CityGML line can name it.

use std::collections::{HashMap, HashSet};

/// Line (1-based) of the first occurrence of each of `ids` as a JSON object key.
pub fn key_lines(bytes: &[u8], ids: &[&str]) -> HashMap<String, usize> {
    let wanted: HashSet<&[u8]> = ids.iter().map(|s| s.as_bytes()).collect();
    let mut out = HashMap::new();
    let (mut line, mut i) = (1usize, 0usize);
    while i < bytes.len() && out.len() < wanted.len() {
        match bytes[i] {
            b'\n' => line += 1,
            b'"' => {
                let start = i + 1;
                let mut j = start;
                while j < bytes.len() && bytes[j] != b'"' {
                    j += if bytes[j] == b'\\' { 2 } else { 1 };
                }
                let key = &bytes[start..j.min(bytes.len())];
                let mut k = j + 1;
                while k < bytes.len() && bytes[k].is_ascii_whitespace() && bytes[k] != b'\n' {
                    k += 1;
                }
                if bytes.get(k) == Some(&b':') && wanted.contains(key) {
                    out.entry(String::from_utf8_lossy(key).into_owned()).or_insert(line);
                }
                i = j;
            }
            _ => {}
        }
        i += 1;
    }
    out
}
