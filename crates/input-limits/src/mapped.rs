//! A whole input as one byte slice, memory-mapped when it is a regular file, so that a reader
//! that streams through it (the CityGML object stream) holds only the pages it has not passed
//! yet: [`InputBytes::release_before`] hands the pages behind the reader back to the kernel
//! (docs/decisions.md#streaming-citygml).
//!
//! A mapped file is read from the page cache on demand; a released page is read again if the
//! reader goes back (an XLink into an earlier object), so releasing never changes what the
//! reader sees. A file truncated by another process while mapped would fault: geofit's own
//! writers replace files by rename and never truncate one in place.
//!
//! # Examples
//!
//! ```
//! use input_limits::mapped::InputBytes;
//!
//! let dir = std::env::temp_dir().join(format!("mapped-doctest-{}", std::process::id()));
//! std::fs::create_dir_all(&dir).unwrap();
//! let path = dir.join("tile.gml");
//! std::fs::write(&path, vec![b'x'; 3 << 20]).unwrap();
//! let bytes = InputBytes::map(&std::fs::File::open(&path).unwrap()).unwrap();
//! assert_eq!(bytes.len(), 3 << 20);
//! bytes.release_before(2 << 20); // the first 2 MiB are no longer held
//! assert_eq!(bytes[0], b'x'); // and still read correctly, from the page cache
//! std::fs::remove_dir_all(&dir).unwrap();
//! ```

use std::fs::File;
use std::ops::Deref;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Releases happen in steps of at least this many bytes (one madvise call per step).
const RELEASE_STEP: usize = 1 << 20;

/// How far back each release reaches behind the previous one. The kernel may map a whole large
/// page-cache folio (up to 2 MiB, a huge page) on one fault: the reader's first fault past a
/// release can map released pages of its folio again, which the next release must cover.
const RELEASE_OVERLAP: usize = 2 << 20;

/// The bytes of one input: a read-only private mapping of a regular file, or bytes read into
/// memory (a pipe, a device, stdin).
pub enum InputBytes {
    Mapped { map: memmap2::Mmap, released: AtomicUsize },
    Read(Vec<u8>),
}

impl InputBytes {
    /// Maps a regular file (an empty file becomes an empty slice: a zero-length mapping is not
    /// allowed).
    pub fn map(file: &File) -> std::io::Result<InputBytes> {
        if file.metadata()?.len() == 0 {
            return Ok(InputBytes::Read(Vec::new()));
        }
        // SAFETY: a private read-only mapping; the module docs say what a concurrent truncation
        // would do and why geofit's writers never cause one.
        let map = unsafe { memmap2::Mmap::map(file)? };
        Ok(InputBytes::Mapped { map, released: AtomicUsize::new(0) })
    }

    /// Tells the kernel the bytes before `offset` will (most likely) not be read again, so their
    /// pages stop counting against this process. No effect on bytes read into memory.
    pub fn release_before(&self, offset: usize) {
        let InputBytes::Mapped { map, released } = self else { return };
        let end = offset.min(map.len());
        let done_to = released.load(Ordering::Relaxed);
        if end < done_to + RELEASE_STEP {
            return;
        }
        let start = done_to.saturating_sub(RELEASE_OVERLAP);
        // SAFETY: DONTNEED on a private, never-written file mapping drops clean pages only; a
        // later read of them faults the file's contents back in, so no byte the slice shows
        // changes (memmap2 widens the range to whole pages, which is harmless for that reason).
        let done = unsafe { map.unchecked_advise_range(memmap2::UncheckedAdvice::DontNeed, start, end - start) };
        if done.is_ok() {
            released.store(end, Ordering::Relaxed);
        }
    }
}

impl Deref for InputBytes {
    type Target = [u8];

    fn deref(&self) -> &[u8] {
        match self {
            InputBytes::Mapped { map, .. } => map,
            InputBytes::Read(v) => v,
        }
    }
}
