//! What a LAS/LAZ header claims, checked against the file before the `las`/`laz` crates read it.
//!
//! Those crates size allocations by header fields: `Reader::read_all` allocates the claimed
//! point count times the record length (10¹² points: an abort in the allocator), the LAZ chunk
//! table is pre-allocated for its claimed chunk count (4·10⁹ × 16 bytes), an EVLR buffer for its
//! claimed length. A header is a few hundred bytes anyone can write; the file size is what the
//! file really holds. [`check`] compares the two:
//!
//! - points start inside the file;
//! - uncompressed LAS: count × record length fits between the point offset and the end;
//! - LAZ: the chunk table lies inside the file, and its chunk count fits the compressed data
//!   (every chunk starts with one point stored raw, so it takes at least one record length —
//!   at most 20 bytes are assumed, the smallest standard record);
//! - LAS 1.4: the first EVLR (the one the `las` crate reads) lies inside the file.
//!
//! The compressed point count cannot be bounded by the file size (identical points compress to
//! almost nothing): readers of LAZ must read in batches and let memory grow with what is
//! decoded, not with the header.

use std::io::{self, Read, Seek, SeekFrom};

/// What the header claims that the file cannot hold (the message says both).
#[derive(Debug, thiserror::Error)]
pub enum LasClaim {
    #[error("the header claims the points start at byte {offset}, but the file has {len} bytes")]
    PointOffset { offset: u64, len: u64 },
    #[error("the header claims {points} points of {record} bytes ({need} bytes), but the file holds {have} bytes of point data")]
    Points { points: u64, record: u64, need: u128, have: u64 },
    #[error("the LAZ chunk table is claimed at byte {offset}, beyond the file's {len} bytes")]
    ChunkTableOffset { offset: u64, len: u64 },
    #[error("the LAZ chunk table claims {chunks} chunks, but {data} bytes of compressed points hold at most {max}")]
    Chunks { chunks: u64, data: u64, max: u64 },
    #[error("the header claims an extended VLR at byte {offset} of {length} bytes, but the file has {len} bytes")]
    Evlr { offset: u64, length: u64, len: u64 },
    #[error("{0}")]
    Io(#[from] io::Error),
}

/// The fields of a LAS header that size allocations.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Claims {
    pub minor: u8,
    pub offset_to_points: u64,
    pub compressed: bool,
    pub record_len: u64,
    pub points: u64,
    /// (start of the first EVLR, number of EVLRs), LAS 1.4 only.
    pub evlr: Option<(u64, u32)>,
}

fn u16_at(h: &[u8], i: usize) -> u64 {
    u16::from_le_bytes([h[i], h[i + 1]]) as u64
}
fn u32_at(h: &[u8], i: usize) -> u64 {
    u32::from_le_bytes(h[i..i + 4].try_into().unwrap()) as u64
}
fn u64_at(h: &[u8], i: usize) -> u64 {
    u64::from_le_bytes(h[i..i + 8].try_into().unwrap())
}

/// The claims of a header (`None` when the bytes are not a LAS header: the `las` crate then
/// says what is wrong).
pub fn claims(h: &[u8]) -> Option<Claims> {
    if h.len() < 227 || !h.starts_with(b"LASF") {
        return None;
    }
    let minor = h[25];
    let header_size = u16_at(h, 94);
    let format = h[104];
    let legacy = u32_at(h, 107);
    let (evlr, large) = if minor >= 4 && header_size >= 375 && h.len() >= 375 {
        (Some((u64_at(h, 235), u32_at(h, 243) as u32)), u64_at(h, 247))
    } else {
        (None, 0)
    };
    Some(Claims {
        minor,
        offset_to_points: u32_at(h, 96),
        // the `las` crate's test: bit 7 (LASzip sets bits 7 and 6)
        compressed: format & 0x80 != 0,
        record_len: u16_at(h, 105),
        // as the `las` crate reads it: the legacy count when it is set, else the 1.4 count
        points: if legacy > 0 { legacy } else { large },
        evlr,
    })
}

/// Checks a LAS/LAZ source of `len` bytes (see the module documentation). Leaves `r` at an
/// unspecified position. A source too short or without signature passes: the `las` crate
/// refuses it with its own message.
pub fn check<R: Read + Seek>(r: &mut R, len: u64) -> Result<(), LasClaim> {
    let mut h = vec![0u8; 375.min(len) as usize];
    r.seek(SeekFrom::Start(0))?;
    r.read_exact(&mut h)?;
    let Some(c) = claims(&h) else { return Ok(()) };
    if c.offset_to_points > len {
        return Err(LasClaim::PointOffset { offset: c.offset_to_points, len });
    }
    let have = len - c.offset_to_points;
    if !c.compressed {
        let need = c.points as u128 * c.record_len as u128;
        if need > have as u128 {
            return Err(LasClaim::Points { points: c.points, record: c.record_len, need, have });
        }
    } else {
        check_chunk_table(r, len, &c)?;
    }
    if let Some((start, n)) = c.evlr {
        // the `las` crate reads an EVLR when both fields are set (raw::Header::evlr)
        if start > 0 && n > 0 {
            if start.saturating_add(60) > len {
                return Err(LasClaim::Evlr { offset: start, length: 0, len });
            }
            let mut e = [0u8; 60];
            r.seek(SeekFrom::Start(start))?;
            r.read_exact(&mut e)?;
            let length = u64_at(&e, 20);
            if start.saturating_add(60).saturating_add(length) > len {
                return Err(LasClaim::Evlr { offset: start, length, len });
            }
        }
    }
    Ok(())
}

