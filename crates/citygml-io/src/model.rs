//! In-memory CityGML model: just what geofit's algorithms need (objects, semantics, geometry,
//! ids), plus byte spans back into the source document so the writer can stay lossless.

use serde::Serialize;
use std::ops::Range;

/// CityGML version, detected from the namespaces in the document (never the file name).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub enum CityGmlVersion {
    #[serde(rename = "1.0")]
    V1_0,
    #[serde(rename = "2.0")]
    V2_0,
    #[serde(rename = "3.0")]
    V3_0,
}

impl CityGmlVersion {
    pub fn as_str(self) -> &'static str {
        match self {
            CityGmlVersion::V1_0 => "1.0",
            CityGmlVersion::V2_0 => "2.0",
            CityGmlVersion::V3_0 => "3.0",
        }
    }
}

/// A 3D point in the document's CRS (2D coordinates get z = 0 and `srs_dimension = 2`).
pub type Point3 = [f64; 3];

/// Axis-aligned box.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Envelope {
    pub min: Point3,
    pub max: Point3,
}

/// The empty envelope: what [`Envelope::merge`] starts from.
impl Default for Envelope {
    fn default() -> Self {
        Envelope::empty()
    }
}

impl Envelope {
    pub fn empty() -> Self {
        Envelope { min: [f64::INFINITY; 3], max: [f64::NEG_INFINITY; 3] }
    }
    pub fn is_empty(&self) -> bool {
        self.min[0] > self.max[0]
    }
    pub fn add_point(&mut self, p: &Point3) {
        for (i, v) in p.iter().enumerate() {
            self.min[i] = self.min[i].min(*v);
            self.max[i] = self.max[i].max(*v);
        }
    }
    pub fn merge(&mut self, o: &Envelope) {
        if !o.is_empty() {
            self.add_point(&o.min);
            self.add_point(&o.max);
        }
    }
}

/// Where something sits in the source document: byte range and 1-based line/column of its start.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize)]
pub struct SourceSpan {
    pub bytes: Range<usize>,
    pub line: usize,
    pub column: usize,
}

/// How a ring's coordinates were written, so an edit can write them back the same way.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum CoordEncoding {
    /// One `gml:posList` element.
    PosList,
    /// A sequence of `gml:pos` elements (each has its own text span in `Ring::pos_spans`).
    Pos,
    /// `gml:coordinates` (CityGML 1.0 era), tuples separated by whitespace, values by commas.
    Coordinates,
}

/// A closed linear ring. `points` keeps the closing point as written in the file
/// (first == last for valid rings); `text_span` is the byte span of the coordinate text.
/// The reader keeps rings exactly as written, also invalid ones (fewer than 4 positions, not
/// closed): reporting them is the validator's job (QIE 101/103), not a read error.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Ring {
    pub id: Option<String>,
    pub points: Vec<Point3>,
    pub srs_dimension: u8,
    pub encoding: CoordEncoding,
    /// Span of the `gml:posList`/`gml:coordinates` text, or of the first..last `gml:pos` text
    /// (leading/trailing whitespace excluded, so an edit keeps the indentation). Use
    /// [`crate::ring_edits`] to build the edits that replace the coordinates.
    pub text_span: SourceSpan,
    /// For `CoordEncoding::Pos`: the text span of each `gml:pos`.
    pub pos_spans: Vec<SourceSpan>,
    /// Span of the whole `gml:LinearRing` element.
    pub span: SourceSpan,
}

/// Thematic surface type of a polygon (the boundary surface or opening it belongs to).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, PartialOrd, Ord)]
pub enum SurfaceType {
    Wall,
    Roof,
    Ground,
    Closure,
    Floor,
    Ceiling,
    InteriorWall,
    OuterFloor,
    OuterCeiling,
    Window,
    Door,
}

impl SurfaceType {
    /// From a CityGML element local name (`WallSurface`, `Window`, ...).
    pub fn from_local_name(name: &str) -> Option<SurfaceType> {
        Some(match name {
            "WallSurface" => SurfaceType::Wall,
            "RoofSurface" => SurfaceType::Roof,
            "GroundSurface" => SurfaceType::Ground,
            "ClosureSurface" => SurfaceType::Closure,
            "FloorSurface" => SurfaceType::Floor,
            "CeilingSurface" => SurfaceType::Ceiling,
            "InteriorWallSurface" => SurfaceType::InteriorWall,
            "OuterFloorSurface" => SurfaceType::OuterFloor,
            "OuterCeilingSurface" => SurfaceType::OuterCeiling,
            // CityGML 3.0 spells the openings `con:WindowSurface` / `con:DoorSurface`.
            "Window" | "WindowSurface" => SurfaceType::Window,
            "Door" | "DoorSurface" => SurfaceType::Door,
            _ => return None,
        })
    }
    pub fn local_name(self) -> &'static str {
        match self {
            SurfaceType::Wall => "WallSurface",
            SurfaceType::Roof => "RoofSurface",
            SurfaceType::Ground => "GroundSurface",
            SurfaceType::Closure => "ClosureSurface",
            SurfaceType::Floor => "FloorSurface",
            SurfaceType::Ceiling => "CeilingSurface",
            SurfaceType::InteriorWall => "InteriorWallSurface",
            SurfaceType::OuterFloor => "OuterFloorSurface",
            SurfaceType::OuterCeiling => "OuterCeilingSurface",
            SurfaceType::Window => "Window",
            SurfaceType::Door => "Door",
        }
    }
    pub fn is_opening(self) -> bool {
        matches!(self, SurfaceType::Window | SurfaceType::Door)
    }
}

