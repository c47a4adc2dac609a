//! Point text as offices write it: which character separates the fields and which marks the
//! decimals (docs/decisions.md#point-text-separators-and-decimal-commas-issue-41).
//!
//! - The separator is read from the first content line (a header or the first row): `;` if it
//!   has one; else a tab, unless the tabs only align numbers that blanks also split; else a
//!   comma, unless the commas sit inside blank-separated numbers (`341000,5 5724000,25 12,5`,
//!   decimal commas between blanks); else whitespace. A line that commas and blanks split in
//!   two incompatible ways is refused ([`detect_separator`]). Double quotes protect a
//!   separator inside a field (`"12,5"` in a comma-separated file).
//! - The decimal mark is fixed by the first number that has one ([`Decimals`]): a `,` in a
//!   field (where `;`, a tab or blanks separate, or inside quotes) is a decimal comma, a `.` a
//!   decimal point; whole numbers read the same either way. A later number with the other mark
//!   is an error naming both lines, never a guess; so is a number with both marks or with two
//!   commas (a thousands separator, `1.234,5`, `1,234,567`), and a quoted `"1,234"` in a
//!   comma-separated file (thousands or decimals?).
//! - [`TextFormat`] carries what the user said (`--sep`, `--decimal`); given, it replaces the
//!   detection.

use input_limits::quote;

/// What separates the fields of a line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Separator {
    Comma,
    Semicolon,
    Tab,
    /// Any run of blanks (spaces and tabs).
    Whitespace,
}

impl Separator {
    /// `,` `;` `tab` `space`/`whitespace` (and the characters themselves).
    pub fn from_name(name: &str) -> Option<Separator> {
        Some(match name {
            "," | "comma" => Separator::Comma,
            ";" | "semicolon" => Separator::Semicolon,
            "tab" | "\t" => Separator::Tab,
            "space" | "whitespace" | " " => Separator::Whitespace,
            _ => return None,
        })
    }

    /// How messages name it.
    pub fn describe(self) -> &'static str {
        match self {
            Separator::Comma => "','",
            Separator::Semicolon => "';'",
            Separator::Tab => "tabs",
            Separator::Whitespace => "blanks",
        }
    }
}

/// The character between the whole and the fractional part of a number.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DecimalMark {
    Point,
    Comma,
}

impl DecimalMark {
    /// `.` or `,` (and `point`, `comma`).
    pub fn from_name(name: &str) -> Option<DecimalMark> {
        Some(match name {
            "." | "point" => DecimalMark::Point,
            "," | "comma" => DecimalMark::Comma,
            _ => return None,
        })
    }

    pub fn describe(self) -> &'static str {
        match self {
            DecimalMark::Point => "decimal point",
            DecimalMark::Comma => "decimal comma",
        }
    }
}

/// The separator and decimal mark a user gave; `None` is "detect it".
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TextFormat {
    pub separator: Option<Separator>,
    pub decimal: Option<DecimalMark>,
}

impl TextFormat {
    /// From the names of `--sep` and `--decimal` ([`Separator::from_name`],
    /// [`DecimalMark::from_name`]); an unknown name is an error naming the choices.
    pub fn from_names(sep: Option<&str>, decimal: Option<&str>) -> Result<TextFormat, String> {
        let separator = match sep {
            Some(s) => Some(
                Separator::from_name(s)
                    .ok_or_else(|| format!("separator {:?}: expected one of , ; tab space", quote(s)))?,
            ),
            None => None,
        };
        let decimal = match decimal {
            Some(d) => {
                Some(DecimalMark::from_name(d).ok_or_else(|| format!("decimal mark {:?}: expected . or ,", quote(d)))?)
            }
            None => None,
        };
        Ok(TextFormat { separator, decimal })
    }
}

/// Whether `c` is a blank (space or tab; a line's end is cut before splitting).
fn blank(c: char) -> bool {
    c == ' ' || c == '\t'
}

