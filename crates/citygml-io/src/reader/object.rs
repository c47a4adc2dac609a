//! City objects: an object element with its nested objects, properties and envelope.

use super::*;

impl<'a> Parser<'a> {
    // ---------------------------------------------------------------------------------------
    // City objects

    /// Parses a city object whose start tag was just read, up to its end tag. XLinks are left
    /// as placeholders; [`resolve_object`] replaces them.
    pub fn parse_object(&mut self, tag: Tag<'a>) -> Result<CityObject, ReadError> {
        let kind = tag.local_str();
        let module = match tag.ns {
            Ns::CityGml(_, m) => Some(m.to_string()),
            _ => None,
        };
        let id = tag.attr_string(b"id");
        let saved_sem = self.cur_sem.take();
        if let Some(t) = SurfaceType::from_local_name(&kind) {
            self.cur_sem = Some((t, id.clone()));
        }
        let mut obj = CityObject {
            id,
            kind,
            module,
            geometries: Vec::new(),
            children: Vec::new(),
            envelope: Envelope::empty(),
            span: SourceSpan::default(),
        };
        // Elements open inside the object (properties, wrappers): start offset and LoD of name.
        let mut stack: Vec<(usize, Option<u8>)> = Vec::new();
        loop {
            match self.next()? {
                Ev::Start(t) => {
                    let l = t.local();
                    match t.ns {
                        Ns::Gml => {
                            if stack.is_empty() && l == b"boundedBy" {
                                if let Some(env) = self.parse_bounded_by(&t)? {
                                    obj.envelope = env;
                                }
                            } else if is_geometry(l) && !stack.is_empty() {
                                let (prop, _) = *stack.last().unwrap();
                                let lod = stack.iter().rev().find_map(|s| s.1);
                                let g = self.parse_geometry(t, prop, lod)?;
                                obj.geometries.push(g);
                            } else {
                                self.skip(&t)?;
                            }
                        }
                        Ns::CityGml(_, m) => {
                            if m == "app" || is_skipped(l) {
                                self.skip(&t)?;
                            } else if !stack.is_empty() && is_nested_object(l) {
                                let child = self.parse_object(t)?;
                                obj.children.push(child);
                            } else if by_reference_lod(l).is_some() && t.attr(b"href").is_some() {
                                // the same reference written with an end tag
                                // (`<bldg:lod2Solid xlink:href="#s"></bldg:lod2Solid>`)
                                let end = self.skip(&t)?;
                                if let Some(g) = self.geometry_by_reference(&t, end) {
                                    obj.geometries.push(g);
                                }
                            } else {
                                stack.push((t.start, lod_of(l)));
                            }
                        }
                        Ns::Xal => {
                            self.skip(&t)?;
                        }
                        Ns::Other => {
                            // ADE wrappers and properties: look through them for geometry.
                            stack.push((t.start, lod_of(l)));
                        }
                    }
                }
                Ev::Empty(t) => {
                    // `<bldg:lod2Solid xlink:href="#solid"/>`: a whole geometry by reference.
                    let end = self.pos();
                    if let Some(g) = self.geometry_by_reference(&t, end) {
                        obj.geometries.push(g);
                    }
                }
                Ev::End { end } => {
                    if stack.pop().is_none() {
                        obj.span = self.span(tag.start, end);
                        break;
                    }
                }
                Ev::Text { .. } => {}
                Ev::Eof => return Err(self.unclosed(tag.raw.name().as_ref(), tag.start)),
            }
        }
        self.cur_sem = saved_sem;
        Ok(obj)
    }

    /// A `lodN…` geometry property that is only an `xlink:href` (ending at `end`): a
    /// placeholder geometry resolved with the other XLinks (a solid property (`lodNSolid`)
    /// becomes the solid it points to, resolved with the solidMember references; anything
    /// else the geometry it points to), or None for other properties.
    pub(super) fn geometry_by_reference(&mut self, t: &Tag<'_>, end: usize) -> Option<Geometry> {
        let l = t.local();
        let lod = by_reference_lod(l)?;
        let href = t.attr_string(b"href")?;
        let kind = if memchr::memmem::find(l, b"Solid").is_some() {
            GeometryKind::Solids(vec![self.solid_placeholder(href, t.start, end)])
        } else {
            GeometryKind::Surfaces(vec![self.placeholder(href, t.start, end, false)])
        };
        Some(Geometry {
            id: None,
            lod: Some(lod),
            property: t.local_str(),
            gml_type: "xlink".to_string(),
            srs_name: None,
            kind,
            span: self.span(t.start, end),
            skipped_members: Vec::new(),
        })
    }

    /// `gml:boundedBy/gml:Envelope` → envelope (None when absent or not finite, e.g. the NaN
    /// heights of empty NRW tiles).
    pub fn parse_bounded_by(&mut self, t: &Tag<'_>) -> Result<Option<Envelope>, ReadError> {
        let mut corners: Vec<Vec<f64>> = Vec::new();
        let mut ok = true;
        let mut depth = 0usize;
        loop {
            match self.next()? {
                Ev::Start(c) => {
                    let l = c.local();
                    if c.ns == Ns::Gml && l == b"Envelope" {
                        depth += 1;
                        if let Some(s) = c.attr_string(b"srsName") {
                            if self.first_srs.is_none() {
                                self.first_srs = Some(s);
                            }
                        }
                    } else if c.ns == Ns::Gml && matches!(l, b"lowerCorner" | b"upperCorner" | b"pos") {
                        let r = self.content(&c)?;
                        let mut v = Vec::new();
                        for (at, tok) in tokens(&self.src[r.clone()], r.start) {
                            match parse_f64(tok) {
                                Some(x) if x.is_finite() => v.push(x),
                                Some(_) => ok = false,
                                None => {
                                    return Err(self.err(
                                        at,
                                        format!("gml:{}: '{}' is not a number", String::from_utf8_lossy(l), lossy(tok)),
                                    ))
                                }
                            }
                        }
                        corners.push(v);
                    } else {
                        self.skip(&c)?;
                    }
                }
                Ev::End { .. } => {
                    if depth == 0 {
                        break;
                    }
                    depth -= 1;
                }
                Ev::Eof => return Err(self.unclosed(t.raw.name().as_ref(), t.start)),
                _ => {}
            }
        }
        if !ok || corners.len() != 2 || corners.iter().any(|c| c.len() < 2 || c.len() > 3) {
            return Ok(None);
        }
        let p = |c: &Vec<f64>| [c[0], c[1], if c.len() == 3 { c[2] } else { 0.0 }];
        let mut env = Envelope::empty();
        env.add_point(&p(&corners[0]));
        env.add_point(&p(&corners[1]));
        Ok(Some(env))
    }
}
