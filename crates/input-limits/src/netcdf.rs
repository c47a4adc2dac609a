//! What a netCDF classic header (CDF-1, CDF-2, CDF-5) claims, checked against the file before
//! GDAL's netCDF driver (libnetcdf) reads it.
//!
//! libnetcdf sizes allocations by header counts before it compares them with the file: one
//! attribute whose element count was flipped to 2³¹ + 2 in a 10 KB file made it allocate and
//! clear 16 GB (fuzzing the shipped GMT grids found 1.7–21 GB peaks and a hang). [`check`] walks
//! the header as the format defines it (Unidata, "The NetCDF Classic Format Specification") and
//! refuses a count whose elements cannot fit in the bytes left in the file: every dimension,
//! attribute, variable and name takes at least one byte per element in the header itself.
//! Files that do not start with `CDF` (HDF5-based netCDF-4, other formats) pass unchecked.
//!
//! # Examples
//!
//! ```
//! use input_limits::netcdf::{check, NetcdfClaim};
//!
//! // CDF-1, no records, no dimensions, one global attribute "a" of 2³¹ doubles, no variables
//! let mut header = b"CDF\x01".to_vec();
//! header.extend([0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]); // numrecs, dim_list ABSENT
//! header.extend([0, 0, 0, 0x0C, 0, 0, 0, 1]); // NC_ATTRIBUTE, 1 attribute
//! header.extend([0, 0, 0, 1, b'a', 0, 0, 0]); // its name
//! header.extend([0, 0, 0, 6, 0x80, 0, 0, 0]); // NC_DOUBLE, 2³¹ values
//! let err = check(&mut &header[..], header.len() as u64).unwrap_err();
//! assert!(matches!(err, NetcdfClaim::Count { .. }));
//! assert!(err.to_string().contains("attribute 'a'"));
//! ```

use std::io::{self, Read};

/// What the header claims that the file cannot hold.
#[derive(Debug, thiserror::Error)]
pub enum NetcdfClaim {
    #[error(
        "the netCDF header claims {count} {what} at byte {at} ({need} bytes), but only {left} bytes follow in the file"
    )]
    Count { what: String, count: u64, need: u128, at: u64, left: u64 },
    #[error("the netCDF header is malformed at byte {at}: {why}")]
    Malformed { at: u64, why: String },
    #[error("{0}")]
    Io(#[from] io::Error),
}

const NC_DIMENSION: u32 = 0x0A;
const NC_VARIABLE: u32 = 0x0B;
const NC_ATTRIBUTE: u32 = 0x0C;

/// [`check`] on the file at `path` when it is a regular file; anything else (a missing file, a
/// GDAL virtual path, a device) is left to the reader to report.
pub fn check_file(path: &std::path::Path) -> Result<(), NetcdfClaim> {
    let Ok(file) = std::fs::File::open(path) else { return Ok(()) };
    let Ok(meta) = file.metadata() else { return Ok(()) };
    if !meta.is_file() {
        return Ok(());
    }
    check(&mut io::BufReader::new(file), meta.len())
}

/// Checks the header of the file read by `r` (positioned at its start) of `len` bytes.
pub fn check<R: Read>(r: &mut R, len: u64) -> Result<(), NetcdfClaim> {
    let mut magic = [0u8; 4];
    if len < 4 || r.read_exact(&mut magic).is_err() || &magic[..3] != b"CDF" {
        return Ok(());
    }
    let version = magic[3];
    if !matches!(version, 1 | 2 | 5) {
        return Ok(()); // not a classic file libnetcdf would read as one
    }
    let mut h = Header { r, len, at: 4, wide: version == 5, wide_begin: version != 1 };
    h.count()?; // numrecs (may be the streaming marker: not a size)
    let dims = h.list(NC_DIMENSION, "dimensions", 8)?;
    for d in 0..dims {
        h.name(&format!("dimension {d}"))?;
        h.count()?; // its length: sizes data, not the header
    }
    h.attributes("global")?;
    let vars = h.list(NC_VARIABLE, "variables", 16)?;
    for v in 0..vars {
        let name = h.name(&format!("variable {v}"))?;
        let ranks = h.counted(&format!("dimension ids of variable '{name}'"), if h.wide { 8 } else { 4 })?;
        h.skip(ranks * if h.wide { 8 } else { 4 })?;
        h.attributes(&format!("variable '{name}'"))?;
        h.u32()?; // nc_type
        h.count()?; // vsize
        h.skip(if h.wide_begin { 8 } else { 4 })?; // begin
    }
    Ok(())
}

struct Header<'r, R> {
    r: &'r mut R,
    len: u64,
    at: u64,
    /// CDF-5: counts and dimension ids are 8 bytes.
    wide: bool,
    /// CDF-2 and CDF-5: variable offsets are 8 bytes.
    wide_begin: bool,
}

