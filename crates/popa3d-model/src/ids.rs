//! Typed element ids: one namespace per element type (spec §2.1, MA01). An id is the element's
//! index in its `Vec` inside [`crate::Popa3d`].

use serde::Serialize;
use std::fmt;

macro_rules! id_type {
    ($(#[$doc:meta])* $name:ident, $tag:literal) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
        pub struct $name(pub u32);
        impl $name {
            /// The index into the model's vector of this element type.
            #[inline]
            pub fn idx(self) -> usize {
                self.0 as usize
            }
            /// The element type's name, as used in messages and XML (`node`, `plane`, ...).
            pub const KIND: &'static str = $tag;
        }
        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "{} {}", $tag, self.0)
            }
        }
        impl From<usize> for $name {
            fn from(i: usize) -> Self {
                $name(i as u32)
            }
        }
    };
}

id_type!(/// A [`crate::Node`].
    NodeId, "node");
id_type!(/// A directed [`crate::Edge`].
    EdgeId, "edge");
id_type!(/// A [`crate::HalfEdge`].
    HalfEdgeId, "halfedge");
id_type!(/// A [`crate::Face`].
    FaceId, "face");
id_type!(/// A [`crate::Solid`] (room, building, or the exterior space).
    SolidId, "solid");
id_type!(/// A [`crate::Plane`].
    PlaneId, "plane");
id_type!(/// A [`crate::NormalVector`].
    NormalId, "normal");
id_type!(/// A [`crate::Parameter`].
    ParamId, "parameter");
id_type!(/// A [`crate::FixedPoint`].
    FixedPointId, "fixedpoint");
id_type!(/// A [`crate::Setup`].
    SetupId, "setup");
id_type!(/// An [`crate::Observation`] (observations and conditions share one namespace).
    ObsId, "observation");

/// A sign ±1 on a reference (half-edge direction, plane→normal, normal→parameter, face→plane).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
pub enum Sign {
    Plus,
    Minus,
}

impl Sign {
    #[inline]
    pub fn f64(self) -> f64 {
        match self {
            Sign::Plus => 1.0,
            Sign::Minus => -1.0,
        }
    }
    #[inline]
    pub fn i8(self) -> i8 {
        match self {
            Sign::Plus => 1,
            Sign::Minus => -1,
        }
    }
    #[inline]
    pub fn flip(self) -> Sign {
        match self {
            Sign::Plus => Sign::Minus,
            Sign::Minus => Sign::Plus,
        }
    }
    /// Product of two signs.
    #[inline]
    pub fn times(self, o: Sign) -> Sign {
        if self == o {
            Sign::Plus
        } else {
            Sign::Minus
        }
    }
    /// The sign of `x` (zero counts as `Plus`).
    #[inline]
    pub fn of(x: f64) -> Sign {
        if x < 0.0 {
            Sign::Minus
        } else {
            Sign::Plus
        }
    }
}
