//! The compact binary T-mesh (`.tmb`): the same surface as the XML `.tmesh` (the documented
//! exchange format, [`crate::format`]) in a fraction of the bytes; lossless, or with the
//! heights stored to an error budget ([`heights`], issue 37). The full byte layout, for
//! readers outside geofit, is in docs/tmb-format.md.
//!
//! Why: a text line "s t x y z w" spends ~60 bytes per control point where the information of
//! a direct fit is one height; the reduced model was often bigger than the raster it reduces
//! (issue 19). Here the mesh structure is implicit and the heights are compressed.
//!
//! Layout (little-endian):
//! ```text
//! magic    8 bytes  89 'T' 'M' 'B' 0D 0A 1A 0A   (PNG-style: catches text-mode mangling)
//! version  u8       2 (1: the same body, zlib instead of zstd, never quantised; still read)
//! body_len u64      bytes of the body before compression
//! body     one zstd frame of the body (version 1: a deflate (zlib) stream)
//! crc32    u32      CRC-32 (IEEE) of the uncompressed body
//! ```
//! Body: `degree u8`, `flags u8`, the georeference (`x0 y0 dx dy` f64, CRS as varint length +
//! UTF-8), the structure, then the per-point arrays, the mask and the warp:
//! - structure, flag [`QUADTREE`]: the leaf cells as a forest of quadtrees over `ns × nt` root
//!   squares of side `c0` from (`s0`, `t0`) (f64, f64, f64, varint, varint): one bit per node in
//!   depth-first order (children SW, SE, NW, NE), 1 = split at the centre, 0 = leaf — what
//!   the fit produces (4-way splits of an initial grid), ~1.3 bits per leaf cell. Flag
//!   [`KDTREE`] (meshes of `fit --split aniso`, docs/decisions.md#anisotropic-splits-issue-19):
//!   the same roots, two bits per node (0 leaf, 1 four children SW, SE, NW, NE, 2 cut across s:
//!   W, E, 3 cut across t: S, N), a varint symbol count and the symbols four to a byte, low bits
//!   first. Otherwise the explicit form: the distinct s and t values (varint count + f64 each) and per cell four
//!   varint indices into them (s_min, s_max − s_min, t_min, t_max − t_min).
//! - control points are the leaf corners in the canonical order of [`canonical`] (by t, then
//!   s), so neither their count nor their parameters are stored. Heights, flag [`QUANT`]:
//!   quantised to a step (see [`heights`]); else lossless: each f64 XOR-ed with
//!   the previous one (neighbours share sign, exponent and leading mantissa bits), then the 8
//!   byte planes one after the other (the compressor then finds the zero runs). `x, y`
//!   (flag [`XY`], else x = s, y = t) and `w` (flag [`W`], else 1) always lossless that way.
//! - mask (flag [`MASK`]): width, height, run count and the runs as varints (as the XML: from
//!   t = 0, alternating no data / data, starting with no data); warp (flag [`WARP`]): varint
//!   length + the JSON.
//!
//! Lossless: `read(write(f))` gives the mesh [`canonical`] gives, bit for bit; evaluation
//! sums over points in the order of their parameters, not their ids (`PbSpline::from_parts`),
//! so `.tmb` and `.tmesh` of one fit evaluate to the same bits. Quantised
//! ([`write_with`]): the same mesh with every height within `q` of its own, so the surface
//! within `q` of the lossless one at every point. Every defect of a file (magic, version, truncation, checksum, lengths, an invalid mesh)
//! is a [`TsplineError::Format`] naming it, never a panic.

pub mod heights;

use std::collections::{HashMap, HashSet};
use std::io::{Read, Write};

use crate::format::{DataMask, Georef, TMeshFile};
use crate::mesh::{ControlPoint, Degree, PointId, Rect, TMesh};
use crate::TsplineError;

pub const MAGIC: &[u8; 8] = b"\x89TMB\r\n\x1a\n";
/// The version written; [`read`] also reads 1 (zlib body, lossless heights).
pub const VERSION: u8 = 2;
/// Structure flag: leaf cells as a quadtree forest (else explicit).
pub const QUADTREE: u8 = 1;
/// Control points' x, y stored (else x = s, y = t).
pub const XY: u8 = 2;
/// Weights stored (else 1).
pub const W: u8 = 4;
pub const MASK: u8 = 8;
pub const WARP: u8 = 16;
/// Structure flag: leaf cells as a forest of 2-/4-split trees (anisotropic refinement, see
/// `kdtree`); only when the quadtree form does not fit.
pub const KDTREE: u8 = 32;
/// Heights quantised to a step (version 2; [`heights`]).
pub const QUANT: u8 = 64;
/// zstd level of the body: the smallest files; ~0.1 s for a body of 10⁵ points.
const ZSTD_LEVEL: i32 = 19;
/// Largest body a reader inflates (a corrupt length must not allocate terabytes).
const MAX_BODY: u64 = 1 << 36;

