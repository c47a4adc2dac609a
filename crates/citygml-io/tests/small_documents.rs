//! Hand-written small documents for what the shared fixtures do not contain: gml:coordinates,
//! 2D rings, OrientableSurface reversal, an XLink to a CompositeSurface, CityGML 3.0 nesting,
//! opaque features, writer edge cases and read errors with their positions.

use citygml_io::*;

fn doc(version: &str, body: &str) -> String {
    let (core, bldg, gml) = match version {
        "3.0" => (
            "http://www.opengis.net/citygml/3.0",
            "http://www.opengis.net/citygml/building/3.0",
            "http://www.opengis.net/gml/3.2",
        ),
        v => (
            if v == "1.0" { "http://www.opengis.net/citygml/1.0" } else { "http://www.opengis.net/citygml/2.0" },
            if v == "1.0" {
                "http://www.opengis.net/citygml/building/1.0"
            } else {
                "http://www.opengis.net/citygml/building/2.0"
            },
            "http://www.opengis.net/gml",
        ),
    };
    format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<core:CityModel xmlns:core=\"{core}\" xmlns:bldg=\"{bldg}\" \
         xmlns:con=\"http://www.opengis.net/citygml/construction/3.0\" xmlns:gen=\"http://www.opengis.net/citygml/generics/2.0\" \
         xmlns:gml=\"{gml}\" xmlns:xlink=\"http://www.w3.org/1999/xlink\">\n{body}\n</core:CityModel>\n"
    )
}

const SQUARE: &str = "0 0 0 1 0 0 1 1 0 0 1 0 0 0 0";

#[test]
fn coordinates_encoding_and_2d_rings() {
    let body = r##"<core:cityObjectMember><bldg:Building gml:id="b"><bldg:lod0FootPrint><gml:MultiSurface>
<gml:surfaceMember><gml:Polygon gml:id="p1"><gml:exterior><gml:LinearRing>
<gml:coordinates>0,0,5 4,0,5 4,3,5 0,0,5</gml:coordinates></gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember>
<gml:surfaceMember><gml:Polygon gml:id="p2"><gml:exterior><gml:LinearRing>
<gml:posList srsDimension="2">10 10 12 10 12 12 10 10</gml:posList></gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember>
</gml:MultiSurface></bldg:lod0FootPrint></bldg:Building></core:cityObjectMember>"##;
    let src = doc("1.0", body);
    let m = parse(src.as_bytes()).unwrap();
    assert_eq!(m.version, CityGmlVersion::V1_0);
    let polys = m.all_polygons();
    assert_eq!(polys.len(), 2);
    let r1 = &polys[0].exterior;
    assert_eq!(r1.encoding, CoordEncoding::Coordinates);
    assert_eq!(r1.points, vec![[0.0, 0.0, 5.0], [4.0, 0.0, 5.0], [4.0, 3.0, 5.0], [0.0, 0.0, 5.0]]);
    assert_eq!(format_coordinates(r1, &[[1.5, 2.0, 3.0], [0.1, 0.2, 0.3]]), "1.5,2,3 0.1,0.2,0.3");
    let r2 = &polys[1].exterior;
    assert_eq!((r2.srs_dimension, r2.points[1]), (2, [12.0, 10.0, 0.0]));
    assert_eq!(format_coordinates(r2, &[[1.0, 2.0, 99.0]]), "1 2");
    assert_eq!(m.objects[0].geometries[0].lod, Some(0));
    assert_eq!(m.envelope.min, [0.0, 0.0, 0.0]);
    assert_eq!(m.envelope.max, [12.0, 12.0, 5.0]);
    // Edit the coordinates text: the writer splices exactly the text span.
    let edits = ring_edits(r1, &[[0.0, 0.0, 6.0], [4.0, 0.0, 6.0], [4.0, 3.0, 6.0], [0.0, 0.0, 6.0]]).unwrap();
    let mut out = Vec::new();
    write_with_edits(src.as_bytes(), &edits, &mut out).unwrap();
    let expected = src.replace("0,0,5 4,0,5 4,3,5 0,0,5", "0,0,6 4,0,6 4,3,6 0,0,6");
    assert_eq!(String::from_utf8(out).unwrap(), expected);
}