/// The LAZ chunk table as `laz` finds it (`ChunkTable::read_offset`): an i64 offset at the start
/// of the point data, or, when the writer could not update it, in the last 8 bytes.
fn check_chunk_table<R: Read + Seek>(r: &mut R, len: u64, c: &Claims) -> Result<(), LasClaim> {
    let start = c.offset_to_points;
    if start.saturating_add(8) > len {
        return Ok(()); // the laz crate fails reading the offset: a plain read error
    }
    let mut b = [0u8; 8];
    r.seek(SeekFrom::Start(start))?;
    r.read_exact(&mut b)?;
    let mut offset = i64::from_le_bytes(b);
    if offset <= start as i64 {
        r.seek(SeekFrom::Start(len - 8))?;
        r.read_exact(&mut b)?;
        offset = i64::from_le_bytes(b);
        if offset <= start as i64 {
            return Ok(()); // no chunk table: laz reads without one
        }
    }
    let offset = offset as u64;
    if offset.saturating_add(8) > len {
        return Err(LasClaim::ChunkTableOffset { offset, len });
    }
    let mut t = [0u8; 8];
    r.seek(SeekFrom::Start(offset))?;
    r.read_exact(&mut t)?;
    let chunks = u32_at(&t, 4);
    let data = offset - (start + 8);
    let max = data / c.record_len.clamp(1, 20);
    if chunks > max {
        return Err(LasClaim::Chunks { chunks, data, max });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;

    /// A LAS 1.2 header of format 0 (20-byte records) with `points` claimed.
    pub(crate) fn header(points: u32, format: u8) -> Vec<u8> {
        let mut h = vec![0u8; 227];
        h[..4].copy_from_slice(b"LASF");
        h[24] = 1;
        h[25] = 2;
        h[94..96].copy_from_slice(&227u16.to_le_bytes());
        h[96..100].copy_from_slice(&227u32.to_le_bytes());
        h[104] = format;
        h[105..107].copy_from_slice(&20u16.to_le_bytes());
        h[107..111].copy_from_slice(&points.to_le_bytes());
        h
    }

    #[test]
    fn point_counts_beyond_the_file_are_refused() {
        let mut f = header(3, 0);
        f.extend(vec![0u8; 60]);
        let len = f.len() as u64;
        assert!(check(&mut Cursor::new(&f), len).is_ok());
        f[107..111].copy_from_slice(&4u32.to_le_bytes());
        let e = check(&mut Cursor::new(&f), len).unwrap_err().to_string();
        assert_eq!(e, "the header claims 4 points of 20 bytes (80 bytes), but the file holds 60 bytes of point data");
        f[96..100].copy_from_slice(&10_000u32.to_le_bytes());
        assert!(matches!(check(&mut Cursor::new(&f), len), Err(LasClaim::PointOffset { offset: 10_000, .. })));
        // not LAS: left to the las crate
        assert!(check(&mut Cursor::new(b"hello".to_vec()), 5).is_ok());
    }

    #[test]
    fn chunk_counts_beyond_the_data_are_refused() {
        let mut f = header(1000, 0x83);
        let data_start = f.len() as u64 + 8;
        let table = data_start + 400; // 400 bytes of chunks: at most 20 of them
        f.extend(table.to_le_bytes());
        f.extend(vec![0u8; 400]);
        f.extend(0u32.to_le_bytes()); // version
        f.extend(20u32.to_le_bytes());
        f.extend([0u8; 8]);
        let len = f.len() as u64;
        assert!(check(&mut Cursor::new(&f), len).is_ok());
        let at = table as usize + 4;
        f[at..at + 4].copy_from_slice(&4_000_000_000u32.to_le_bytes());
        let e = check(&mut Cursor::new(&f), len).unwrap_err().to_string();
        assert!(e.contains("claims 4000000000 chunks") && e.contains("at most 20"), "{e}");
        let at = data_start as usize - 8;
        f[at..at + 8].copy_from_slice(&(len + 100).to_le_bytes());
        assert!(matches!(check(&mut Cursor::new(&f), len), Err(LasClaim::ChunkTableOffset { .. })));
    }
}
