//! Unit tests on hand-made rings, polygons and shells whose verdicts are known by construction.

use crate::codes::ErrorCode;
use crate::polygon::PolygonInput;
use crate::{check_composite_solid, check_solid, check_surfaces, Options};

type P = [f64; 3];

fn poly(ext: &[P]) -> Vec<P> {
    let mut v = ext.to_vec();
    v.push(ext[0]);
    v
}

fn codes_surfaces(rings: &[(Vec<P>, Vec<Vec<P>>)], opts: &Options) -> Vec<u16> {
    let inp: Vec<PolygonInput> = rings
        .iter()
        .map(|(e, i)| PolygonInput {
            exterior: e,
            interiors: i.iter().map(|r| r.as_slice()).collect(),
            reversed: false,
        })
        .collect();
    check_surfaces(&inp, opts).iter().map(|i| i.code.code()).collect()
}

fn square(z: f64) -> Vec<P> {
    poly(&[[0., 0., z], [1., 0., z], [1., 1., z], [0., 1., z]])
}

/// The six faces of the unit cube [0,1]³, counter-clockwise seen from outside.
fn cube() -> Vec<Vec<P>> {
    vec![
        poly(&[[0., 0., 0.], [0., 1., 0.], [1., 1., 0.], [1., 0., 0.]]),
        poly(&[[0., 0., 1.], [1., 0., 1.], [1., 1., 1.], [0., 1., 1.]]),
        poly(&[[0., 0., 0.], [1., 0., 0.], [1., 0., 1.], [0., 0., 1.]]),
        poly(&[[1., 0., 0.], [1., 1., 0.], [1., 1., 1.], [1., 0., 1.]]),
        poly(&[[1., 1., 0.], [0., 1., 0.], [0., 1., 1.], [1., 1., 1.]]),
        poly(&[[0., 1., 0.], [0., 0., 0.], [0., 0., 1.], [0., 1., 1.]]),
    ]
}

fn solid_codes(faces: &[Vec<P>], opts: &Options) -> Vec<u16> {
    let inp: Vec<PolygonInput> =
        faces.iter().map(|f| PolygonInput { exterior: f, interiors: vec![], reversed: false }).collect();
    check_solid(&[inp], opts).iter().map(|i| i.code.code()).collect()
}

#[test]
fn codes_and_names_are_val3dity_s() {
    assert_eq!(ErrorCode::from_code(307).unwrap().name(), "POLYGON_WRONG_ORIENTATION");
    assert_eq!(ErrorCode::from_code(405).unwrap().name(), "WRONG_ORIENTATION_SHELL");
    assert_eq!(ErrorCode::ALL.len(), 28);
}

#[test]
fn ring_level() {
    let o = Options::default();
    assert_eq!(codes_surfaces(&[(square(0.), vec![])], &o), Vec::<u16>::new());
    // 101: two distinct points
    assert_eq!(codes_surfaces(&[(vec![[0., 0., 0.], [1., 0., 0.], [0., 0., 0.]], vec![])], &o), vec![101]);
    // 102: a repeated point (within the snap tolerance)
    let r = poly(&[[0., 0., 0.], [1., 0., 0.], [1., 0.0005, 0.], [1., 1., 0.], [0., 1., 0.]]);
    assert_eq!(codes_surfaces(&[(r, vec![])], &o), vec![102]);
    // 103: not closed
    let r = vec![[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]];
    assert_eq!(codes_surfaces(&[(r, vec![])], &o), vec![103]);
    // 104: bow-tie
    let r = poly(&[[0., 0., 0.], [1., 1., 0.], [1., 0., 0.], [0., 1., 0.]]);
    assert_eq!(codes_surfaces(&[(r, vec![])], &o), vec![104]);
    // 901: a coordinate that is not a number (the reader may accept "NaN")
    let r = poly(&[[0., 0., 0.], [1., 0., f64::NAN], [1., 1., 0.]]);
    assert_eq!(codes_surfaces(&[(r, vec![])], &o), vec![901]);
    // 104: a long zig-zag ring whose last segment crosses the first (sweep over many segments)
    let mut z: Vec<P> = (0..2000).map(|k| [k as f64 * 0.01, if k % 2 == 0 { 0.0 } else { 0.5 }, 0.]).collect();
    z.push([19.99, -1.0, 0.]);
    z.push([0.005, 0.2, 0.]);
    assert_eq!(codes_surfaces(&[(poly(&z), vec![])], &o), vec![104]);
    // 104: collapsed triangle
    let r = poly(&[[0., 0., 0.], [1., 0., 0.], [2., 0., 0.]]);
    assert_eq!(codes_surfaces(&[(r, vec![])], &o), vec![104]);
}

