//! XLink resolution: placeholders left by the parser become copies of their targets (in the
//! object itself, re-parsed from their bytes, or found through the document index).

use super::*;

/// Placeholders are polygons reached by `xlink:href` that are not yet filled in.
pub(super) fn is_placeholder(p: &Polygon) -> bool {
    p.via_xlink.is_some() && p.span.bytes.end == 0
}

/// A solid standing for a `solidMember xlink:href` (see [`Parser::solid_placeholder`]).
pub(super) fn is_solid_placeholder(s: &(Shell, Vec<Shell>)) -> bool {
    s.1.is_empty()
        && s.0.polygons.len() == 1
        && is_placeholder(&s.0.polygons[0])
        && s.0.polygons[0].exterior.srs_dimension == 0
}

pub(super) type Solid = (Shell, Vec<Shell>);

/// What one solid XLink stands for: its solids and the members left out.
pub(super) type ResolvedSolids = (Vec<Solid>, Vec<SkippedMember>);

pub(super) fn visit_geoms<'o>(obj: &'o CityObject, f: &mut dyn FnMut(&'o Geometry)) {
    for g in &obj.geometries {
        f(g);
    }
    for c in &obj.children {
        visit_geoms(c, f);
    }
}

pub(super) fn visit_geoms_mut(obj: &mut CityObject, f: &mut dyn FnMut(&mut Geometry)) {
    for g in &mut obj.geometries {
        f(g);
    }
    for c in &mut obj.children {
        visit_geoms_mut(c, f);
    }
}

/// The one placeholder of a whole surface-type geometry given by reference
/// (`<bldg:lod2MultiSurface xlink:href="#ms"/>`), before it is resolved.
pub(super) fn whole_surface_ref(g: &Geometry) -> Option<&Polygon> {
    match &g.kind {
        GeometryKind::Surfaces(v) if g.gml_type == "xlink" && v.len() == 1 && is_placeholder(&v[0]) => Some(&v[0]),
        _ => None,
    }
}

pub(super) fn solid_placeholders_in(g: &Geometry) -> bool {
    matches!(&g.kind, GeometryKind::Solids(v) if v.iter().any(is_solid_placeholder))
}

pub(super) fn href_id(href: &str) -> Option<&str> {
    match href.strip_prefix('#') {
        Some(id) => Some(id),
        None if !href.contains('#') && !href.contains('/') => Some(href),
        None => None,
    }
}

pub(super) fn visit_polys<'o>(obj: &'o CityObject, f: &mut dyn FnMut(&'o Polygon)) {
    for g in &obj.geometries {
        for p in g.polygons() {
            f(p);
        }
    }
    for c in &obj.children {
        visit_polys(c, f);
    }
}

pub(super) fn visit_vecs_mut(obj: &mut CityObject, f: &mut dyn FnMut(&mut Vec<Polygon>)) {
    for g in &mut obj.geometries {
        match &mut g.kind {
            GeometryKind::Surfaces(v) => f(v),
            GeometryKind::Solid { exterior, interior } => {
                f(&mut exterior.polygons);
                for s in interior {
                    f(&mut s.polygons);
                }
            }
            GeometryKind::Solids(v) => {
                for (e, i) in v {
                    f(&mut e.polygons);
                    for s in i {
                        f(&mut s.polygons);
                    }
                }
            }
        }
    }
    for c in &mut obj.children {
        visit_vecs_mut(c, f);
    }
}

/// Where XLink targets outside the current object are looked up (the stream's lazy index).
pub(crate) trait GlobalIds {
    fn lookup(&mut self, id: &str) -> Result<Option<IdEntry>, ReadError>;
}

/// The element `id` names: the current object's own id'd aggregates first, then the document's
/// index (built on first use).
pub(super) fn find_id(
    local_ids: &FxMap<String, IdEntry>,
    global: &mut dyn GlobalIds,
    id: &str,
) -> Result<Option<IdEntry>, ReadError> {
    match local_ids.get(id) {
        Some(e) => Ok(Some(e.clone())),
        None => global.lookup(id),
    }
}

/// Context to re-parse an id'd element from its own bytes.
pub(crate) struct Reparse<'s, 'a> {
    pub src: &'a [u8],
    pub lines: &'s Arc<LineIndex<'a>>,
    pub bindings: &'s [Binding],
}

