//! Numbers in point files: a coordinate, value or normal component must be a finite f64 (a
//! sounding without a depth is a data error, not a hole). Each dialect words the error itself
//! (its messages are part of its interface); this module only says which error it is.

/// Why a field is not a usable number.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NumberError {
    /// Not a decimal number at all (`abc`).
    NotANumber,
    /// A number, but NaN or ±infinity.
    NotFinite,
}

/// `field` as a finite f64 (Rust's float syntax: `1`, `-2.5e3`; `nan`/`inf` parse but are
/// refused as [`NumberError::NotFinite`]).
pub fn parse_finite(field: &str) -> Result<f64, NumberError> {
    let v: f64 = field.parse().map_err(|_| NumberError::NotANumber)?;
    if !v.is_finite() {
        return Err(NumberError::NotFinite);
    }
    Ok(v)
}

/// Whether `field` reads as a number (NaN and infinities included): how a header line is told
/// from a data line.
pub fn is_number(field: &str) -> bool {
    field.parse::<f64>().is_ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finite_numbers_only() {
        assert_eq!(parse_finite("-2.5e3"), Ok(-2500.0));
        assert_eq!(parse_finite("nan"), Err(NumberError::NotFinite));
        assert_eq!(parse_finite("-inf"), Err(NumberError::NotFinite));
        assert_eq!(parse_finite("abc"), Err(NumberError::NotANumber));
        assert_eq!(parse_finite(""), Err(NumberError::NotANumber));
        assert!(is_number("NaN") && !is_number("x"));
    }
}