/// The leaf-only mesh with points ordered by (t, s) and cells by (t_min, s_min): the order the
/// binary form stores (implicit in the structure, so no ids are stored).
pub fn canonical(mesh: &TMesh) -> TMesh {
    let active = mesh.active_points();
    let mut ids: Vec<u32> = (0..mesh.points.len() as u32).filter(|&i| active[i as usize]).collect();
    ids.sort_by(|&a, &b| {
        let (p, q) = (&mesh.points[a as usize], &mesh.points[b as usize]);
        p.t.total_cmp(&q.t).then(p.s.total_cmp(&q.s))
    });
    let mut remap = vec![u32::MAX; mesh.points.len()];
    for (k, &i) in ids.iter().enumerate() {
        remap[i as usize] = k as u32;
    }
    let points: Vec<ControlPoint> = ids.iter().map(|&i| mesh.points[i as usize]).collect();
    let mut cells: Vec<(Rect, [PointId; 4])> =
        mesh.cells.iter().filter(|c| c.is_leaf()).map(|c| (c.rect, c.corners.map(|p| remap[p as usize]))).collect();
    cells.sort_by(|a, b| a.0.t_min.total_cmp(&b.0.t_min).then(a.0.s_min.total_cmp(&b.0.s_min)));
    TMesh::from_cells(mesh.degree, points, cells.into_iter().map(|c| c.1).collect())
        .expect("a valid mesh stays valid when reordered")
}

fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

fn put_f64(out: &mut Vec<u8>, v: f64) {
    out.extend_from_slice(&v.to_le_bytes());
}

/// XOR with the previous value, then byte planes (see the module doc).
fn put_f64s(out: &mut Vec<u8>, v: &[f64]) {
    let mut prev = 0u64;
    let x: Vec<[u8; 8]> = v
        .iter()
        .map(|a| {
            let b = a.to_bits();
            let d = b ^ prev;
            prev = b;
            d.to_le_bytes()
        })
        .collect();
    for plane in 0..8 {
        out.extend(x.iter().map(|b| b[plane]));
    }
}

fn rect_key(r: &Rect) -> [u64; 4] {
    [r.s_min, r.t_min, r.s_max, r.t_max].map(|v| (v + 0.0).to_bits())
}

/// Children of a quadtree square as `TMesh::split` makes them, in the order SW, SE, NW, NE.
fn children(r: &Rect) -> [Rect; 4] {
    let sm = 0.5 * (r.s_min + r.s_max);
    let tm = 0.5 * (r.t_min + r.t_max);
    [
        Rect::new(r.s_min, r.t_min, sm, tm),
        Rect::new(sm, r.t_min, r.s_max, tm),
        Rect::new(r.s_min, tm, sm, r.t_max),
        Rect::new(sm, tm, r.s_max, r.t_max),
    ]
}

/// Depth limit of a quadtree (2⁶⁰ subdivisions is far past f64 resolution).
const MAX_DEPTH: usize = 60;

/// The lattice of equal squares both tree forms start from: the largest leaf's size, from the
/// leaves' lower-left corner, as many columns and rows as cover them.
#[derive(Debug, Clone, Copy)]
struct Roots {
    s0: f64,
    t0: f64,
    c0: f64,
    ns: u64,
    nt: u64,
}

impl Roots {
    /// The lattice of `leaves`, or None when it is degenerate (no extent, ≥ 4·10⁹ roots a side).
    fn of_leaves(leaves: &[Rect]) -> Option<Roots> {
        let c0 = leaves.iter().map(|r| r.width().max(r.height())).fold(0.0, f64::max);
        let s0 = leaves.iter().map(|r| r.s_min).fold(f64::INFINITY, f64::min);
        let t0 = leaves.iter().map(|r| r.t_min).fold(f64::INFINITY, f64::min);
        let s1 = leaves.iter().map(|r| r.s_max).fold(f64::NEG_INFINITY, f64::max);
        let t1 = leaves.iter().map(|r| r.t_max).fold(f64::NEG_INFINITY, f64::max);
        let ns = ((s1 - s0) / c0).round();
        let nt = ((t1 - t0) / c0).round();
        if !(c0 > 0.0 && ns >= 1.0 && nt >= 1.0 && ns < 4e9 && nt < 4e9) {
            return None;
        }
        Some(Roots { s0, t0, c0, ns: ns as u64, nt: nt as u64 })
    }

