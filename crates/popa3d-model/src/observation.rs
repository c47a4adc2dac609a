//! Observations and conditions: every equation class of Table B.1 (spec §2.5), each with its
//! references, value and σ. Units as stored: metres, gon for Hz/V (MA10), cosines for angle
//! constraints (MA09).

use crate::ids::*;
use serde::Serialize;

/// A value with its standard deviation (σ > 0, MA12). Observations are uncorrelated (diagonal
/// covariance, spec §2.5).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Measured {
    pub value: f64,
    pub sigma: f64,
}

impl Measured {
    pub fn new(value: f64, sigma: f64) -> Self {
        Measured { value, sigma }
    }
}

/// One single unknown of the model (for ParameterFix / ParameterObs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
pub enum Unknown {
    /// A plane's distance d.
    PlaneD(PlaneId),
    /// A normal-vector parameter.
    Param(ParamId),
    /// Component 0..3 (x, y, z) of a fixed point's translation.
    Translation(FixedPointId, u8),
    /// Component 0..4 (q0..q3) of a set-up's quaternion.
    Rotation(SetupId, u8),
}

/// Why an observation or condition is in the document.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub enum ObsOrigin {
    /// Measured in the field (laser distance, total station) or added with `geofit observe`.
    Measured,
    /// Derived from CityGML semantics and geometry (spec §8.2 step 5: coplanarity, parallelism,
    /// orthogonality, wall–window distances).
    Semantic,
    /// An a-priori difference from the sketch (spec §4.6, P10).
    Sketch,
    /// Induced by a distance observation (spec §4.5, P9).
    Induced,
    /// Consistency rules: unit norms, the zero parameter of a swap pair (spec §3.3, §4.2).
    Consistency,
    /// Datum: soft identity observations or hard fixes (spec §4.7).
    Datum,
}

impl ObsOrigin {
    pub fn as_str(self) -> &'static str {
        match self {
            ObsOrigin::Measured => "measured",
            ObsOrigin::Semantic => "semantic",
            ObsOrigin::Sketch => "sketch",
            ObsOrigin::Induced => "induced",
            ObsOrigin::Consistency => "consistency",
            ObsOrigin::Datum => "datum",
        }
    }
    pub fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "measured" => ObsOrigin::Measured,
            "semantic" => ObsOrigin::Semantic,
            "sketch" => ObsOrigin::Sketch,
            "induced" => ObsOrigin::Induced,
            "consistency" => ObsOrigin::Consistency,
            "datum" => ObsOrigin::Datum,
            _ => return None,
        })
    }
}

/// An observation or condition with its origin and, for induced constraints, the distance that
/// induced it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Observation {
    pub kind: ObsKind,
    pub origin: ObsOrigin,
    /// For [`ObsOrigin::Induced`]: the distance observation that induced this constraint.
    pub induced_by: Option<ObsId>,
    /// A free-text label (e.g. the CSV line or the source gml:ids it was derived from).
    pub label: Option<String>,
}

impl Observation {
    pub fn new(kind: ObsKind, origin: ObsOrigin) -> Self {
        Observation { kind, origin, induced_by: None, label: None }
    }
    pub fn with_label(mut self, label: impl Into<String>) -> Self {
        self.label = Some(label.into());
        self
    }
}

