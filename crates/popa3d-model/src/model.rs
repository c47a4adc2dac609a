//! The popa3d entities (spec §2.2–§2.4) and the document that holds them.

use crate::ids::*;
use crate::observation::Observation;
use serde::Serialize;

/// A whole popa3d document: one or more buildings/sketches, their observations and set-ups.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct Popa3d {
    /// Local origin in the source CRS. Every plane distance `d` and every fixed point is relative to
    /// it: a source point `X` corresponds to the model point `X - origin`. Chosen near the model (and
    /// rounded, so people can read it) to keep `d` small for UTM-sized coordinates.
    pub origin: [f64; 3],
    /// The source CRS (CityGML `srsName`), if known.
    pub srs_name: Option<String>,
    /// Where the model came from (file name and format), for messages and the way back.
    pub source: Option<SourceDocument>,
    pub nodes: Vec<Node>,
    pub edges: Vec<Edge>,
    /// Source vertices that lie on an edge between its end nodes: collinear vertices that
    /// normalization removed because they were no plane intersection (GA01 repair, spec §7.4). The
    /// way back to CityGML puts them on the edge's line. Sorted by edge.
    pub edge_vertices: Vec<EdgeVertices>,
    pub half_edges: Vec<HalfEdge>,
    pub faces: Vec<Face>,
    pub solids: Vec<Solid>,
    pub planes: Vec<Plane>,
    pub normals: Vec<NormalVector>,
    pub parameters: Vec<Parameter>,
    pub fixed_points: Vec<FixedPoint>,
    pub setups: Vec<Setup>,
    pub observations: Vec<Observation>,
}

/// The document a model was converted from.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct SourceDocument {
    /// `citygml` or `obj`.
    pub format: String,
    /// The file name as given on the command line (`-` for stdin).
    pub file: String,
}

/// A node: no coordinates (spec §2.2); its position is the intersection of its faces' planes.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct Node {
    /// The source vertices merged into this node (every ring occurrence, closing repeat excluded).
    pub sources: Vec<VertexSource>,
}

/// One source vertex a node came from.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Serialize)]
pub enum VertexSource {
    /// Vertex `index` (0-based, the repeated closing point not counted) of ring `ring` (0 = exterior,
    /// 1.. = interiors in document order) of a CityGML polygon. `polygon` is the polygon's gml:id, or
    /// `#<n>` (the n-th polygon of the building in document order, 0-based) when it has none.
    CityGml { polygon: String, ring: u32, index: u32 },
    /// 0-based vertex index of an OBJ file (the `v` lines in order).
    Obj { vertex: u32 },
}

/// A directed edge between two distinct nodes (MA02, TA02).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Edge {
    pub start: NodeId,
    pub end: NodeId,
}

/// Source vertices lying on one edge (see [`Popa3d::edge_vertices`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct EdgeVertices {
    pub edge: EdgeId,
    pub sources: Vec<VertexSource>,
}

/// One use of an edge by a face: `sign` Plus means the face's boundary runs start→end.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct HalfEdge {
    pub edge: EdgeId,
    pub sign: Sign,
    pub face: FaceId,
}

/// A face: a planar polygon, possibly with holes, separating two solids.
///
/// Orientation convention (spec §2.2 \[gap\], §10.2 item 12, decided here): the *face normal* is the
/// right-hand normal of its outer loop (half-edges chained in their signed direction); `front` is the
/// solid on the side the face normal points to, `back` the one behind it. The face normal equals
/// `orientation ×` the plane's normal, because a plane is shared by faces of either orientation.
/// For a building shell written counter-clockwise seen from outside (as GML demands), `front` is the
/// exterior space and `back` the building.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Face {
    pub plane: PlaneId,
    pub orientation: Sign,
    pub front: SolidId,
    pub back: SolidId,
    /// Where the face came from.
    pub source: Option<FaceSource>,
}

/// Provenance and semantics of a face.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Default)]
pub struct FaceSource {
    /// CityGML polygon gml:id (or `@line:column` of a polygon without id); OBJ: `f<line>` of the face.
    pub polygon: String,
    /// Semantic type as the CityGML element name (`WallSurface`, `Window`, ...), if any.
    pub semantic: Option<String>,
    /// gml:id of the thematic surface / opening that owns the polygon, if any.
    pub owner: Option<String>,
    /// Source polygons that normalization merged into this face (coplanar neighbours whose common
    /// edge left a node without three planes, spec §7.4): the write-back replaces them by this
    /// face, so their surface is not lost.
    pub merged: Vec<String>,
}

/// What a solid stands for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum SolidKind {
    /// The space outside every building (one per document, normally solid 0).
    Exterior,
    /// A building or building part (CityGML).
    Building,
    /// A room (sketch object/group, CityGML Room).
    Room,
    /// Anything else (a building component).
    Component,
}