    /// The lattice as a tree form's header stores it.
    fn read(c: &mut Cursor) -> Result<Roots, TsplineError> {
        let (s0, t0, c0) = (c.f64("root s0")?, c.f64("root t0")?, c.f64("root size")?);
        if c0 <= 0.0 {
            return Err(c.err("root size must be positive"));
        }
        let ns = c.varint("root columns")?;
        let nt = c.varint("root rows")?;
        Ok(Roots { s0, t0, c0, ns, nt })
    }

    /// The root squares row by row from the bottom: the order in which both forms walk them.
    fn cells(self) -> impl Iterator<Item = Rect> {
        let Roots { s0, t0, c0, ns, nt } = self;
        (0..nt).flat_map(move |j| {
            (0..ns).map(move |i| {
                Rect::new(s0 + i as f64 * c0, t0 + j as f64 * c0, s0 + (i + 1) as f64 * c0, t0 + (j + 1) as f64 * c0)
            })
        })
    }
}

/// The quadtree encoding of the leaves, or None when they are not a quadtree forest over a
/// regular grid of squares.
fn quadtree(leaves: &[Rect]) -> Option<(f64, f64, f64, u64, u64, Vec<u8>)> {
    let roots = Roots::of_leaves(leaves)?;
    let set: HashSet<[u64; 4]> = leaves.iter().map(rect_key).collect();
    let mut bits = Vec::new();
    let mut found = 0usize;
    fn walk(r: Rect, depth: usize, set: &HashSet<[u64; 4]>, bits: &mut Vec<u8>, found: &mut usize) -> bool {
        if set.contains(&rect_key(&r)) {
            bits.push(0);
            *found += 1;
            return true;
        }
        if depth >= MAX_DEPTH {
            return false;
        }
        bits.push(1);
        children(&r).into_iter().all(|c| walk(c, depth + 1, set, bits, found))
    }
    if !roots.cells().all(|r| walk(r, 0, &set, &mut bits, &mut found)) || found != leaves.len() {
        return None;
    }
    Some((roots.s0, roots.t0, roots.c0, roots.ns, roots.nt, packed_symbols(&bits, TreeForm::Quad)))
}

/// The 2-/4-split tree encoding of the leaves (flag [`KDTREE`]), or None when they are not such
/// a forest over a regular grid of squares: at each node, the leaves inside it decide the
/// split (a cut at a mid-line exists where no leaf crosses it: both cuts are a 4-split, one is a
/// 2-split); a leaf larger than a node, or a node with no cut, is not such a forest.
fn kdtree(leaves: &[Rect]) -> Option<(f64, f64, f64, u64, u64, Vec<u8>)> {
    use rstar::{primitives::Rectangle, RTree, AABB};
    let roots = Roots::of_leaves(leaves)?;
    let tree: RTree<Rectangle<[f64; 2]>> = RTree::bulk_load(
        leaves.iter().map(|r| Rectangle::from_corners([r.s_min, r.t_min], [r.s_max, r.t_max])).collect(),
    );
    let mut syms: Vec<u8> = Vec::new();
    let mut found = 0usize;
    fn walk(r: Rect, depth: usize, tree: &RTree<Rectangle<[f64; 2]>>, syms: &mut Vec<u8>, found: &mut usize) -> bool {
        // the leaves overlapping the node's interior
        let inside: Vec<Rect> = tree
            .locate_in_envelope_intersecting(&AABB::from_corners([r.s_min, r.t_min], [r.s_max, r.t_max]))
            .map(|e| Rect::new(e.lower()[0], e.lower()[1], e.upper()[0], e.upper()[1]))
            .filter(|o| o.s_max.min(r.s_max) > o.s_min.max(r.s_min) && o.t_max.min(r.t_max) > o.t_min.max(r.t_min))
            .collect();
        if inside.is_empty()
            || inside.iter().any(|o| o.s_min < r.s_min || o.s_max > r.s_max || o.t_min < r.t_min || o.t_max > r.t_max)
        {
            return false; // a hole, or a leaf larger than the node
        }
        if inside.len() == 1 && inside[0] == r {
            syms.push(0);
            *found += 1;
            return true;
        }
        if depth >= MAX_DEPTH {
            return false;
        }
        let sm = 0.5 * (r.s_min + r.s_max);
        let tm = 0.5 * (r.t_min + r.t_max);
        let cut_s = !inside.iter().any(|o| o.s_min < sm && sm < o.s_max);
        let cut_t = !inside.iter().any(|o| o.t_min < tm && tm < o.t_max);
        let (sym, kids): (u8, Vec<Rect>) = match (cut_s, cut_t) {
            (true, true) => (1, children(&r).to_vec()),
            (true, false) => {
                (2, vec![Rect::new(r.s_min, r.t_min, sm, r.t_max), Rect::new(sm, r.t_min, r.s_max, r.t_max)])
            }
            (false, true) => {
                (3, vec![Rect::new(r.s_min, r.t_min, r.s_max, tm), Rect::new(r.s_min, tm, r.s_max, r.t_max)])
            }
            (false, false) => return false,
        };
        syms.push(sym);
        kids.into_iter().all(|c| walk(c, depth + 1, tree, syms, found))
    }
    if !roots.cells().all(|r| walk(r, 0, &tree, &mut syms, &mut found)) || found != leaves.len() {
        return None;
    }
    Some((roots.s0, roots.t0, roots.c0, roots.ns, roots.nt, packed_symbols(&syms, TreeForm::Kd)))
}