impl Reparse<'_, '_> {
    /// The solids of the element at `e` (a Solid, or the members of a CompositeSolid /
    /// MultiSolid) with the members it skips; `Err(name)` when the element is not a solid.
    #[allow(clippy::type_complexity)]
    pub(super) fn solids(&self, e: &IdEntry) -> Result<Result<(Vec<Solid>, Vec<SkippedMember>), String>, ReadError> {
        let mut p = Parser::new(self.src, self.lines.clone(), e.bytes.clone(), self.bindings.to_vec());
        p.cur_sem = e.semantic.clone();
        loop {
            match p.next()? {
                Ev::Start(t) => {
                    if let Some(d) = t.attr(b"srsDimension").and_then(|v| parse_dim(&v)) {
                        p.dim_hint = Some(d);
                    }
                    let (mut solids, mut skipped) = (Vec::new(), Vec::new());
                    if t.is_gml(b"Solid") {
                        solids.push(p.parse_solid(&t)?);
                    } else if t.ns == Ns::Gml && matches!(t.local(), b"CompositeSolid" | b"MultiSolid") {
                        p.parse_solid_members(&t, &mut solids, &mut skipped)?;
                    } else {
                        return Ok(Err(String::from_utf8_lossy(t.raw.name().as_ref()).into_owned()));
                    }
                    return Ok(Ok((solids, skipped)));
                }
                Ev::Empty(t) => {
                    if t.is_gml(b"Solid") {
                        return Ok(Ok((
                            vec![(Shell { id: None, polygons: Vec::new(), via_xlink: None }, Vec::new())],
                            Vec::new(),
                        )));
                    }
                    return Ok(Err(String::from_utf8_lossy(t.raw.name().as_ref()).into_owned()));
                }
                Ev::Eof => return Ok(Err("nothing".to_string())),
                _ => {}
            }
        }
    }

    pub(super) fn surfaces(&self, e: &IdEntry) -> Result<Vec<Polygon>, ReadError> {
        let mut p = Parser::new(self.src, self.lines.clone(), e.bytes.clone(), self.bindings.to_vec());
        p.cur_sem = e.semantic.clone();
        let mut out = Vec::new();
        loop {
            match p.next()? {
                Ev::Start(t) => {
                    if t.ns == Ns::Gml && is_surface_like(t.local()) {
                        p.collect_element(t, false, None, &mut out)?;
                    } else {
                        p.skip(&t)?;
                    }
                    break;
                }
                Ev::Eof => break,
                _ => {}
            }
        }
        Ok(out)
    }
}

/// Replaces the XLink placeholders of one top-level object by copies of their targets:
/// polygons defined in the object itself, id'd aggregates of the object (re-parsed from their
/// bytes), then anything else in the document through `global`. Unresolvable ones are removed
/// and returned.
pub(crate) fn resolve_object(
    obj: &mut CityObject,
    local_ids: &FxMap<String, IdEntry>,
    reparse: &Reparse<'_, '_>,
    global: &mut dyn GlobalIds,
) -> Result<Vec<XLinkRef>, ReadError> {
    let mut unresolved = Vec::new();
    let mut lk = Lookups { local_ids, reparse, global };
    resolve_whole_surface_refs(obj, &mut lk)?;
    resolve_solid_refs(obj, &mut lk, &mut unresolved)?;
    resolve_polygon_refs(obj, &mut lk, &mut unresolved)?;
    // Each reference says where it sits (the innermost object holding it) and, when its id
    // names an element that is not a geometry (a city object, an appearance...), what that is.
    for u in &mut unresolved {
        if let Some(o) = innermost_at(obj, u.span.bytes.start) {
            u.feature = o.id.clone();
            u.feature_type = o.kind.clone();
        }
        if let Some(id) = href_id(&u.href) {
            u.target = find_id(lk.local_ids, lk.global, id)?
                .map(|e| String::from_utf8_lossy(qname_at(lk.reparse.src, e.bytes.start)).into_owned());
        }
    }
    Ok(unresolved)
}

/// The lookups an object's XLinks are resolved through: the object's own ids, the document
/// bytes targets are re-parsed from, and the ids of the rest of the document.
pub(super) struct Lookups<'l, 's, 'a> {
    local_ids: &'l FxMap<String, IdEntry>,
    reparse: &'l Reparse<'s, 'a>,
    global: &'l mut dyn GlobalIds,
}