#[test]
fn orientable_surface_and_xlink_to_composite_surface() {
    // A 3.0 building: WallSurface under core:boundary holding a CompositeSurface; the solid
    // references the composite (two polygons) and a reversed polygon through OrientableSurface.
    let body = format!(
        r##"<core:cityObjectMember><bldg:Building gml:id="b">
<core:boundary><con:WallSurface gml:id="w"><core:lod2MultiSurface><gml:MultiSurface><gml:surfaceMember>
<gml:CompositeSurface gml:id="cs"><gml:surfaceMember><gml:Polygon gml:id="a"><gml:exterior><gml:LinearRing><gml:posList>{SQUARE}</gml:posList></gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember>
<gml:surfaceMember><gml:Polygon gml:id="c"><gml:exterior><gml:LinearRing><gml:posList>{SQUARE}</gml:posList></gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember></gml:CompositeSurface>
</gml:surfaceMember></gml:MultiSurface></core:lod2MultiSurface></con:WallSurface></core:boundary>
<core:boundary><con:RoofSurface gml:id="r"><core:lod2MultiSurface><gml:MultiSurface><gml:surfaceMember><gml:Polygon gml:id="roof"><gml:exterior><gml:LinearRing><gml:posList>{SQUARE}</gml:posList></gml:LinearRing></gml:exterior>
<gml:interior><gml:LinearRing><gml:posList>0.2 0.2 0 0.2 0.4 0 0.4 0.4 0 0.2 0.2 0</gml:posList></gml:LinearRing></gml:interior></gml:Polygon></gml:surfaceMember></gml:MultiSurface></core:lod2MultiSurface></con:RoofSurface></core:boundary>
<core:lod2Solid><gml:Solid gml:id="s"><gml:exterior><gml:Shell gml:id="sh">
<gml:surfaceMember xlink:href="#cs"/>
<gml:surfaceMember><gml:OrientableSurface orientation="-"><gml:baseSurface xlink:href="#roof"/></gml:OrientableSurface></gml:surfaceMember>
</gml:Shell></gml:exterior></gml:Solid></core:lod2Solid>
</bldg:Building></core:cityObjectMember>
<core:cityObjectMember><gen:GenericCityObject gml:id="g"><gml:boundedBy><gml:Envelope srsName="EPSG:25832"><gml:lowerCorner>1 2 3</gml:lowerCorner><gml:upperCorner>4 5 6</gml:upperCorner></gml:Envelope></gml:boundedBy></gen:GenericCityObject></core:cityObjectMember>"##
    );
    let src = doc("3.0", &body);
    let m = parse(src.as_bytes()).unwrap();
    assert_eq!(m.version, CityGmlVersion::V3_0);
    assert_eq!(m.objects.len(), 2);
    let b = &m.objects[0];
    assert_eq!(b.children.iter().map(|c| c.kind.as_str()).collect::<Vec<_>>(), ["WallSurface", "RoofSurface"]);
    let solid = b.geometries.iter().find(|g| g.gml_type == "Solid").unwrap();
    assert_eq!(solid.lod, Some(2));
    let GeometryKind::Solid { exterior, interior } = &solid.kind else { panic!("not a solid") };
    assert!(interior.is_empty());
    assert_eq!(exterior.id.as_deref(), Some("sh"));
    let ids: Vec<_> = exterior.polygons.iter().map(|p| p.id.as_deref().unwrap()).collect();
    assert_eq!(ids, ["a", "c", "roof"]);
    let sem: Vec<_> = exterior.polygons.iter().map(|p| p.semantic.unwrap()).collect();
    assert_eq!(sem, [SurfaceType::Wall, SurfaceType::Wall, SurfaceType::Roof]);
    assert_eq!(exterior.polygons[0].semantic_owner.as_deref(), Some("w"));
    assert_eq!(exterior.polygons.iter().map(|p| p.reversed).collect::<Vec<_>>(), [false, false, true]);
    assert!(exterior.polygons.iter().all(|p| p.via_xlink.is_some()));
    assert_eq!(exterior.polygons[2].interiors.len(), 1);
    // Definitions are counted once.
    assert_eq!(m.all_polygons().len(), 3);
    // The opaque feature keeps id, type and its declared envelope.
    let g = &m.objects[1];
    assert_eq!((g.id.as_deref(), g.kind.as_str(), g.module.as_deref()), (Some("g"), "GenericCityObject", Some("gen")));
    assert_eq!(g.envelope.min, [1.0, 2.0, 3.0]);
    assert!(m.unresolved_xlinks.is_empty());
}

#[test]
fn missing_xlink_target_is_reported_not_fatal() {
    let body = r##"<core:cityObjectMember><bldg:Building gml:id="b"><bldg:lod2MultiSurface><gml:MultiSurface>
<gml:surfaceMember xlink:href="#nowhere"/></gml:MultiSurface></bldg:lod2MultiSurface></bldg:Building></core:cityObjectMember>"##;
    let m = parse(doc("2.0", body).as_bytes()).unwrap();
    assert_eq!(m.unresolved_xlinks.len(), 1);
    assert_eq!(m.unresolved_xlinks[0].href, "#nowhere");
    assert_eq!(m.unresolved_xlinks[0].span.line, 4);
    assert!(m.all_polygons().is_empty());
}

fn err(src: &str) -> ReadError {
    parse(src.as_bytes()).expect_err("should not parse")
}

