//! Byte offset → 1-based line/column, computed lazily as the reader moves through the document.
//!
//! A table of every line start would cost 8 bytes per line (≈ 200 MB for a 1 GB tile) and a scan
//! of the whole file before the first object is read, which keeps every page of a memory-mapped
//! document resident (docs/decisions.md#streaming-citygml). Instead the index keeps one
//! checkpoint per [`BLOCK`] bytes, built only as far as a lookup has asked, and the place of the
//! last lookup: the reader asks for offsets near the previous one, so a lookup counts the
//! newlines between the two (or from the nearest checkpoint), never the whole file.

use std::sync::Mutex;

use crate::model::SourceSpan;

/// Bytes per checkpoint: 16 bytes of index per 64 KiB of document, and at most 64 KiB counted
/// per lookup that jumps.
const BLOCK: usize = 1 << 16;

/// Where a line is: the line number (0-based) of a byte and the offset its line starts at.
#[derive(Debug, Clone, Copy)]
struct Place {
    byte: usize,
    line: usize,
    line_start: usize,
}

#[derive(Debug)]
struct Cursor {
    /// `checkpoints[k]`: the place of byte `k * BLOCK`.
    checkpoints: Vec<Place>,
    last: Place,
}

#[derive(Debug)]
pub struct LineIndex<'a> {
    src: &'a [u8],
    cursor: Mutex<Cursor>,
}

impl<'a> LineIndex<'a> {
    pub fn new(src: &'a [u8]) -> LineIndex<'a> {
        let start = Place { byte: 0, line: 0, line_start: 0 };
        LineIndex { src, cursor: Mutex::new(Cursor { checkpoints: vec![start], last: start }) }
    }

    /// 1-based (line, column) of a byte offset (offsets past the end count as the end).
    pub fn line_col(&self, byte: usize) -> (usize, usize) {
        let byte = byte.min(self.src.len());
        let mut cursor = self.cursor.lock().unwrap_or_else(|e| e.into_inner());
        let last = cursor.last;
        let place = if last.byte <= byte && byte - last.byte <= BLOCK {
            advance(self.src, last, byte)
        } else if byte < last.byte && last.byte - byte <= BLOCK {
            self.step_back(&mut cursor, last, byte)
        } else {
            let from = self.checkpoint(&mut cursor, byte);
            advance(self.src, from, byte)
        };
        cursor.last = place;
        (place.line + 1, byte - place.line_start + 1)
    }

    pub fn span(&self, start: usize, end: usize) -> SourceSpan {
        let (line, column) = self.line_col(start);
        SourceSpan { bytes: start..end, line, column }
    }

    /// The place of `byte` from a later place `later`: the newlines between them counted back,
    /// the line start searched back no further than `byte`'s checkpoint.
    fn step_back(&self, cursor: &mut Cursor, later: Place, byte: usize) -> Place {
        let newlines = count_newlines(&self.src[byte..later.byte]);
        if newlines == 0 {
            return Place { byte, ..later };
        }
        let floor = self.checkpoint(cursor, byte);
        let line_start = match memchr::memrchr(b'\n', &self.src[floor.byte..byte]) {
            Some(i) => floor.byte + i + 1,
            None => floor.line_start,
        };
        Place { byte, line: later.line - newlines, line_start }
    }

    /// The checkpoint at or before `byte`, scanning the blocks up to it on first use.
    fn checkpoint(&self, cursor: &mut Cursor, byte: usize) -> Place {
        let block = byte / BLOCK;
        while cursor.checkpoints.len() <= block {
            let prev = *cursor.checkpoints.last().expect("the first checkpoint is made in new");
            let next = advance(self.src, prev, prev.byte + BLOCK);
            cursor.checkpoints.push(next);
        }
        cursor.checkpoints[block]
    }
}

/// The place of `to` (≥ `from.byte`), counting the newlines in between.
fn advance(src: &[u8], from: Place, to: usize) -> Place {
    let gap = &src[from.byte..to];
    let newlines = count_newlines(gap);
    let line_start = match memchr::memrchr(b'\n', gap) {
        Some(i) => from.byte + i + 1,
        None => from.line_start,
    };
    Place { byte: to, line: from.line + newlines, line_start }
}

/// Newlines in `bytes`: 16 bytes per step with SSE2 (part of every x86_64 CPU) as one compare +
/// movemask + popcount.
#[cfg(target_arch = "x86_64")]
fn count_newlines(bytes: &[u8]) -> usize {
    use std::arch::x86_64::{__m128i, _mm_cmpeq_epi8, _mm_loadu_si128, _mm_movemask_epi8, _mm_set1_epi8};
    let mut chunks = bytes.chunks_exact(16);
    let mut count = 0usize;
    // SAFETY: SSE2 is in the x86_64 baseline; loads are unaligned loads of 16 in-bounds bytes.
    unsafe {
        let nl = _mm_set1_epi8(b'\n' as i8);
        for c in &mut chunks {
            let v = _mm_loadu_si128(c.as_ptr() as *const __m128i);
            count += (_mm_movemask_epi8(_mm_cmpeq_epi8(v, nl)) as u32).count_ones() as usize;
        }
    }
    count + memchr::memchr_iter(b'\n', chunks.remainder()).count()
}

#[cfg(not(target_arch = "x86_64"))]
fn count_newlines(bytes: &[u8]) -> usize {
    memchr::memchr_iter(b'\n', bytes).count()
}

#[cfg(test)]
mod tests {
    use super::{LineIndex, BLOCK};

    /// Line/column from the lazy index against a naive count, for offsets visited forwards,
    /// backwards, at random and across checkpoints, on lines of every length around the 16-byte
    /// chunk size and on lines longer than a checkpoint block.
    #[test]
    fn line_col_agrees_with_naive_count() {
        let mut src = Vec::new();
        let mut x: u32 = 12345;
        for i in 0..6000 {
            x = x.wrapping_mul(1103515245).wrapping_add(12345);
            let len = if i % 1500 == 7 { BLOCK + 3000 } else { ((x >> 16) % 70) as usize };
            src.extend(std::iter::repeat_n(b'a', len));
            src.push(b'\n');
        }
        src.extend(b"tail");
        let mut line_of = Vec::with_capacity(src.len() + 1);
        let mut start_of = Vec::with_capacity(src.len() + 1);
        let (mut line, mut start) = (1, 0);
        for (i, &c) in src.iter().enumerate() {
            line_of.push(line);
            start_of.push(start);
            if c == b'\n' {
                line += 1;
                start = i + 1;
            }
        }
        line_of.push(line);
        start_of.push(start);
        let naive = |b: usize| (line_of[b], b - start_of[b] + 1);
        let idx = LineIndex::new(&src);
        let mut order: Vec<usize> = (0..=src.len()).step_by(7).collect();
        order.extend((0..src.len()).rev().step_by(13));
        for _ in 0..3000 {
            x = x.wrapping_mul(1103515245).wrapping_add(12345);
            let b = (x as usize >> 4) % src.len();
            order.extend([b, b.saturating_sub(40), b.saturating_sub(BLOCK / 2), b + 3 * BLOCK / 2]);
        }
        for b in order.into_iter().filter(|&b| b <= src.len()) {
            assert_eq!(idx.line_col(b), naive(b), "byte {b}");
        }
    }
}
