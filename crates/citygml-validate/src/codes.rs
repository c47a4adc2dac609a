//! The geometric error codes shared by val3dity and the OGC CityGML Quality Interoperability
//! Experiment (QIE). Names follow val3dity's current list; the legacy QIE codes map as
//! 105 COLLAPSED_TO_LINE → 104, 304 NON_MANIFOLD_EDGE → 303, 308 ALL_POLYGONS_WRONG_ORIENTATION → 405.

use serde::Serialize;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
pub enum ErrorCode {
    TooFewPoints,
    ConsecutivePointsSame,
    RingNotClosed,
    RingSelfIntersection,
    IntersectionRings,
    DuplicatedRings,
    NonPlanarPolygonDistancePlane,
    NonPlanarPolygonNormalsDeviation,
    InteriorDisconnected,
    InnerRingOutside,
    InnerRingsNested,
    OrientationRingsSame,
    TooFewPolygons,
    ShellNotClosed,
    NonManifoldCase,
    MultipleConnectedComponents,
    ShellSelfIntersection,
    PolygonWrongOrientation,
    IntersectionShells,
    DuplicatedShells,
    InnerShellOutside,
    SolidInteriorDisconnected,
    WrongOrientationShell,
    IntersectionSolids,
    DuplicatedSolids,
    DisconnectedSolids,
    InvalidInputFile,
    EmptyPrimitive,
}

impl ErrorCode {
    pub const ALL: [ErrorCode; 28] = [
        ErrorCode::TooFewPoints,
        ErrorCode::ConsecutivePointsSame,
        ErrorCode::RingNotClosed,
        ErrorCode::RingSelfIntersection,
        ErrorCode::IntersectionRings,
        ErrorCode::DuplicatedRings,
        ErrorCode::NonPlanarPolygonDistancePlane,
        ErrorCode::NonPlanarPolygonNormalsDeviation,
        ErrorCode::InteriorDisconnected,
        ErrorCode::InnerRingOutside,
        ErrorCode::InnerRingsNested,
        ErrorCode::OrientationRingsSame,
        ErrorCode::TooFewPolygons,
        ErrorCode::ShellNotClosed,
        ErrorCode::NonManifoldCase,
        ErrorCode::MultipleConnectedComponents,
        ErrorCode::ShellSelfIntersection,
        ErrorCode::PolygonWrongOrientation,
        ErrorCode::IntersectionShells,
        ErrorCode::DuplicatedShells,
        ErrorCode::InnerShellOutside,
        ErrorCode::SolidInteriorDisconnected,
        ErrorCode::WrongOrientationShell,
        ErrorCode::IntersectionSolids,
        ErrorCode::DuplicatedSolids,
        ErrorCode::DisconnectedSolids,
        ErrorCode::InvalidInputFile,
        ErrorCode::EmptyPrimitive,
    ];

    /// The numeric code (val3dity / QIE).
    pub fn code(self) -> u16 {
        use ErrorCode::*;
        match self {
            TooFewPoints => 101,
            ConsecutivePointsSame => 102,
            RingNotClosed => 103,
            RingSelfIntersection => 104,
            IntersectionRings => 201,
            DuplicatedRings => 202,
            NonPlanarPolygonDistancePlane => 203,
            NonPlanarPolygonNormalsDeviation => 204,
            InteriorDisconnected => 205,
            InnerRingOutside => 206,
            InnerRingsNested => 207,
            OrientationRingsSame => 208,
            TooFewPolygons => 301,
            ShellNotClosed => 302,
            NonManifoldCase => 303,
            MultipleConnectedComponents => 305,
            ShellSelfIntersection => 306,
            PolygonWrongOrientation => 307,
            IntersectionShells => 401,
            DuplicatedShells => 402,
            InnerShellOutside => 403,
            SolidInteriorDisconnected => 404,
            WrongOrientationShell => 405,
            IntersectionSolids => 501,
            DuplicatedSolids => 502,
            DisconnectedSolids => 503,
            InvalidInputFile => 901,
            EmptyPrimitive => 902,
        }
    }

    /// The upper-case name val3dity prints.
    pub fn name(self) -> &'static str {
        use ErrorCode::*;
        match self {
            TooFewPoints => "TOO_FEW_POINTS",
            ConsecutivePointsSame => "CONSECUTIVE_POINTS_SAME",
            RingNotClosed => "RING_NOT_CLOSED",
            RingSelfIntersection => "RING_SELF_INTERSECTION",
            IntersectionRings => "INTERSECTION_RINGS",
            DuplicatedRings => "DUPLICATED_RINGS",
            NonPlanarPolygonDistancePlane => "NON_PLANAR_POLYGON_DISTANCE_PLANE",
            NonPlanarPolygonNormalsDeviation => "NON_PLANAR_POLYGON_NORMALS_DEVIATION",
            InteriorDisconnected => "INTERIOR_DISCONNECTED",
            InnerRingOutside => "INNER_RING_OUTSIDE",
            InnerRingsNested => "INNER_RINGS_NESTED",
            OrientationRingsSame => "ORIENTATION_RINGS_SAME",
            TooFewPolygons => "TOO_FEW_POLYGONS",
            ShellNotClosed => "SHELL_NOT_CLOSED",
            NonManifoldCase => "NON_MANIFOLD_CASE",
            MultipleConnectedComponents => "MULTIPLE_CONNECTED_COMPONENTS",
            ShellSelfIntersection => "SHELL_SELF_INTERSECTION",
            PolygonWrongOrientation => "POLYGON_WRONG_ORIENTATION",
            IntersectionShells => "INTERSECTION_SHELLS",
            DuplicatedShells => "DUPLICATED_SHELLS",
            InnerShellOutside => "INNER_SHELL_OUTSIDE",
            SolidInteriorDisconnected => "SOLID_INTERIOR_DISCONNECTED",
            WrongOrientationShell => "WRONG_ORIENTATION_SHELL",
            IntersectionSolids => "INTERSECTION_SOLIDS",
            DuplicatedSolids => "DUPLICATED_SOLIDS",
            DisconnectedSolids => "DISCONNECTED_SOLIDS",
            InvalidInputFile => "INVALID_INPUT_FILE",
            EmptyPrimitive => "EMPTY_PRIMITIVE",
        }
    }

    pub fn from_code(code: u16) -> Option<ErrorCode> {
        ErrorCode::ALL.iter().copied().find(|c| c.code() == code)
    }
}