#[test]
fn read_errors_carry_position_and_message() {
    assert_eq!(err("").message, "empty file (0 bytes), not a CityGML document");
    let e = err("\u{1}\u{2}binary\u{0}");
    assert_eq!((e.line, e.column), (1, 1));
    assert!(e.message.contains("not an XML document"));
    let e = err("<?xml version=\"1.0\"?>\n<foo:Bar xmlns:foo=\"urn:x\"/>");
    assert_eq!((e.line, e.column), (2, 1));
    assert!(e.message.contains("root element is <foo:Bar>"), "{}", e.message);
    let ring = |pl: &str| {
        doc(
            "2.0",
            &format!(
                "<core:cityObjectMember><bldg:Building><bldg:lod1MultiSurface><gml:MultiSurface><gml:surfaceMember><gml:Polygon><gml:exterior>\n  <gml:LinearRing>{pl}</gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember></gml:MultiSurface></bldg:lod1MultiSurface></bldg:Building></core:cityObjectMember>"
            ),
        )
    };
    let e = err(&ring(""));
    assert_eq!((e.line, e.column), (4, 3));
    assert!(e.message.contains("no coordinates"));
    let e = err(&ring("<gml:posList>0 0 0 1 1</gml:posList>"));
    assert_eq!((e.line, e.column), (4, 19));
    assert!(e.message.contains("5 values, not a multiple of srsDimension 3"), "{}", e.message);
    let e = err(&ring("<gml:posList>0 0 0 1 x 1 0 0 0</gml:posList>"));
    assert_eq!((e.line, e.column), (4, 32 + 8));
    assert!(e.message.contains("'x' is not a number"));
    let e = err(&ring("<gml:posList>0 0 0 1 NaN 1 0 0 0</gml:posList>"));
    assert!(e.message.contains("non-finite"));
    // A ring with 3 positions is readable (validators report QIE 101 on it).
    let m = parse(ring("<gml:posList>0 0 0 1 0 0 0 0 0</gml:posList>").as_bytes()).unwrap();
    assert_eq!(m.all_polygons()[0].exterior.points.len(), 3);
    // Truncation anywhere is an error, never a panic.
    let full = ring("<gml:posList>0 0 0 1 0 0 1 1 0 0 0 0</gml:posList>");
    for cut in 1..full.len() - 2 {
        if let Ok(m) = parse(&full.as_bytes()[..cut]) {
            panic!("truncated at {cut} parsed: {m:?}");
        }
    }
}

#[test]
fn writer_rejects_overlaps_and_applies_unsorted_edits() {
    let src = b"0123456789";
    let e = |a: usize, b: usize, r: &str| Edit { bytes: a..b, replacement: r.as_bytes().to_vec() };
    let mut out = Vec::new();
    write_with_edits(src, &[e(6, 8, "x"), e(1, 2, "ab"), e(9, 9, "!")], &mut out).unwrap();
    assert_eq!(out, b"0ab2345x8!9");
    assert!(matches!(
        write_with_edits(src, &[e(1, 5, ""), e(4, 6, "")], &mut Vec::new()),
        Err(WriteError::Overlap { .. })
    ));
    assert!(matches!(write_with_edits(src, &[e(5, 11, "")], &mut Vec::new()), Err(WriteError::OutOfBounds { .. })));
}

#[test]
fn pos_rings_edit_each_pos_and_keep_markup() {
    let body = r##"<core:cityObjectMember><bldg:Building><bldg:lod1MultiSurface><gml:MultiSurface><gml:surfaceMember><gml:Polygon><gml:exterior><gml:LinearRing>
<gml:pos>0 0 0</gml:pos>
<gml:pos> 1 0 0 </gml:pos>
<gml:pos>1 1 0</gml:pos>
<gml:pos>0 0 0</gml:pos>
</gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember></gml:MultiSurface></bldg:lod1MultiSurface></bldg:Building></core:cityObjectMember>"##;
    let src = doc("2.0", body);
    let m = parse(src.as_bytes()).unwrap();
    let r = &m.all_polygons()[0].exterior;
    assert_eq!(r.encoding, CoordEncoding::Pos);
    let new = [[0.0, 0.0, 0.5], [1.0, 0.0, 0.5], [1.0, 1.0, 0.5], [0.0, 0.0, 0.5]];
    let mut out = Vec::new();
    write_with_edits(src.as_bytes(), &ring_edits(r, &new).unwrap(), &mut out).unwrap();
    let want = src
        .replace("<gml:pos>0 0 0</gml:pos>", "<gml:pos>0 0 0.5</gml:pos>")
        .replace("<gml:pos> 1 0 0 </gml:pos>", "<gml:pos> 1 0 0.5 </gml:pos>")
        .replace("<gml:pos>1 1 0</gml:pos>", "<gml:pos>1 1 0.5</gml:pos>");
    assert_eq!(String::from_utf8(out).unwrap(), want);
    assert!(ring_edits(r, &new[..3]).is_err());
    assert!(ring_edits(r, &[[f64::NAN, 0.0, 0.0]; 4]).is_err());
}

