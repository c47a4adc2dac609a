//! Solid level (401–405): each shell must be valid on its own; then the exterior shell must face
//! outwards and interior shells (cavities) inwards (405), interior shells must not be duplicates
//! (402), cross other shells (401) or lie outside the exterior (403).
//! 404 SOLID_INTERIOR_DISCONNECTED (shells touching so that the interior splits) is not detected.

use crate::codes::ErrorCode;
use crate::geom::V3;
use crate::polygon::PolygonInput;
use crate::shell::{check_shell, contact_eps, ShellMesh};
use crate::tritri::contact;
use crate::{Issue, Options};
use rstar::{primitives::GeomWithData, primitives::Rectangle, RTree, AABB};

fn solid_issue(code: ErrorCode, shell: usize, detail: String) -> Issue {
    Issue { code, polygon: None, ring: None, shell: Some(shell), detail, value: None }
}

/// Checks a solid given as its shells (index 0 = exterior, then cavities).
pub fn check_solid(shells: &[Vec<PolygonInput>], opts: &Options) -> Vec<Issue> {
    let mut issues = Vec::new();
    let mut meshes: Vec<ShellMesh> = Vec::new();
    for (si, polys) in shells.iter().enumerate() {
        let (is, mesh) = check_shell(polys, opts);
        issues.extend(is.into_iter().map(|mut i| {
            i.shell = Some(si);
            i
        }));
        if let Some(m) = mesh {
            meshes.push(m);
        }
    }
    if !issues.is_empty() {
        return issues;
    }
    for (si, m) in meshes.iter().enumerate() {
        let vol = m.signed_volume();
        if si == 0 && vol < 0.0 {
            issues.push(solid_issue(
                ErrorCode::WrongOrientationShell,
                si,
                format!("exterior shell has its normals pointing inwards (signed volume {:.6} m³)", vol),
            ));
        } else if si > 0 && vol > 0.0 {
            issues.push(solid_issue(
                ErrorCode::WrongOrientationShell,
                si,
                format!("interior shell {} has its normals pointing outwards (signed volume {:.6} m³)", si, vol),
            ));
        }
    }
    if !issues.is_empty() || meshes.len() < 2 {
        return issues;
    }
    // common frame: the exterior shell's origin
    let o = meshes[0].origin;
    let pts: Vec<Vec<V3>> = meshes.iter().map(|m| m.points.iter().map(|p| p + m.origin - o).collect()).collect();
    // 402: two shells with the same vertices
    let key = |ps: &Vec<V3>| {
        let mut k: Vec<[i64; 3]> = ps.iter().map(|p| [p.x, p.y, p.z].map(|c| (c / opts.snap_tol.max(1e-9)).round() as i64)).collect();
        k.sort_unstable();
        k
    };
    let keys: Vec<_> = pts.iter().map(key).collect();
    for a in 0..meshes.len() {
        for b in a + 1..meshes.len() {
            if keys[a] == keys[b] {
                issues.push(solid_issue(ErrorCode::DuplicatedShells, b, format!("shells {} and {} are identical", a + 1, b + 1)));
            }
        }
    }
    if !issues.is_empty() {
        return issues;
    }
    // 401: shells may touch at a point, but not cross or share an edge/face piece
    let extent = pts[0].iter().map(|p| p.norm()).fold(0.0, f64::max);
    let (eps, touch) = contact_eps(opts, extent);
    let tri = |s: usize, t: &[u32; 3]| [pts[s][t[0] as usize], pts[s][t[1] as usize], pts[s][t[2] as usize]];
    let boxed = |s: usize| -> RTree<GeomWithData<Rectangle<[f64; 3]>, usize>> {
        let items = meshes[s]
            .triangles
            .iter()
            .enumerate()
            .map(|(k, t)| {
                let p = tri(s, t);
                let lo = [0, 1, 2].map(|i| p.iter().map(|q| q[i]).fold(f64::INFINITY, f64::min) - touch);
                let hi = [0, 1, 2].map(|i| p.iter().map(|q| q[i]).fold(f64::NEG_INFINITY, f64::max) + touch);
                GeomWithData::new(Rectangle::from_corners(lo, hi), k)
            })
            .collect();
        RTree::bulk_load(items)
    };
    let trees: Vec<_> = (0..meshes.len()).map(boxed).collect();
    'pairs: for a in 0..meshes.len() {
        for b in a + 1..meshes.len() {
            for ia in trees[a].iter() {
                let ta = &meshes[a].triangles[ia.data];
                let env = AABB::from_corners(ia.geom().lower(), ia.geom().upper());
                for ib in trees[b].locate_in_envelope_intersecting(&env) {
                    let tb = &meshes[b].triangles[ib.data];
                    let c = contact(&tri(a, ta), &tri(b, tb), eps);
                    let spread = c.iter().flat_map(|p| c.iter().map(move |q| (p - q).norm())).fold(0.0, f64::max);
                    if !c.is_empty() && spread > touch {
                        issues.push(solid_issue(
                            ErrorCode::IntersectionShells,
                            b,
                            format!("shells {} and {} intersect near {}", a + 1, b + 1, fmt(&(c[0] + o))),
                        ));
                        continue 'pairs;
                    }
                }
            }
        }
    }
    if !issues.is_empty() {
        return issues;
    }
    // 403: a cavity must lie inside the exterior shell (generalised winding number of its vertices)
    for s in 1..meshes.len() {
        let outside = pts[s].iter().any(|p| winding_number(&pts[0], &meshes[0].triangles, p).abs() < 0.5);
        if outside {
            issues.push(solid_issue(ErrorCode::InnerShellOutside, s, format!("interior shell {} is not inside the exterior shell", s)));
        }
    }
    issues
}

fn fmt(p: &V3) -> String {
    let r = |x: f64| (x * 1e6).round() / 1e6;
    format!("({}, {}, {})", r(p.x), r(p.y), r(p.z))
}

/// Generalised winding number of `q` with respect to a closed triangle mesh (Van Oosterom and
/// Strackee solid angles): 1 inside, 0 outside.
pub fn winding_number(points: &[V3], tris: &[[u32; 3]], q: &V3) -> f64 {
    let mut total = 0.0;
    for t in tris {
        let a = points[t[0] as usize] - q;
        let b = points[t[1] as usize] - q;
        let c = points[t[2] as usize] - q;
        let (la, lb, lc) = (a.norm(), b.norm(), c.norm());
        let num = a.dot(&b.cross(&c));
        let den = la * lb * lc + a.dot(&b) * lc + b.dot(&c) * la + c.dot(&a) * lb;
        total += 2.0 * num.atan2(den);
    }
    total / (4.0 * std::f64::consts::PI)
}