#[test]
fn polygon_level() {
    let o = Options::default();
    let hole = |pts: &[P]| poly(pts);
    // a proper hole (clockwise) is valid
    let h = hole(&[[0.25, 0.25, 0.], [0.25, 0.75, 0.], [0.75, 0.75, 0.], [0.75, 0.25, 0.]]);
    assert_eq!(codes_surfaces(&[(square(0.), vec![h.clone()])], &o), Vec::<u16>::new());
    // 208: same orientation as the exterior
    let mut h2 = h.clone();
    h2.reverse();
    assert_eq!(codes_surfaces(&[(square(0.), vec![h2])], &o), vec![208]);
    // 202: the same hole twice
    assert_eq!(codes_surfaces(&[(square(0.), vec![h.clone(), h.clone()])], &o), vec![202]);
    // 206: hole outside
    let out = hole(&[[2., 2., 0.], [2., 3., 0.], [3., 3., 0.], [3., 2., 0.]]);
    assert_eq!(codes_surfaces(&[(square(0.), vec![out])], &o), vec![206]);
    // 201: hole crossing the exterior
    let cross = hole(&[[0.5, 0.5, 0.], [0.5, 1.5, 0.], [1.5, 1.5, 0.], [1.5, 0.5, 0.]]);
    assert_eq!(codes_surfaces(&[(square(0.), vec![cross])], &o), vec![201]);
    // 207: hole inside another hole
    let inner = hole(&[[0.4, 0.4, 0.], [0.4, 0.6, 0.], [0.6, 0.6, 0.], [0.6, 0.4, 0.]]);
    assert_eq!(codes_surfaces(&[(square(0.), vec![h.clone(), inner])], &o), vec![207]);
    // 205: a hole touching the exterior at two points cuts the polygon in two
    let cut = hole(&[[0., 0.5, 0.], [0.5, 0.6, 0.], [1., 0.5, 0.], [0.5, 0.4, 0.]]);
    assert_eq!(codes_surfaces(&[(square(0.), vec![cut])], &o), vec![205]);
    // a hole touching the exterior at one point is valid
    let touch = hole(&[[0., 0.5, 0.], [0.5, 0.6, 0.], [0.6, 0.5, 0.], [0.5, 0.4, 0.]]);
    assert_eq!(codes_surfaces(&[(square(0.), vec![touch])], &o), Vec::<u16>::new());
}

#[test]
fn planarity_distance_is_the_least_squares_residual() {
    // one corner of the unit square lifted by h: the least-squares plane leaves residuals of ±h/4
    let h = 0.1;
    let r = poly(&[[0., 0., 0.], [1., 0., 0.], [1., 1., h], [0., 1., 0.]]);
    let inp = [PolygonInput { exterior: &r, interiors: vec![], reversed: false }];
    let is = check_surfaces(&inp, &Options { planarity_tol: 0.02, ..Options::default() });
    assert_eq!(is.len(), 1);
    assert_eq!(is[0].code.code(), 203);
    let d = is[0].value.unwrap();
    // the same square as QIE t203_1.gml, for which tests/scripts/validate_tolerance.py (numpy SVD)
    // gives 0.02506179826000084; ordinary least squares in z would give h/4/sqrt(1+h²/2) = 0.024938
    assert!((d - 0.02506179826000084).abs() < 1e-12, "{d}");
    assert!(check_surfaces(&inp, &Options { planarity_tol: 0.03, ..Options::default() }).is_empty());
}