#[test]
fn absurd_nesting_is_an_error_not_a_stack_overflow() {
    let mut body = String::from("<core:cityObjectMember><bldg:Building><bldg:lod2MultiSurface>");
    for _ in 0..100_000 {
        body.push_str("<gml:MultiGeometry><gml:geometryMember>");
    }
    let e = parse(doc("2.0", &body).as_bytes()).expect_err("too deep");
    assert!(e.message.contains("nested deeper"), "{}", e.message);
}

/// Random byte edits of a valid document: every result is Ok or a ReadError, never a panic, and
/// an error position always lies inside the input.
#[test]
fn mutated_documents_never_panic() {
    let body = format!(
        r##"<core:cityObjectMember><bldg:Building gml:id="b"><bldg:boundedBy><bldg:WallSurface gml:id="w"><bldg:lod2MultiSurface><gml:MultiSurface><gml:surfaceMember><gml:Polygon gml:id="p"><gml:exterior><gml:LinearRing><gml:posList srsDimension="3">{SQUARE}</gml:posList></gml:LinearRing></gml:exterior><gml:interior><gml:LinearRing><gml:pos>0.1 0.1 0</gml:pos><gml:pos>0.2 0.1 0</gml:pos><gml:pos>0.2 0.2 0</gml:pos><gml:pos>0.1 0.1 0</gml:pos></gml:LinearRing></gml:interior></gml:Polygon></gml:surfaceMember></gml:MultiSurface></bldg:lod2MultiSurface></bldg:WallSurface></bldg:boundedBy>
<bldg:lod2Solid><gml:Solid><gml:exterior><gml:CompositeSurface><gml:surfaceMember xlink:href="#p"/><gml:surfaceMember><gml:OrientableSurface orientation="-"><gml:baseSurface xlink:href="#p"/></gml:OrientableSurface></gml:surfaceMember></gml:CompositeSurface></gml:exterior></gml:Solid></bldg:lod2Solid></bldg:Building></core:cityObjectMember>"##
    );
    let src = doc("2.0", &body).into_bytes();
    assert_eq!(parse(&src).unwrap().all_polygons().len(), 1);
    let mut x: u64 = 0x2545F4914F6CDD1D;
    let mut rnd = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    let alphabet = b"<>/\"=:# -.0123456789abcxmlnsgml\n\x00\xff";
    for _ in 0..4000 {
        let mut m = src.clone();
        for _ in 0..1 + rnd() % 4 {
            let i = (rnd() as usize) % m.len();
            match rnd() % 3 {
                0 => m[i] = alphabet[(rnd() as usize) % alphabet.len()],
                1 => {
                    m.remove(i);
                }
                _ => m.insert(i, alphabet[(rnd() as usize) % alphabet.len()]),
            }
        }
        if let Err(e) = parse(&m) {
            assert!(e.byte <= m.len() && e.line >= 1 && e.column >= 1, "{e:?}");
        }
        let _ = ObjectStream::new(&m).map(|s| s.count());
    }
}

/// A unit cube `[dx, dx+1] × [0,1]²` as a gml:Solid (faces counter-clockwise seen from outside).
fn cube_solid(id: &str, dx: f64) -> String {
    let faces: [[[f64; 3]; 4]; 6] = [
        [[0., 0., 0.], [0., 1., 0.], [1., 1., 0.], [1., 0., 0.]],
        [[0., 0., 1.], [1., 0., 1.], [1., 1., 1.], [0., 1., 1.]],
        [[0., 0., 0.], [1., 0., 0.], [1., 0., 1.], [0., 0., 1.]],
        [[1., 0., 0.], [1., 1., 0.], [1., 1., 1.], [1., 0., 1.]],
        [[1., 1., 0.], [0., 1., 0.], [0., 1., 1.], [1., 1., 1.]],
        [[0., 1., 0.], [0., 0., 0.], [0., 0., 1.], [0., 1., 1.]],
    ];
    let mut s = format!("<gml:Solid gml:id=\"{id}\"><gml:exterior><gml:Shell>\n");
    for (k, f) in faces.iter().enumerate() {
        let pos: Vec<String> =
            f.iter().chain(std::iter::once(&f[0])).map(|p| format!("{} {} {}", p[0] + dx, p[1], p[2])).collect();
        s += &format!(
            "<gml:surfaceMember><gml:Polygon gml:id=\"{id}-f{k}\"><gml:exterior><gml:LinearRing><gml:posList>{}</gml:posList></gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember>\n",
            pos.join(" ")
        );
    }
    s + "</gml:Shell></gml:exterior></gml:Solid>"
}

