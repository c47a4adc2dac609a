//! Byte offset → 1-based line/column, via a table of line starts built once per document
//! (memchr finds the newlines at memory speed, so this costs next to nothing).

use std::sync::atomic::{AtomicUsize, Ordering};

use crate::model::SourceSpan;

#[derive(Debug)]
pub struct LineIndex {
    starts: Vec<usize>,
    /// Line of the last lookup: the reader asks for offsets a few lines from the previous one,
    /// so a galloping search from here beats a binary search over the whole table.
    hint: AtomicUsize,
}

impl Clone for LineIndex {
    fn clone(&self) -> Self {
        LineIndex { starts: self.starts.clone(), hint: AtomicUsize::new(self.hint.load(Ordering::Relaxed)) }
    }
}

impl LineIndex {
    pub fn new(src: &[u8]) -> LineIndex {
        let mut starts = Vec::with_capacity(src.len() / 40 + 1);
        starts.push(0);
        newlines(src, &mut starts);
        LineIndex { starts, hint: AtomicUsize::new(0) }
    }

    /// 1-based (line, column) of a byte offset.
    pub fn line_col(&self, byte: usize) -> (usize, usize) {
        let st = &self.starts;
        let n = st.len();
        // Galloping search from the line of the last lookup (the reader asks for offsets near
        // the previous one, forwards and backwards): O(log distance) instead of O(log lines).
        // Invariant: st[lo] <= byte < st[hi] (hi == n: past the last line start).
        let h = self.hint.load(Ordering::Relaxed).min(n - 1);
        let (mut lo, mut hi);
        if st[h] <= byte {
            lo = h;
            let mut step = 1;
            loop {
                let next = lo + step;
                if next >= n {
                    hi = n;
                    break;
                }
                if st[next] <= byte {
                    lo = next;
                    step *= 2;
                } else {
                    hi = next;
                    break;
                }
            }
        } else {
            hi = h;
            let mut step = 1;
            loop {
                if hi < step {
                    lo = 0; // st[0] == 0 <= byte
                    break;
                }
                let next = hi - step;
                if st[next] <= byte {
                    lo = next;
                    break;
                }
                hi = next;
                step *= 2;
            }
        }
        while hi - lo > 1 {
            let mid = lo + (hi - lo) / 2;
            if st[mid] <= byte {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let line = lo;
        self.hint.store(line, Ordering::Relaxed);
        (line + 1, byte - self.starts[line] + 1)
    }

    pub fn span(&self, start: usize, end: usize) -> SourceSpan {
        let (line, column) = self.line_col(start);
        SourceSpan { bytes: start..end, line, column }
    }
}

/// Pushes the offset after every `\n` of `src`: 16 bytes per step with SSE2 (part of every
/// x86_64 CPU) as one compare + movemask, then one push per newline; memchr_iter pays a call and
/// a new search set-up per newline, which on short XML lines costs more than the scan itself.
#[cfg(target_arch = "x86_64")]
fn newlines(src: &[u8], starts: &mut Vec<usize>) {
    use std::arch::x86_64::{__m128i, _mm_cmpeq_epi8, _mm_loadu_si128, _mm_movemask_epi8, _mm_set1_epi8};
    let mut chunks = src.chunks_exact(16);
    let mut base = 0usize;
    // SAFETY: SSE2 is in the x86_64 baseline; loads are unaligned loads of 16 in-bounds bytes.
    unsafe {
        let nl = _mm_set1_epi8(b'\n' as i8);
        for c in &mut chunks {
            let v = _mm_loadu_si128(c.as_ptr() as *const __m128i);
            let mut m = _mm_movemask_epi8(_mm_cmpeq_epi8(v, nl)) as u32;
            while m != 0 {
                starts.push(base + m.trailing_zeros() as usize + 1);
                m &= m - 1;
            }
            base += 16;
        }
    }
    starts.extend(memchr::memchr_iter(b'\n', chunks.remainder()).map(|i| base + i + 1));
}

#[cfg(not(target_arch = "x86_64"))]
fn newlines(src: &[u8], starts: &mut Vec<usize>) {
    starts.extend(memchr::memchr_iter(b'\n', src).map(|i| i + 1));
}

#[cfg(test)]
mod tests {
    use super::LineIndex;

    /// Line/column from the table (chunked newline scan + lookup hint) against a naive count,
    /// for offsets visited forwards, backwards and at random, on lines of every length around
    /// the 32-byte chunk size.
    #[test]
    fn line_col_agrees_with_naive_count() {
        let mut src = Vec::new();
        let mut x: u32 = 12345;
        for _ in 0..2000 {
            x = x.wrapping_mul(1103515245).wrapping_add(12345);
            let len = (x >> 16) % 70;
            src.extend(std::iter::repeat_n(b'a', len as usize));
            src.push(b'\n');
        }
        src.extend(b"tail");
        let naive = |b: usize| {
            let line = src[..b].iter().filter(|&&c| c == b'\n').count() + 1;
            let col = b - src[..b].iter().rposition(|&c| c == b'\n').map(|i| i + 1).unwrap_or(0) + 1;
            (line, col)
        };
        let idx = LineIndex::new(&src);
        let mut order: Vec<usize> = (0..src.len()).step_by(7).collect();
        order.extend((0..src.len()).rev().step_by(13));
        for _ in 0..3000 {
            x = x.wrapping_mul(1103515245).wrapping_add(12345);
            order.push((x as usize >> 8) % src.len());
        }
        for b in order {
            assert_eq!(idx.line_col(b), naive(b), "byte {b}");
        }
    }
}
