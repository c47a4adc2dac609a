//! The one LAS/LAZ reader: points in the `las` crate's batches, optionally of one ASPRS class,
//! after the header's claims were checked against the input's size (`input_limits::las`: a LAZ
//! chunk table of 4·10⁹ entries aborted inside `laz`, and `read_all` pre-allocated 10¹² points
//! for a 300-byte file). Memory grows with the points decoded, never with a count a header
//! claims. Errors are typed; each dialect words them ([`LasError`]'s text is the terrain one).

use std::io::Cursor;
use std::path::Path;

use input_limits::las::LasClaim;

use crate::BATCH_POINTS;

/// Why a LAS/LAZ input cannot be read, or ends short.
#[derive(Debug, thiserror::Error)]
pub enum LasError {
    /// The header claims more than the input holds, or the input could not be read to check.
    #[error("{0}")]
    Claim(LasClaim),
    /// The `las` crate refused the header.
    #[error("{0}")]
    Open(las::Error),
    /// The `las` crate could not decode points.
    #[error("{0}")]
    Read(las::Error),
    /// A point (0-based, counting every point of the file) with a NaN or infinite coordinate.
    #[error("point {index} has a non-finite coordinate")]
    NonFinite { index: usize },
    /// The file ended before the point count its header announces.
    #[error("header announces {announced} points but the file holds {held}")]
    Short { announced: u64, held: u64 },
    /// The file holds no point.
    #[error("no points")]
    NoPoints,
    /// The file holds points, but none of the wanted class; `present` lists `class (count)`.
    #[error("no point of class {class}; classes present: {present}")]
    NoPointOfClass { class: u8, present: String },
}

/// A LAS/LAZ input read batch by batch, keeping the points of `class` (all when `None`).
/// Coordinates are the scaled and offset real-world values.
pub struct LasPoints {
    reader: las::Reader,
    class: Option<u8>,
    total: u64,
    read: u64,
    kept: u64,
    classes_seen: [u64; 256],
}

impl LasPoints {
    /// Opens a LAS/LAZ file; an unopenable file is named by the `las` crate's error.
    pub fn open(path: &Path, class: Option<u8>) -> Result<LasPoints, LasError> {
        check_file_claims(path)?;
        let reader = decode_guarded(|| las::Reader::from_path(path))?.map_err(LasError::Open)?;
        Ok(LasPoints::new(reader, class))
    }

    /// Reads LAS/LAZ from bytes already in memory (stdin, a sniffed `LASF` signature).
    pub fn from_bytes(bytes: Vec<u8>, class: Option<u8>) -> Result<LasPoints, LasError> {
        let mut cursor = Cursor::new(bytes);
        let len = cursor.get_ref().len() as u64;
        input_limits::las::check(&mut cursor, len).map_err(LasError::Claim)?;
        cursor.set_position(0);
        let reader = decode_guarded(|| las::Reader::new(cursor))?.map_err(LasError::Open)?;
        Ok(LasPoints::new(reader, class))
    }

    fn new(reader: las::Reader, class: Option<u8>) -> LasPoints {
        let total = reader.header().number_of_points();
        LasPoints { reader, class, total, read: 0, kept: 0, classes_seen: [0; 256] }
    }

    /// The CRS from the WKT VLR (LAS 1.4), if the file has a non-empty one.
    pub fn wkt_crs(&self) -> Option<String> {
        let bytes = self.reader.header().get_wkt_crs_bytes()?;
        Some(String::from_utf8_lossy(bytes).trim_end_matches('\0').trim().to_string()).filter(|s| !s.is_empty())
    }

    /// The EPSG code of the GeoTIFF key VLRs (LAS 1.0–1.3): the projected code, else the
    /// geographic one; `None` for user-defined (32767) or absent codes.
    pub fn geotiff_epsg(&self) -> Option<u16> {
        let keys = self.reader.header().get_geotiff_crs().ok()??;
        let code = keys.get_projected_crs_geo_key_value().or_else(|| keys.get_geodetic_crs_geo_key_value())?;
        (code != 0 && code < 32767).then_some(code)
    }