/// A building whose lod2Solid is a CompositeSolid with the given members, plus a second
/// top-level building whose lod1Solid defines the cube `B` at x = 1..2.
fn composite_doc(members: &str) -> String {
    let body = format!(
        "<core:cityObjectMember><bldg:Building gml:id=\"b\"><bldg:lod2Solid><gml:CompositeSolid gml:id=\"cs\">\n{members}\n\
         </gml:CompositeSolid></bldg:lod2Solid></bldg:Building></core:cityObjectMember>\n\
         <core:cityObjectMember><bldg:Building gml:id=\"other\"><bldg:lod1Solid>{}</bldg:lod1Solid></bldg:Building></core:cityObjectMember>",
        cube_solid("B", 1.0)
    );
    doc("2.0", &body)
}

fn composite(m: &CityModel) -> &Geometry {
    &m.objects[0].geometries[0]
}

#[test]
fn composite_solid_member_by_xlink_is_a_copy_of_its_target() {
    let members = format!(
        "<gml:solidMember>{}</gml:solidMember>\n<gml:solidMember xlink:href=\"#B\"/>\n<gml:solidMember>{}</gml:solidMember>",
        cube_solid("A", 0.0),
        cube_solid("C", 2.0)
    );
    let src = composite_doc(&members);
    let m = parse(src.as_bytes()).unwrap();
    let g = composite(&m);
    let GeometryKind::Solids(solids) = &g.kind else { panic!("{:?}", g.kind) };
    assert_eq!(solids.len(), 3, "the XLinked member is kept");
    assert!(g.skipped_members.is_empty() && m.unresolved_xlinks.is_empty());
    let b = &solids[1].0.polygons;
    assert_eq!(b.len(), 6);
    assert_eq!(b[0].id.as_deref(), Some("B-f0"));
    assert_eq!(b[0].exterior.points[0], [1.0, 0.0, 0.0]);
    // Copies: via_xlink is the referencing solidMember, span the definition.
    let member_line = src.lines().position(|l| l.contains("xlink:href=\"#B\"")).unwrap() + 1;
    assert!(b.iter().all(|p| p.via_xlink.as_ref().map(|v| v.line) == Some(member_line)));
    let def_line = src.lines().position(|l| l.contains("gml:id=\"B-f0\"")).unwrap() + 1;
    assert_eq!(b[0].span.line, def_line);
    assert!(solids[0].0.polygons.iter().chain(&solids[2].0.polygons).all(|p| p.via_xlink.is_none()));
    // Each polygon is counted once, where it is defined.
    assert_eq!(m.all_polygons().len(), 18);
    assert_eq!(m.objects[0].envelope.max, [3.0, 1.0, 1.0]);
}

#[test]
fn composite_solid_xlinks_within_the_object_and_to_xlinked_faces() {
    // The referenced solid is in the same building (a BuildingPart) and its faces are XLinks
    // to polygons of the part's MultiSurface: the copy has the polygons, all marked as copies.
    let faces: String = (0..6).map(|k| format!("<gml:surfaceMember xlink:href=\"#P-f{k}\"/>")).collect();
    let part_ms = cube_solid("P", 5.0)
        .replace("<gml:Solid gml:id=\"P\"><gml:exterior><gml:Shell>", "<gml:MultiSurface>")
        .replace("</gml:Shell></gml:exterior></gml:Solid>", "</gml:MultiSurface>");
    let body = format!(
        "<core:cityObjectMember><bldg:Building gml:id=\"b\"><bldg:lod2Solid><gml:CompositeSolid>\n\
         <gml:solidMember>{a}</gml:solidMember><gml:solidMember xlink:href=\"#PS\"></gml:solidMember>\n\
         </gml:CompositeSolid></bldg:lod2Solid>\n\
         <bldg:consistsOfBuildingPart><bldg:BuildingPart gml:id=\"part\"><bldg:lod2MultiSurface>{part_ms}</bldg:lod2MultiSurface>\n\
         <bldg:lod2Solid><gml:Solid gml:id=\"PS\"><gml:exterior><gml:Shell>{faces}</gml:Shell></gml:exterior></gml:Solid></bldg:lod2Solid>\n\
         </bldg:BuildingPart></bldg:consistsOfBuildingPart></bldg:Building></core:cityObjectMember>",
        a = cube_solid("A", 0.0)
    );
    let src = doc("2.0", &body);
    let m = parse(src.as_bytes()).unwrap();
    let g = composite(&m);
    let GeometryKind::Solids(solids) = &g.kind else { panic!() };
    assert_eq!(solids.len(), 2);
    let p = &solids[1].0.polygons;
    assert_eq!(
        p.iter().map(|p| p.id.as_deref().unwrap()).collect::<Vec<_>>(),
        ["P-f0", "P-f1", "P-f2", "P-f3", "P-f4", "P-f5"]
    );
    assert_eq!(p[3].exterior.points[0], [6.0, 0.0, 0.0]);
    let member_line = src.lines().position(|l| l.contains("xlink:href=\"#PS\"")).unwrap() + 1;
    assert!(p.iter().all(|p| p.via_xlink.as_ref().unwrap().line == member_line));
    assert!(m.unresolved_xlinks.is_empty() && g.skipped_members.is_empty());
    assert_eq!(m.all_polygons().len(), 12);
}