/// The fields of `line` split by `sep`, each trimmed of blanks and of one pair of enclosing
/// double quotes; a separator between double quotes does not split. `None`: a double quote is
/// not closed on the line.
pub fn split_fields(line: &str, sep: Separator) -> Option<Vec<&str>> {
    if !line.contains('"') {
        // the common case, without quote tracking
        return Some(match sep {
            Separator::Whitespace => line.split(blank).filter(|f| !f.is_empty()).collect(),
            Separator::Comma => line.split(',').map(|f| f.trim_matches(blank)).collect(),
            Separator::Semicolon => line.split(';').map(|f| f.trim_matches(blank)).collect(),
            Separator::Tab => line.split('\t').map(|f| f.trim_matches(blank)).collect(),
        });
    }
    let mut fields = Vec::new();
    let mut quoted = false;
    match sep {
        Separator::Whitespace => {
            let mut start = None;
            for (i, c) in line.char_indices() {
                if c == '"' {
                    quoted = !quoted;
                }
                if blank(c) && !quoted {
                    if let Some(s) = start.take() {
                        fields.push(&line[s..i]);
                    }
                } else if start.is_none() {
                    start = Some(i);
                }
            }
            if let Some(s) = start {
                fields.push(&line[s..]);
            }
        }
        _ => {
            let ch = match sep {
                Separator::Comma => ',',
                Separator::Semicolon => ';',
                _ => '\t',
            };
            let mut start = 0;
            for (i, c) in line.char_indices() {
                if c == '"' {
                    quoted = !quoted;
                } else if c == ch && !quoted {
                    fields.push(&line[start..i]);
                    start = i + 1;
                }
            }
            fields.push(&line[start..]);
        }
    }
    if quoted {
        return None;
    }
    Some(fields.into_iter().map(unquote).collect())
}

/// A field without surrounding blanks and one pair of enclosing double quotes.
fn unquote(field: &str) -> &str {
    let t = field.trim_matches(blank);
    match t.strip_prefix('"').and_then(|s| s.strip_suffix('"')) {
        Some(inner) => inner.trim_matches(blank),
        None => t,
    }
}

/// Whether `c` occurs in `line` outside double quotes.
fn has_unquoted(line: &str, ch: char) -> bool {
    let mut quoted = false;
    for c in line.chars() {
        if c == '"' {
            quoted = !quoted;
        } else if c == ch && !quoted {
            return true;
        }
    }
    false
}

/// Whether a field looks like a number in either decimal notation (digits, signs, `.`, `,`,
/// an exponent) or names one that is not finite (`nan`, `inf`): data, not a column name.
pub fn looks_numeric(field: &str) -> bool {
    let lower = field.to_ascii_lowercase();
    let bare = lower.trim_start_matches(['+', '-']);
    if matches!(bare, "nan" | "inf" | "infinity") {
        return true;
    }
    let mut digits = false;
    for c in bare.chars() {
        match c {
            '0'..='9' => digits = true,
            '.' | ',' | 'e' | '+' | '-' => {}
            _ => return false,
        }
    }
    digits && !bare.starts_with('e')
}

/// Whether a field (split by `sep`) holds two or more blank-separated numbers: blanks that
/// separate, not a name with a space in it (`Depth (m)`).
fn holds_numbers_between_blanks(field: &str) -> bool {
    let mut words = field.split(blank).filter(|w| !w.is_empty());
    let n = words.clone().count();
    n >= 2 && words.all(looks_numeric)
}

/// The separator of the first content line of a point text (see the module docs); the error
/// says why none can be told.
pub fn detect_separator(line: &str) -> Result<Separator, String> {
    if has_unquoted(line, ';') {
        return Ok(Separator::Semicolon);
    }
    let splits_cleanly =
        |sep| split_fields(line, sep).is_some_and(|f| !f.iter().any(|f| holds_numbers_between_blanks(f)));
    if has_unquoted(line, '\t') && splits_cleanly(Separator::Tab) {
        return Ok(Separator::Tab);
    }
    if has_unquoted(line, ',') {
        if splits_cleanly(Separator::Comma) {
            return Ok(Separator::Comma);
        }
        // commas inside blank-separated numbers: decimal commas (`341000,5 5724000,25 12,5`)
        let words = split_fields(line, Separator::Whitespace).unwrap_or_default();
        if words.iter().all(|w| w.matches(',').count() <= 1 && !w.starts_with(',') && !w.ends_with(',')) {
            return Ok(Separator::Whitespace);
        }
        return Err(format!(
            "cannot tell the field separator of {:?}: both commas and blanks split it; give --sep",
            quote(line)
        ));
    }
    Ok(Separator::Whitespace)
}

/// Whether the fields of a first row in a comma-separated text could as well be half as many
/// numbers with decimal commas (`341000,5,5724000,25,12,5`): an even number (6 or more, three
/// coordinates) of whole numbers, every second one unsigned. Such a text is refused unless the
/// separator or the decimal mark is given.
pub fn could_be_decimal_commas(fields: &[&str]) -> bool {
    let whole = |f: &str| {
        let d = f.strip_prefix(['+', '-']).unwrap_or(f);
        !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit())
    };
    let unsigned = |f: &str| !f.is_empty() && f.bytes().all(|b| b.is_ascii_digit());
    fields.len() >= 6 && fields.len().is_multiple_of(2) && fields.chunks(2).all(|p| whole(p[0]) && unsigned(p[1]))
}

