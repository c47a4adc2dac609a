//! The working copy of one building's geometry that the repairs change: every polygon once (a
//! polygon reached by XLink is the polygon it points to, keyed by the byte span of its
//! definition), and the snap contexts the validator checks them in (each surface set and each
//! shell), so a repair sees the vertices the validator sees.

use super::ring::{Vx, P3};
use citygml_io::{CityObject, GeometryKind, Polygon, Shell};
use citygml_validate::geom::Snapper;
use std::collections::HashMap;

/// One face of a polygon's current geometry: its rings (open, exterior first).
pub type Face = Vec<Vec<P3>>;

/// One polygon of the building (its definition) as the repairs leave it.
pub struct WPoly<'a> {
    pub src: &'a Polygon,
    /// The polygon's own face (ring 0 exterior), current.
    pub face: Face,
    /// Faces split off this polygon (lobes of a pinched ring), written as new polygons.
    pub extra: Vec<Face>,
    /// Removed (a ring collapsed to no area).
    pub removed: bool,
    /// A copy of it is reached through an XLink in this building: it cannot be removed or
    /// split into several polygons without rewriting the reference.
    pub referenced: bool,
    /// Its rings cannot be repaired here (a ring not closed, too short or not 3D): left as is.
    pub frozen: bool,
}

impl WPoly<'_> {
    pub fn changed(&self) -> bool {
        self.removed || !self.extra.is_empty() || self.face.len() != 1 + self.src.interiors.len() || {
            let orig = std::iter::once(&self.src.exterior).chain(self.src.interiors.iter());
            orig.zip(&self.face)
                .any(|(r, f)| r.points.len() != f.len() + 1 || r.points.iter().zip(f).any(|(a, b)| a != b))
        }
    }
    /// All faces, own first.
    pub fn faces(&self) -> impl Iterator<Item = &Face> {
        std::iter::once(&self.face).chain(self.extra.iter())
    }
}

/// What kind of boundary a snap context is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A MultiSurface / CompositeSurface: polygons checked one by one.
    Surfaces,
    /// The exterior shell of a solid (faces point outwards).
    Exterior,
    /// An interior shell (a cavity; faces point into it).
    Interior,
}

/// The polygons the validator checks together, with one snapper: (polygon index, whether this
/// use is `-` oriented).
pub struct Context {
    pub kind: Kind,
    pub members: Vec<(usize, bool)>,
}

/// The working copy of one building.
pub struct Work<'a> {
    pub polys: Vec<WPoly<'a>>,
    pub contexts: Vec<Context>,
}

fn open_ring(points: &[P3]) -> Option<Vec<P3>> {
    if points.len() < 4 || points[0] != points[points.len() - 1] {
        return None;
    }
    Some(points[..points.len() - 1].to_vec())
}

impl<'a> Work<'a> {
    /// Collects the polygons and contexts of a unit's own objects.
    pub fn new(objects: &[&'a CityObject]) -> Work<'a> {
        let mut w = Work { polys: Vec::new(), contexts: Vec::new() };
        let mut index: HashMap<(usize, usize), usize> = HashMap::new();
        for o in objects {
            for g in &o.geometries {
                match &g.kind {
                    GeometryKind::Surfaces(ps) => w.add_context(Kind::Surfaces, ps, &mut index),
                    GeometryKind::Solid { exterior, interior } => w.add_solid(exterior, interior, &mut index),
                    GeometryKind::Solids(v) => {
                        for (e, i) in v {
                            w.add_solid(e, i, &mut index);
                        }
                    }
                }
            }
        }
        w
    }

    fn add_solid(&mut self, exterior: &'a Shell, interior: &'a [Shell], index: &mut HashMap<(usize, usize), usize>) {
        self.add_context(Kind::Exterior, &exterior.polygons, index);
        for s in interior {
            self.add_context(Kind::Interior, &s.polygons, index);
        }
    }

    fn add_context(&mut self, kind: Kind, ps: &'a [Polygon], index: &mut HashMap<(usize, usize), usize>) {
        let mut members = Vec::with_capacity(ps.len());
        for p in ps {
            let key = (p.span.bytes.start, p.span.bytes.end);
            let i = *index.entry(key).or_insert_with(|| {
                let rings: Option<Face> =
                    std::iter::once(&p.exterior).chain(p.interiors.iter()).map(|r| open_ring(&r.points)).collect();
                let dims_ok = std::iter::once(&p.exterior).chain(p.interiors.iter()).all(|r| r.srs_dimension == 3);
                let frozen = rings.is_none() || !dims_ok;
                let face = rings.unwrap_or_default();
                self.polys.push(WPoly { src: p, face, extra: Vec::new(), removed: false, referenced: false, frozen });
                self.polys.len() - 1
            });
            if p.via_xlink.is_some() {
                self.polys[i].referenced = true;
            } else {
                self.polys[i].src = p; // the definition (its member span is the one to edit)
            }
            members.push((i, p.reversed));
        }
        self.contexts.push(Context { kind, members });
    }

    /// The context's faces as rings of snapped vertices, in the validator's order, and the
    /// coordinates of each vertex id as first written. Faces: (polygon, face index, reversed).
    pub fn snap(&self, c: &Context, tol: f64) -> (Vec<P3>, Vec<FaceRef>, Vec<Vec<Vec<Vx>>>) {
        let mut snap = Snapper::new(tol);
        let mut coords: Vec<P3> = Vec::new();
        let mut add = |q: &P3| {
            let id = snap.add(q);
            if id as usize == coords.len() {
                coords.push(*q);
            }
            id
        };
        let mut refs = Vec::new();
        let mut rings = Vec::new();
        for &(pi, rev) in &c.members {
            let p = &self.polys[pi];
            if p.removed || p.frozen {
                continue;
            }
            for (fi, f) in p.faces().enumerate() {
                let face: Vec<Vec<Vx>> = f
                    .iter()
                    .map(|r| {
                        let v: Vec<Vx> = r.iter().map(|q| (add(q), *q)).collect();
                        if let Some(q) = r.first() {
                            add(q);
                        }
                        v
                    })
                    .collect();
                refs.push(FaceRef { poly: pi, face: fi, reversed: rev });
                rings.push(face);
            }
        }
        (coords, refs, rings)
    }

    /// Writes rings of snapped vertices back into a face.
    pub fn set_face(&mut self, r: &FaceRef, rings: &[Vec<Vx>]) {
        let face: Face = rings.iter().map(|ring| ring.iter().map(|v| v.1).collect()).collect();
        let p = &mut self.polys[r.poly];
        if r.face == 0 {
            p.face = face;
        } else {
            p.extra[r.face - 1] = face;
        }
    }
}

/// One face in a context.
#[derive(Debug, Clone, Copy)]
pub struct FaceRef {
    pub poly: usize,
    pub face: usize,
    pub reversed: bool,
}