/// A planar polygon: one exterior ring and any number of interior rings (holes).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Polygon {
    pub id: Option<String>,
    pub exterior: Ring,
    pub interiors: Vec<Ring>,
    /// Semantic type of the thematic surface that owns this polygon where it is DEFINED, if any
    /// (a Solid face reached by XLink carries the type of the WallSurface/RoofSurface... that
    /// defines it).
    pub semantic: Option<SurfaceType>,
    /// gml:id of the thematic surface / opening feature that owns this polygon, if any.
    pub semantic_owner: Option<String>,
    /// `-` orientation (`gml:OrientableSurface orientation="-"`) reverses the rings' sense.
    /// `points` are always as written; a consumer that needs the effective orientation reverses
    /// them when this is true (nested `-` orientations cancel out).
    pub reversed: bool,
    /// Span of the `gml:Polygon` element (where it is defined, not where it is referenced).
    pub span: SourceSpan,
    /// Span of the property element directly enclosing the `gml:Polygon` where it is defined
    /// (`gml:surfaceMember`, `gml:baseSurface`, `gml:exterior` of a Solid, a `lodN…` property,
    /// ...), so a writer can remove or replace the polygon together with its wrapper.
    pub member_span: Option<SourceSpan>,
    /// `Some(span of the referencing element)` when this polygon was reached through an
    /// `xlink:href` (e.g. an NRW Solid face that points into a WallSurface): it is a copy of the
    /// polygon defined at `span`, with that definition's semantics. `None` where it is defined.
    /// [`CityObject::all_polygons`] skips copies, so each polygon is counted once.
    pub via_xlink: Option<SourceSpan>,
}

/// A shell: the polygons bounding one solid (exterior or one cavity).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Shell {
    pub id: Option<String>,
    pub polygons: Vec<Polygon>,
    /// `Some(span of the referencing element)` when this shell belongs to a solid reached
    /// through an `xlink:href` (`gml:solidMember`, a whole `lodNSolid` by reference): a copy of
    /// the solid defined elsewhere, so counts of solids skip it. Faces that are XLinks of their
    /// own (NRW solids point into the boundary surfaces face by face) do not make a shell a copy.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub via_xlink: Option<SourceSpan>,
}

/// A geometry primitive or aggregate as found under a `lodN…` property. Polygons appear where
/// the geometry lists them: a Solid whose faces are `xlink:href`s contains copies of the
/// referenced polygons (`Polygon::via_xlink` is `Some`), the boundary surfaces that define them
/// contain the originals. Use `CityObject::all_polygons` to see each polygon once.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum GeometryKind {
    /// MultiSurface / CompositeSurface / a single Polygon / TIN triangles: a set of polygons.
    Surfaces(Vec<Polygon>),
    /// A gml:Solid: exterior shell and interior shells (cavities).
    Solid { exterior: Shell, interior: Vec<Shell> },
    /// CompositeSolid or MultiSolid: several solids (each exterior + interiors).
    Solids(Vec<(Shell, Vec<Shell>)>),
}

/// One geometry property of a city object (`bldg:lod2Solid`, `lod2MultiSurface`, ...).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Geometry {
    /// gml:id of the geometry element (e.g. the gml:Solid), if it has one.
    pub id: Option<String>,
    /// Level of detail from the property name (`lod2Solid` → 2), if the name has one.
    pub lod: Option<u8>,
    /// Local name of the property element (`lod2Solid`, `lod2MultiSurface`, ...).
    pub property: String,
    /// Local name of the GML geometry element (`Solid`, `MultiSurface`, `CompositeSurface`, ...).
    pub gml_type: String,
    pub srs_name: Option<String>,
    pub kind: GeometryKind,
    /// Span of the GML geometry element (`gml:Solid`, `gml:MultiSurface`, ...), or of the
    /// property element when the whole geometry is an `xlink:href` (then `gml_type` is `xlink`).
    pub span: SourceSpan,
    /// Members of a CompositeSolid / MultiSolid that are not among the solids of `kind`, in
    /// document order: an `xlink:href` whose target is not in the document or is not a solid,
    /// an empty member, or member content the model does not represent. The geometry is then
    /// incomplete, and says so (the validator reports each), instead of losing a solid silently.
    /// Always empty for other geometries.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub skipped_members: Vec<SkippedMember>,
}

