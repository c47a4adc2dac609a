//! Byte offset → 1-based line/column, via a table of line starts built once per document
//! (memchr finds the newlines at memory speed, so this costs next to nothing).

use crate::model::SourceSpan;

#[derive(Debug, Clone)]
pub struct LineIndex {
    starts: Vec<usize>,
}

impl LineIndex {
    pub fn new(src: &[u8]) -> LineIndex {
        let mut starts = Vec::with_capacity(src.len() / 40 + 1);
        starts.push(0);
        starts.extend(memchr::memchr_iter(b'\n', src).map(|i| i + 1));
        LineIndex { starts }
    }

    /// 1-based (line, column) of a byte offset.
    pub fn line_col(&self, byte: usize) -> (usize, usize) {
        let line = match self.starts.binary_search(&byte) {
            Ok(i) => i,
            Err(i) => i - 1,
        };
        (line + 1, byte - self.starts[line] + 1)
    }

    pub fn span(&self, start: usize, end: usize) -> SourceSpan {
        let (line, column) = self.line_col(start);
        SourceSpan { bytes: start..end, line, column }
    }
}
