//! How a text line splits into fields. Three rules, because the dialects mean different things
//! by an empty field: the terrain dialect folds separators together (`1, 2,  3` is three
//! fields) until a CSV header fixes the columns, after which an empty field is a missing
//! value; the LoopStructural dialect splits on the first separator kind the line holds and
//! keeps empty fields as "absent" (a row with a normal but no value).

/// Fields separated by any mix of whitespace, commas and semicolons; empty fields dropped.
pub fn split_folded(line: &str) -> impl Iterator<Item = &str> {
    line.split(|c: char| c.is_whitespace() || c == ',' || c == ';').filter(|s| !s.is_empty())
}

/// CSV fields separated by commas or semicolons, trimmed; empty fields kept.
pub fn split_csv(line: &str) -> Vec<&str> {
    line.split([',', ';']).map(str::trim).collect()
}

/// Fields separated by commas if the line has one, else by semicolons if it has one (trimmed,
/// empty fields kept), else by whitespace.
pub fn split_by_first_separator(line: &str) -> Vec<&str> {
    if line.contains(',') {
        line.split(',').map(|s| s.trim()).collect()
    } else if line.contains(';') {
        line.split(';').map(|s| s.trim()).collect()
    } else {
        line.split_whitespace().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folded_drops_empty_fields_and_mixes_separators() {
        assert_eq!(split_folded(" 1, 2;;3\t4 ").collect::<Vec<_>>(), ["1", "2", "3", "4"]);
    }

    #[test]
    fn csv_keeps_empty_fields() {
        assert_eq!(split_csv("1, ,3;"), ["1", "", "3", ""]);
    }

    #[test]
    fn first_separator_decides() {
        assert_eq!(split_by_first_separator("1 2, 3,,4"), ["1 2", "3", "", "4"]);
        assert_eq!(split_by_first_separator("1 2; 3"), ["1 2", "3"]);
        assert_eq!(split_by_first_separator(" 1  2\t3 "), ["1", "2", "3"]);
    }
}