/// How [`write_with`] stores the heights.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct WriteOptions {
    /// The storage share `q` of the tolerance: heights rounded to multiples of `2q`, so each
    /// moves by at most `q` and so does the surface (partition of unity,
    /// docs/decisions.md#heights-quantised-to-the-error-budget-issue-37). None: lossless.
    pub quantum: Option<f64>,
}

/// Writes the compact binary form of `f`, lossless.
pub fn write(f: &TMeshFile, w: &mut dyn Write) -> std::io::Result<()> {
    write_with(f, &WriteOptions::default(), w)
}

/// Writes the compact binary form of `f` with the heights as `opts` says; a quantum too small
/// for the heights (more than 2⁵² steps) is an `InvalidInput` error.
pub fn write_with(f: &TMeshFile, opts: &WriteOptions, w: &mut dyn Write) -> std::io::Result<()> {
    let m = canonical(&f.mesh);
    let mut body = Vec::new();
    let leaves: Vec<Rect> = m.cells.iter().map(|c| c.rect).collect();
    let qt = quadtree(&leaves);
    let kd = if qt.is_none() { kdtree(&leaves) } else { None };
    let xy = m.points.iter().any(|p| p.x.to_bits() != p.s.to_bits() || p.y.to_bits() != p.t.to_bits());
    let wt = m.points.iter().any(|p| p.w != 1.0);
    let mut flags = 0;
    if qt.is_some() {
        flags |= QUADTREE;
    }
    if kd.is_some() {
        flags |= KDTREE;
    }
    if xy {
        flags |= XY;
    }
    if wt {
        flags |= W;
    }
    if f.mask.is_some() {
        flags |= MASK;
    }
    if f.warp.is_some() {
        flags |= WARP;
    }
    if opts.quantum.is_some() {
        flags |= QUANT;
    }
    body.push(m.degree.k() as u8);
    body.push(flags);
    let g = &f.georef;
    for v in [g.x0, g.y0, g.dx, g.dy] {
        put_f64(&mut body, v);
    }
    put_varint(&mut body, g.crs.len() as u64);
    body.extend_from_slice(g.crs.as_bytes());
    match qt.or(kd) {
        Some((s0, t0, c0, ns, nt, bits)) => {
            for v in [s0, t0, c0] {
                put_f64(&mut body, v);
            }
            put_varint(&mut body, ns);
            put_varint(&mut body, nt);
            body.extend_from_slice(&bits);
        }
        None => {
            // (+0.0: -0.0 and 0.0 are one lattice value)
            let mut sv: Vec<f64> = m.points.iter().map(|p| p.s + 0.0).collect();
            let mut tv: Vec<f64> = m.points.iter().map(|p| p.t + 0.0).collect();
            for v in [&mut sv, &mut tv] {
                v.sort_by(|a, b| a.total_cmp(b));
                v.dedup();
            }
            for v in [&sv, &tv] {
                put_varint(&mut body, v.len() as u64);
                v.iter().for_each(|&x| put_f64(&mut body, x));
            }
            let idx = |v: &[f64], x: f64| {
                v.binary_search_by(|a| a.total_cmp(&(x + 0.0))).expect("a corner value is in its list") as u64
            };
            put_varint(&mut body, leaves.len() as u64);
            for r in &leaves {
                let (a, b) = (idx(&sv, r.s_min), idx(&sv, r.s_max));
                let (c, d) = (idx(&tv, r.t_min), idx(&tv, r.t_max));
                for v in [a, b - a, c, d - c] {
                    put_varint(&mut body, v);
                }
            }
        }
    }
    let z: Vec<f64> = m.points.iter().map(|p| p.z).collect();
    match opts.quantum {
        Some(q) => heights::encode(&z, heights::step_for(q), &mut body)
            .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e))?,
        None => put_f64s(&mut body, &z),
    }
    if xy {
        put_f64s(&mut body, &m.points.iter().map(|p| p.x).collect::<Vec<_>>());
        put_f64s(&mut body, &m.points.iter().map(|p| p.y).collect::<Vec<_>>());
    }
    if wt {
        put_f64s(&mut body, &m.points.iter().map(|p| p.w).collect::<Vec<_>>());
    }
    if let Some(mask) = &f.mask {
        put_varint(&mut body, mask.width as u64);
        put_varint(&mut body, mask.height as u64);
        let runs = mask.runs();
        put_varint(&mut body, runs.len() as u64);
        runs.iter().for_each(|&r| put_varint(&mut body, r as u64));
    }
    if let Some(json) = &f.warp {
        put_varint(&mut body, json.len() as u64);
        body.extend_from_slice(json.as_bytes());
    }
    seal(&body, w)
}

