//! The polygon soup: what every input format is turned into before normalization.

use popa3d_model::{FaceSource, SolidKind, VertexSource};

/// One object to normalize (a CityGML building (part), or an OBJ sketch): solids and polygons.
#[derive(Debug, Clone, Default)]
pub struct Soup {
    /// Name for messages (the building's gml:id, the OBJ file).
    pub name: String,
    /// The solids the polygons bound. The exterior space is implicit (not listed here).
    pub solids: Vec<SoupSolid>,
    pub polygons: Vec<SoupPolygon>,
    /// Source counts (polygons, rings, points) for the before/after report.
    pub source_rings: usize,
    /// True when the polygons come from MultiSurfaces only (no solid in the source): an open shell is
    /// then reported as rule NO-SOLID.
    pub multisurface_only: bool,
}

#[derive(Debug, Clone)]
pub struct SoupSolid {
    pub kind: SolidKind,
    pub name: Option<String>,
}

/// A polygon: rings (exterior first) of points without the closing repeat, in source coordinates.
#[derive(Debug, Clone)]
pub struct SoupPolygon {
    pub rings: Vec<Vec<[f64; 3]>>,
    /// Per ring, per point: where the point came from.
    pub vertex_sources: Vec<Vec<VertexSource>>,
    /// Index into [`Soup::solids`] of the solid this polygon bounds (it lies behind the polygon's
    /// right-hand normal once oriented).
    pub solid: usize,
    pub source: FaceSource,
    /// Locator for messages (gml:id or `line N`).
    pub locator: String,
    /// For an opening (window, door): the gml:id of the boundary surface it sits in (the wall), used
    /// to generate wall–window distances.
    pub parent: Option<String>,
}