#[test]
fn shell_level() {
    let o = Options::default();
    assert_eq!(solid_codes(&cube(), &o), Vec::<u16>::new());
    // 302: a missing face
    assert_eq!(solid_codes(&cube()[1..], &o), vec![302]);
    // 301
    assert_eq!(solid_codes(&cube()[..3], &o), vec![301]);
    // 307: one face flipped
    let mut c = cube();
    c[1].reverse();
    assert_eq!(solid_codes(&c, &o), vec![307]);
    // 405: all faces flipped
    let c: Vec<Vec<P>> = cube()
        .into_iter()
        .map(|mut f| {
            f.reverse();
            f
        })
        .collect();
    assert_eq!(solid_codes(&c, &o), vec![405]);
    // 305: two cubes apart
    let mut two = cube();
    two.extend(cube().into_iter().map(|f| f.into_iter().map(|p| [p[0] + 3., p[1], p[2]]).collect()));
    assert_eq!(solid_codes(&two, &o), vec![305]);
    // two overlapping cubes are two closed components: 305 comes first, as in val3dity
    let mut two = cube();
    two.extend(cube().into_iter().map(|f| f.into_iter().map(|p| [p[0] + 0.5, p[1] + 0.5, p[2] + 0.5]).collect()));
    assert_eq!(solid_codes(&two, &o), vec![305]);
    // 306: a closed, connected shell whose roof apex touches the floor (QIE i306_2)
    let apex = [0.5, 0.5, 0.0];
    let mut house = vec![cube()[0].clone()];
    house.extend(cube()[2..].iter().cloned());
    for (a, b) in [
        ([0., 0., 1.], [1., 0., 1.]),
        ([1., 0., 1.], [1., 1., 1.]),
        ([1., 1., 1.], [0., 1., 1.]),
        ([0., 1., 1.], [0., 0., 1.]),
    ] {
        house.push(poly(&[a, b, apex]));
    }
    let c = solid_codes(&house, &o);
    assert!(!c.is_empty() && c.iter().all(|&c| c == 306), "{c:?}");
}

fn inp(s: &[Vec<P>]) -> Vec<PolygonInput<'_>> {
    s.iter().map(|f| PolygonInput { exterior: f, interiors: vec![], reversed: false }).collect()
}

#[test]
fn cavity_checks() {
    let o = Options::default();
    let ext: Vec<Vec<P>> =
        cube().into_iter().map(|f| f.into_iter().map(|p| [p[0] * 4., p[1] * 4., p[2] * 4.]).collect()).collect();
    // a cavity is an inward-facing shell inside the exterior
    let cav: Vec<Vec<P>> = cube()
        .into_iter()
        .map(|f| {
            let mut f: Vec<P> = f.into_iter().map(|p| [p[0] + 1.5, p[1] + 1.5, p[2] + 1.5]).collect();
            f.reverse();
            f
        })
        .collect();
    assert!(check_solid(&[inp(&ext), inp(&cav)], &o).is_empty());
    // outside the exterior: 403
    let far: Vec<Vec<P>> = cav.iter().map(|f| f.iter().map(|p| [p[0] + 10., p[1], p[2]]).collect()).collect();
    let c: Vec<u16> = check_solid(&[inp(&ext), inp(&far)], &o).iter().map(|i| i.code.code()).collect();
    assert_eq!(c, vec![403]);
    // crossing the exterior: 401
    let cross: Vec<Vec<P>> = cav.iter().map(|f| f.iter().map(|p| [p[0] + 2., p[1], p[2]]).collect()).collect();
    let c: Vec<u16> = check_solid(&[inp(&ext), inp(&cross)], &o).iter().map(|i| i.code.code()).collect();
    assert_eq!(c, vec![401]);
    // the same cavity twice: 402
    let c: Vec<u16> = check_solid(&[inp(&ext), inp(&cav), inp(&cav)], &o).iter().map(|i| i.code.code()).collect();
    assert_eq!(c, vec![402]);
}

fn scaled(s: &[Vec<P>], k: f64, d: P) -> Vec<Vec<P>> {
    s.iter().map(|f| f.iter().map(|p| [p[0] * k + d[0], p[1] * k + d[1], p[2] * k + d[2]]).collect()).collect()
}

fn reversed(s: &[Vec<P>]) -> Vec<Vec<P>> {
    s.iter().map(|f| f.iter().rev().copied().collect()).collect()
}

/// A cavity shaped like a cup: two downward pyramids on the same square rim `[lo, hi]²` at
/// height `top`, apexes at `top - deep` and `top - shallow`: the solid between them, faces
/// pointing into it (a cavity faces inwards).
fn cup(lo: f64, hi: f64, top: f64, deep: f64, shallow: f64) -> Vec<Vec<P>> {
    let c = (lo + hi) / 2.0;
    let rim = [[lo, lo, top], [hi, lo, top], [hi, hi, top], [lo, hi, top]];
    let (outer, inner) = ([c, c, top - deep], [c, c, top - shallow]);
    let mut faces = Vec::new();
    for i in 0..4 {
        let (a, b) = (rim[i], rim[(i + 1) % 4]);
        // outward normals of the cup solid: the outer pyramid's sides face down/out, the inner
        // ones up/in; reversed below for a cavity
        faces.push(poly(&[a, outer, b]));
        faces.push(poly(&[a, b, inner]));
    }
    reversed(&faces)
}