#[test]
fn composite_solid_member_referenced_twice_is_kept_twice() {
    let src = composite_doc("<gml:solidMember xlink:href=\"#B\"/><gml:solidMember xlink:href=\"#B\"/>");
    let m = parse(src.as_bytes()).unwrap();
    let GeometryKind::Solids(solids) = &composite(&m).kind else { panic!() };
    assert_eq!(solids.len(), 2);
    // The same polygons, each copy marked by its own solidMember.
    let ids = |k: usize| {
        solids[k]
            .0
            .polygons
            .iter()
            .map(|p| (p.id.clone(), p.exterior.points.clone(), p.span.clone()))
            .collect::<Vec<_>>()
    };
    assert_eq!(ids(0).len(), 6);
    assert_eq!(ids(0), ids(1));
    let via = |k: usize| solids[k].0.polygons[0].via_xlink.clone().unwrap().bytes.start;
    assert!(via(0) < via(1));
    // the shells say they are copies (counts of solids skip them); the definition does not
    assert!(solids.iter().all(|s| s
        .0
        .via_xlink
        .as_ref()
        .is_some_and(|v| v.bytes.start == s.0.polygons[0].via_xlink.as_ref().unwrap().bytes.start)));
    let GeometryKind::Solid { exterior, .. } = &m.objects[1].geometries[0].kind else { panic!() };
    assert!(exterior.via_xlink.is_none());
}

/// A surface XLink whose id names a city object (not a geometry) brings nothing in and says
/// what it points to (an empty polygon in another building is not a target either), under the innermost object holding the reference (here a WallSurface of
/// another building); one whose id names nothing says so, with the same owner.
#[test]
fn xlink_to_a_city_object_says_what_it_points_to() {
    let body = r##"<core:cityObjectMember><bldg:Building gml:id="a"/></core:cityObjectMember>
<core:cityObjectMember><bldg:Building gml:id="e"><bldg:lod2MultiSurface><gml:MultiSurface><gml:surfaceMember><gml:Polygon gml:id="empty"/></gml:surfaceMember></gml:MultiSurface></bldg:lod2MultiSurface></bldg:Building></core:cityObjectMember>
<core:cityObjectMember><bldg:Building gml:id="b"><bldg:boundedBy><bldg:WallSurface gml:id="w">
<bldg:lod2MultiSurface><gml:MultiSurface><gml:surfaceMember xlink:href="#a"/>
<gml:surfaceMember xlink:href="#gone"/><gml:surfaceMember xlink:href="#empty"/></gml:MultiSurface></bldg:lod2MultiSurface>
</bldg:WallSurface></bldg:boundedBy></bldg:Building></core:cityObjectMember>"##;
    let src = doc("2.0", body);
    let line_of = |s: &str| src.lines().position(|l| l.contains(s)).unwrap() + 1;
    let m = parse(src.as_bytes()).unwrap();
    let got: Vec<(&str, Option<&str>, &str, Option<&str>, usize, String)> = m
        .unresolved_xlinks
        .iter()
        .map(|u| {
            (
                u.href.as_str(),
                u.feature.as_deref(),
                u.feature_type.as_str(),
                u.target.as_deref(),
                u.span.line,
                u.reason(),
            )
        })
        .collect();
    assert_eq!(
        got,
        [
            (
                "#a",
                Some("w"),
                "WallSurface",
                Some("bldg:Building"),
                line_of("#a\""),
                "xlink:href=\"#a\" points to <bldg:Building>, not a geometry".to_string()
            ),
            (
                "#gone",
                Some("w"),
                "WallSurface",
                None,
                line_of("#gone"),
                "xlink:href=\"#gone\" points to nothing in the document".to_string()
            ),
            // an empty polygon brings nothing in either: unresolved, not silently "resolved"
            (
                "#empty",
                Some("w"),
                "WallSurface",
                None,
                line_of("#gone"),
                "xlink:href=\"#empty\" points to nothing in the document".to_string()
            ),
        ]
    );
    assert!(m.all_polygons().is_empty(), "the building's polygons must not come in");
}