/// Why a field is not a usable number; the message follows `axis = "field"` in an error.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FieldError {
    /// Not a number (`abc`, `5 724 000`).
    NotANumber,
    /// NaN or ±infinity.
    NotFinite,
    /// A number that breaks the decimal rules, with what is wrong.
    Decimal(String),
}

/// The decimal mark of one text: given, or fixed by the first number that has one (see the
/// module docs), with the line and field that fixed it for messages.
#[derive(Debug, Clone, Default)]
pub struct Decimals {
    given: Option<DecimalMark>,
    seen: Option<(DecimalMark, usize, String)>,
}

impl Decimals {
    pub fn new(given: Option<DecimalMark>) -> Decimals {
        Decimals { given, seen: None }
    }

    /// The mark in force: given, seen, or `None` while every number was whole.
    pub fn mark(&self) -> Option<DecimalMark> {
        self.given.or(self.seen.as_ref().map(|s| s.0))
    }

    /// `field` (of a line split by `sep`, at `line`) as a finite f64.
    pub fn parse(&mut self, field: &str, sep: Separator, line: usize) -> Result<f64, FieldError> {
        let (mut commas, mut points) = (0, 0);
        for b in field.bytes() {
            commas += (b == b',') as usize;
            points += (b == b'.') as usize;
        }
        let found = match (commas, points) {
            (0, 0) => None,
            (1, 0) => Some(DecimalMark::Comma),
            (0, 1) => Some(DecimalMark::Point),
            (0, _) if self.mark() == Some(DecimalMark::Comma) => {
                return Err(FieldError::Decimal(
                    "has points between digit groups (a thousands separator?); write numbers without them".into(),
                ));
            }
            (0, _) => return Err(FieldError::NotANumber),
            _ => {
                return Err(FieldError::Decimal(
                    "has both ',' and '.' or several commas (a thousands separator?); write numbers without them"
                        .into(),
                ));
            }
        };
        if found == Some(DecimalMark::Comma) && sep == Separator::Comma && self.given.is_none() {
            let after = field.rsplit(',').next().unwrap_or("");
            if after.len() == 3 && after.bytes().all(|b| b.is_ascii_digit()) {
                return Err(FieldError::Decimal(
                    "in a comma-separated file may be a decimal comma or a thousands separator; give --decimal".into(),
                ));
            }
        }
        if let Some(found) = found {
            match (self.given, &self.seen) {
                (Some(given), _) if given != found => {
                    let more = if found == DecimalMark::Point { " (a thousands separator?)" } else { "" };
                    return Err(FieldError::Decimal(format!(
                        "has a {}{more}, but the decimal mark given is '{}'",
                        found.describe(),
                        mark_char(given)
                    )));
                }
                (None, Some((seen, at, example))) if *seen != found => {
                    return Err(FieldError::Decimal(format!(
                        "has a {}, but line {at} has a {} ({:?}); give --decimal",
                        found.describe(),
                        seen.describe(),
                        quote(example)
                    )));
                }
                (None, None) => self.seen = Some((found, line, field.to_string())),
                _ => {}
            }
        }
        let v: f64 = if found == Some(DecimalMark::Comma) { field.replace(',', ".").parse() } else { field.parse() }
            .map_err(|_| FieldError::NotANumber)?;
        if !v.is_finite() {
            return Err(FieldError::NotFinite);
        }
        Ok(v)
    }
}