/// A member of an aggregate geometry that the model leaves out, and why (see
/// [`Geometry::skipped_members`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct SkippedMember {
    /// The `xlink:href` as written, when the member is a reference.
    pub href: Option<String>,
    /// Why it is not in the geometry, for messages (`points to nothing in the document`, ...).
    pub reason: String,
    /// Span of the member element (`gml:solidMember`, or what it contains).
    pub span: SourceSpan,
}

impl Geometry {
    /// All polygons of this geometry, whatever its kind.
    pub fn polygons(&self) -> Vec<&Polygon> {
        match &self.kind {
            GeometryKind::Surfaces(p) => p.iter().collect(),
            GeometryKind::Solid { exterior, interior } => {
                exterior.polygons.iter().chain(interior.iter().flat_map(|s| s.polygons.iter())).collect()
            }
            GeometryKind::Solids(v) => {
                v.iter().flat_map(|(e, i)| e.polygons.iter().chain(i.iter().flat_map(|s| s.polygons.iter()))).collect()
            }
        }
    }
}

/// A city object: a Building, BuildingPart, boundary surface, opening, Room, or any other feature
/// (kept as an opaque object with id, type and bounding box).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CityObject {
    pub id: Option<String>,
    /// Local element name (`Building`, `BuildingPart`, `WallSurface`, `Window`, `TINRelief`, ...).
    pub kind: String,
    /// Namespace prefix-independent module name (`bldg`, `dem`, `gen`, `core`, `con`, ...) from
    /// the element's CityGML namespace (`other` for an unknown CityGML module, `None` outside
    /// CityGML, e.g. an ADE).
    pub module: Option<String>,
    pub geometries: Vec<Geometry>,
    /// Nested city objects: parts, boundary surfaces, openings, rooms, installations.
    pub children: Vec<CityObject>,
    /// Envelope of all coordinates of this object and its children; for an object without
    /// geometry, its declared `gml:boundedBy` envelope (or empty).
    pub envelope: Envelope,
    /// Span of the feature element (`<bldg:Building ...>` .. `</bldg:Building>`).
    pub span: SourceSpan,
}

impl CityObject {
    /// This object and all nested objects, depth first.
    pub fn walk(&self) -> Vec<&CityObject> {
        let mut out = vec![self];
        for c in &self.children {
            out.extend(c.walk());
        }
        out
    }

    /// Every polygon of this object and its children (each listed once, where it is defined).
    pub fn all_polygons(&self) -> Vec<&Polygon> {
        self.walk()
            .into_iter()
            .flat_map(|o| o.geometries.iter().flat_map(|g| g.polygons()))
            .filter(|p| p.via_xlink.is_none())
            .collect()
    }
}

/// A whole CityGML document.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CityModel {
    pub version: CityGmlVersion,
    /// srsName of the document's boundedBy envelope, or the first srsName found.
    pub srs_name: Option<String>,
    /// Envelope declared in the document's gml:boundedBy, if any.
    pub declared_envelope: Option<Envelope>,
    /// Envelope computed from all coordinates.
    pub envelope: Envelope,
    /// Top-level city objects (cityObjectMember / featureMember contents).
    pub objects: Vec<CityObject>,
    /// `xlink:href`s on geometry properties whose target is not in the document (left out of
    /// the geometry they belong to; reported, not fatal).
    pub unresolved_xlinks: Vec<XLinkRef>,
}

/// An `xlink:href` on a geometry property that could not be resolved, as written and where.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct XLinkRef {
    pub href: String,
    pub span: SourceSpan,
    /// gml:id and type of the innermost city object holding the reference (for reports).
    pub feature: Option<String>,
    pub feature_type: String,
    /// The element (qualified name as written) the id belongs to when it exists but is not a
    /// geometry (`bldg:Building`, ...); `None` when no element of the document has that gml:id.
    pub target: Option<String>,
}

impl XLinkRef {
    /// A reference at `span` whose owner and target are not known yet.
    pub fn at(href: String, span: SourceSpan) -> XLinkRef {
        XLinkRef { href, span, feature: None, feature_type: String::new(), target: None }
    }
    /// Why the reference brings nothing in, for messages.
    pub fn reason(&self) -> String {
        match &self.target {
            Some(t) => format!("xlink:href=\"{}\" points to <{t}>, not a geometry", self.href),
            None => format!("xlink:href=\"{}\" points to nothing in the document", self.href),
        }
    }
}

impl CityModel {
    /// Every city object, nested ones included, depth first.
    pub fn all_objects(&self) -> Vec<&CityObject> {
        self.objects.iter().flat_map(|o| o.walk()).collect()
    }

    /// Every polygon of the document, each once, where it is defined (XLink copies skipped).
    pub fn all_polygons(&self) -> Vec<&Polygon> {
        self.objects.iter().flat_map(|o| o.all_polygons()).collect()
    }
}
