//! Text lines of bounded length.
//!
//! `BufRead::read_line` grows its buffer until it meets a newline: on `/dev/zero`, a FIFO fed
//! by a binary producer, or any file without newlines it takes all the memory there is before
//! failing. Point and grid text formats have short lines, so a line longer than
//! [`MAX_LINE_BYTES`] is an error that says so.

use std::io::{self, BufRead};

/// The longest text line a reader accepts (1 MiB; an XYZ line is some 40 bytes).
pub const MAX_LINE_BYTES: usize = 1 << 20;

/// Why a line could not be read.
#[derive(Debug, thiserror::Error)]
pub enum LineError {
    /// The line has no newline within `max` bytes.
    #[error("the line is longer than {} (no newline: a binary file or an endless stream?)", human(*.max))]
    TooLong { max: usize },
    /// The line is not UTF-8 text.
    #[error("not UTF-8 text (binary file?)")]
    NotUtf8,
    /// Reading failed.
    #[error("{0}")]
    Io(#[from] io::Error),
}

fn human(bytes: usize) -> String {
    if bytes >= 1 << 20 && bytes & ((1 << 20) - 1) == 0 {
        format!("{} MiB", bytes >> 20)
    } else {
        format!("{bytes} bytes")
    }
}

/// Like `BufRead::read_line` (appends the line with its newline to `buf`, returns the bytes
/// read, 0 at the end), but refuses a line longer than `max` bytes without reading on.
pub fn read_line_max<R: BufRead + ?Sized>(r: &mut R, buf: &mut String, max: usize) -> Result<usize, LineError> {
    let mut bytes: Vec<u8> = Vec::new();
    loop {
        let available = match r.fill_buf() {
            Ok(b) => b,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e.into()),
        };
        if available.is_empty() {
            break;
        }
        let (take, done) = match available.iter().position(|&b| b == b'\n') {
            Some(i) => (i + 1, true),
            None => (available.len(), false),
        };
        if bytes.len() + take > max.saturating_add(1) || (!done && bytes.len() + take > max) {
            return Err(LineError::TooLong { max });
        }
        bytes.extend_from_slice(&available[..take]);
        r.consume(take);
        if done {
            break;
        }
    }
    let n = bytes.len();
    buf.push_str(&String::from_utf8(bytes).map_err(|_| LineError::NotUtf8)?);
    Ok(n)
}

/// [`read_line_max`] with [`MAX_LINE_BYTES`].
pub fn read_line<R: BufRead + ?Sized>(r: &mut R, buf: &mut String) -> Result<usize, LineError> {
    read_line_max(r, buf, MAX_LINE_BYTES)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_up_to_the_limit_are_read_longer_ones_refused() {
        let mut r = io::Cursor::new(b"abc\ndefgh\nxy".to_vec());
        let mut s = String::new();
        assert_eq!(read_line_max(&mut r, &mut s, 4).unwrap(), 4);
        assert_eq!(s, "abc\n");
        s.clear();
        assert!(matches!(read_line_max(&mut r, &mut s, 4), Err(LineError::TooLong { max: 4 })));
        let mut r = io::Cursor::new(b"abcd\nxy".to_vec());
        assert_eq!(read_line_max(&mut r, &mut s, 4).unwrap(), 5, "the newline does not count");
        s.clear();
        assert_eq!(read_line_max(&mut r, &mut s, 4).unwrap(), 2);
        assert_eq!(read_line_max(&mut r, &mut s, 4).unwrap(), 0);
        // an endless stream without newline stops at the limit
        let mut zero = io::BufReader::with_capacity(64, io::repeat(0));
        assert!(matches!(read_line_max(&mut zero, &mut s, 1000), Err(LineError::TooLong { .. })));
        let mut bad = io::Cursor::new(vec![0xFF, b'\n']);
        assert!(matches!(read_line_max(&mut bad, &mut s, 10), Err(LineError::NotUtf8)));
    }
}