    /// The next batch of kept points (at most [`BATCH_POINTS`] read); empty at the end.
    pub fn next_batch(&mut self) -> Result<Vec<[f64; 3]>, LasError> {
        let mut kept = Vec::new();
        while kept.is_empty() && self.read < self.total {
            let reader = &mut self.reader;
            let batch = decode_guarded(|| reader.read_points(BATCH_POINTS as u64))?.map_err(LasError::Read)?;
            if batch.is_empty() {
                break;
            }
            let first = self.read as usize;
            self.read += batch.len() as u64;
            for (i, ((x, y), (z, c))) in batch.x().zip(batch.y()).zip(batch.z().zip(batch.classification())).enumerate()
            {
                self.classes_seen[c as usize] += 1;
                if self.class.is_some_and(|k| k != c) {
                    continue;
                }
                if !(x.is_finite() && y.is_finite() && z.is_finite()) {
                    return Err(LasError::NonFinite { index: first + i });
                }
                kept.push([x, y, z]);
            }
        }
        self.kept += kept.len() as u64;
        Ok(kept)
    }

    /// After the last batch: whether the file held what its header announced and at least one
    /// kept point.
    pub fn check_end(&self) -> Result<(), LasError> {
        if self.read < self.total {
            return Err(LasError::Short { announced: self.total, held: self.read });
        }
        if self.kept > 0 {
            return Ok(());
        }
        let present: Vec<String> =
            self.classes_seen.iter().enumerate().filter(|(_, n)| **n > 0).map(|(c, n)| format!("{c} ({n})")).collect();
        Err(match self.class {
            Some(class) => LasError::NoPointOfClass { class, present: present.join(", ") },
            None => LasError::NoPoints,
        })
    }
}

/// Runs a read of the `las`/`laz` crates, turning a panic inside them into a read error:
/// corrupt compressed points can trip an assertion of `laz`'s arithmetic decoder (the `las`
/// fuzz target found `sym < (1 << 16)`, docs/decisions.md#crashes-and-hangs-of-issue-40).
/// The panic message is not printed (the error carries it). The hook is not swapped per call:
/// that raced between threads reading several files (`info a.laz b.laz`) and could leave every
/// later panic of the process silent. One hook, installed once, stays quiet only on a thread
/// inside this guard.
fn decode_guarded<T>(f: impl FnOnce() -> T) -> Result<T, LasError> {
    thread_local!(static DECODING: std::cell::Cell<bool> = const { std::cell::Cell::new(false) });
    static QUIET_HOOK: std::sync::Once = std::sync::Once::new();
    QUIET_HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !DECODING.with(std::cell::Cell::get) {
                previous(info);
            }
        }));
    });
    DECODING.with(|d| d.set(true));
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    DECODING.with(|d| d.set(false));
    r.map_err(|p| {
        let why = p
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        let e = std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("the compressed points are corrupt (the LAZ decoder failed: {why})"),
        );
        LasError::Read(las::Error::Io(e))
    })
}

