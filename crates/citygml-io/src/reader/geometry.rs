//! Geometry elements: surfaces, solids and their members (inline or by XLink placeholder),
//! polygons and their rings.

use super::*;

impl<'a> Parser<'a> {
    // ---------------------------------------------------------------------------------------
    // Geometry

    pub(super) fn parse_geometry(
        &mut self,
        t: Tag<'a>,
        prop_start: usize,
        lod: Option<u8>,
    ) -> Result<Geometry, ReadError> {
        let id = t.attr_string(b"id");
        let srs_name = t.attr_string(b"srsName");
        if self.first_srs.is_none() {
            self.first_srs = srs_name.clone();
        }
        let saved_dim = self.dim_hint;
        if let Some(d) = t.attr(b"srsDimension").and_then(|v| parse_dim(&v)) {
            self.dim_hint = Some(d);
        }
        let gml_type = t.local_str();
        let property = String::from_utf8_lossy(name_at(self.src, prop_start)).into_owned();
        let start = t.start;
        let mut skipped_members = Vec::new();
        let kind = match t.local() {
            b"Solid" => {
                let (e, i) = self.parse_solid(&t)?;
                GeometryKind::Solid { exterior: e, interior: i }
            }
            b"CompositeSolid" | b"MultiSolid" => {
                let mut solids = Vec::new();
                self.parse_solid_members(&t, &mut solids, &mut skipped_members)?;
                GeometryKind::Solids(solids)
            }
            _ => {
                let mut buf = std::mem::take(&mut self.polys);
                let mark = buf.len();
                self.collect_element(t, false, Some(prop_start), &mut buf)?;
                let v = buf.drain(mark..).collect(); // exact size
                self.polys = buf;
                GeometryKind::Surfaces(v)
            }
        };
        self.dim_hint = saved_dim;
        let end = self.pos();
        Ok(Geometry { id, lod, property, gml_type, srs_name, kind, span: self.span(start, end), skipped_members })
    }

    /// The members of a `gml:CompositeSolid` / `gml:MultiSolid` whose start tag was just read:
    /// each `gml:Solid` as parsed, each `solidMember xlink:href` as a placeholder solid (see
    /// [`Parser::solid_placeholder`]; [`resolve_object`] replaces it by a copy of its target),
    /// the solids of a nested CompositeSolid / MultiSolid as members of their own; anything
    /// else goes to `skipped` (never dropped silently).
    pub(super) fn parse_solid_members(
        &mut self,
        t: &Tag<'a>,
        solids: &mut Vec<(Shell, Vec<Shell>)>,
        skipped: &mut Vec<SkippedMember>,
    ) -> Result<(), ReadError> {
        let id = t.attr_string(b"id");
        loop {
            match self.next()? {
                Ev::Start(c) => {
                    if !(c.ns == Ns::Gml && matches!(c.local(), b"solidMember" | b"solidMembers")) {
                        self.skip(&c)?;
                        continue;
                    }
                    if let Some(href) = c.attr_string(b"href") {
                        self.skip(&c)?;
                        let ph = self.solid_placeholder(href, c.start, self.pos());
                        solids.push(ph);
                        continue;
                    }
                    let before = solids.len() + skipped.len();
                    loop {
                        match self.next()? {
                            Ev::Start(s) if s.is_gml(b"Solid") => {
                                let solid = self.parse_solid(&s)?;
                                solids.push(solid);
                            }
                            Ev::Start(s)
                                if s.ns == Ns::Gml && matches!(s.local(), b"CompositeSolid" | b"MultiSolid") =>
                            {
                                self.parse_solid_members(&s, solids, skipped)?;
                            }
                            Ev::Start(s) => {
                                let end = self.skip(&s)?;
                                skipped.push(self.not_a_solid(&s, end));
                            }
                            Ev::Empty(s) if s.is_gml(b"Solid") => {
                                let shell = Shell { id: None, polygons: Vec::new(), via_xlink: None };
                                solids.push((shell, Vec::new()));
                            }
                            Ev::Empty(s) => {
                                let end = self.pos();
                                skipped.push(self.not_a_solid(&s, end));
                            }
                            Ev::End { end } => {
                                if solids.len() + skipped.len() == before {
                                    skipped.push(SkippedMember {
                                        href: None,
                                        reason: format!("gml:{} holds no solid", c.local_str()),
                                        span: self.span(c.start, end),
                                    });
                                }
                                break;
                            }
                            Ev::Eof => return Err(self.unclosed(c.raw.name().as_ref(), c.start)),
                            Ev::Text { .. } => {}
                        }
                    }
                }
                Ev::Empty(c) => {
                    if c.ns == Ns::Gml && matches!(c.local(), b"solidMember" | b"solidMembers") {
                        let end = self.pos();
                        if let Some(href) = c.attr_string(b"href") {
                            let ph = self.solid_placeholder(href, c.start, end);
                            solids.push(ph);
                        } else {
                            skipped.push(SkippedMember {
                                href: None,
                                reason: format!("empty gml:{} (no solid, no xlink:href)", c.local_str()),
                                span: self.span(c.start, end),
                            });
                        }
                    }
                }
                Ev::End { end } => {
                    if let Some(id) = id {
                        self.local_ids.insert(id, IdEntry { bytes: t.start..end, semantic: self.cur_sem.clone() });
                    }
                    return Ok(());
                }
                Ev::Eof => return Err(self.unclosed(t.raw.name().as_ref(), t.start)),
                Ev::Text { .. } => {}
            }
        }
    }