impl<R: Read> Header<'_, R> {
    fn u32(&mut self) -> Result<u32, NetcdfClaim> {
        let mut b = [0u8; 4];
        self.read(&mut b)?;
        Ok(u32::from_be_bytes(b))
    }

    fn count(&mut self) -> Result<u64, NetcdfClaim> {
        if !self.wide {
            return self.u32().map(u64::from);
        }
        let mut b = [0u8; 8];
        self.read(&mut b)?;
        Ok(u64::from_be_bytes(b))
    }

    fn read(&mut self, buf: &mut [u8]) -> Result<(), NetcdfClaim> {
        self.r.read_exact(buf).map_err(|e| match e.kind() {
            io::ErrorKind::UnexpectedEof => {
                NetcdfClaim::Malformed { at: self.at, why: "the header ends before the file does".into() }
            }
            _ => NetcdfClaim::Io(e),
        })?;
        self.at += buf.len() as u64;
        Ok(())
    }

    fn skip(&mut self, n: u64) -> Result<(), NetcdfClaim> {
        let copied = io::copy(&mut self.r.by_ref().take(n), &mut io::sink())?;
        self.at += copied;
        if copied < n {
            return Err(NetcdfClaim::Malformed { at: self.at, why: "the header ends before the file does".into() });
        }
        Ok(())
    }

    /// A count of elements of at least `bytes_each` header bytes each, refused when they
    /// cannot fit in what is left of the file.
    fn counted(&mut self, what: &str, bytes_each: u64) -> Result<u64, NetcdfClaim> {
        let at = self.at;
        let count = self.count()?;
        let need = count as u128 * bytes_each as u128;
        let left = self.len.saturating_sub(self.at);
        if need > left as u128 {
            return Err(NetcdfClaim::Count { what: what.to_string(), count, need, at, left });
        }
        Ok(count)
    }

    /// A tagged list: ABSENT (two zeros) or the tag and its element count.
    fn list(&mut self, tag: u32, what: &str, bytes_each: u64) -> Result<u64, NetcdfClaim> {
        let at = self.at;
        let found = self.u32()?;
        let count = self.counted(what, bytes_each)?;
        if found != tag && !(found == 0 && count == 0) {
            return Err(NetcdfClaim::Malformed {
                at,
                why: format!("expected the tag of the {what} list ({tag:#x}) or none, found {found:#x}"),
            });
        }
        Ok(count)
    }

    /// A name: its length, then its bytes padded to 4; returned for messages (cut to 64 bytes).
    fn name(&mut self, what: &str) -> Result<String, NetcdfClaim> {
        let n = self.counted(&format!("name bytes of {what}"), 1)?;
        let mut shown = vec![0u8; n.min(64) as usize];
        self.read(&mut shown)?;
        self.skip(padded(n) - shown.len() as u64)?;
        // a corrupt name may hold control bytes: they would garble a one-line message
        Ok(String::from_utf8_lossy(&shown).chars().map(|c| if c.is_control() { '?' } else { c }).collect())
    }

    fn attributes(&mut self, owner: &str) -> Result<(), NetcdfClaim> {
        let n = self.list(NC_ATTRIBUTE, &format!("attributes of {owner}"), 12)?;
        for a in 0..n {
            let name = self.name(&format!("attribute {a} of {owner}"))?;
            let at = self.at;
            let size = type_size(self.u32()?)
                .ok_or_else(|| NetcdfClaim::Malformed { at, why: format!("attribute '{name}' has an unknown type") })?;
            let values = self.counted(&format!("values of attribute '{name}'"), size)?;
            self.skip(padded(values * size))?;
        }
        Ok(())
    }
}

fn padded(n: u64) -> u64 {
    n.div_ceil(4) * 4
}

/// Bytes per value of a netCDF external type (classic and CDF-5 types).
fn type_size(nc_type: u32) -> Option<u64> {
    match nc_type {
        1 | 2 | 7 => Some(1),
        3 | 8 => Some(2),
        4 | 5 | 9 => Some(4),
        6 | 10 | 11 => Some(8),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grid of `../shared/fixtures/terrain` (or `$GEOFIT_SHARED/fixtures/terrain`); missing is
    /// a failure in CI, a printed skip elsewhere.
    fn shipped(name: &str) -> Option<Vec<u8>> {
        let shared = std::env::var_os("GEOFIT_SHARED")
            .map(std::path::PathBuf::from)
            .unwrap_or_else(|| std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared"));
        let path = shared.join("fixtures/terrain").join(name);
        let file = std::fs::read(&path).ok();
        if file.is_none() && std::env::var("CI").is_ok_and(|v| v == "true" || v == "1") {
            panic!("fixture missing in CI: {}", path.display());
        }
        file
    }

    /// The shipped classic grids pass; the same grids with one attribute count raised to 2³¹ + 2
    /// (what made libnetcdf allocate 16 GB) are refused naming that attribute.
    #[test]
    fn shipped_grids_pass_and_a_raised_attribute_count_is_refused() {
        for name in ["gmt_tut_bathy.nc", "gmt_guinea_bay.nc"] {
            let Some(file) = shipped(name) else {
                eprintln!("SKIP: fixture {name} not found (set GEOFIT_SHARED)");
                continue;
            };
            check(&mut &file[..], file.len() as u64).unwrap();
            let at = file.windows(12).position(|w| w == b"actual_range").expect("an actual_range attribute") + 12 + 4;
            let mut bad = file.clone();
            bad[at] = 0x80;
            let e = check(&mut &bad[..], bad.len() as u64).unwrap_err();
            assert!(e.to_string().contains("values of attribute 'actual_range'"), "{e}");
        }
    }

    #[test]
    fn other_formats_pass_unchecked() {
        assert!(check(&mut &b"\x89HDF\r\n\x1a\n"[..], 8).is_ok());
        assert!(check(&mut &b"CDF"[..], 3).is_ok());
    }

    #[test]
    fn a_truncated_header_is_malformed() {
        let e = check(&mut &b"CDF\x01\0\0\0\0\0\0\0\x0a"[..], 12).unwrap_err();
        assert!(matches!(e, NetcdfClaim::Malformed { .. }), "{e}");
    }
}