/// Checks what the header of the file at `path` claims against its size before the `las` crate
/// sizes allocations by it. Skipped where the file cannot be opened or is not a regular file
/// (the `las` crate then names the error, or reads a stream).
fn check_file_claims(path: &Path) -> Result<(), LasError> {
    let Ok(mut f) = std::fs::File::open(path) else { return Ok(()) };
    let Ok(meta) = f.metadata() else { return Ok(()) };
    if !meta.is_file() {
        return Ok(());
    }
    input_limits::las::check(&mut f, meta.len()).map_err(LasError::Claim)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use las::point::Classification;

    /// A LAS 1.2 file of the given (x, y, z, class) points, written by the `las` crate.
    pub(crate) fn las_bytes(points: &[([f64; 3], u8)]) -> Vec<u8> {
        let mut writer = las::Writer::new(Cursor::new(Vec::new()), las::Header::default()).unwrap();
        for &([x, y, z], class) in points {
            let classification = Classification::new(class).unwrap();
            writer.write_point(las::Point { x, y, z, classification, ..Default::default() }).unwrap();
        }
        writer.into_inner().unwrap().into_inner()
    }

    fn all(las: &mut LasPoints) -> Result<Vec<[f64; 3]>, LasError> {
        let mut out = Vec::new();
        loop {
            let batch = las.next_batch()?;
            if batch.is_empty() {
                return Ok(out);
            }
            out.extend(batch);
        }
    }

    #[test]
    fn the_class_filter_keeps_one_class() {
        let bytes = las_bytes(&[([1.0, 2.0, 3.0], 2), ([4.0, 5.0, 6.0], 1), ([7.0, 8.0, 9.0], 2)]);
        let mut las = LasPoints::from_bytes(bytes.clone(), Some(2)).unwrap();
        assert_eq!(all(&mut las).unwrap(), [[1.0, 2.0, 3.0], [7.0, 8.0, 9.0]]);
        assert!(las.check_end().is_ok());
        let mut las = LasPoints::from_bytes(bytes, None).unwrap();
        assert_eq!(all(&mut las).unwrap().len(), 3);
        assert_eq!((las.wkt_crs(), las.geotiff_epsg()), (None, None));
    }

    #[test]
    fn no_point_of_the_class_lists_the_classes_present() {
        let mut las =
            LasPoints::from_bytes(las_bytes(&[([1.0, 2.0, 3.0], 2), ([4.0, 5.0, 6.0], 1)]), Some(17)).unwrap();
        assert_eq!(all(&mut las).unwrap(), Vec::<[f64; 3]>::new());
        assert_eq!(las.check_end().unwrap_err().to_string(), "no point of class 17; classes present: 1 (1), 2 (1)");
    }

    #[test]
    fn a_truncated_file_is_refused_before_decoding() {
        let bytes = las_bytes(&[([1.0, 2.0, 3.0], 2), ([4.0, 5.0, 6.0], 2)]);
        let cut = bytes[..bytes.len() - 10].to_vec();
        assert!(matches!(LasPoints::from_bytes(cut, None), Err(LasError::Claim(_))));
    }

    /// A LAZ file (LAS `version`, point `format`) of `n` points on a slope, by the `las` crate.
    pub(crate) fn laz_bytes(version: (u8, u8), format: u8, n: usize) -> Vec<u8> {
        let mut builder = las::Builder::from(version);
        builder.point_format = las::point::Format::new(format).unwrap();
        builder.point_format.is_compressed = true;
        let header = builder.into_header().unwrap();
        let mut writer = las::Writer::new(Cursor::new(Vec::new()), header).unwrap();
        for i in 0..n {
            let (x, y) = ((i % 50) as f64, (i / 50) as f64);
            let gps_time = (format >= 6).then_some(i as f64);
            writer.write_point(las::Point { x, y, z: 0.1 * x + 0.2 * y, gps_time, ..Default::default() }).unwrap();
        }
        writer.into_inner().unwrap().into_inner()
    }

    /// Byte offset of the first item of the LASzip VLR's item list.
    pub(crate) fn laszip_items_at(b: &[u8]) -> usize {
        let mut at = u16::from_le_bytes([b[94], b[95]]) as usize;
        loop {
            let len = u16::from_le_bytes([b[at + 20], b[at + 21]]) as usize;
            if &b[at + 2..at + 16] == b"laszip encoded" {
                return at + 54 + 34;
            }
            at += 54 + len;
        }
    }

    /// Issue 40: one byte of the LASzip VLR (POINT10's item size set to 1) made `laz` panic
    /// (`byteslice.rs: mid > len`); now the header check refuses it.
    #[test]
    fn a_laszip_item_of_the_wrong_size_is_refused() {
        let good = laz_bytes((1, 2), 0, 500);
        let mut las = LasPoints::from_bytes(good.clone(), None).unwrap();
        assert_eq!(all(&mut las).unwrap().len(), 500);
        let at = laszip_items_at(&good);
        assert_eq!(u16::from_le_bytes([good[at], good[at + 1]]), 6, "POINT10 first");
        for size in [1u16, 0, 21, 0xFFFF] {
            let mut bad = good.clone();
            bad[at + 2..at + 4].copy_from_slice(&size.to_le_bytes());
            let e = LasPoints::from_bytes(bad, None).err().expect("refused").to_string();
            assert!(e.contains(&format!("item 0 (POINT10) a size of {size} bytes")), "{e}");
        }
    }

    /// Issue 40: a LAS 1.4 LAZ whose first chunk's layer sizes are 0xFFFFFFFF took 4.2 GB before
    /// failing; now its layers are checked against the bytes that follow.
    #[test]
    fn layer_sizes_beyond_the_file_are_refused() {
        let good = laz_bytes((1, 4), 6, 3000);
        let mut las = LasPoints::from_bytes(good.clone(), None).unwrap();
        assert_eq!(all(&mut las).unwrap().len(), 3000);
        let offset = u32::from_le_bytes(good[96..100].try_into().unwrap()) as usize;
        let sizes = offset + 8 + 30 + 4; // chunk offset, raw first point, point count
        for layer in [0, 3, 8] {
            let mut bad = good.clone();
            bad[sizes + 4 * layer..sizes + 4 * layer + 4].fill(0xFF);
            let e = LasPoints::from_bytes(bad, None).err().expect("refused").to_string();
            assert!(e.starts_with("LAZ chunk 0 at byte") && e.contains("claims layers of"), "{e}");
        }
    }

    /// Found by the `las` fuzz target: a LAS 1.4 point count times the record length beyond
    /// u64 (an overflow panic inside the `las` crate), compressed or not.
    #[test]
    fn point_counts_that_overflow_are_refused() {
        for (version, format) in [((1, 4), 6), ((1, 2), 0)] {
            let mut b = laz_bytes(version, format, 100);
            b[107..111].fill(0);
            if version == (1, 4) {
                b[247..255].copy_from_slice(&u64::MAX.to_le_bytes());
            } else {
                b[107..111].copy_from_slice(&u32::MAX.to_le_bytes());
                b[105..107].copy_from_slice(&u16::MAX.to_le_bytes());
            }
            assert!(LasPoints::from_bytes(b, None).is_err());
        }
    }

    /// Every reproducer the fuzzer found (fuzz/regressions/las) is refused with an error,
    /// never a panic or an allocation the file does not justify; the corpus seeds read.
    #[test]
    fn fuzz_regressions_do_not_panic() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz");
        let files =
            |d: &str| -> Vec<_> { std::fs::read_dir(root.join(d)).unwrap().map(|e| e.unwrap().path()).collect() };
        let bad = files("regressions/las");
        assert!(!bad.is_empty(), "no reproducers");
        for f in bad {
            let read = LasPoints::from_bytes(std::fs::read(&f).unwrap(), None)
                .and_then(|mut l| all(&mut l).and(l.check_end()));
            // a corrupt compressed stream decodes to garbage where laz's debug assertions are off
            if !f.file_name().unwrap().to_string_lossy().starts_with("laz-decoder") {
                assert!(read.is_err(), "{}", f.display());
            }
        }
        for f in files("corpus/las") {
            let mut las = LasPoints::from_bytes(std::fs::read(&f).unwrap(), None).unwrap();
            assert!(!all(&mut las).unwrap().is_empty(), "{}", f.display());
        }
    }
}