impl SolidKind {
    pub fn as_str(self) -> &'static str {
        match self {
            SolidKind::Exterior => "exterior",
            SolidKind::Building => "building",
            SolidKind::Room => "room",
            SolidKind::Component => "component",
        }
    }
    pub fn parse(s: &str) -> Option<SolidKind> {
        Some(match s {
            "exterior" => SolidKind::Exterior,
            "building" => SolidKind::Building,
            "room" => SolidKind::Room,
            "component" => SolidKind::Component,
            _ => return None,
        })
    }
}

/// A solid / room (spec §2.2).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Solid {
    pub kind: SolidKind,
    /// A human name (OBJ object/group name) or the source gml:id of the building (part).
    pub name: Option<String>,
}

/// A plane: points x on it satisfy ⟨sign·n, x⟩ − d = 0 with n the referenced normal (Hesse normal
/// form, spec §2.3). The sign lets antiparallel planes share one normal object: a plane with normal
/// −n is stored as (n, Minus, d).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Plane {
    pub normal: NormalId,
    pub sign: Sign,
    pub d: f64,
}

/// A normal vector: three signed parameter references (x, y, z), spec §2.3. Orthogonality is encoded
/// by sharing parameters with swap and sign, e.g. (a, b, c) and (−b, a, c).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct NormalVector {
    pub comps: [(ParamId, Sign); 3],
}

/// A parameter: one unknown normal-vector component, −1 ≤ value ≤ 1 (MA08).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Parameter {
    pub value: f64,
}

/// A fixed point (Festpunkt): the translation unknowns of the set-ups on it (spec §2.4), relative to
/// the model origin.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FixedPoint {
    pub t: [f64; 3],
}

/// An instrument set-up (Standpunkt) on a fixed point: rotation unknowns as a unit quaternion
/// (q0 = scalar part), a constant instrument height, and whether the instrument is levelled
/// (then q1 = q2 = 0 are enforced, T 3.37).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Setup {
    pub fixed_point: FixedPointId,
    pub instrument_height: f64,
    pub q: [f64; 4],
    pub levelled: bool,
}

impl Popa3d {
    /// An empty model with the given local origin.
    pub fn new(origin: [f64; 3]) -> Self {
        Popa3d { origin, ..Default::default() }
    }

    pub fn node(&self, id: NodeId) -> &Node {
        &self.nodes[id.idx()]
    }
    pub fn edge(&self, id: EdgeId) -> &Edge {
        &self.edges[id.idx()]
    }
    pub fn half_edge(&self, id: HalfEdgeId) -> &HalfEdge {
        &self.half_edges[id.idx()]
    }
    pub fn face(&self, id: FaceId) -> &Face {
        &self.faces[id.idx()]
    }
    pub fn solid(&self, id: SolidId) -> &Solid {
        &self.solids[id.idx()]
    }
    pub fn plane(&self, id: PlaneId) -> &Plane {
        &self.planes[id.idx()]
    }
    pub fn normal(&self, id: NormalId) -> &NormalVector {
        &self.normals[id.idx()]
    }
    pub fn parameter(&self, id: ParamId) -> &Parameter {
        &self.parameters[id.idx()]
    }

    /// Appends and returns the new id (the same pattern for every element type).
    pub fn add_node(&mut self, n: Node) -> NodeId {
        self.nodes.push(n);
        NodeId::from(self.nodes.len() - 1)
    }
    pub fn add_edge(&mut self, e: Edge) -> EdgeId {
        self.edges.push(e);
        EdgeId::from(self.edges.len() - 1)
    }
    pub fn add_half_edge(&mut self, h: HalfEdge) -> HalfEdgeId {
        self.half_edges.push(h);
        HalfEdgeId::from(self.half_edges.len() - 1)
    }
    pub fn add_face(&mut self, f: Face) -> FaceId {
        self.faces.push(f);
        FaceId::from(self.faces.len() - 1)
    }
    pub fn add_solid(&mut self, s: Solid) -> SolidId {
        self.solids.push(s);
        SolidId::from(self.solids.len() - 1)
    }
    pub fn add_plane(&mut self, p: Plane) -> PlaneId {
        self.planes.push(p);
        PlaneId::from(self.planes.len() - 1)
    }
    pub fn add_normal(&mut self, n: NormalVector) -> NormalId {
        self.normals.push(n);
        NormalId::from(self.normals.len() - 1)
    }
    pub fn add_parameter(&mut self, p: Parameter) -> ParamId {
        self.parameters.push(p);
        ParamId::from(self.parameters.len() - 1)
    }
    pub fn add_fixed_point(&mut self, p: FixedPoint) -> FixedPointId {
        self.fixed_points.push(p);
        FixedPointId::from(self.fixed_points.len() - 1)
    }
    pub fn add_setup(&mut self, s: Setup) -> SetupId {
        self.setups.push(s);
        SetupId::from(self.setups.len() - 1)
    }
    pub fn add_observation(&mut self, o: Observation) -> ObsId {
        self.observations.push(o);
        ObsId::from(self.observations.len() - 1)
    }

    /// Number of stored geometry unknowns of the object: plane distances plus normal parameters
    /// (the "stored values" of spec §3.3).
    pub fn object_unknowns(&self) -> usize {
        self.planes.len() + self.parameters.len()
    }
}