#[test]
fn interior_disconnected_404() {
    let o = Options::default();
    let ext = scaled(&cube(), 4., [0., 0., 0.]);
    // a cup-shaped cavity whose rim lies in the roof: the rim touches the exterior along a
    // closed loop, and the pocket between the cup and the roof is cut off from the rest
    let touching = cup(1., 3., 4., 3., 1.);
    let c: Vec<u16> = check_solid(&[inp(&ext), inp(&touching)], &o).iter().map(|i| i.code.code()).collect();
    assert_eq!(c, vec![404]);
    // the same cup 0.5 m lower: no contact, a valid cavity
    let lower = cup(1., 3., 3.5, 3., 1.);
    assert!(check_solid(&[inp(&ext), inp(&lower)], &o).is_empty());
    // a wedge (triangular prism) cavity whose ridge touches the roof along one segment: an
    // open contact, valid
    let (a0, b0, c0) = ([1.5, 1.5, 3.], [1.5, 2.5, 3.], [1.5, 2., 4.]);
    let (a1, b1, c1) = ([2.5, 1.5, 3.], [2.5, 2.5, 3.], [2.5, 2., 4.]);
    let wedge = reversed(&[
        poly(&[a0, c0, b0]),
        poly(&[a1, b1, c1]),
        poly(&[a0, b0, b1, a1]),
        poly(&[b0, c0, c1, b1]),
        poly(&[c0, a0, a1, c1]),
    ]);
    let c: Vec<u16> = check_solid(&[inp(&ext), inp(&wedge)], &o).iter().map(|i| i.code.code()).collect();
    assert_eq!(c, Vec::<u16>::new(), "a line contact is allowed");
    // the wedge pushed 1 cm through the roof: 401
    let through: Vec<Vec<P>> = wedge.iter().map(|f| f.iter().map(|p| [p[0], p[1], p[2] + 0.01]).collect()).collect();
    let c: Vec<u16> = check_solid(&[inp(&ext), inp(&through)], &o).iter().map(|i| i.code.code()).collect();
    assert_eq!(c, vec![401]);
    // a cavity sharing part of the roof: 401
    let flush = reversed(&scaled(&cube(), 1., [1.5, 1.5, 3.]));
    let c: Vec<u16> = check_solid(&[inp(&ext), inp(&flush)], &o).iter().map(|i| i.code.code()).collect();
    assert_eq!(c, vec![401]);
}

#[test]
fn composite_solid_50x() {
    let o = Options::default();
    let codes = |solids: &[Vec<Vec<P>>]| -> Vec<u16> {
        let inps: Vec<Vec<Vec<PolygonInput>>> = solids.iter().map(|s| vec![inp(s)]).collect();
        check_composite_solid(&inps, &o).iter().map(|(_, i)| i.code.code()).collect()
    };
    let a = cube();
    // two cubes sharing a face: valid
    assert_eq!(codes(&[a.clone(), scaled(&a, 1., [1., 0., 0.])]), Vec::<u16>::new());
    // sharing only part of a face (offset by half in y): still connected, valid
    assert_eq!(codes(&[a.clone(), scaled(&a, 1., [1., 0.5, 0.])]), Vec::<u16>::new());
    // 501: overlapping by 1 cm
    assert_eq!(codes(&[a.clone(), scaled(&a, 1., [0.99, 0., 0.])]), vec![501]);
    // 501: one inside the other (no surface crossing at all)
    assert_eq!(codes(&[scaled(&a, 4., [0., 0., 0.]), scaled(&a, 1., [1., 1., 1.])]), vec![501]);
    // 502: the same cube twice
    assert_eq!(codes(&[a.clone(), a.clone()]), vec![502]);
    // 503: a third cube apart, and one touching only along an edge
    assert_eq!(codes(&[a.clone(), scaled(&a, 1., [1., 0., 0.]), scaled(&a, 1., [5., 0., 0.])]), vec![503]);
    assert_eq!(codes(&[a.clone(), scaled(&a, 1., [1., 1., 0.])]), vec![503]);
    // a member that is itself invalid is reported at its own level, nothing between solids
    let c = codes(&[a.clone(), scaled(&a, 1., [1., 0., 0.])[1..].to_vec()]);
    assert_eq!(c, vec![302]);
}