fn mark_char(m: DecimalMark) -> char {
    match m {
        DecimalMark::Point => '.',
        DecimalMark::Comma => ',',
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use Separator::*;

    #[test]
    fn separators_from_the_first_line() {
        assert_eq!(detect_separator("x;y;z"), Ok(Semicolon));
        assert_eq!(detect_separator("341000,5;5724000,25;12,5"), Ok(Semicolon));
        assert_eq!(detect_separator("x\ty\tWater depth"), Ok(Tab));
        assert_eq!(detect_separator("341000,5\t5724000,25\t12,5"), Ok(Tab));
        // GMT's padded tab columns are tabs; tabs that only align blank-separated numbers are blanks
        assert_eq!(detect_separator("326.12501\t-8.68370\t     9.90"), Ok(Tab));
        assert_eq!(detect_separator("4\t5  6"), Ok(Whitespace));
        assert_eq!(detect_separator("1, 2, 3, 99"), Ok(Comma));
        assert_eq!(detect_separator("Easting, Northing, Depth (m)"), Ok(Comma));
        assert_eq!(detect_separator("\"341000,5\" \"5724000,25\" \"12,5\""), Ok(Whitespace));
        assert_eq!(detect_separator("341000,5 5724000,25 12,5"), Ok(Whitespace));
        assert_eq!(detect_separator("1 2 3"), Ok(Whitespace));
        let e = detect_separator("1,2 3,4,5").unwrap_err();
        assert!(e.contains("both commas and blanks") && e.contains("--sep"), "{e}");
        // a quoted comma does not separate
        assert_eq!(detect_separator("\"12,5\" 3 4"), Ok(Whitespace));
    }

    #[test]
    fn quotes_protect_separators() {
        assert_eq!(split_fields("\"1,5\",\"2,5\", 3 ", Comma).unwrap(), ["1,5", "2,5", "3"]);
        assert_eq!(split_fields(" 1  \"a b\"\t3 ", Whitespace).unwrap(), ["1", "a b", "3"]);
        assert_eq!(split_fields("\t1\t\t3", Tab).unwrap(), ["", "1", "", "3"]);
        assert_eq!(split_fields("1;\"2;3", Semicolon), None);
    }

    #[test]
    fn whole_numbers_in_pairs_may_be_decimal_commas() {
        assert!(could_be_decimal_commas(&["341000", "5", "5724000", "25", "12", "5"]));
        assert!(!could_be_decimal_commas(&["341000", "5724000", "12"]));
        assert!(!could_be_decimal_commas(&["341000", "-5", "5724000", "25", "12", "5"]));
        assert!(!could_be_decimal_commas(&["341000.5", "5", "5724000", "25", "12", "5"]));
    }

    #[test]
    fn the_first_mark_decides_and_a_second_is_refused() {
        let mut d = Decimals::new(None);
        assert_eq!(d.parse("12", Semicolon, 2), Ok(12.0));
        assert_eq!(d.mark(), None);
        assert_eq!(d.parse("12,5", Semicolon, 3), Ok(12.5));
        assert_eq!(d.parse("-0,25", Semicolon, 4), Ok(-0.25));
        let FieldError::Decimal(m) = d.parse("7.5", Semicolon, 5).unwrap_err() else { panic!() };
        assert_eq!(m, "has a decimal point, but line 3 has a decimal comma (\"12,5\"); give --decimal");
        let mut d = Decimals::new(None);
        assert_eq!(d.parse("7.5", Whitespace, 1), Ok(7.5));
        assert!(matches!(d.parse("7,5", Whitespace, 2), Err(FieldError::Decimal(_))));
    }

    #[test]
    fn thousands_separators_and_bad_numbers_are_refused() {
        let mut d = Decimals::new(None);
        for f in ["1.234,5", "1,234,567", "5.724.000"] {
            assert!(matches!(d.parse(f, Semicolon, 1), Err(FieldError::NotANumber | FieldError::Decimal(_))), "{f}");
        }
        assert!(matches!(d.parse("1.234,5", Semicolon, 1), Err(FieldError::Decimal(_))));
        let mut d = Decimals::new(None);
        assert_eq!(d.parse("1,5", Comma, 1), Ok(1.5), "a quoted decimal comma in a CSV");
        let FieldError::Decimal(m) = Decimals::new(None).parse("1,234", Comma, 1).unwrap_err() else { panic!() };
        assert!(m.contains("thousands"), "{m}");
        assert_eq!(Decimals::new(Some(DecimalMark::Comma)).parse("1,234", Comma, 1), Ok(1.234));
        let mut d = Decimals::new(Some(DecimalMark::Point));
        assert!(matches!(d.parse("1,5", Semicolon, 1), Err(FieldError::Decimal(_))));
        assert_eq!(d.parse("nan", Semicolon, 1), Err(FieldError::NotFinite));
        assert_eq!(d.parse("5 724 000", Semicolon, 1), Err(FieldError::NotANumber));
        assert_eq!(d.parse("abc", Semicolon, 1), Err(FieldError::NotANumber));
    }

    #[test]
    fn numeric_looking_fields_are_data() {
        for f in ["12", "-1,5", "1.234,5", "NaN", "-inf", "1e5", "+3.5E-2"] {
            assert!(looks_numeric(f), "{f}");
        }
        for f in ["x", "Depth (m)", "e", "", "lon", "east"] {
            assert!(!looks_numeric(f), "{f}");
        }
    }

    #[test]
    fn names_of_the_options() {
        assert_eq!(
            TextFormat::from_names(Some("tab"), Some(",")),
            Ok(TextFormat { separator: Some(Tab), decimal: Some(DecimalMark::Comma) })
        );
        assert!(TextFormat::from_names(Some("|"), None).unwrap_err().contains("expected one of"));
    }
}
