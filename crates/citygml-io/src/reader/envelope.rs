//! Envelopes computed from the coordinates of an object and its children.

use super::*;

/// Computes envelopes from coordinates (children included); keeps the declared one where an
/// object has no geometry of its own.
pub(crate) fn finish_envelopes(obj: &mut CityObject) {
    let mut env = Envelope::empty();
    for c in &mut obj.children {
        finish_envelopes(c);
        env.merge(&c.envelope);
    }
    // Plain comparisons instead of Envelope::add_point's f64::min/max, in locals: the same
    // result (a NaN never wins a comparison, as f64::min ignores it; the reader rejects
    // non-finite coordinates anyway) in straight min/max instructions.
    let (mut lo, mut hi) = (env.min, env.max);
    let mut add_shell = |polys: &[Polygon]| {
        for p in polys {
            for r in std::iter::once(&p.exterior).chain(p.interiors.iter()) {
                for q in &r.points {
                    for i in 0..3 {
                        lo[i] = if q[i] < lo[i] { q[i] } else { lo[i] };
                        hi[i] = if q[i] > hi[i] { q[i] } else { hi[i] };
                    }
                }
            }
        }
    };
    for g in &obj.geometries {
        match &g.kind {
            GeometryKind::Surfaces(v) => add_shell(v),
            GeometryKind::Solid { exterior, interior } => {
                add_shell(&exterior.polygons);
                for s in interior {
                    add_shell(&s.polygons);
                }
            }
            GeometryKind::Solids(v) => {
                for (e, i) in v {
                    add_shell(&e.polygons);
                    for s in i {
                        add_shell(&s.polygons);
                    }
                }
            }
        }
    }
    env.min = lo;
    env.max = hi;
    if !env.is_empty() {
        obj.envelope = env;
    }
}