/// The header, the zstd frame of `body` and its checksum.
fn seal(body: &[u8], w: &mut dyn Write) -> std::io::Result<()> {
    let packed = zstd::bulk::compress(body, ZSTD_LEVEL)?;
    let mut crc = flate2::Crc::new();
    crc.update(body);
    w.write_all(MAGIC)?;
    w.write_all(&[VERSION])?;
    w.write_all(&(body.len() as u64).to_le_bytes())?;
    w.write_all(&packed)?;
    w.write_all(&crc.sum().to_le_bytes())?;
    Ok(())
}

/// Bounds-checked reader of the body; errors name the byte offset in the body.
struct Cursor<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Cursor<'a> {
    fn err(&self, msg: impl Into<String>) -> TsplineError {
        TsplineError::Format { pos: format!("body byte {}", self.pos), msg: msg.into() }
    }
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], TsplineError> {
        if self.data.len() - self.pos < n {
            return Err(self
                .err(format!("the body ends inside {what} ({n} bytes needed, {} left)", self.data.len() - self.pos)));
        }
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn u8(&mut self, what: &str) -> Result<u8, TsplineError> {
        Ok(self.take(1, what)?[0])
    }
    fn f64(&mut self, what: &str) -> Result<f64, TsplineError> {
        let v = f64::from_le_bytes(self.take(8, what)?.try_into().expect("8 bytes"));
        if !v.is_finite() {
            return Err(self.err(format!("{what} is not finite")));
        }
        Ok(v)
    }
    fn varint(&mut self, what: &str) -> Result<u64, TsplineError> {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let b = self.u8(what)?;
            v |= ((b & 0x7f) as u64) << shift;
            if b & 0x80 == 0 {
                return Ok(v);
            }
        }
        Err(self.err(format!("{what}: varint longer than 64 bits")))
    }
    /// A count of items of `item_bytes` each that must fit in what is left.
    fn count(&mut self, item_bytes: usize, what: &str) -> Result<usize, TsplineError> {
        let n = self.varint(what)?;
        if n.saturating_mul(item_bytes.max(1) as u64) > (self.data.len() - self.pos) as u64 {
            return Err(self.err(format!("{what} {n} exceeds the rest of the body")));
        }
        Ok(n as usize)
    }
    fn f64s(&mut self, n: usize, what: &str) -> Result<Vec<f64>, TsplineError> {
        let planes = self.take(n.checked_mul(8).ok_or_else(|| self.err(format!("{what}: too many values")))?, what)?;
        let mut prev = 0u64;
        let mut out = Vec::with_capacity(n);
        for i in 0..n {
            let mut b = [0u8; 8];
            for (p, bp) in b.iter_mut().enumerate() {
                *bp = planes[p * n + i];
            }
            prev ^= u64::from_le_bytes(b);
            let v = f64::from_bits(prev);
            if !v.is_finite() {
                return Err(self.err(format!("{what}: value {i} is not finite")));
            }
            out.push(v);
        }
        Ok(out)
    }
    fn string(&mut self, what: &str) -> Result<String, TsplineError> {
        let n = self.count(1, what)?;
        let b = self.take(n, what)?;
        String::from_utf8(b.to_vec()).map_err(|_| self.err(format!("{what} is not UTF-8")))
    }
}