/// Phase -1: a whole surface-type geometry property by reference (`<bldg:lod2MultiSurface
/// xlink:href="#ms"/>`, read as one polygon placeholder) becomes what its target is: a solid
/// placeholder for a Solid/CompositeSolid/MultiSolid (resolved by [`resolve_solid_refs`] with the
/// solidMember references), the surfaces of a surface geometry (named after it), and for anything
/// else a skipped member instead of the polygons it happens to contain. A target that does not
/// exist stays a placeholder: the polygon phase reports it as an unresolved XLink.
pub(super) fn resolve_whole_surface_refs(obj: &mut CityObject, lk: &mut Lookups<'_, '_, '_>) -> Result<(), ReadError> {
    let whole = whole_surface_targets(obj, lk)?;
    if whole.is_empty() {
        return Ok(());
    }
    let mut it = whole.into_iter();
    visit_geoms_mut(obj, &mut |g| {
        if whole_surface_ref(g).is_none() {
            return;
        }
        let Some(Some((name, qname))) = it.next() else { return };
        let GeometryKind::Surfaces(v) = &mut g.kind else { return };
        if matches!(name.as_str(), "Solid" | "CompositeSolid" | "MultiSolid") {
            let Some(mut ph) = v.pop() else { return };
            ph.exterior.srs_dimension = 0;
            g.kind = GeometryKind::Solids(vec![(Shell { id: None, polygons: vec![ph], via_xlink: None }, Vec::new())]);
        } else if is_surface_like(name.as_bytes()) {
            g.gml_type = name;
        } else {
            let Some(ph) = v.pop() else { return };
            let href = ph.id.unwrap_or_default();
            g.skipped_members.push(SkippedMember {
                reason: format!("xlink:href=\"{}\" points to <{}>, not a geometry", quote(&href), quote(&qname)),
                href: Some(href),
                span: ph.via_xlink.unwrap_or_default(),
            });
        }
    });
    Ok(())
}

/// Per whole surface-type property by reference, in visiting order: (local name, qualified name
/// for messages) of its target, `None` when there is none.
pub(super) fn whole_surface_targets(
    obj: &CityObject,
    lk: &mut Lookups<'_, '_, '_>,
) -> Result<Vec<Option<(String, String)>>, ReadError> {
    let (local_ids, reparse, global) = (lk.local_ids, lk.reparse, &mut *lk.global);
    let mut by_id: rustc_hash::FxHashSet<&str> = Default::default();
    visit_polys(obj, &mut |p| {
        if let (false, Some(id)) = (is_placeholder(p), &p.id) {
            by_id.insert(id.as_str());
        }
    });
    let mut hrefs: Vec<&str> = Vec::new();
    visit_geoms(obj, &mut |g| {
        if let Some(ph) = whole_surface_ref(g) {
            hrefs.push(ph.id.as_deref().unwrap_or(""));
        }
    });
    let mut whole = Vec::new();
    for href in hrefs {
        let name = match href_id(href) {
            Some(id) if by_id.contains(id) => Some(("Polygon".to_string(), "gml:Polygon".to_string())),
            Some(id) => find_id(local_ids, global, id)?.map(|e| {
                let at = e.bytes.start;
                (
                    String::from_utf8_lossy(name_at(reparse.src, at)).into_owned(),
                    String::from_utf8_lossy(qname_at(reparse.src, at)).into_owned(),
                )
            }),
            None => None,
        };
        whole.push(name);
    }
    Ok(whole)
}

/// Phase 0: `solidMember xlink:href`s become copies of the solids they point to (their own
/// polygon XLinks resolved), or skipped members that say why not.
pub(super) fn resolve_solid_refs(
    obj: &mut CityObject,
    lk: &mut Lookups<'_, '_, '_>,
    unresolved: &mut Vec<XLinkRef>,
) -> Result<(), ReadError> {
    let mut has_solid_refs = false;
    visit_geoms(obj, &mut |g| has_solid_refs |= solid_placeholders_in(g));
    if !has_solid_refs {
        return Ok(());
    }
    let resolved = solid_ref_targets(obj, lk, unresolved)?;
    let mut it = resolved.into_iter();
    visit_geoms_mut(obj, &mut |g| {
        if !solid_placeholders_in(g) {
            return;
        }
        let GeometryKind::Solids(v) = &mut g.kind else { return };
        let old = std::mem::take(v);
        let mut target = None;
        for s in old {
            if is_solid_placeholder(&s) {
                if let Some(((solids, skipped), name)) = it.next() {
                    v.extend(solids);
                    g.skipped_members.extend(skipped);
                    target = target.or(name);
                }
            } else {
                v.push(s);
            }
        }
        g.skipped_members.sort_by_key(|m| m.span.bytes.start);
        if g.gml_type == "xlink" {
            // `<bldg:lod2Solid xlink:href="#s"/>`: the geometry is what it points to
            if let Some(name) = target.filter(|_| !v.is_empty()) {
                g.gml_type = name;
            }
            if g.gml_type == "Solid" && v.len() == 1 && g.skipped_members.is_empty() {
                if let Some((exterior, interior)) = v.pop() {
                    g.kind = GeometryKind::Solid { exterior, interior };
                }
            }
        }
    });
    Ok(())
}