/// A CityGML 2.0 document: a building whose lod2Solid is a CompositeSolid with `members`, and
/// a second building whose lod1Solid defines the unit cube `B` at x = 1..2 (faces from `cube`).
fn composite_doc(members: &str) -> String {
    let solid = |id: &str, dx: f64| {
        let mut s = format!("<gml:Solid gml:id=\"{id}\"><gml:exterior><gml:Shell>\n");
        for f in cube() {
            let pos: Vec<String> = f.iter().map(|p| format!("{} {} {}", p[0] + dx, p[1], p[2])).collect();
            s += &format!(
                "<gml:surfaceMember><gml:Polygon><gml:exterior><gml:LinearRing><gml:posList>{}</gml:posList></gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember>\n",
                pos.join(" ")
            );
        }
        s + "</gml:Shell></gml:exterior></gml:Solid>"
    };
    let members =
        members.replace("{A}", &solid("A", 0.0)).replace("{C}", &solid("C", 2.0)).replace("{D}", &solid("D", 0.0));
    format!(
        "<?xml version=\"1.0\"?>\n<core:CityModel xmlns:core=\"http://www.opengis.net/citygml/2.0\" \
         xmlns:bldg=\"http://www.opengis.net/citygml/building/2.0\" xmlns:gml=\"http://www.opengis.net/gml\" \
         xmlns:xlink=\"http://www.w3.org/1999/xlink\">\n\
         <core:cityObjectMember><bldg:Building gml:id=\"b\"><bldg:lod2Solid><gml:CompositeSolid gml:id=\"cs\">\n{members}\n\
         </gml:CompositeSolid></bldg:lod2Solid></bldg:Building></core:cityObjectMember>\n\
         <core:cityObjectMember><bldg:Building gml:id=\"other\"><bldg:lod1Solid>{}</bldg:lod1Solid></bldg:Building></core:cityObjectMember>\n\
         </core:CityModel>\n",
        solid("B", 1.0)
    )
}

fn doc_findings(members: &str) -> Vec<crate::Finding> {
    let src = composite_doc(members);
    let m = citygml_io::parse(src.as_bytes()).unwrap();
    crate::validate_model(&m, &Options::default())
}

fn doc_codes(members: &str) -> Vec<u16> {
    doc_findings(members).iter().map(|f| f.code).collect()
}

#[test]
fn composite_solid_members_by_xlink() {
    // A | B | C in a row, B only by XLink to a solid of another building: connected, valid.
    let row = "<gml:solidMember>{A}</gml:solidMember>\n<gml:solidMember xlink:href=\"#B\"/>\n<gml:solidMember>{C}</gml:solidMember>";
    assert_eq!(doc_codes(row), Vec::<u16>::new());
    // Without B, A and C share nothing: 503 (the XLinked member is what connects them).
    let apart = "<gml:solidMember>{A}</gml:solidMember>\n<gml:solidMember>{C}</gml:solidMember>";
    assert_eq!(doc_codes(apart), vec![503]);
    // The same solid referenced twice, and a solid defined inline and referenced again: 502.
    assert_eq!(doc_codes("<gml:solidMember xlink:href=\"#B\"/><gml:solidMember xlink:href=\"#B\"/>"), vec![502]);
    assert_eq!(doc_codes("<gml:solidMember>{A}</gml:solidMember>\n<gml:solidMember xlink:href=\"#A\"/>"), vec![502]);
}

/// A face XLink to a city object (not a geometry) is a 901 under the object holding it, with
/// what the id names.
#[test]
fn face_xlink_to_a_city_object_is_a_901_of_its_feature() {
    let members =
        "<gml:solidMember>{A}</gml:solidMember>\n<gml:solidMember><gml:Solid gml:id=\"X\"><gml:exterior><gml:Shell>\n\
                   <gml:surfaceMember xlink:href=\"#other\"/></gml:Shell></gml:exterior></gml:Solid></gml:solidMember>";
    let f = doc_findings(members);
    let x: Vec<_> = f.iter().filter(|f| f.code == 901).collect();
    assert_eq!(x.len(), 1, "{f:?}");
    let line = composite_doc(members).lines().position(|l| l.contains("#other")).unwrap() + 1;
    assert_eq!(
        (x[0].feature.as_deref(), x[0].feature_type.as_str(), x[0].detail.as_str(), x[0].line),
        (Some("b"), "Building", "xlink:href=\"#other\" points to <bldg:Building>, not a geometry", line)
    );
}