fn head_err(pos: usize, msg: impl Into<String>) -> TsplineError {
    TsplineError::Format { pos: format!("byte {pos}"), msg: msg.into() }
}

/// Reads a `.tmb` file (see the module doc); `data` starts with [`MAGIC`].
pub fn read(data: &[u8]) -> Result<TMeshFile, TsplineError> {
    if !data.starts_with(MAGIC) {
        return Err(head_err(0, "not a binary T-mesh (magic bytes missing)"));
    }
    if data.len() < 8 + 1 + 8 + 4 {
        return Err(head_err(
            data.len(),
            format!("truncated binary T-mesh: {} bytes, the header and checksum alone take 21", data.len()),
        ));
    }
    let version = data[8];
    if version != 1 && version != VERSION {
        return Err(head_err(
            8,
            format!("binary T-mesh version {version} is not supported (this reader knows 1 and {VERSION})"),
        ));
    }
    let body_len = u64::from_le_bytes(data[9..17].try_into().expect("8 bytes"));
    if body_len > MAX_BODY {
        return Err(head_err(9, format!("body length {body_len} is beyond any T-mesh (corrupt header)")));
    }
    let (packed, crc_bytes) = data[17..].split_at(data.len() - 17 - 4);
    let mut body = Vec::with_capacity(body_len.min(1 << 26) as usize);
    let damaged = |e: std::io::Error| head_err(17, format!("the compressed body is damaged or truncated: {e}"));
    if version == 1 {
        flate2::read::ZlibDecoder::new(packed).take(body_len + 1).read_to_end(&mut body).map_err(damaged)?;
    } else {
        // streaming, so a corrupt length cannot allocate more than the frame holds
        zstd::stream::read::Decoder::with_buffer(packed)
            .map_err(damaged)?
            .take(body_len + 1)
            .read_to_end(&mut body)
            .map_err(damaged)?;
    }
    if body.len() as u64 != body_len {
        return Err(head_err(
            17,
            format!("the body holds {} bytes, the header says {body_len} (truncated or corrupt file)", body.len()),
        ));
    }
    let mut crc = flate2::Crc::new();
    crc.update(&body);
    let want = u32::from_le_bytes(crc_bytes.try_into().expect("4 bytes"));
    if crc.sum() != want {
        return Err(head_err(
            data.len() - 4,
            format!("checksum mismatch (CRC-32 {:08x}, file says {want:08x}): the file is corrupt", crc.sum()),
        ));
    }
    parse_body(&body, version)
}