/// Per solid placeholder, in visiting order: its solids and skipped members, and the element
/// name of its target (a whole `lodNSolid xlink:href` geometry takes the target's type).
pub(super) fn solid_ref_targets(
    obj: &CityObject,
    lk: &mut Lookups<'_, '_, '_>,
    unresolved: &mut Vec<XLinkRef>,
) -> Result<Vec<(ResolvedSolids, Option<String>)>, ReadError> {
    let (local_ids, reparse, global) = (lk.local_ids, lk.reparse, &mut *lk.global);
    let mut by_id: FxMap<&str, &Polygon> = FxMap::default();
    visit_polys(obj, &mut |p| {
        if let (false, Some(id)) = (is_placeholder(p), &p.id) {
            by_id.insert(id.as_str(), p);
        }
    });
    let mut phs: Vec<&Polygon> = Vec::new();
    visit_geoms(obj, &mut |g| {
        if let GeometryKind::Solids(v) = &g.kind {
            phs.extend(v.iter().filter(|s| is_solid_placeholder(s)).map(|s| &s.0.polygons[0]));
        }
    });
    let ctx = SolidCtx { by_id: &by_id, local_ids, reparse };
    let mut resolved = Vec::new();
    for ph in phs {
        let via = ph.via_xlink.clone().unwrap_or_default();
        let mut out = (Vec::new(), Vec::new());
        let href = ph.id.as_deref().unwrap_or("");
        ctx.resolve_solid(href, &via, global, 0, &mut out, unresolved)?;
        let target = match href_id(href) {
            Some(id) => find_id(local_ids, global, id)?,
            None => None,
        };
        let name = target.map(|e| String::from_utf8_lossy(name_at(reparse.src, e.bytes.start)).into_owned());
        resolved.push((out, name));
    }
    Ok(resolved)
}

/// Phases 1 and 2: what each polygon placeholder becomes (under a shared borrow, in visiting
/// order), then spliced in in the same order.
pub(super) fn resolve_polygon_refs(
    obj: &mut CityObject,
    lk: &mut Lookups<'_, '_, '_>,
    unresolved: &mut Vec<XLinkRef>,
) -> Result<(), ReadError> {
    let (local_ids, reparse, global) = (lk.local_ids, lk.reparse, &mut *lk.global);
    let mut replacements: Vec<Option<Vec<Polygon>>> = Vec::new();
    {
        let mut by_id: FxMap<&str, &Polygon> = FxMap::default();
        let mut phs: Vec<&Polygon> = Vec::new();
        visit_polys(obj, &mut |p| {
            if is_placeholder(p) {
                phs.push(p);
            } else if let Some(id) = &p.id {
                by_id.insert(id.as_str(), p);
            }
        });
        for ph in phs {
            let r = resolve_one(ph, &by_id, local_ids, reparse, global, 0)?;
            if r.is_none() {
                unresolved
                    .push(XLinkRef::at(ph.id.clone().unwrap_or_default(), ph.via_xlink.clone().unwrap_or_default()));
            }
            replacements.push(r);
        }
    }
    let mut it = replacements.into_iter();
    visit_vecs_mut(obj, &mut |v| {
        if !v.iter().any(is_placeholder) {
            return;
        }
        let cap = v.len();
        let old = std::mem::replace(v, Vec::with_capacity(cap));
        for p in old {
            if is_placeholder(&p) {
                if let Some(Some(r)) = it.next() {
                    v.extend(r);
                }
            } else {
                v.push(p);
            }
        }
    });
    Ok(())
}

/// The deepest object of `obj` (itself included) whose element holds byte `at`.
pub(super) fn innermost_at(obj: &CityObject, at: usize) -> Option<&CityObject> {
    if !obj.span.bytes.contains(&at) {
        return None;
    }
    obj.children.iter().find_map(|c| innermost_at(c, at)).or(Some(obj))
}

/// What resolving a solid XLink needs besides the global index.
pub(super) struct SolidCtx<'m, 'o, 'r, 'a> {
    by_id: &'m FxMap<&'o str, &'o Polygon>,
    local_ids: &'m FxMap<String, IdEntry>,
    reparse: &'m Reparse<'r, 'a>,
}

