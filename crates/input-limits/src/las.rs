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
//! - LAS 1.4: the first EVLR (the one the `las` crate reads) lies inside the file;
//! - LAZ: every item of the LASzip VLR has its type's size, and the items make the record
//!   length (a POINT10 of 1 byte made `laz` panic);
//! - layered LAZ (LAS 1.4): each chunk's layer sizes fit before the chunk table (`laz`
//!   allocates them before reading: 0xFFFFFFFF took 4.2 GB).
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
    #[error("the LASzip VLR gives item {index} ({kind}) a size of {size} bytes, but that item has {expected}")]
    ItemSize { index: usize, kind: &'static str, size: u64, expected: String },
    #[error("the LASzip VLR's items add up to {items} bytes a point, but the header's records are {record} bytes")]
    ItemSum { items: u64, record: u64 },
    #[error("LAZ chunk {chunk} at byte {at} claims layers of {layers} bytes, but only {have} bytes of compressed points follow")]
    Layers { chunk: u64, at: u64, layers: u64, have: u64 },
    #[error("the header claims {points} points of {record} bytes, more bytes than any file can hold")]
    Overflow { points: u64, record: u64 },
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
    pub header_size: u64,
    pub vlrs: u64,
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
    // as the `las` crate reads them: by the version, whatever the header size says
    let (evlr, large) = if minor >= 4 && h.len() >= 375 {
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
        header_size,
        vlrs: u32_at(h, 100),
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
    // the `las` crate computes offset + points × record length in u64 (an overflow panic)
    if c.points.checked_mul(c.record_len).and_then(|n| n.checked_add(c.offset_to_points)).is_none() {
        return Err(LasClaim::Overflow { points: c.points, record: c.record_len });
    }
    if !c.compressed {
        let need = c.points as u128 * c.record_len as u128;
        if need > have as u128 {
            return Err(LasClaim::Points { points: c.points, record: c.record_len, need, have });
        }
    } else {
        let items = check_laszip_items(r, len, &c)?;
        let table = check_chunk_table(r, len, &c)?;
        if let Some(items) = items.filter(|i| i.first().is_some_and(|i| i.0 == 10)) {
            check_layers(r, len, &c, &items, table)?;
        }
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

/// The name and fixed size of a LASzip item type (`None`: a size the VLR gives, extra bytes);
/// unknown types are left to `laz`, which refuses them.
fn item_kind(t: u64) -> Option<(&'static str, Option<u64>)> {
    Some(match t {
        0 => ("BYTE", None),
        6 => ("POINT10", Some(20)),
        7 => ("GPSTIME11", Some(8)),
        8 => ("RGB12", Some(6)),
        9 => ("WAVEPACKET13", Some(29)),
        10 => ("POINT14", Some(30)),
        11 => ("RGB14", Some(6)),
        12 => ("RGBNIR14", Some(8)),
        13 => ("WAVEPACKET14", Some(29)),
        14 => ("BYTE14", None),
        _ => return None,
    })
}

/// The items (type, size) of the LASzip VLR, checked: every item has its type's size (a
/// POINT10 of 1 byte made `laz` panic splitting the record, docs/decisions.md#crashes-and-hangs-of-issue-40)
/// and together they make the header's record length. `None` without a LASzip VLR (`las`
/// refuses the file then).
fn check_laszip_items<R: Read + Seek>(r: &mut R, len: u64, c: &Claims) -> Result<Option<Vec<(u64, u64)>>, LasClaim> {
    let mut at = c.header_size;
    for _ in 0..c.vlrs {
        if at.saturating_add(54) > len.min(c.offset_to_points) {
            return Ok(None);
        }
        let mut v = [0u8; 54];
        r.seek(SeekFrom::Start(at))?;
        r.read_exact(&mut v)?;
        let length = u16_at(&v, 20);
        let body = at + 54;
        at = body + length;
        if &v[2..17] != b"laszip encoded\0" || u16_at(&v, 18) != 22204 {
            continue;
        }
        if length < 34 || at > len {
            return Ok(None); // laz refuses the short record
        }
        let mut d = vec![0u8; length as usize];
        r.seek(SeekFrom::Start(body))?;
        r.read_exact(&mut d)?;
        let n = u16_at(&d, 32) as usize;
        if 34 + 6 * n > d.len() {
            return Ok(None);
        }
        let mut items = Vec::with_capacity(n);
        for i in 0..n {
            let (t, size) = (u16_at(&d, 34 + 6 * i), u16_at(&d, 36 + 6 * i));
            let Some((kind, fixed)) = item_kind(t) else { return Ok(None) };
            match fixed {
                Some(f) if f != size => {
                    return Err(LasClaim::ItemSize { index: i, kind, size, expected: f.to_string() });
                }
                None if size == 0 => {
                    return Err(LasClaim::ItemSize { index: i, kind, size, expected: "at least 1".into() })
                }
                _ => {}
            }
            items.push((t, size));
        }
        let sum: u64 = items.iter().map(|i| i.1).sum();
        if sum != c.record_len {
            return Err(LasClaim::ItemSum { items: sum, record: c.record_len });
        }
        return Ok(Some(items));
    }
    Ok(None)
}

/// Layers an item of a LAS 1.4 (layered) chunk has: one per field group of POINT14, one per
/// extra byte, two for RGB + NIR, one otherwise.
fn layers_of(item: (u64, u64)) -> u64 {
    match item.0 {
        10 => 9,
        12 => 2,
        14 => item.1,
        _ => 1,
    }
}

/// Walks the chunks of a layered (LAS 1.4) LAZ as `laz` reads them: the first point raw, a
/// point count, the layer sizes, the layers. `laz` allocates each layer's claimed size before
/// reading it: sizes of 0xFFFFFFFF took 4.2 GB from a 14.7 KB file. Every chunk's layers must
/// fit before the chunk table (or the end of the file). `table`: the chunk table's offset and
/// chunk count, when the file has one (a count is not trusted: the bytes bound the walk).
fn check_layers<R: Read + Seek>(
    r: &mut R,
    len: u64,
    c: &Claims,
    items: &[(u64, u64)],
    table: Option<(u64, u64)>,
) -> Result<(), LasClaim> {
    // without a table the chunks end at the first EVLR, or at the end of the file
    let end = match (table, c.evlr) {
        (Some((offset, _)), _) => offset,
        (None, Some((start, n))) if start > c.offset_to_points && n > 0 => start.min(len),
        (None, _) => len,
    };
    let nlayers: u64 = items.iter().map(|&i| layers_of(i)).sum();
    let head = c.record_len + 4 + 4 * nlayers;
    let mut at = c.offset_to_points + 8;
    let mut chunk = 0;
    let mut sizes = vec![0u8; 4 * nlayers as usize];
    // every chunk takes at least `head` bytes: the walk ends within (end - start) / head steps
    while at.saturating_add(head) <= end {
        r.seek(SeekFrom::Start(at + c.record_len + 4))?;
        r.read_exact(&mut sizes)?;
        let layers: u64 = (0..nlayers as usize).map(|k| u32_at(&sizes, 4 * k)).sum();
        let have = end - (at + head);
        if layers > have {
            return Err(LasClaim::Layers { chunk, at, layers, have });
        }
        at += head + layers;
        chunk += 1;
    }
    Ok(())
}

/// The LAZ chunk table as `laz` finds it (`ChunkTable::read_offset`): an i64 offset at the start
/// of the point data, or, when the writer could not update it, in the last 8 bytes. Returns
/// the table's (offset, chunk count) where there is one.
fn check_chunk_table<R: Read + Seek>(r: &mut R, len: u64, c: &Claims) -> Result<Option<(u64, u64)>, LasClaim> {
    let start = c.offset_to_points;
    if start.saturating_add(8) > len {
        return Ok(None); // the laz crate fails reading the offset: a plain read error
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
            return Ok(None); // no chunk table: laz reads without one
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
    Ok(Some((offset, chunks)))
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