fn parse_body(body: &[u8], version: u8) -> Result<TMeshFile, TsplineError> {
    let mut c = Cursor { data: body, pos: 0 };
    let k = c.u8("degree")?;
    let degree = Degree::from_u32(k as u32).ok_or_else(|| c.err(format!("degree {k} is not supported (1 or 3)")))?;
    let flags = c.u8("flags")?;
    let known = if version == 1 {
        QUADTREE | XY | W | MASK | WARP | KDTREE
    } else {
        QUADTREE | XY | W | MASK | WARP | KDTREE | QUANT
    };
    if flags & !known != 0 || flags & (QUADTREE | KDTREE) == QUADTREE | KDTREE {
        return Err(c.err(format!("unknown flags {flags:#04x}")));
    }
    let georef = Georef {
        x0: c.f64("georef x0")?,
        y0: c.f64("georef y0")?,
        dx: c.f64("georef dx")?,
        dy: c.f64("georef dy")?,
        crs: c.string("CRS")?,
    };
    if georef.dx == 0.0 || georef.dy == 0.0 {
        return Err(c.err("georef dx and dy must be non-zero"));
    }
    let leaves = if flags & QUADTREE != 0 {
        read_tree(&mut c, TreeForm::Quad)?
    } else if flags & KDTREE != 0 {
        read_tree(&mut c, TreeForm::Kd)?
    } else {
        read_explicit(&mut c)?
    };
    // points: the leaf corners in canonical order
    let mut st: Vec<(f64, f64)> = leaves
        .iter()
        .flat_map(|r| [(r.s_min, r.t_max), (r.s_max, r.t_max), (r.s_min, r.t_min), (r.s_max, r.t_min)])
        .collect();
    st.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.total_cmp(&b.0)));
    st.dedup_by(|a, b| a.0 == b.0 && a.1 == b.1);
    let n = st.len();
    let z = if flags & QUANT != 0 {
        let (z, used) = heights::decode(&c.data[c.pos..], n).map_err(|e| c.err(format!("quantised heights: {e}")))?;
        c.pos += used;
        z
    } else {
        c.f64s(n, "heights")?
    };
    let (x, y) = if flags & XY != 0 {
        (c.f64s(n, "x")?, c.f64s(n, "y")?)
    } else {
        (st.iter().map(|p| p.0).collect(), st.iter().map(|p| p.1).collect())
    };
    let w = if flags & W != 0 { c.f64s(n, "weights")? } else { vec![1.0; n] };
    let points: Vec<ControlPoint> =
        (0..n).map(|i| ControlPoint { s: st[i].0, t: st[i].1, x: x[i], y: y[i], z: z[i], w: w[i] }).collect();
    let mut id: HashMap<(u64, u64), PointId> = HashMap::with_capacity(n);
    for (i, p) in st.iter().enumerate() {
        id.insert(((p.0 + 0.0).to_bits(), (p.1 + 0.0).to_bits()), i as PointId);
    }
    let pid = |s: f64, t: f64| id[&((s + 0.0).to_bits(), (t + 0.0).to_bits())];
    let mut cells: Vec<(Rect, [PointId; 4])> = leaves
        .iter()
        .map(|r| (*r, [pid(r.s_min, r.t_max), pid(r.s_max, r.t_max), pid(r.s_min, r.t_min), pid(r.s_max, r.t_min)]))
        .collect();
    cells.sort_by(|a, b| a.0.t_min.total_cmp(&b.0.t_min).then(a.0.s_min.total_cmp(&b.0.s_min)));
    let mask = if flags & MASK != 0 { Some(read_mask(&mut c)?) } else { None };
    let warp = if flags & WARP != 0 { Some(c.string("warp")?) } else { None };
    if c.pos != body.len() {
        return Err(c.err(format!("{} bytes after the last section", body.len() - c.pos)));
    }
    let mesh = TMesh::from_cells(degree, points, cells.into_iter().map(|c| c.1).collect())
        .map_err(|e| TsplineError::Format { pos: "structure".into(), msg: e.to_string() })?;
    Ok(TMeshFile { mesh, georef, mask, warp })
}

/// The two tree forms as the reader walks them: a symbol per node, of one bit (quadtree: leaf
/// or 4-split) or two (KDTREE: leaf, 4-split, cut across s, cut across t).
#[derive(Debug, Clone, Copy, PartialEq)]
enum TreeForm {
    Quad,
    Kd,
}

impl TreeForm {
    fn bits(self) -> usize {
        match self {
            TreeForm::Quad => 1,
            TreeForm::Kd => 2,
        }
    }
    /// (form, symbol, symbols) as the error messages name them.
    fn names(self) -> (&'static str, &'static str, &'static str) {
        match self {
            TreeForm::Quad => ("quadtree", "bit", "bits"),
            TreeForm::Kd => ("tree", "symbol", "symbols"),
        }
    }
    /// The children a split symbol `v` (≠ 0) makes of `r`, in the writer's order.
    fn children(self, v: u8, r: &Rect) -> Vec<Rect> {
        let sm = 0.5 * (r.s_min + r.s_max);
        let tm = 0.5 * (r.t_min + r.t_max);
        match (self, v) {
            (TreeForm::Quad, _) | (TreeForm::Kd, 1) => children(r).to_vec(),
            (TreeForm::Kd, 2) => {
                vec![Rect::new(r.s_min, r.t_min, sm, r.t_max), Rect::new(sm, r.t_min, r.s_max, r.t_max)]
            }
            _ => vec![Rect::new(r.s_min, r.t_min, r.s_max, tm), Rect::new(r.s_min, tm, r.s_max, r.t_max)],
        }
    }
}

/// A tree form's symbols as stored: their count (varint), then `form.bits()` bits each, from the
/// low bits of each byte up.
fn packed_symbols(syms: &[u8], form: TreeForm) -> Vec<u8> {
    let bits = form.bits();
    let mut packed = vec![0u8; (syms.len() * bits).div_ceil(8)];
    for (k, &v) in syms.iter().enumerate() {
        packed[k * bits / 8] |= v << (k * bits % 8);
    }
    let mut head = Vec::new();
    put_varint(&mut head, syms.len() as u64);
    head.extend_from_slice(&packed);
    head
}