    pub(super) fn not_a_solid(&self, s: &Tag<'_>, end: usize) -> SkippedMember {
        SkippedMember {
            href: None,
            reason: format!("<{}> is not a solid (not read)", String::from_utf8_lossy(s.raw.name().as_ref())),
            span: self.span(s.start, end),
        }
    }

    /// A solid that stands for a `solidMember xlink:href`: an exterior shell holding one
    /// placeholder polygon marked by `srs_dimension == 0` (see [`is_solid_placeholder`]).
    pub(super) fn solid_placeholder(&mut self, href: String, start: usize, end: usize) -> (Shell, Vec<Shell>) {
        let mut ph = self.placeholder(href, start, end, false);
        ph.exterior.srs_dimension = 0;
        (Shell { id: None, polygons: vec![ph], via_xlink: None }, Vec::new())
    }

    /// A `gml:Solid` whose start tag was just read → (exterior shell, interior shells).
    pub(super) fn parse_solid(&mut self, t: &Tag<'a>) -> Result<(Shell, Vec<Shell>), ReadError> {
        let id = t.attr_string(b"id");
        let mut exterior = Shell { id: None, polygons: Vec::new(), via_xlink: None };
        let mut interior = Vec::new();
        loop {
            match self.next()? {
                Ev::Start(c) => {
                    let is_ext = c.is_gml(b"exterior");
                    if is_ext || c.is_gml(b"interior") {
                        let mut buf = std::mem::take(&mut self.polys);
                        let mark = buf.len();
                        let id = self.collect_prop(c, false, &mut buf)?;
                        let shell = Shell { id, polygons: buf.drain(mark..).collect(), via_xlink: None };
                        self.polys = buf;
                        if is_ext {
                            exterior = shell;
                        } else {
                            interior.push(shell);
                        }
                    } else {
                        self.skip(&c)?;
                    }
                }
                Ev::Empty(c) => {
                    if let Some(href) = c.attr_string(b"href") {
                        let ph = self.placeholder(href, c.start, self.pos(), false);
                        let shell = Shell { id: None, polygons: vec![ph], via_xlink: None };
                        if c.is_gml(b"exterior") {
                            exterior = shell;
                        } else {
                            interior.push(shell);
                        }
                    }
                }
                Ev::End { end } => {
                    // A solid can be a CompositeSolid member by reference (`solidMember xlink:href`).
                    if let Some(id) = id {
                        self.local_ids.insert(id, IdEntry { bytes: t.start..end, semantic: self.cur_sem.clone() });
                    }
                    break;
                }
                Ev::Text { .. } => {}
                Ev::Eof => return Err(self.unclosed(t.raw.name().as_ref(), t.start)),
            }
        }
        Ok((exterior, interior))
    }

    /// Reads a geometry property element (`surfaceMember`, `baseSurface`, `exterior`, ...)
    /// whose start tag was just read; its surfaces go to `out`. Returns the gml:id of the
    /// first geometry inside (a Shell's id).
    pub(super) fn collect_prop(
        &mut self,
        p: Tag<'a>,
        reversed: bool,
        out: &mut Vec<Polygon>,
    ) -> Result<Option<String>, ReadError> {
        if let Some(href) = p.attr_string(b"href") {
            self.skip(&p)?;
            let ph = self.placeholder(href, p.start, self.pos(), reversed);
            out.push(ph);
            return Ok(None);
        }
        let mut first_id = None;
        loop {
            match self.next()? {
                Ev::Start(c) => {
                    if c.ns == Ns::Gml && is_surface_like(c.local()) {
                        if first_id.is_none() {
                            first_id = c.attr_string(b"id");
                        }
                        self.collect_element(c, reversed, Some(p.start), out)?;
                    } else {
                        self.skip(&c)?;
                    }
                }
                Ev::End { .. } => return Ok(first_id),
                Ev::Eof => return Err(self.unclosed(p.raw.name().as_ref(), p.start)),
                _ => {}
            }
        }
    }

