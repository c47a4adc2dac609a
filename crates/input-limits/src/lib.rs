//! Limits on what untrusted input can make geofit do (issue 13, docs/decisions.md#input-limits):
//!
//! - [`quote`]: how much of the input an error message repeats (a 100 MB attribute value must
//!   not come back whole on stderr);
//! - [`lines`]: how long one text line may grow before the reader gives up (`/dev/zero` has no
//!   newline and would otherwise fill the memory);
//! - [`las`]: whether the counts and offsets a LAS/LAZ header claims fit the file, checked
//!   before the `las`/`laz` crates size allocations by them;
//! - [`budget`]: how many cells, points or bytes a command may hold, from the memory available
//!   or an environment variable;
//! - [`netcdf`]: whether the counts a netCDF classic header claims fit the file, checked before
//!   libnetcdf sizes allocations by them;
//! - [`mapped`]: a whole input as one slice that a streaming reader holds only ahead of itself.
//!
//! No dependency on any format crate: every reader of untrusted text or binary can use it.
//!
//! # Examples
//!
//! An endless line (`/dev/zero` read as text) is refused after a bounded read, and a 100 kB
//! token is quoted by its first bytes:
//!
//! ```
//! use std::io::{BufReader, Read};
//! use input_limits::lines::{read_line_max, LineError};
//! let mut endless = BufReader::new(std::io::repeat(b'7').take(10 << 20));
//! let mut line = String::new();
//! let err = read_line_max(&mut endless, &mut line, 1 << 20).unwrap_err();
//! assert!(matches!(err, LineError::TooLong { max } if max == 1 << 20));
//! assert!(line.is_empty());
//!
//! let token = "9".repeat(100_000);
//! let quoted = input_limits::quote(&token);
//! assert!(quoted.len() < 250 && quoted.ends_with("(100000 bytes)"));
//! ```

pub mod budget;
pub mod las;
pub mod lines;
pub mod mapped;
pub mod netcdf;

use std::borrow::Cow;

/// The most bytes of input an error message quotes.
pub const QUOTE_MAX_BYTES: usize = 200;

/// `s` as an error message may quote it: whole when at most [`QUOTE_MAX_BYTES`] bytes, else its
/// first bytes (cut at a character boundary) followed by "…" and the full length.
pub fn quote(s: &str) -> Cow<'_, str> {
    quote_max(s, QUOTE_MAX_BYTES)
}

/// [`quote`] with another limit (a reader that wants shorter excerpts, e.g. one number).
pub fn quote_max(s: &str, max_bytes: usize) -> Cow<'_, str> {
    if s.len() <= max_bytes {
        return Cow::Borrowed(s);
    }
    let mut end = max_bytes;
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    Cow::Owned(format!("{}… ({} bytes)", &s[..end], s.len()))
}

/// [`quote`] for bytes that may not be UTF-8: only the quoted prefix is converted (lossily), so
/// quoting a 100 MB token costs no 100 MB copy.
pub fn quote_bytes(b: &[u8]) -> String {
    quote_bytes_max(b, QUOTE_MAX_BYTES)
}

/// [`quote_bytes`] with another limit.
pub fn quote_bytes_max(b: &[u8], max_bytes: usize) -> String {
    if b.len() <= max_bytes {
        return String::from_utf8_lossy(b).into_owned();
    }
    // Cut before a UTF-8 continuation byte so a character is not split into U+FFFD.
    let mut end = max_bytes;
    while end > 0 && (b[end] & 0xC0) == 0x80 {
        end -= 1;
    }
    format!("{}… ({} bytes)", String::from_utf8_lossy(&b[..end]), b.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn short_text_is_quoted_whole_long_text_is_cut_at_a_character() {
        assert_eq!(quote("abc"), "abc");
        let long = "é".repeat(150); // 300 bytes
        let q = quote(&long);
        assert!(q.len() < QUOTE_MAX_BYTES + 20, "{q}");
        assert!(q.starts_with(&"é".repeat(100)) && q.ends_with("… (300 bytes)"), "{q}");
        let b = quote_bytes(long.as_bytes());
        assert_eq!(b, q);
        assert_eq!(quote_bytes_max(b"12345", 3), "123… (5 bytes)");
        assert!(!quote_bytes(&[0xFFu8; 1000]).is_empty());
    }
}