#[test]
fn composite_solid_member_that_cannot_be_read_is_a_finding() {
    let members = "<gml:solidMember>{A}</gml:solidMember>\n<gml:solidMember xlink:href=\"#nowhere\"/>\n<gml:solidMember>{C}</gml:solidMember>";
    let f = doc_findings(members);
    // 901 names the href and where it is; A and C are still checked (each valid on its own),
    // but not how they fit together (no 503 from the missing link).
    assert_eq!(f.iter().map(|f| f.code).collect::<Vec<_>>(), vec![901], "{f:?}");
    assert!(f[0].detail.contains("xlink:href=\"#nowhere\" points to nothing in the document"), "{}", f[0].detail);
    let line = composite_doc(members).lines().position(|l| l.contains("#nowhere")).unwrap() + 1;
    assert_eq!((f[0].line, f[0].primitive.as_deref(), f[0].feature.as_deref()), (line, Some("cs"), Some("b")));
    // A member that is no solid at all is reported the same way.
    let f = doc_findings("<gml:solidMember>{A}</gml:solidMember>\n<gml:solidMember><gml:Polygon/></gml:solidMember>");
    assert_eq!(f.iter().map(|f| f.code).collect::<Vec<_>>(), vec![901]);
    assert!(f[0].detail.contains("<gml:Polygon> is not a solid"), "{}", f[0].detail);
}

#[test]
fn composite_solid_tolerance_and_box_filter() {
    let o = Options::default();
    let codes = |solids: &[Vec<Vec<P>>]| -> Vec<u16> {
        let inps: Vec<Vec<Vec<PolygonInput>>> = solids.iter().map(|s| vec![inp(s)]).collect();
        check_composite_solid(&inps, &o).iter().map(|(_, i)| i.code.code()).collect()
    };
    let a = cube();
    let boxed = |lo: P, hi: P| -> Vec<Vec<P>> {
        a.iter().map(|f| f.iter().map(|p| [0, 1, 2].map(|i| lo[i] + p[i] * (hi[i] - lo[i]))).collect()).collect()
    };
    // A unit cube, a 5 km bar against it, and a cube 1 µm off the bar's far end: the contact
    // tolerance follows the largest coordinate of all solids (5 km: ~5 µm), not the first
    // solid's (~2 m: ~2 nm, which would call the last cube disconnected, 503).
    let bar = boxed([1., 0., 0.], [5001., 1., 1.]);
    let last = boxed([5001.000001, 0., 0.], [5002., 1., 1.]);
    assert_eq!(codes(&[a.clone(), bar.clone(), last.clone()]), Vec::<u16>::new());
    assert_eq!(codes(&[a.clone(), bar, boxed([5001.001, 0., 0.], [5002., 1., 1.])]), vec![503], "1 mm apart is apart");
    // Many solids in a row: only neighbours' boxes meet; all connected.
    let row: Vec<Vec<Vec<P>>> = (0..40).map(|k| scaled(&a, 1., [k as f64, 0., 0.])).collect();
    assert_eq!(codes(&row), Vec::<u16>::new());
    // One inside another far down the list is still found (its box is inside the other's).
    let mut r2 = row.clone();
    r2.push(scaled(&a, 0.5, [20.25, 0.25, 0.25]));
    assert_eq!(codes(&r2), vec![501]);
}

/// An open box (floor and four walls up to z = 1) and a roof of four quadrants whose edges are
/// split at the midpoints of the walls' top edges: the two groups share the four corner vertices
/// and no edge (four T-junctions), like the real NRW solids of issue 14.
fn t_junction_box() -> Vec<Vec<P>> {
    let mut faces = vec![cube()[0].clone()];
    faces.extend(cube()[2..].iter().cloned());
    let (c, h) = (0.5, 1.0);
    for q in [
        [[0., 0., h], [c, 0., h], [c, c, h], [0., c, h]],
        [[c, 0., h], [1., 0., h], [1., c, h], [c, c, h]],
        [[c, c, h], [1., c, h], [1., 1., h], [c, 1., h]],
        [[0., c, h], [c, c, h], [c, 1., h], [0., 1., h]],
    ] {
        faces.push(poly(&q));
    }
    faces
}