/// The leaves of a tree-form body: the roots, then each root's nodes depth first.
fn read_tree(c: &mut Cursor, form: TreeForm) -> Result<Vec<Rect>, TsplineError> {
    let (name, one, many) = form.names();
    let roots = Roots::read(c)?;
    let (ns, nt) = (roots.ns, roots.nt);
    let per_byte = (8 / form.bits()) as u64;
    let nsym = c.varint(&format!("{name} {one} count"))?;
    if nsym < ns.saturating_mul(nt) || nsym.div_ceil(per_byte) > (c.data.len() - c.pos) as u64 {
        return Err(c.err(format!("{name} of {nsym} {many} for {ns}×{nt} roots does not fit the body")));
    }
    let bytes = c.take(nsym.div_ceil(per_byte) as usize, &format!("{name} {many}"))?;
    let (bits, mask) = (form.bits(), (1u8 << form.bits()) - 1);
    let sym = |k: usize| bytes[k * bits / 8] >> (k * bits % 8) & mask;
    let mut leaves = Vec::new();
    let mut k = 0usize;
    let mut stack: Vec<(Rect, usize)> = Vec::new();
    for root in roots.cells() {
        stack.push((root, 0));
        while let Some((r, depth)) = stack.pop() {
            if k >= nsym as usize {
                return Err(c.err(format!("the {name} {many} end before the tree does")));
            }
            let v = sym(k);
            k += 1;
            if v == 0 {
                leaves.push(r);
                continue;
            }
            if depth >= MAX_DEPTH {
                return Err(c.err(format!("{name} deeper than {MAX_DEPTH} levels")));
            }
            // depth first in the writer's order (quadtree: SW, SE, NW, NE): push in reverse
            for ch in form.children(v, &r).into_iter().rev() {
                stack.push((ch, depth + 1));
            }
        }
    }
    if k != nsym as usize {
        return Err(c.err(format!("{} {name} {many} left over", nsym as usize - k)));
    }
    Ok(leaves)
}

fn read_explicit(c: &mut Cursor) -> Result<Vec<Rect>, TsplineError> {
    let ns = c.count(8, "s value count")?;
    let sv: Vec<f64> = (0..ns).map(|_| c.f64("s value")).collect::<Result<_, _>>()?;
    let nt = c.count(8, "t value count")?;
    let tv: Vec<f64> = (0..nt).map(|_| c.f64("t value")).collect::<Result<_, _>>()?;
    let nc = c.count(4, "cell count")?;
    let mut leaves = Vec::with_capacity(nc);
    for ci in 0..nc {
        let a = c.varint("cell index")?;
        let da = c.varint("cell index")?;
        let b = c.varint("cell index")?;
        let db = c.varint("cell index")?;
        let get = |v: &[f64], i: u64| v.get(i as usize).copied();
        match (get(&sv, a), get(&sv, a.saturating_add(da)), get(&tv, b), get(&tv, b.saturating_add(db))) {
            (Some(s0), Some(s1), Some(t0), Some(t1)) if s0 < s1 && t0 < t1 => leaves.push(Rect::new(s0, t0, s1, t1)),
            _ => return Err(c.err(format!("cell {ci}: indices out of range or an empty rectangle"))),
        }
    }
    Ok(leaves)
}

fn read_mask(c: &mut Cursor) -> Result<DataMask, TsplineError> {
    let width = c.varint("mask width")? as usize;
    let height = c.varint("mask height")? as usize;
    let total =
        width.checked_mul(height).filter(|&t| t as u64 <= MAX_BODY * 8).ok_or_else(|| c.err("mask size overflows"))?;
    let nr = c.count(1, "mask run count")?;
    let mut bits = Vec::with_capacity(total);
    let mut bit = false;
    for _ in 0..nr {
        let r = c.varint("mask run")? as usize;
        if r > total - bits.len() {
            return Err(c.err(format!("mask runs exceed {width}×{height} cells")));
        }
        bits.extend(std::iter::repeat_n(bit, r));
        bit = !bit;
    }
    if bits.len() != total {
        return Err(c.err(format!("mask runs cover {} of {total} cells", bits.len())));
    }
    Ok(DataMask { width, height, bits })
}

#[cfg(test)]
mod tests;