/// The equation classes of Table B.1. Names are the thesis class names (also the XML element names).
///
/// Angle constraints store *signed* cosines (spec §4.5 \[proposal\]: MA09 allows −1, and |·| has no
/// derivative at 0): `value` = ⟨a, b⟩ of the unit directions involved, with a face's direction being its
/// plane's signed normal and an edge's direction n_j×n_k / ‖n_j×n_k‖ (j, k: the planes of its two faces
/// in the order of its half-edges). Distances are ≥ 0 (MA11).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub enum ObsKind {
    DistanceFaceFace {
        a: FaceId,
        b: FaceId,
        l: Measured,
    },
    DistanceFaceEdge {
        a: FaceId,
        b: EdgeId,
        l: Measured,
    },
    DistanceFaceNode {
        a: FaceId,
        b: NodeId,
        l: Measured,
    },
    DistanceEdgeEdge {
        a: EdgeId,
        b: EdgeId,
        l: Measured,
    },
    DistanceEdgeNode {
        a: EdgeId,
        b: NodeId,
        l: Measured,
    },
    DistanceNodeNode {
        a: NodeId,
        b: NodeId,
        l: Measured,
    },
    /// A reflectorless total-station pointing (Hz, V in gon, slope distance s in m) on a face.
    PointOnFace {
        setup: SetupId,
        target: FaceId,
        hz: Measured,
        v: Measured,
        s: Measured,
    },
    PointOnEdge {
        setup: SetupId,
        target: EdgeId,
        hz: Measured,
        v: Measured,
        s: Measured,
    },
    PointOnNode {
        setup: SetupId,
        target: NodeId,
        hz: Measured,
        v: Measured,
        s: Measured,
    },
    /// Cosine between two faces' normals: 0 orthogonal, ±1 parallel.
    ConstraintFaceFace {
        a: FaceId,
        b: FaceId,
        l: Measured,
    },
    /// Cosine between a face normal and an edge direction: 0 edge parallel to the face, ±1 orthogonal.
    ConstraintFaceEdge {
        a: FaceId,
        b: EdgeId,
        l: Measured,
    },
    /// Cosine between two edge directions: 0 orthogonal, ±1 parallel.
    ConstraintEdgeEdge {
        a: EdgeId,
        b: EdgeId,
        l: Measured,
    },
    /// Sketch prior Δd = d'_upper − d'_lower of two planes on one normal object (spec §4.6), where
    /// d' = sign·d is a plane's offset along the normal object's own direction (so planes stored with
    /// opposite signs compare correctly); the sort order makes the value ≥ 0.
    RelativeDistancePlanePlane {
        lower: PlaneId,
        upper: PlaneId,
        l: Measured,
    },
    /// Sketch prior ⟨n_a, n_b⟩ of two normals (spec §4.6).
    RelativeAngleNormalNormal {
        a: NormalId,
        b: NormalId,
        l: Measured,
    },
    /// ‖n‖ = 1: a pseudo-observation with σ, or a restriction when `sigma` is `None` (T 3.5/3.6).
    NormNV {
        normal: NormalId,
        sigma: Option<f64>,
    },
    /// ‖q‖ = 1 of a set-up: always a restriction (T 3.14).
    NormQ {
        setup: SetupId,
    },
    /// Restriction x = value (hard datum, or the zero parameter of a swap pair).
    ParameterFix {
        unknown: Unknown,
        value: f64,
    },
    /// Identity observation x0 + v = x (soft datum), weakly weighted.
    ParameterObs {
        unknown: Unknown,
        l: Measured,
    },
}

impl ObsKind {
    /// The Table B.1 class name (and XML element name).
    pub fn class_name(&self) -> &'static str {
        match self {
            ObsKind::DistanceFaceFace { .. } => "DistanceFaceFace",
            ObsKind::DistanceFaceEdge { .. } => "DistanceFaceEdge",
            ObsKind::DistanceFaceNode { .. } => "DistanceFaceNode",
            ObsKind::DistanceEdgeEdge { .. } => "DistanceEdgeEdge",
            ObsKind::DistanceEdgeNode { .. } => "DistanceEdgeNode",
            ObsKind::DistanceNodeNode { .. } => "DistanceNodeNode",
            ObsKind::PointOnFace { .. } => "PointOnFace",
            ObsKind::PointOnEdge { .. } => "PointOnEdge",
            ObsKind::PointOnNode { .. } => "PointOnNode",
            ObsKind::ConstraintFaceFace { .. } => "ConstraintFaceFace",
            ObsKind::ConstraintFaceEdge { .. } => "ConstraintFaceEdge",
            ObsKind::ConstraintEdgeEdge { .. } => "ConstraintEdgeEdge",
            ObsKind::RelativeDistancePlanePlane { .. } => "RelativeDistancePlanePlane",
            ObsKind::RelativeAngleNormalNormal { .. } => "RelativeAngleNormalNormal",
            ObsKind::NormNV { .. } => "NormNV",
            ObsKind::NormQ { .. } => "NormQ",
            ObsKind::ParameterFix { .. } => "ParameterFix",
            ObsKind::ParameterObs { .. } => "ParameterObs",
        }
    }

    /// True for restrictions g(x) = 0 (no observation, no σ).
    pub fn is_restriction(&self) -> bool {
        matches!(self, ObsKind::NormQ { .. } | ObsKind::ParameterFix { .. } | ObsKind::NormNV { sigma: None, .. })
    }

    /// The stochastic observations of this equation (value, σ): one for most classes, three for
    /// polar pointings, none for restrictions. NormNV as a pseudo-observation has l = 1.
    pub fn measured(&self) -> Vec<Measured> {
        use ObsKind::*;
        match *self {
            DistanceFaceFace { l, .. }
            | DistanceFaceEdge { l, .. }
            | DistanceFaceNode { l, .. }
            | DistanceEdgeEdge { l, .. }
            | DistanceEdgeNode { l, .. }
            | DistanceNodeNode { l, .. }
            | ConstraintFaceFace { l, .. }
            | ConstraintFaceEdge { l, .. }
            | ConstraintEdgeEdge { l, .. }
            | RelativeDistancePlanePlane { l, .. }
            | RelativeAngleNormalNormal { l, .. }
            | ParameterObs { l, .. } => vec![l],
            PointOnFace { hz, v, s, .. } | PointOnEdge { hz, v, s, .. } | PointOnNode { hz, v, s, .. } => {
                vec![hz, v, s]
            }
            NormNV { sigma: Some(s), .. } => vec![Measured::new(1.0, s)],
            NormNV { sigma: None, .. } | NormQ { .. } | ParameterFix { .. } => vec![],
        }
    }
}
