//! Coordinates: the three GML encodings of a ring's positions (`gml:posList`, `gml:pos`,
//! `gml:coordinates`) and the number scanning they share.

use super::*;

/// What [`Parser::parse_linear_ring`] has read of a ring's coordinates so far.
pub(super) struct RingCoords {
    points: Vec<Point3>,
    /// The encoding seen first; `None` until a coordinate element is read.
    encoding: Option<CoordEncoding>,
    dim: u8,
    text_span: SourceSpan,
    pos_spans: Vec<SourceSpan>,
}

impl<'a> Parser<'a> {
    /// A `gml:LinearRing` in any of GML's three coordinate encodings (never mixed); the text
    /// spans are kept so the coordinates can be rewritten in place.
    pub(super) fn parse_linear_ring(&mut self, t: Tag<'a>) -> Result<Ring, ReadError> {
        let id = t.attr_string(b"id");
        let mut acc = RingCoords {
            points: Vec::new(),
            encoding: None,
            dim: 3,
            text_span: SourceSpan::default(),
            pos_spans: Vec::new(),
        };
        let end;
        loop {
            match self.next()? {
                Ev::Start(c) => {
                    let l = c.local();
                    if c.ns != Ns::Gml {
                        self.skip(&c)?;
                        continue;
                    }
                    match l {
                        b"posList" => self.ring_pos_list(&c, &mut acc)?,
                        b"pos" => self.ring_pos(&c, &mut acc)?,
                        b"coordinates" => self.ring_coordinates(&c, &mut acc)?,
                        _ => {
                            self.skip(&c)?;
                        }
                    }
                }
                Ev::Empty(c) => {
                    if c.ns == Ns::Gml && matches!(c.local(), b"posList" | b"pos" | b"coordinates") {
                        return Err(self.err(c.start, format!("empty gml:{} (missing coordinates)", c.local_str())));
                    }
                }
                Ev::End { end: e } => {
                    end = e;
                    break;
                }
                Ev::Eof => return Err(self.unclosed(t.raw.name().as_ref(), t.start)),
                Ev::Text { .. } => {}
            }
        }
        let RingCoords { points, encoding, dim, text_span, pos_spans } = acc;
        let Some(encoding) = encoding else {
            return Err(
                self.err(t.start, "gml:LinearRing has no coordinates (no gml:posList, gml:pos or gml:coordinates)")
            );
        };
        Ok(Ring { id, points, srs_dimension: dim, encoding, text_span, pos_spans, span: self.span(t.start, end) })
    }

    /// A ring's `gml:posList`: all its points at once, in the declared (or inherited) dimension.
    pub(super) fn ring_pos_list(&mut self, c: &Tag<'a>, acc: &mut RingCoords) -> Result<(), ReadError> {
        if acc.encoding.is_some() {
            return Err(self.err(c.start, "gml:LinearRing mixes coordinate encodings"));
        }
        let d = c.attr(b"srsDimension").and_then(|v| parse_dim(&v)).or(self.dim_hint).unwrap_or(3);
        let r = self.content(c)?;
        let (pts, nvals) = self.pos_list(r.clone(), d)?;
        if nvals == 0 {
            return Err(self.err(c.start, "empty gml:posList (missing coordinates)"));
        }
        if nvals % d as usize != 0 {
            return Err(
                self.err(c.start, format!("gml:posList has {nvals} values, not a multiple of srsDimension {d}"))
            );
        }
        acc.points = pts;
        acc.dim = d;
        let tr = self.trimmed(r);
        acc.text_span = self.span(tr.start, tr.end);
        acc.encoding = Some(CoordEncoding::PosList);
        Ok(())
    }

    /// One `gml:pos` of a ring: one point, in the dimension of the ring's first; the text span
    /// grows to cover first..last `gml:pos`.
    pub(super) fn ring_pos(&mut self, c: &Tag<'a>, acc: &mut RingCoords) -> Result<(), ReadError> {
        if acc.encoding.is_some_and(|e| e != CoordEncoding::Pos) {
            return Err(self.err(c.start, "gml:LinearRing mixes coordinate encodings"));
        }
        let d_attr = c.attr(b"srsDimension").and_then(|v| parse_dim(&v));
        let r = self.content(c)?;
        let vals = self.numbers(r.clone(), "gml:pos")?;
        let d = d_attr.unwrap_or(vals.len() as u8);
        if !(vals.len() == 2 || vals.len() == 3) || vals.len() != d as usize {
            return Err(self.err(c.start, format!("gml:pos has {} values, expected 2 or 3 (one position)", vals.len())));
        }
        let tr = self.trimmed(r);
        if acc.encoding.is_none() {
            acc.dim = d;
            acc.text_span = self.span(tr.start, tr.end);
        } else if d != acc.dim {
            return Err(self.err(c.start, format!("gml:pos has {d} values, the ring's first has {}", acc.dim)));
        }
        acc.text_span.bytes.end = tr.end;
        acc.points.push(to_point(&vals));
        acc.pos_spans.push(self.span(tr.start, tr.end));
        acc.encoding = Some(CoordEncoding::Pos);
        Ok(())
    }