impl SolidCtx<'_, '_, '_, '_> {
    /// The solids `href` (a `solidMember xlink:href` at `via`) stands for, appended to `out.0`
    /// as copies (every polygon's `via_xlink` = `via`, polygon XLinks inside them resolved);
    /// when there are none, a skipped member saying why goes to `out.1`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn resolve_solid(
        &self,
        href: &str,
        via: &SourceSpan,
        global: &mut dyn GlobalIds,
        depth: usize,
        out: &mut (Vec<Solid>, Vec<SkippedMember>),
        unresolved: &mut Vec<XLinkRef>,
    ) -> Result<(), ReadError> {
        let skip = |reason: String| SkippedMember { href: Some(href.to_string()), reason, span: via.clone() };
        let nowhere = |unresolved: &mut Vec<XLinkRef>| {
            unresolved.push(XLinkRef::at(href.to_string(), via.clone()));
            skip(format!("xlink:href=\"{}\" points to nothing in the document", quote(href)))
        };
        let Some(id) = href_id(href) else {
            out.1.push(nowhere(unresolved));
            return Ok(());
        };
        if depth > 8 {
            out.1.push(skip(format!("xlink:href=\"{}\": reference cycle", quote(href))));
            return Ok(());
        }
        let entry = find_id(self.local_ids, global, id)?;
        let Some(entry) = entry else {
            out.1.push(nowhere(unresolved));
            return Ok(());
        };
        let (solids, skipped) = match self.reparse.solids(&entry)? {
            Ok(r) => r,
            Err(name) => {
                out.1.push(skip(format!("xlink:href=\"{}\" points to <{}>, not a solid", quote(href), quote(&name))));
                return Ok(());
            }
        };
        out.1.extend(skipped);
        for mut s in solids {
            if is_solid_placeholder(&s) {
                let ph = &s.0.polygons[0];
                let inner = ph.id.clone().unwrap_or_default();
                self.resolve_solid(&inner, via, global, depth + 1, out, unresolved)?;
                continue;
            }
            for shell in std::iter::once(&mut s.0).chain(s.1.iter_mut()) {
                if shell.polygons.iter().any(is_placeholder) {
                    let old = std::mem::take(&mut shell.polygons);
                    for p in old {
                        if !is_placeholder(&p) {
                            shell.polygons.push(p);
                            continue;
                        }
                        match resolve_one(&p, self.by_id, self.local_ids, self.reparse, global, 0)? {
                            Some(r) => shell.polygons.extend(r),
                            None => unresolved.push(XLinkRef::at(
                                p.id.clone().unwrap_or_default(),
                                p.via_xlink.clone().unwrap_or_default(),
                            )),
                        }
                    }
                }
                for p in &mut shell.polygons {
                    p.via_xlink = Some(via.clone());
                }
                shell.via_xlink = Some(via.clone());
            }
            out.0.push(s);
        }
        Ok(())
    }
}

pub(super) fn resolve_one(
    ph: &Polygon,
    by_id: &FxMap<&str, &Polygon>,
    local_ids: &FxMap<String, IdEntry>,
    reparse: &Reparse<'_, '_>,
    global: &mut dyn GlobalIds,
    depth: usize,
) -> Result<Option<Vec<Polygon>>, ReadError> {
    let href = ph.id.as_deref().unwrap_or("");
    let Some(id) = href_id(href) else { return Ok(None) };
    let via = ph.via_xlink.clone();
    let copy = |p: &Polygon| {
        let mut c = p.clone();
        c.reversed ^= ph.reversed;
        c.via_xlink = via.clone();
        c
    };
    if let Some(p) = by_id.get(id) {
        return Ok(Some(vec![copy(p)]));
    }
    if depth > 8 {
        return Ok(None); // reference cycle
    }
    let Some(entry) = find_id(local_ids, global, id)? else { return Ok(None) };
    if !is_surface_like(name_at(reparse.src, entry.bytes.start)) {
        return Ok(None); // an id'd element that is not a geometry (the global index holds all ids)
    }
    let mut out = Vec::new();
    for p in reparse.surfaces(&entry)? {
        if is_placeholder(&p) {
            if let Some(r) = resolve_one(&p, by_id, local_ids, reparse, global, depth + 1)? {
                out.extend(r.iter().map(&copy));
            }
        } else {
            out.push(copy(&p));
        }
    }
    Ok(Some(out))
}