#[test]
fn parts_meeting_at_t_junctions_are_one_component_with_holes() {
    // val3dity: connected through shared vertices, so not 305; the edges used once are holes (302)
    let o = Options::default();
    let faces = t_junction_box();
    let inp: Vec<PolygonInput> =
        faces.iter().map(|f| PolygonInput { exterior: f, interiors: vec![], reversed: false }).collect();
    let is = check_solid(&[inp], &o);
    assert!(!is.is_empty() && is.iter().all(|i| i.code == ErrorCode::ShellNotClosed), "{is:?}");
    let all: String = is.iter().map(|i| i.detail.as_str()).collect();
    // the walls' top edges and the roof's split halves are all named, with their coordinates
    let named = |a: &str, b: &str| all.contains(&format!("{a}–{b}")) || all.contains(&format!("{b}–{a}"));
    for (a, b) in [
        ("(0, 0, 1)", "(1, 0, 1)"),
        ("(0, 0, 1)", "(0.5, 0, 1)"),
        ("(0.5, 0, 1)", "(1, 0, 1)"),
        ("(1, 1, 1)", "(0, 1, 1)"),
        ("(0, 1, 1)", "(0, 0.5, 1)"),
    ] {
        assert!(named(a, b), "{a}–{b} not in {all}");
    }
    assert!(all.contains("2 parts"), "{all}");
    // parts that share no vertex stay 305
    let mut apart = t_junction_box();
    apart.truncate(5);
    apart.extend(cube().into_iter().map(|f| f.into_iter().map(|p| [p[0] + 3., p[1], p[2]]).collect()));
    assert_eq!(solid_codes(&apart, &o), vec![305]);
}

#[test]
fn pinched_vertex_is_non_manifold_303() {
    // QIE i306_4: a torus whose hole touches the outer ring of the floor and of the roof at
    // (1, 0.5, z); the hole's walls meet along x = 1, y = 0.5, inside the wall x = 1
    let o = Options::default();
    let f: Vec<Vec<P>> = vec![
        poly(&[[0., 0., 0.], [0., 1., 0.], [1., 1., 0.], [1., 0.5, 0.], [1., 0., 0.]]),
        poly(&[[0.2, 0.2, 0.], [1., 0.5, 0.], [0.5, 0.8, 0.]]),
        poly(&[[0., 0., 1.], [1., 0., 1.], [1., 0.5, 1.], [1., 1., 1.], [0., 1., 1.]]),
        poly(&[[0.2, 0.2, 1.], [0.5, 0.8, 1.], [1., 0.5, 1.]]),
        poly(&[[0., 0., 0.], [1., 0., 0.], [1., 0., 1.], [0., 0., 1.]]),
        poly(&[[1., 0., 0.], [1., 0.5, 0.], [1., 1., 0.], [1., 1., 1.], [1., 0.5, 1.], [1., 0., 1.]]),
        poly(&[[1., 1., 0.], [0., 1., 0.], [0., 1., 1.], [1., 1., 1.]]),
        poly(&[[0., 1., 0.], [0., 0., 0.], [0., 0., 1.], [0., 1., 1.]]),
        poly(&[[0.5, 0.8, 0.], [1., 0.5, 0.], [1., 0.5, 1.], [0.5, 0.8, 1.]]),
        poly(&[[0.2, 0.2, 0.], [0.5, 0.8, 0.], [0.5, 0.8, 1.], [0.2, 0.2, 1.]]),
        poly(&[[1., 0.5, 0.], [0.2, 0.2, 0.], [0.2, 0.2, 1.], [1., 0.5, 1.]]),
    ];
    let mut inp = vec![
        PolygonInput { exterior: &f[0], interiors: vec![f[1].as_slice()], reversed: false },
        PolygonInput { exterior: &f[2], interiors: vec![f[3].as_slice()], reversed: false },
    ];
    inp.extend(f[4..].iter().map(|r| PolygonInput { exterior: r, interiors: vec![], reversed: false }));
    let is = check_solid(&[inp], &o);
    assert!(!is.is_empty() && is.iter().all(|i| i.code == ErrorCode::NonManifoldCase), "{is:?}");
    assert!(is.iter().any(|i| i.detail.contains("(1, 0.5, 0)")), "{is:?}");
}