    /// A ring's `gml:coordinates` (GML 2 style, with its own separators): all its points at once.
    pub(super) fn ring_coordinates(&mut self, c: &Tag<'a>, acc: &mut RingCoords) -> Result<(), ReadError> {
        if acc.encoding.is_some() {
            return Err(self.err(c.start, "gml:LinearRing mixes coordinate encodings"));
        }
        let cs = c.attr(b"cs").map(|v| v.into_owned()).unwrap_or_else(|| b",".to_vec());
        let dec = c.attr(b"decimal").map(|v| v.into_owned()).unwrap_or_else(|| b".".to_vec());
        let r = self.content(c)?;
        let (pts, d) = self.coordinates(r.clone(), &cs, &dec)?;
        if pts.is_empty() {
            return Err(self.err(c.start, "empty gml:coordinates (missing coordinates)"));
        }
        acc.points = pts;
        acc.dim = d;
        let tr = self.trimmed(r);
        acc.text_span = self.span(tr.start, tr.end);
        acc.encoding = Some(CoordEncoding::Coordinates);
        Ok(())
    }

    /// A posList straight into points (no intermediate Vec<f64>, no token slices: each number
    /// is parsed in place from the buffer): returns the complete positions and the number of
    /// values read (a count that is not a multiple of `d` is the caller's error to report).
    pub(super) fn pos_list(&mut self, r: Range<usize>, d: u8) -> Result<(Vec<Point3>, usize), ReadError> {
        let mut pts = std::mem::take(&mut self.scratch);
        pts.clear();
        let mut cur = [0.0f64; 3];
        let (mut k, mut n) = (0usize, 0usize);
        let d = d as usize;
        let read = self.each_number(r, "gml:posList", |x| {
            cur[k] = x;
            k += 1;
            n += 1;
            if k == d {
                if d == 2 {
                    cur[2] = 0.0;
                }
                pts.push(cur);
                k = 0;
            }
        });
        let out = read.map(|()| (pts.as_slice().to_vec(), n));
        self.scratch = pts;
        out
    }

    pub(super) fn number_err(&self, at: usize, bad: NumErr<'_>, what: &str) -> ReadError {
        match bad {
            NumErr::NonFinite(tok) => self.err(at, format!("{what}: non-finite coordinate '{}'", lossy(tok))),
            NumErr::NotANumber(tok) if tok.contains(&b'<') => {
                self.err(at, format!("{what}: unexpected markup inside the coordinate text"))
            }
            NumErr::NotANumber(tok) => self.err(at, format!("{what}: '{}' is not a number", lossy(tok))),
        }
    }

    /// Whitespace-separated numbers of `src[r]`; a bad token is an error at its own position.
    pub(super) fn numbers(&self, r: Range<usize>, what: &str) -> Result<Vec<f64>, ReadError> {
        let mut v = Vec::with_capacity(3);
        self.each_number(r, what, |x| v.push(x))?;
        Ok(v)
    }

    /// Calls `f` with each whitespace-separated number of `src[r]` in order, parsed in place
    /// from the buffer; a bad token is an error at its own position (`what` names the element).
    #[inline]
    pub(super) fn each_number(&self, r: Range<usize>, what: &str, mut f: impl FnMut(f64)) -> Result<(), ReadError> {
        let s = &self.src[r.clone()];
        let mut i = 0usize;
        loop {
            while i < s.len() && is_ws(s[i]) {
                i += 1;
            }
            if i >= s.len() {
                return Ok(());
            }
            match number_at(s, i) {
                Ok((x, len)) => {
                    f(x);
                    i += len;
                }
                Err(bad) => return Err(self.number_err(r.start + i, bad, what)),
            }
        }
    }

