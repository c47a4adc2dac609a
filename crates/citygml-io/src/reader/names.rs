//! What the reader makes of an element name: geometry, nested object, thematic surface,
//! skipped content, LoD property; and the name of the element at a byte offset.

use super::*;

/// Element names that open a (surface or solid) geometry.
pub(super) fn is_geometry(local: &[u8]) -> bool {
    matches!(
        local,
        b"Polygon"
            | b"MultiSurface"
            | b"CompositeSurface"
            | b"OrientableSurface"
            | b"Surface"
            | b"TriangulatedSurface"
            | b"Tin"
            | b"Shell"
            | b"Solid"
            | b"CompositeSolid"
            | b"MultiSolid"
            | b"MultiGeometry"
            | b"GeometricComplex"
    )
}

pub(super) fn is_polygon_like(local: &[u8]) -> bool {
    matches!(local, b"Polygon" | b"PolygonPatch" | b"Triangle" | b"Rectangle")
}

/// Elements that hold surfaces: the geometries plus the polygon-like patches inside them.
pub(super) fn is_surface_like(local: &[u8]) -> bool {
    is_geometry(local) || is_polygon_like(local)
}

/// City objects that nest inside other city objects (parts, rooms, installations, boundary
/// surfaces, openings, relief components, ...). Any other CityGML element inside an object is
/// looked through for geometry (properties, ADE wrappers).
pub(super) fn is_nested_object(local: &[u8]) -> bool {
    if surface_type(local).is_some() {
        return true;
    }
    matches!(
        local,
        b"Building"
            | b"BuildingPart"
            | b"Room"
            | b"BuildingRoom"
            | b"BuildingInstallation"
            | b"IntBuildingInstallation"
            | b"BuildingFurniture"
            | b"BuildingConstructiveElement"
            | b"BuildingUnit"
            | b"Storey"
            | b"BridgePart"
            | b"BridgeRoom"
            | b"BridgeInstallation"
            | b"IntBridgeInstallation"
            | b"BridgeConstructionElement"
            | b"BridgeConstructiveElement"
            | b"BridgeFurniture"
            | b"TunnelPart"
            | b"HollowSpace"
            | b"TunnelInstallation"
            | b"IntTunnelInstallation"
            | b"TunnelConstructiveElement"
            | b"TunnelFurniture"
            | b"TINRelief"
            | b"MassPointRelief"
            | b"BreaklineRelief"
            | b"RasterRelief"
            | b"TrafficArea"
            | b"AuxiliaryTrafficArea"
            | b"TrafficSpace"
            | b"AuxiliaryTrafficSpace"
            | b"Section"
            | b"Intersection"
            | b"Marking"
            | b"HoleSurface"
            | b"WaterSurface"
            | b"WaterGroundSurface"
            | b"WaterClosureSurface"
    )
}

/// `SurfaceType::from_local_name` on bytes (no UTF-8 check: the names are ASCII).
pub(super) fn surface_type(local: &[u8]) -> Option<SurfaceType> {
    if !local.ends_with(b"Surface") && local != b"Window" && local != b"Door" {
        return None;
    }
    std::str::from_utf8(local).ok().and_then(SurfaceType::from_local_name)
}

/// CityGML elements whose content is never the object's own geometry.
pub(super) fn is_skipped(local: &[u8]) -> bool {
    matches!(local, b"Address" | b"ImplicitGeometry" | b"ExternalReference" | b"address" | b"externalReference")
}

/// `lod2Solid` → 2.
pub(super) fn lod_of(local: &[u8]) -> Option<u8> {
    if local.len() > 3 && local.starts_with(b"lod") && local[3].is_ascii_digit() {
        Some(local[3] - b'0')
    } else {
        None
    }
}

/// The LoD of a geometry property name (`lod2Solid`, `lod1MultiSurface`, `lod0FootPrint`, ...),
/// None for other `lodN…` properties (`lod2TerrainIntersection` curves, ...).
pub(super) fn by_reference_lod(l: &[u8]) -> Option<u8> {
    // called for every element: the cheap lodN test first, the name search only on a hit
    lod_of(l).filter(|_| {
        [&b"Solid"[..], b"Surface", b"Geometry", b"FootPrint", b"RoofEdge"]
            .iter()
            .any(|k| memchr::memmem::find(l, k).is_some())
    })
}

/// Qualified name (as written, prefix included) of the element whose `<` is at `start`.
pub(super) fn qname_at(src: &[u8], start: usize) -> &[u8] {
    let s = &src[start + 1..];
    let end = s.iter().position(|b| b.is_ascii_whitespace() || *b == b'>' || *b == b'/').unwrap_or(s.len());
    &s[..end]
}

/// Local name of the element whose `<` is at `start`.
pub(super) fn name_at(src: &[u8], start: usize) -> &[u8] {
    let q = qname_at(src, start);
    match memchr::memchr(b':', q) {
        Some(i) => &q[i + 1..],
        None => q,
    }
}