#[test]
fn composite_solid_members_not_read_are_reported_not_dropped() {
    let members = format!(
        "<gml:solidMember>{}</gml:solidMember>\n<gml:solidMember xlink:href=\"#nowhere\"/>\n\
         <gml:solidMember xlink:href=\"#B-f0\"/>\n<gml:solidMember><gml:Polygon gml:id=\"q\"/></gml:solidMember>\n<gml:solidMember/>",
        cube_solid("A", 0.0)
    );
    let src = composite_doc(&members);
    let line_of = |s: &str| src.lines().position(|l| l.contains(s)).unwrap() + 1;
    let m = parse(src.as_bytes()).unwrap();
    let g = composite(&m);
    let GeometryKind::Solids(solids) = &g.kind else { panic!() };
    assert_eq!(solids.len(), 1);
    let sk: Vec<(Option<&str>, &str, usize)> =
        g.skipped_members.iter().map(|s| (s.href.as_deref(), s.reason.as_str(), s.span.line)).collect();
    assert_eq!(
        sk,
        [
            (Some("#nowhere"), "xlink:href=\"#nowhere\" points to nothing in the document", line_of("#nowhere")),
            (
                Some("#B-f0"),
                "xlink:href=\"#B-f0\" points to <gml:Polygon>, not a solid",
                line_of("xlink:href=\"#B-f0\"")
            ),
            (None, "<gml:Polygon> is not a solid (not read)", line_of("gml:id=\"q\"")),
            (None, "empty gml:solidMember (no solid, no xlink:href)", line_of("<gml:solidMember/>")),
        ]
    );
    // The unresolvable one is also in the document's list (what `geofit info` reports).
    assert_eq!(m.unresolved_xlinks.iter().map(|u| u.href.as_str()).collect::<Vec<_>>(), ["#nowhere"]);
}

/// `<bldg:lod2Solid xlink:href="#S"/>` (a whole geometry by reference, here into another
/// building): the geometry is the Solid it points to, faces marked as copies, counted once;
/// a reference to nothing is a skipped member and an unresolved XLink, not a silent gap.
#[test]
fn whole_solid_by_xlink_is_the_solid_it_points_to() {
    for version in ["2.0", "3.0"] {
        let body = format!(
            "<core:cityObjectMember><bldg:Building gml:id=\"a\"><bldg:lod2Solid>{}</bldg:lod2Solid></bldg:Building></core:cityObjectMember>\n\
             <core:cityObjectMember><bldg:Building gml:id=\"b\"><bldg:lod2Solid xlink:href=\"#B\"/></bldg:Building></core:cityObjectMember>",
            cube_solid("B", 1.0)
        );
        let src = doc(version, &body);
        let m = parse(src.as_bytes()).unwrap();
        let g = &m.objects[1].geometries[0];
        assert_eq!((g.lod, g.property.as_str(), g.gml_type.as_str()), (Some(2), "lod2Solid", "Solid"), "{version}");
        let GeometryKind::Solid { exterior, interior } = &g.kind else {
            panic!("{version}: not a solid: {:?}", g.kind)
        };
        assert!(interior.is_empty());
        assert_eq!(exterior.polygons.len(), 6);
        let line = src.lines().position(|l| l.contains("xlink:href=\"#B\"")).unwrap() + 1;
        assert!(exterior.polygons.iter().all(|p| p.via_xlink.as_ref().is_some_and(|v| v.line == line)));
        assert!(exterior.via_xlink.as_ref().is_some_and(|v| v.line == line), "{version}: the shell is marked a copy");
        assert_eq!(m.all_polygons().len(), 6, "{version}: faces counted once, where defined");
        assert!(m.unresolved_xlinks.is_empty() && g.skipped_members.is_empty());

        // the same reference written with an end tag
        let long = src.replace("xlink:href=\"#B\"/>", "xlink:href=\"#B\"></bldg:lod2Solid>");
        assert_ne!(long, src);
        let m2 = parse(long.as_bytes()).unwrap();
        let g2 = &m2.objects[1].geometries[0];
        assert!(
            matches!(&g2.kind, GeometryKind::Solid { exterior, .. } if exterior.polygons.len() == 6),
            "{version}: end-tag form"
        );
        let broken = src.replace("xlink:href=\"#B\"", "xlink:href=\"#nowhere\"");
        let m = parse(broken.as_bytes()).unwrap();
        let g = &m.objects[1].geometries[0];
        assert_eq!(m.unresolved_xlinks.len(), 1);
        assert_eq!(m.unresolved_xlinks[0].href, "#nowhere");
        assert_eq!(g.skipped_members.len(), 1, "{version}");
        assert!(g.skipped_members[0].reason.contains("#nowhere"));
    }
}