    /// `gml:coordinates`: tuples separated by whitespace, values by `cs`.
    pub(super) fn coordinates(&self, r: Range<usize>, cs: &[u8], dec: &[u8]) -> Result<(Vec<Point3>, u8), ReadError> {
        let mut pts = Vec::new();
        let mut dim = 0u8;
        for (at, tuple) in tokens(&self.src[r.clone()], r.start) {
            let mut vals = Vec::with_capacity(3);
            let sep = cs.first().copied().unwrap_or(b',');
            for part in tuple.split(|b| *b == sep) {
                let owned;
                let part = if dec != b"." && dec.len() == 1 {
                    owned = part.iter().map(|b| if *b == dec[0] { b'.' } else { *b }).collect::<Vec<u8>>();
                    &owned[..]
                } else {
                    part
                };
                match parse_f64(part) {
                    Some(x) if x.is_finite() => vals.push(x),
                    _ => {
                        return Err(
                            self.err(at, format!("gml:coordinates: '{}' is not a coordinate tuple", lossy(tuple)))
                        )
                    }
                }
            }
            if !(vals.len() == 2 || vals.len() == 3) {
                return Err(
                    self.err(at, format!("gml:coordinates: tuple '{}' has {} values", lossy(tuple), vals.len()))
                );
            }
            if dim == 0 {
                dim = vals.len() as u8;
            } else if dim as usize != vals.len() {
                return Err(self.err(at, "gml:coordinates: tuples of different dimension"));
            }
            pts.push(to_point(&vals));
        }
        Ok((pts, dim))
    }
}

pub(super) fn empty_ring() -> Ring {
    Ring {
        id: None,
        points: Vec::new(),
        srs_dimension: 3,
        encoding: CoordEncoding::PosList,
        text_span: SourceSpan::default(),
        pos_spans: Vec::new(),
        span: SourceSpan::default(),
    }
}

pub(super) fn to_point(v: &[f64]) -> Point3 {
    [v[0], v[1], if v.len() > 2 { v[2] } else { 0.0 }]
}

pub(super) fn parse_dim(v: &[u8]) -> Option<u8> {
    match v {
        b"2" => Some(2),
        b"3" => Some(3),
        _ => None,
    }
}

pub(super) fn lossy(b: &[u8]) -> String {
    let s = String::from_utf8_lossy(b);
    if s.chars().count() > 40 {
        format!("{}…", s.chars().take(40).collect::<String>())
    } else {
        s.into_owned()
    }
}

/// XML whitespace (what separates the values of a coordinate list).
#[inline]
pub(super) fn is_ws(b: u8) -> bool {
    matches!(b, b' ' | b'\n' | b'\t' | b'\r' | b'\x0c')
}

pub(crate) enum NumErr<'s> {
    NotANumber(&'s [u8]),
    NonFinite(&'s [u8]),
}

/// The finite number that starts at `s[i]` (not whitespace) and runs to the next whitespace or
/// the end, and its length in bytes. Parsed in place by Eisel–Lemire (`fast-float2`: correctly
/// rounded, the same value as `str::parse::<f64>`); no token slice is scanned twice.
#[inline]
pub(super) fn number_at(s: &[u8], i: usize) -> Result<(f64, usize), NumErr<'_>> {
    let rest = &s[i..];
    if let Ok((x, len)) = fast_float2::parse_partial::<f64, _>(rest) {
        if len > 0 && (len == rest.len() || is_ws(rest[len])) {
            if x.is_finite() {
                return Ok((x, len));
            }
            return Err(NumErr::NonFinite(&rest[..len]));
        }
    }
    let end = rest.iter().position(|b| is_ws(*b)).unwrap_or(rest.len());
    Err(NumErr::NotANumber(&rest[..end]))
}

/// Decimal text → f64 (correctly rounded, like `str::parse::<f64>`, without the UTF-8 check).
pub(crate) fn parse_f64(tok: &[u8]) -> Option<f64> {
    match fast_float2::parse_partial::<f64, _>(tok) {
        Ok((x, len)) if len == tok.len() && len > 0 => Some(x),
        _ => None,
    }
}

/// Whitespace-separated tokens with their absolute byte offsets.
pub(super) fn tokens(s: &[u8], base: usize) -> impl Iterator<Item = (usize, &[u8])> {
    let mut i = 0;
    std::iter::from_fn(move || {
        while i < s.len() && s[i].is_ascii_whitespace() {
            i += 1;
        }
        if i >= s.len() {
            return None;
        }
        let st = i;
        while i < s.len() && !s[i].is_ascii_whitespace() {
            i += 1;
        }
        Some((base + st, &s[st..i]))
    })
}