    /// A surface element whose start tag was just read: a polygon, or an aggregate whose
    /// members are collected (an `OrientableSurface` with `orientation="-"` flips them).
    pub(super) fn collect_element(
        &mut self,
        t: Tag<'a>,
        reversed: bool,
        member_start: Option<usize>,
        out: &mut Vec<Polygon>,
    ) -> Result<(), ReadError> {
        if is_polygon_like(t.local()) {
            let p = self.parse_polygon(t, reversed, member_start)?;
            out.push(p);
            return Ok(());
        }
        let rev = if t.local() == b"OrientableSurface" && t.attr(b"orientation").as_deref() == Some(b"-") {
            !reversed
        } else {
            reversed
        };
        let id = t.attr_string(b"id");
        loop {
            match self.next()? {
                Ev::Start(c) => {
                    if c.ns == Ns::Gml {
                        self.collect_prop(c, rev, out)?;
                    } else {
                        self.skip(&c)?;
                    }
                }
                Ev::Empty(c) => {
                    if let Some(href) = c.attr_string(b"href") {
                        let ph = self.placeholder(href, c.start, self.pos(), rev);
                        out.push(ph);
                    }
                }
                Ev::End { end } => {
                    if let Some(id) = id {
                        self.local_ids.insert(id, IdEntry { bytes: t.start..end, semantic: self.cur_sem.clone() });
                    }
                    return Ok(());
                }
                Ev::Text { .. } => {}
                Ev::Eof => return Err(self.unclosed(t.raw.name().as_ref(), t.start)),
            }
        }
    }

    pub(super) fn placeholder(&mut self, href: String, start: usize, end: usize, reversed: bool) -> Polygon {
        self.placeholders += 1;
        Polygon {
            id: Some(href),
            exterior: empty_ring(),
            interiors: Vec::new(),
            semantic: None,
            semantic_owner: None,
            reversed,
            span: SourceSpan::default(),
            member_span: None,
            via_xlink: Some(self.span(start, end)),
        }
    }

    /// Span of the property element that encloses a polygon: from the property's start tag
    /// to the end tag that directly follows the polygon (None when something else follows).
    pub(super) fn member_span(&self, member_start: usize, poly_end: usize) -> Option<SourceSpan> {
        let mut i = poly_end;
        while i < self.src.len() && self.src[i].is_ascii_whitespace() {
            i += 1;
        }
        if self.src.get(i..i + 2) != Some(b"</") {
            return None;
        }
        let close = memchr::memchr(b'>', &self.src[i..])?;
        Some(self.span(member_start, i + close + 1))
    }

    pub(super) fn parse_polygon(
        &mut self,
        t: Tag<'a>,
        reversed: bool,
        member_start: Option<usize>,
    ) -> Result<Polygon, ReadError> {
        let id = t.attr_string(b"id");
        let mut exterior = None;
        let mut interiors = Vec::new();
        let end;
        loop {
            match self.next()? {
                Ev::Start(c) => {
                    let l = c.local();
                    if c.ns == Ns::Gml && matches!(l, b"exterior" | b"outerBoundaryIs") {
                        exterior = self.parse_ring_prop(c)?;
                    } else if c.ns == Ns::Gml && matches!(l, b"interior" | b"innerBoundaryIs") {
                        if let Some(r) = self.parse_ring_prop(c)? {
                            interiors.push(r);
                        }
                    } else {
                        self.skip(&c)?;
                    }
                }
                Ev::End { end: e } => {
                    end = e;
                    break;
                }
                Ev::Eof => return Err(self.unclosed(t.raw.name().as_ref(), t.start)),
                _ => {}
            }
        }
        let Some(exterior) = exterior else {
            return Err(self.err(
                t.start,
                format!(
                    "gml:{} {}has no exterior gml:LinearRing (missing coordinates)",
                    t.local_str(),
                    id.as_ref().map(|i| format!("'{}' ", quote(i))).unwrap_or_default()
                ),
            ));
        };
        let (semantic, semantic_owner) = match &self.cur_sem {
            Some((s, o)) => (Some(*s), o.clone()),
            None => (None, None),
        };
        Ok(Polygon {
            id,
            exterior,
            interiors,
            semantic,
            semantic_owner,
            reversed,
            span: self.span(t.start, end),
            member_span: member_start.and_then(|m| self.member_span(m, end)),
            via_xlink: None,
        })
    }

    /// `gml:exterior`/`gml:interior` of a polygon → its LinearRing.
    pub(super) fn parse_ring_prop(&mut self, p: Tag<'a>) -> Result<Option<Ring>, ReadError> {
        let mut ring = None;
        loop {
            match self.next()? {
                Ev::Start(c) => {
                    if c.is_gml(b"LinearRing") {
                        ring = Some(self.parse_linear_ring(c)?);
                    } else {
                        self.skip(&c)?;
                    }
                }
                Ev::End { .. } => return Ok(ring),
                Ev::Eof => return Err(self.unclosed(p.raw.name().as_ref(), p.start)),
                _ => {}
            }
        }
    }
}
