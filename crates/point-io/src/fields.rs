//! How a LoopStructural text line splits into fields: on the first separator kind the line
//! holds, keeping empty fields as "absent" (a row with a normal but no value). The terrain
//! dialect detects its separator once per text instead ([`crate::text`]).

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
    fn first_separator_decides() {
        assert_eq!(split_by_first_separator("1 2, 3,,4"), ["1 2", "3", "", "4"]);
        assert_eq!(split_by_first_separator("1 2; 3"), ["1 2", "3"]);
        assert_eq!(split_by_first_separator(" 1  2\t3 "), ["1", "2", "3"]);
    }
}