/// A whole surface geometry by reference (`lod2MultiSurface xlink:href`, CityGML 3.0
/// `core:lod2MultiSurface`): it comes back as what it points to, with the referencing
/// property's lod and name, copies marked via_xlink and counted once: a MultiSurface or a
/// Polygon as surfaces named after the target, a gml:Solid as a Solid; a reference to a city
/// object (not a geometry) is a skipped member, not the object's polygons.
#[test]
fn whole_surface_geometry_by_xlink_is_what_it_points_to() {
    for (version, p) in [("2.0", "bldg"), ("3.0", "core")] {
        let body = format!(
            "<core:cityObjectMember><bldg:Building gml:id=\"b\">\n\
             <{p}:lod2MultiSurface xlink:href=\"#MS\"/>\n\
             <{p}:lod1MultiSurface xlink:href=\"#B-f0\"/>\n\
             <{p}:lod3MultiSurface xlink:href=\"#B\"/>\n\
             <{p}:lod4MultiSurface xlink:href=\"#a\"/>\n\
             </bldg:Building></core:cityObjectMember>\n\
             <core:cityObjectMember><bldg:Building gml:id=\"a\"><bldg:lod2Solid>{}</bldg:lod2Solid>\n\
             <{p}:lod2MultiSurface><gml:MultiSurface gml:id=\"MS\">\
             <gml:surfaceMember><gml:Polygon><gml:exterior><gml:LinearRing><gml:posList>{SQUARE}</gml:posList></gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember>\
             <gml:surfaceMember><gml:Polygon><gml:exterior><gml:LinearRing><gml:posList>{SQUARE}</gml:posList></gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember>\
             </gml:MultiSurface></{p}:lod2MultiSurface></bldg:Building></core:cityObjectMember>",
            cube_solid("B", 5.0)
        );
        let src = doc(version, &body);
        let line = |href: &str| src.lines().position(|l| l.contains(&format!("xlink:href=\"{href}\""))).unwrap() + 1;
        let m = parse(src.as_bytes()).unwrap();
        let gs = &m.objects[0].geometries;
        assert_eq!(gs.len(), 4, "{version}");
        let head: Vec<_> = gs.iter().map(|g| (g.lod, g.property.as_str())).collect();
        assert_eq!(
            head,
            [
                (Some(2), "lod2MultiSurface"),
                (Some(1), "lod1MultiSurface"),
                (Some(3), "lod3MultiSurface"),
                (Some(4), "lod4MultiSurface")
            ],
            "{version}"
        );
        let GeometryKind::Surfaces(ms) = &gs[0].kind else { panic!("{version}: {:?}", gs[0].kind) };
        assert_eq!((gs[0].gml_type.as_str(), ms.len()), ("MultiSurface", 2), "{version}");
        assert!(ms.iter().all(|p| p.via_xlink.as_ref().is_some_and(|v| v.line == line("#MS"))));
        let GeometryKind::Surfaces(poly) = &gs[1].kind else { panic!("{version}: {:?}", gs[1].kind) };
        assert_eq!((gs[1].gml_type.as_str(), poly.len()), ("Polygon", 1), "{version}");
        assert_eq!(poly[0].via_xlink.as_ref().map(|v| v.line), Some(line("#B-f0")));
        let GeometryKind::Solid { exterior, interior } = &gs[2].kind else {
            panic!("{version}: not a solid: {:?}", gs[2].kind)
        };
        assert_eq!((gs[2].gml_type.as_str(), exterior.polygons.len(), interior.len()), ("Solid", 6, 0), "{version}");
        assert!(exterior.polygons.iter().all(|p| p.via_xlink.as_ref().is_some_and(|v| v.line == line("#B"))));
        // the Building is not a geometry: a skipped member that says what the id names, with
        // the href and line, not the building's 8 polygons
        assert_eq!(gs[3].polygons().len(), 0, "{version}");
        assert!(m.unresolved_xlinks.is_empty(), "{version}");
        let sk: Vec<_> =
            gs[3].skipped_members.iter().map(|s| (s.href.as_deref(), s.reason.as_str(), s.span.line)).collect();
        assert_eq!(
            sk,
            [(Some("#a"), "xlink:href=\"#a\" points to <bldg:Building>, not a geometry", line("#a"))],
            "{version}"
        );
        assert!(gs[..3].iter().all(|g| g.skipped_members.is_empty()));
        assert_eq!(m.all_polygons().len(), 8, "{version}: each polygon counted once, where defined");

        // a reference to nothing: an unresolved XLink with the href and its line
        let broken = src.replace("xlink:href=\"#MS\"", "xlink:href=\"#nowhere\"");
        let m = parse(broken.as_bytes()).unwrap();
        let u: Vec<_> = m.unresolved_xlinks.iter().map(|u| (u.href.as_str(), u.span.line)).collect();
        assert_eq!(u, [("#nowhere", line("#MS"))], "{version}");
        assert_eq!(m.objects[0].geometries[0].polygons().len(), 0);
    }
}
