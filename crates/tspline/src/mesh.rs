//! The T-mesh stored in a rectangle R-tree (spec §5.2): cells are axis-aligned parameter
//! rectangles with exactly four corner control points. The tree holds the leaves only; refined
//! parent cells stay in the cell list with their children (history, enables coarsening). Why
//! leaves only: a query around a leaf met every ancestor of it and of its neighbours, and the
//! neighbour queries of the repair were ~16 % of a large fit's one thread (BAG 0.1 m).
//!
//! Decisions (spec §9.2):
//! - **A13** rule-2 / 1:2 repair: we split whole cells into four (never in two), so with square
//!   initial cells every cell stays a square of dyadic size. A leaf cell is split when a leaf
//!   neighbour is more than twice as fine along the shared side (1:2 balance), or when both
//!   opposite sides carry a hanging vertex (rule 2: the two vertices could be joined). The two
//!   checks alternate until neither fires ([`TMesh::repair`]). Rule 3 is satisfied by
//!   construction: new edge points are mid-points of straight edges.
//!   Analysis-suitability: these rules keep linear meshes analysis-suitable in the cases we test,
//!   but a lone 4-split in a cubic mesh is not (the T-junction edge extensions meet at the
//!   centre) and Σ N ≠ 1 there (see the counter-example test in `eval.rs`). We therefore always
//!   evaluate the rational form (spec §3.2 "always normalise"); the fit's regulariser keeps the
//!   least-squares system definite if blending functions become dependent.
//! - **A14** rays stop at the domain boundary: a ray that would have to cross a gap of a
//!   non-convex or disconnected (merged) domain ends there and is padded like a border ray.
//! - **A22** degrees 1 and 3 only, no zero knot intervals (all cells have positive extent).

use std::collections::HashMap;

use rstar::{RTree, RTreeObject, AABB};

use crate::TsplineError;

/// Index of a control point in [`TMesh::points`].
pub type PointId = u32;
/// Index of a cell in [`TMesh::cells`] (parents included).
pub type CellId = u32;

/// Polynomial degree K of the T-spline (spec §3.3: only odd degrees 1 and 3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum Degree {
    Linear = 1,
    Cubic = 3,
}

impl Degree {
    pub fn from_u32(k: u32) -> Option<Degree> {
        match k {
            1 => Some(Degree::Linear),
            3 => Some(Degree::Cubic),
            _ => None,
        }
    }
    pub fn k(self) -> usize {
        self as usize
    }
    /// Knots collected per ray direction: (K+1)/2.
    pub fn half(self) -> usize {
        (self as usize).div_ceil(2)
    }
}

/// A control point: parameter pair, geometry and weight (spec §3.4).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlPoint {
    pub s: f64,
    pub t: f64,
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

/// An axis-aligned parameter rectangle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rect {
    pub s_min: f64,
    pub t_min: f64,
    pub s_max: f64,
    pub t_max: f64,
}

impl Rect {
    pub fn new(s_min: f64, t_min: f64, s_max: f64, t_max: f64) -> Rect {
        Rect { s_min, t_min, s_max, t_max }
    }
    pub fn width(&self) -> f64 {
        self.s_max - self.s_min
    }
    pub fn height(&self) -> f64 {
        self.t_max - self.t_min
    }
    pub fn contains_closed(&self, s: f64, t: f64) -> bool {
        self.s_min <= s && s <= self.s_max && self.t_min <= t && t <= self.t_max
    }
    fn aabb(&self) -> AABB<[f64; 2]> {
        AABB::from_corners([self.s_min, self.t_min], [self.s_max, self.t_max])
    }
    pub fn union(&self, o: &Rect) -> Rect {
        Rect::new(self.s_min.min(o.s_min), self.t_min.min(o.t_min), self.s_max.max(o.s_max), self.t_max.max(o.t_max))
    }
}

/// A T-mesh cell. Corner order as in the thesis' Table 5.3:
/// (s_min,t_max), (s_max,t_max), (s_min,t_min), (s_max,t_min).
#[derive(Debug, Clone)]
pub struct Cell {
    pub corners: [PointId; 4],
    pub rect: Rect,
    pub parent: Option<CellId>,
    pub children: Option<Children>,
    /// How the cell was last split (kept after coarsening, so that a split back restores it).
    pub split_as: SplitDir,
    /// False once removed by coarsening.
    pub alive: bool,
}

/// How a cell is split: into four at its centre, or in two across s (a cut at the s mid-point:
/// west and east halves) or across t (south and north halves).
/// docs/decisions.md#anisotropic-splits-issue-19
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SplitDir {
    #[default]
    Quad,
    S,
    T,
}

/// Which splits the refinement and the repair may make (docs/decisions.md#anisotropic-splits-issue-19).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum SplitRule {
    /// Every split is a 4-split (A13): cells stay squares of dyadic size.
    #[default]
    Quad,
    /// A cell is split in two across the direction that needs it, or in four when both do;
    /// cells are rectangles of aspect at most [`MAX_ASPECT`].
    Anisotropic,
}

/// The largest aspect ratio (longer side / shorter side) anisotropic splits make.
pub const MAX_ASPECT: f64 = 4.0;

/// The children of a split cell: four (a 4-split, in the order NW, NE, SW, SE) or two (a 2-split:
/// west, east or south, north).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Children {
    ids: [CellId; 4],
    len: u8,
}

impl Children {
    pub fn as_slice(&self) -> &[CellId] {
        &self.ids[..self.len as usize]
    }
    pub fn iter(&self) -> impl Iterator<Item = CellId> + '_ {
        self.as_slice().iter().copied()
    }
}

impl IntoIterator for Children {
    type Item = CellId;
    type IntoIter = std::iter::Take<std::array::IntoIter<CellId, 4>>;
    fn into_iter(self) -> Self::IntoIter {
        self.ids.into_iter().take(self.len as usize)
    }
}

impl Cell {
    /// A leaf with the given corners (in the order (s_min,t_max),(s_max,t_max),(s_min,t_min),
    /// (s_max,t_min)) and no parent.
    fn leaf(corners: [PointId; 4], points: &[ControlPoint]) -> Cell {
        let [a, b, c, _] = corners.map(|i| points[i as usize]);
        Cell {
            corners,
            rect: Rect::new(a.s, c.t, b.s, a.t),
            parent: None,
            children: None,
            split_as: SplitDir::Quad,
            alive: true,
        }
    }

    pub fn is_leaf(&self) -> bool {
        self.alive && self.children.is_none()
    }
}

/// One R-tree entry: a cell's exact box and id.
#[derive(Debug, Clone, PartialEq)]
struct CellEntry {
    id: CellId,
    env: AABB<[f64; 2]>,
}

impl RTreeObject for CellEntry {
    type Envelope = AABB<[f64; 2]>;
    fn envelope(&self) -> Self::Envelope {
        self.env
    }
}

/// Direction of a neighbour relative to a cell (spec §5.2 neighbour classification).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Side {
    West,
    East,
    South,
    North,
}

/// A T-mesh: control points, cells (leaves and retained parents) and the R-tree of the leaves.
#[derive(Debug, Clone)]
pub struct TMesh {
    pub degree: Degree,
    pub points: Vec<ControlPoint>,
    pub cells: Vec<Cell>,
    tree: RTree<CellEntry>,
    point_at: HashMap<(u64, u64), PointId>,
}

fn key(s: f64, t: f64) -> (u64, u64) {
    // +0.0 and -0.0 must be the same vertex.
    ((s + 0.0).to_bits(), (t + 0.0).to_bits())
}

impl TMesh {
    /// Builds a mesh from control points and leaf cells given by their four corner points;
    /// the R-tree is bulk loaded. Checks the T-mesh rules that the format can break: corners must
    /// form a rectangle of positive size, leaves must not overlap, no duplicate points.
    pub fn from_cells(
        degree: Degree,
        points: Vec<ControlPoint>,
        corners: Vec<[PointId; 4]>,
    ) -> Result<TMesh, TsplineError> {
        let mut point_at = HashMap::with_capacity(points.len());
        for (i, p) in points.iter().enumerate() {
            if !(p.s.is_finite()
                && p.t.is_finite()
                && p.x.is_finite()
                && p.y.is_finite()
                && p.z.is_finite()
                && p.w.is_finite())
            {
                return Err(TsplineError::InvalidMesh(format!("control point {i} has a non-finite value")));
            }
            if p.w <= 0.0 {
                return Err(TsplineError::InvalidMesh(format!("control point {i} has weight {} (must be > 0)", p.w)));
            }
            if point_at.insert(key(p.s, p.t), i as PointId).is_some() {
                return Err(TsplineError::InvalidMesh(format!(
                    "control point {i} duplicates the parameter pair ({}, {})",
                    p.s, p.t
                )));
            }
        }
        let mut cells = Vec::with_capacity(corners.len());
        for (ci, c) in corners.iter().enumerate() {
            for &p in c {
                if p as usize >= points.len() {
                    return Err(TsplineError::InvalidMesh(format!(
                        "cell {ci} refers to control point {p}, but there are {}",
                        points.len()
                    )));
                }
            }
            let [a, b, cc, d] = c.map(|i| points[i as usize]);
            let ok = a.s == cc.s && b.s == d.s && a.t == b.t && cc.t == d.t && a.s < b.s && cc.t < a.t;
            if !ok {
                return Err(TsplineError::InvalidMesh(format!(
                    "cell {ci}: corners {:?} do not form a rectangle in the order (s_min,t_max),(s_max,t_max),(s_min,t_min),(s_max,t_min)",
                    c
                )));
            }
            cells.push(Cell::leaf(*c, &points));
        }
        if cells.is_empty() {
            return Err(TsplineError::InvalidMesh("the mesh has no cells".into()));
        }
        let mesh = TMesh::with_tree(degree, points, cells, point_at);
        // Overlap check: two leaves may share edges but not area.
        for (i, c) in mesh.cells.iter().enumerate() {
            for o in mesh.tree.locate_in_envelope_intersecting(&c.rect.aabb()) {
                if o.id as usize == i {
                    continue;
                }
                let r = mesh.cells[o.id as usize].rect;
                let ow = c.rect.s_max.min(r.s_max) - c.rect.s_min.max(r.s_min);
                let oh = c.rect.t_max.min(r.t_max) - c.rect.t_min.max(r.t_min);
                if ow > 0.0 && oh > 0.0 {
                    return Err(TsplineError::InvalidMesh(format!("cells {i} and {} overlap", o.id)));
                }
            }
        }
        // Every control point must be a corner of some cell (no I-points, spec §5.2).
        let mut used = vec![false; mesh.points.len()];
        for c in &mesh.cells {
            for &p in &c.corners {
                used[p as usize] = true;
            }
        }
        if let Some(i) = used.iter().position(|u| !u) {
            return Err(TsplineError::InvalidMesh(format!("control point {i} is not a corner of any cell")));
        }
        // A vertex lying inside a cell's side must be a corner of a neighbouring cell (no
        // I-points); a vertex strictly inside a cell is an error.
        for (i, p) in mesh.points.iter().enumerate() {
            for e in mesh.tree.locate_in_envelope_intersecting(&AABB::from_point([p.s, p.t])) {
                let r = mesh.cells[e.id as usize].rect;
                if r.s_min < p.s && p.s < r.s_max && r.t_min < p.t && p.t < r.t_max {
                    return Err(TsplineError::InvalidMesh(format!("control point {i} lies inside cell {}", e.id)));
                }
            }
        }
        Ok(mesh)
    }

    /// [`TMesh::from_cells`] without its checks, for leaves taken from a mesh that passed them
    /// (a valid mesh stays valid when compacted): the checks query the R-tree once per cell and
    /// once per point, and a fit compacts its mesh for every acceptance check and output.
    fn from_valid_cells(degree: Degree, points: Vec<ControlPoint>, corners: Vec<[PointId; 4]>) -> TMesh {
        let point_at = points.iter().enumerate().map(|(i, p)| (key(p.s, p.t), i as PointId)).collect();
        let cells = corners.iter().map(|c| Cell::leaf(*c, &points)).collect();
        TMesh::with_tree(degree, points, cells, point_at)
    }

    /// The mesh with its R-tree bulk loaded over `cells`.
    fn with_tree(
        degree: Degree,
        points: Vec<ControlPoint>,
        cells: Vec<Cell>,
        point_at: HashMap<(u64, u64), PointId>,
    ) -> TMesh {
        let entries =
            cells.iter().enumerate().map(|(i, c)| CellEntry { id: i as CellId, env: c.rect.aabb() }).collect();
        TMesh { degree, points, cells, tree: RTree::bulk_load(entries), point_at }
    }

    /// A regular grid of `ns × nt` square cells of side `size` starting at (s0, t0); geometry
    /// (x, y) = (s, t), z = 0, w = 1. Used as the initial mesh of the fit (spec §4.1.1).
    pub fn grid(degree: Degree, s0: f64, t0: f64, size: f64, ns: usize, nt: usize) -> TMesh {
        let mut points = Vec::with_capacity((ns + 1) * (nt + 1));
        for j in 0..=nt {
            for i in 0..=ns {
                let s = s0 + i as f64 * size;
                let t = t0 + j as f64 * size;
                points.push(ControlPoint { s, t, x: s, y: t, z: 0.0, w: 1.0 });
            }
        }
        let id = |i: usize, j: usize| (j * (ns + 1) + i) as PointId;
        let mut corners = Vec::with_capacity(ns * nt);
        for j in 0..nt {
            for i in 0..ns {
                corners.push([id(i, j + 1), id(i + 1, j + 1), id(i, j), id(i + 1, j)]);
            }
        }
        TMesh::from_cells(degree, points, corners).expect("a regular grid is a valid T-mesh")
    }

    pub fn point_id_at(&self, s: f64, t: f64) -> Option<PointId> {
        self.point_at.get(&key(s, t)).copied()
    }

    /// Ids of leaf cells.
    pub fn leaves(&self) -> impl Iterator<Item = CellId> + '_ {
        self.cells.iter().enumerate().filter(|(_, c)| c.is_leaf()).map(|(i, _)| i as CellId)
    }

    pub fn leaf_count(&self) -> usize {
        self.cells.iter().filter(|c| c.is_leaf()).count()
    }

    /// Points that are corners of at least one leaf (after coarsening some points are orphaned).
    pub fn active_points(&self) -> Vec<bool> {
        let mut used = vec![false; self.points.len()];
        for c in self.cells.iter().filter(|c| c.is_leaf()) {
            for &p in &c.corners {
                used[p as usize] = true;
            }
        }
        used
    }

    /// Bounding rectangle of all leaves.
    pub fn bounds(&self) -> Rect {
        let mut it = self.cells.iter().filter(|c| c.is_leaf()).map(|c| c.rect);
        let first = it.next().expect("a mesh has at least one cell");
        it.fold(first, |a, r| a.union(&r))
    }

    /// Point query: the leaves whose closed box holds (s, t).
    pub fn cells_at(&self, s: f64, t: f64) -> Vec<CellId> {
        let mut v: Vec<CellId> =
            self.tree.locate_in_envelope_intersecting(&AABB::from_point([s, t])).map(|e| e.id).collect();
        v.sort_unstable();
        v
    }

    /// Point-in-domain test (the domain is the union of leaf rectangles, closed).
    pub fn contains(&self, s: f64, t: f64) -> bool {
        self.tree
            .locate_in_envelope_intersecting(&AABB::from_point([s, t]))
            .any(|e| self.cells[e.id as usize].is_leaf())
    }

    /// Area query: leaf cells whose closed box intersects `r`.
    pub fn leaves_in(&self, r: Rect) -> Vec<CellId> {
        let mut v: Vec<CellId> = self
            .tree
            .locate_in_envelope_intersecting(&r.aabb())
            .map(|e| e.id)
            .filter(|&id| self.cells[id as usize].is_leaf())
            .collect();
        v.sort_unstable();
        v
    }

    /// Neighbour query: leaf cells sharing a side segment of positive length with `cell`,
    /// classified by direction with coordinate comparisons (west: s_max ≤ this s_min, ...).
    pub fn neighbours(&self, cell: CellId) -> Vec<(Side, CellId)> {
        let r = self.cells[cell as usize].rect;
        let mut out = Vec::new();
        for e in self.tree.locate_in_envelope_intersecting(&r.aabb()) {
            if e.id == cell || !self.cells[e.id as usize].is_leaf() {
                continue;
            }
            let o = self.cells[e.id as usize].rect;
            let overlap_t = r.t_max.min(o.t_max) - r.t_min.max(o.t_min);
            let overlap_s = r.s_max.min(o.s_max) - r.s_min.max(o.s_min);
            let side = if o.s_max <= r.s_min && overlap_t > 0.0 {
                Side::West
            } else if o.s_min >= r.s_max && overlap_t > 0.0 {
                Side::East
            } else if o.t_max <= r.t_min && overlap_s > 0.0 {
                Side::South
            } else if o.t_min >= r.t_max && overlap_s > 0.0 {
                Side::North
            } else {
                continue; // corner contact or a retained ancestor/descendant
            };
            out.push((side, e.id));
        }
        out.sort_unstable_by_key(|&(s, id)| (s as u8, id));
        out
    }

    /// Gives back the spare capacity of the point and cell arrays and of the point index.
    /// Why: a clone has exact capacity and the first split after it doubles the arrays, so a
    /// refined or repaired mesh held up to twice its size through the solves that follow
    /// (docs/decisions.md#knots-only-through-the-solve).
    pub fn shrink_to_fit(&mut self) {
        self.points.shrink_to_fit();
        self.cells.shrink_to_fit();
        self.point_at.shrink_to_fit();
    }

    fn add_point(&mut self, s: f64, t: f64, z: f64) -> PointId {
        if let Some(&id) = self.point_at.get(&key(s, t)) {
            return id;
        }
        let id = self.points.len() as PointId;
        self.points.push(ControlPoint { s, t, x: s, y: t, z, w: 1.0 });
        self.point_at.insert(key(s, t), id);
        id
    }

    /// Splits a leaf cell at its centre into four children (spec §5.2 refinement). New points
    /// (edge mid-points and centre) are shared with neighbours that already have them; their
    /// geometry is set by `geom(s, t) -> (x, y, z)` (interpolated from the current surface).
    /// The parent stays in the cell list (not in the leaves' tree). Returns the children ids.
    pub fn split(&mut self, cell: CellId, geom: &mut dyn FnMut(f64, f64) -> (f64, f64, f64)) -> [CellId; 4] {
        let k = self.split_dir(cell, SplitDir::Quad, geom);
        k.ids
    }

    /// Splits a leaf cell into four ([`SplitDir::Quad`], as [`TMesh::split`]) or in two at the
    /// mid-point of one side: [`SplitDir::S`] cuts at the s mid-point (children west, east),
    /// [`SplitDir::T`] at the t mid-point (children south, north). The two new points of a
    /// 2-split are the mid-points of the two sides the cut crosses.
    pub fn split_dir(
        &mut self,
        cell: CellId,
        dir: SplitDir,
        geom: &mut dyn FnMut(f64, f64) -> (f64, f64, f64),
    ) -> Children {
        let c = self.cells[cell as usize].clone();
        assert!(c.is_leaf(), "split of a non-leaf cell");
        let r = c.rect;
        let sm = 0.5 * (r.s_min + r.s_max);
        let tm = 0.5 * (r.t_min + r.t_max);
        let mut pt = |m: &mut TMesh, s: f64, t: f64| {
            if let Some(id) = m.point_id_at(s, t) {
                id
            } else {
                let (x, y, z) = geom(s, t);
                let id = m.add_point(s, t, z);
                m.points[id as usize].x = x;
                m.points[id as usize].y = y;
                id
            }
        };
        let [nw, ne, sw, se] = c.corners;
        let kids: Vec<([PointId; 4], Rect)> = match dir {
            SplitDir::Quad => {
                let n = pt(self, sm, r.t_max);
                let s_ = pt(self, sm, r.t_min);
                let w = pt(self, r.s_min, tm);
                let e = pt(self, r.s_max, tm);
                let ctr = pt(self, sm, tm);
                vec![
                    ([nw, n, w, ctr], Rect::new(r.s_min, tm, sm, r.t_max)),
                    ([n, ne, ctr, e], Rect::new(sm, tm, r.s_max, r.t_max)),
                    ([w, ctr, sw, s_], Rect::new(r.s_min, r.t_min, sm, tm)),
                    ([ctr, e, s_, se], Rect::new(sm, r.t_min, r.s_max, tm)),
                ]
            }
            SplitDir::S => {
                let n = pt(self, sm, r.t_max);
                let s_ = pt(self, sm, r.t_min);
                vec![
                    ([nw, n, sw, s_], Rect::new(r.s_min, r.t_min, sm, r.t_max)),
                    ([n, ne, s_, se], Rect::new(sm, r.t_min, r.s_max, r.t_max)),
                ]
            }
            SplitDir::T => {
                let w = pt(self, r.s_min, tm);
                let e = pt(self, r.s_max, tm);
                vec![
                    ([w, e, sw, se], Rect::new(r.s_min, r.t_min, r.s_max, tm)),
                    ([nw, ne, w, e], Rect::new(r.s_min, tm, r.s_max, r.t_max)),
                ]
            }
        };
        let mut ids = Children { ids: [0; 4], len: kids.len() as u8 };
        for (k, (corners, rect)) in kids.into_iter().enumerate() {
            let id = self.cells.len() as CellId;
            self.cells.push(Cell {
                corners,
                rect,
                parent: Some(cell),
                children: None,
                split_as: SplitDir::Quad,
                alive: true,
            });
            self.tree.insert(CellEntry { id, env: rect.aabb() });
            ids.ids[k] = id;
        }
        self.tree.remove(&CellEntry { id: cell, env: r.aabb() });
        self.cells[cell as usize].children = Some(ids);
        self.cells[cell as usize].split_as = dir;
        ids
    }

    /// Coarsening (spec §5.2, T28): removes all descendants of `cell` (an area query with the
    /// parent's box), making it a leaf again. Points only used by removed cells become inactive
    /// (see [`TMesh::active_points`]); a later split at the same place reuses them.
    pub fn coarsen(&mut self, cell: CellId) -> Result<(), TsplineError> {
        if self.cells[cell as usize].children.is_none() {
            return Err(TsplineError::InvalidMesh(format!("cell {cell} has no children to remove")));
        }
        let mut stack = vec![cell];
        let mut removed = Vec::new();
        while let Some(c) = stack.pop() {
            if let Some(kids) = self.cells[c as usize].children {
                stack.extend(kids);
            }
            if c != cell {
                removed.push(c);
            }
        }
        for c in removed {
            if self.cells[c as usize].children.is_none() {
                let env = self.cells[c as usize].rect.aabb();
                self.tree.remove(&CellEntry { id: c, env });
            }
            self.cells[c as usize].alive = false;
            self.cells[c as usize].children = None;
        }
        self.cells[cell as usize].children = None;
        self.tree.insert(CellEntry { id: cell, env: self.cells[cell as usize].rect.aabb() });
        // A coarsened cell may now hold hanging vertices of its neighbours on its sides; those
        // are still corners of the neighbours, so the mesh stays valid. Points strictly inside
        // the parent are orphaned.
        Ok(())
    }

    /// Whether a leaf needs a split by the repair rules (A13, see module doc).
    pub fn needs_repair(&self, cell: CellId) -> bool {
        self.repair_need(cell).any()
    }

    /// The directions in which a leaf needs a split by the repair rules (see [`RepairNeed`]).
    pub fn repair_need(&self, cell: CellId) -> RepairNeed {
        let r = self.cells[cell as usize].rect;
        repair_need(&r, self.neighbours(cell).into_iter().map(|(side, n)| (side, self.cells[n as usize].rect)))
    }

    /// [`TMesh::repair_need`] of every leaf at once, indexed by cell id (none for non-leaves):
    /// the neighbours come from the leaves' sides sorted by line ([`SideIndex`]) instead of an
    /// R-tree query per leaf.
    /// The leaves are independent of each other here (the mesh is read only), so they are
    /// visited in parallel: the repair runs on the fit's one thread otherwise, and this batch
    /// was most of it (BENCHMARKS.md "Fit CPU on the largest mesh, again: bit-identical levers").
    fn leaves_needing_repair(&self) -> Vec<RepairNeed> {
        use rayon::prelude::*;
        let sides = SideIndex::new(self);
        let mut out = vec![RepairNeed::default(); self.cells.len()];
        out.par_iter_mut().zip(self.cells.par_iter()).with_min_len(4096).for_each(|(o, c)| {
            if c.is_leaf() {
                *o = repair_need(&c.rect, sides.neighbours(&c.rect));
            }
        });
        out
    }

    /// Alternating rule-2 / 1:2 repair until stable (A13). Cells smaller than `2·min_size` are
    /// never split (their children would undercut the sample spacing, spec §2.2); returns how
    /// many splits were done.
    pub fn repair(&mut self, min_size: f64, geom: &mut dyn FnMut(f64, f64) -> (f64, f64, f64)) -> usize {
        self.repair_with(min_size, SplitRule::Quad, geom)
    }

    /// [`TMesh::repair`] under a split rule: [`SplitRule::Quad`] splits a violating leaf into
    /// four (A13); [`SplitRule::Anisotropic`] splits it only across the direction(s) whose rule
    /// it violates (`aniso_repair_split`), never below `2·min_size` along the split side.
    pub fn repair_with(
        &mut self,
        min_size: f64,
        rule: SplitRule,
        geom: &mut dyn FnMut(f64, f64) -> (f64, f64, f64),
    ) -> usize {
        let mut splits = 0;
        let mut todo: Vec<CellId> = self.leaves().collect();
        // Each round's checks are answered from one batch over the mesh as the round found it
        // (`answers`, in parallel) unless a split of this round touched the leaf (`touched`: the
        // neighbours of each split cell, the only leaves whose neighbourhood a split changes),
        // so every answer is what `needs_repair` gives at that moment (same splits, same order).
        // The first round's batch covers every leaf, from the side index.
        let mut first = true;
        while !todo.is_empty() {
            todo.sort_unstable();
            todo.dedup();
            let answers = self.round_answers(&todo, rule, min_size, first);
            first = false;
            let mut touched = vec![false; self.cells.len()];
            let mut next = Vec::new();
            for (c, answer) in todo.into_iter().zip(answers) {
                let Some((dir, nbrs)) = answer else { continue };
                if !self.cells[c as usize].is_leaf() {
                    continue;
                }
                let (dir, nbrs) =
                    if touched[c as usize] { self.split_and_neighbours(c, rule, min_size) } else { (dir, nbrs) };
                let Some(dir) = dir else {
                    continue;
                };
                for &n in &nbrs {
                    if let Some(t) = touched.get_mut(n as usize) {
                        *t = true;
                    }
                }
                let kids = self.split_dir(c, dir, geom);
                splits += 1;
                next.extend(nbrs);
                next.extend(kids);
            }
            todo = next;
        }
        splits
    }

    /// A repair round's answers for `todo`, from the mesh as the round finds it, in parallel
    /// ([`RoundAnswer`]). The first round (`first`: every leaf) takes the needs from one pass
    /// over the side index and queries the neighbours only of the leaves that split; a later
    /// one asks each leaf with one R-tree query (these ran one after the other on the fit's
    /// thread: ~0.15 s of the BAG at 0.1 m).
    fn round_answers(&self, todo: &[CellId], rule: SplitRule, min_size: f64, first: bool) -> Vec<RoundAnswer> {
        use rayon::prelude::*;
        let flags = first.then(|| self.leaves_needing_repair());
        todo.par_iter()
            .with_min_len(64)
            .map(|&c| {
                let r = self.cells[c as usize].rect;
                if !self.cells[c as usize].is_leaf() || too_small(rule, &r, min_size) {
                    return None;
                }
                Some(match &flags {
                    Some(f) => match repair_split(rule, &r, f[c as usize], min_size) {
                        Some(dir) => (Some(dir), self.neighbours(c).into_iter().map(|(_, n)| n).collect()),
                        None => (None, Vec::new()),
                    },
                    None => self.split_and_neighbours(c, rule, min_size),
                })
            })
            .collect()
    }

    /// The split the repair makes of a leaf under `rule`, if any, and the leaf's neighbours'
    /// ids, from one R-tree query.
    fn split_and_neighbours(&self, cell: CellId, rule: SplitRule, min_size: f64) -> (Option<SplitDir>, Vec<CellId>) {
        let r = self.cells[cell as usize].rect;
        let nbrs = self.neighbours(cell);
        let need = repair_need(&r, nbrs.iter().map(|&(side, n)| (side, self.cells[n as usize].rect)));
        (repair_split(rule, &r, need, min_size), nbrs.into_iter().map(|(_, n)| n).collect())
    }

    /// Merging (spec §3.9, T28): the union of two meshes' leaf cells (C0 seam). Points at equal
    /// parameter pairs are identified (their geometry is taken from `self`); overlapping cells are
    /// an error. Knot inference then treats the union like any other mesh; rays stop at gaps (A14).
    pub fn merge(&self, other: &TMesh) -> Result<TMesh, TsplineError> {
        if self.degree != other.degree {
            return Err(TsplineError::InvalidMesh("cannot merge meshes of different degree".into()));
        }
        let mut points = Vec::new();
        let mut map: HashMap<(u64, u64), PointId> = HashMap::new();
        let mut corners = Vec::new();
        for m in [self, other] {
            for c in m.cells.iter().filter(|c| c.is_leaf()) {
                let mut q = [0; 4];
                for (k, &p) in c.corners.iter().enumerate() {
                    let cp = m.points[p as usize];
                    q[k] = *map.entry(key(cp.s, cp.t)).or_insert_with(|| {
                        points.push(cp);
                        (points.len() - 1) as PointId
                    });
                }
                corners.push(q);
            }
        }
        TMesh::from_cells(self.degree, points, corners)
    }

    /// Leaf-only copy with compact point numbering (what the file format stores).
    pub fn compacted(&self) -> TMesh {
        let active = self.active_points();
        let mut remap = vec![u32::MAX; self.points.len()];
        let mut points = Vec::new();
        for (i, a) in active.iter().enumerate() {
            if *a {
                remap[i] = points.len() as u32;
                points.push(self.points[i]);
            }
        }
        let corners = self.cells.iter().filter(|c| c.is_leaf()).map(|c| c.corners.map(|p| remap[p as usize])).collect();
        let c = TMesh::from_valid_cells(self.degree, points, corners);
        debug_assert!(
            TMesh::from_cells(c.degree, c.points.clone(), c.cells.iter().map(|c| c.corners).collect()).is_ok(),
            "a valid mesh stays valid when compacted"
        );
        c
    }

    /// Leaf cells crossed by the horizontal (`horizontal = true`) or vertical line through
    /// `at`, within the coordinate window [lo, hi] along the line (inclusive boxes).
    pub(crate) fn leaves_on_line(&self, horizontal: bool, at: f64, lo: f64, hi: f64, out: &mut Vec<Rect>) {
        out.clear();
        let env =
            if horizontal { AABB::from_corners([lo, at], [hi, at]) } else { AABB::from_corners([at, lo], [at, hi]) };
        for e in self.tree.locate_in_envelope_intersecting(&env) {
            let c = &self.cells[e.id as usize];
            if c.is_leaf() {
                out.push(c.rect);
            }
        }
    }
}

/// The directions in which a leaf violates the repair rules: `s` (its width must be halved: a
/// south or north neighbour is more than twice as fine along the shared side, or both carry a
/// hanging vertex on its south and north sides) and `t` (the same with west and east and the
/// height). A13's square cells need a split when either is set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RepairNeed {
    pub s: bool,
    pub t: bool,
}

impl RepairNeed {
    pub fn any(self) -> bool {
        self.s || self.t
    }
}

/// A repair round's answer for one cell ([`TMesh::round_answers`]): the split the rules ask
/// of the leaf, if any, and its neighbours (queried only where it splits: the round marks them
/// touched and visits them next); None for a cell the round skips (not a leaf, or one the rules
/// never split).
type RoundAnswer = Option<(Option<SplitDir>, Vec<CellId>)>;

/// Whether the repair never splits the leaf `r`: under [`SplitRule::Quad`], a cell smaller
/// than `2·min_size` (its children would undercut the sample spacing, spec §2.2).
fn too_small(rule: SplitRule, r: &Rect, min_size: f64) -> bool {
    rule == SplitRule::Quad && r.width().min(r.height()) < 2.0 * min_size
}

/// The split the repair makes of a leaf `r` with `need` under `rule`, if any.
fn repair_split(rule: SplitRule, r: &Rect, need: RepairNeed, min_size: f64) -> Option<SplitDir> {
    match rule {
        SplitRule::Quad => need.any().then_some(SplitDir::Quad),
        SplitRule::Anisotropic => aniso_repair_split(r, need, min_size),
    }
}

/// The repair rules (A13) for a leaf `r` with its leaf neighbours: a 1:2 violation on any
/// side, or hanging vertices on two opposite sides (rule 2: they could be joined), per
/// direction (rectangles: the balance is along the shared side).
fn repair_need(r: &Rect, neighbours: impl Iterator<Item = (Side, Rect)>) -> RepairNeed {
    let mut hanging = [false; 4];
    let mut need = RepairNeed::default();
    for (side, o) in neighbours {
        let (mine, theirs) = match side {
            Side::West | Side::East => (r.height(), o.height()),
            Side::South | Side::North => (r.width(), o.width()),
        };
        if theirs * 2.0 < mine {
            // 1:2 balance violated: halve the side shared with the finer neighbour
            match side {
                Side::West | Side::East => need.t = true,
                Side::South | Side::North => need.s = true,
            }
        }
        if theirs < mine {
            hanging[side as usize] = true;
        }
    }
    need.t |= hanging[Side::West as usize] && hanging[Side::East as usize];
    need.s |= hanging[Side::South as usize] && hanging[Side::North as usize];
    need
}

/// The anisotropic repair split of a leaf `r` with repair need `need`: across each direction
/// that needs it and whose side is at least `2·min_size`; four when both remain, or when a
/// 2-split would make a child of aspect above [`MAX_ASPECT`] (and the other side can be halved).
pub(crate) fn aniso_repair_split(r: &Rect, need: RepairNeed, min_size: f64) -> Option<SplitDir> {
    let s = need.s && r.width() >= 2.0 * min_size;
    let t = need.t && r.height() >= 2.0 * min_size;
    match (s, t) {
        (false, false) => None,
        (true, true) => Some(SplitDir::Quad),
        (true, false) => Some(aspect_capped(r, SplitDir::S, min_size)),
        (false, true) => Some(aspect_capped(r, SplitDir::T, min_size)),
    }
}

/// `dir`, or a 4-split when the 2-split's children would exceed [`MAX_ASPECT`] and the other
/// side is at least `2·min_size`.
pub(crate) fn aspect_capped(r: &Rect, dir: SplitDir, min_size: f64) -> SplitDir {
    let (w, h) = (r.width(), r.height());
    match dir {
        SplitDir::S if h > MAX_ASPECT * 0.5 * w && h >= 2.0 * min_size => SplitDir::Quad,
        SplitDir::T if w > MAX_ASPECT * 0.5 * h && w >= 2.0 * min_size => SplitDir::Quad,
        d => d,
    }
}

/// The leaves' sides grouped by the line they lie on: for each [`Side`] `d`, the leaves whose
/// side opposite to `d` lies on a line, so that a leaf's neighbours towards `d` are the entries
/// of `d` on the line of its own `d` side that overlap it (leaves do not overlap, so those
/// form one run of the entries sorted along the line).
struct SideIndex {
    /// Per side: (line coordinate, start along the line, end along the line, rect), sorted by
    /// line then start; line coordinates with -0.0 made +0.0 (one line, as for the R-tree).
    by_side: [Vec<(f64, f64, f64, Rect)>; 4],
}

impl SideIndex {
    fn new(mesh: &TMesh) -> SideIndex {
        let mut by_side: [Vec<(f64, f64, f64, Rect)>; 4] = Default::default();
        for c in mesh.cells.iter().filter(|c| c.is_leaf()) {
            let r = c.rect;
            // a leaf is the West neighbour of leaves whose s_min is its s_max, ...
            by_side[Side::West as usize].push((r.s_max + 0.0, r.t_min, r.t_max, r));
            by_side[Side::East as usize].push((r.s_min + 0.0, r.t_min, r.t_max, r));
            by_side[Side::South as usize].push((r.t_max + 0.0, r.s_min, r.s_max, r));
            by_side[Side::North as usize].push((r.t_min + 0.0, r.s_min, r.s_max, r));
        }
        // (line, start) is unique per side (leaves do not overlap): any sort gives one order
        use rayon::prelude::*;
        by_side.par_iter_mut().for_each(|v| v.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1))));
        SideIndex { by_side }
    }

    /// The leaf neighbours of `r` (sharing a side segment of positive length), as
    /// [`TMesh::neighbours`] finds them.
    fn neighbours<'a>(&'a self, r: &Rect) -> impl Iterator<Item = (Side, Rect)> + 'a {
        let probes = [
            (Side::West, r.s_min, r.t_min, r.t_max),
            (Side::East, r.s_max, r.t_min, r.t_max),
            (Side::South, r.t_min, r.s_min, r.s_max),
            (Side::North, r.t_max, r.s_min, r.s_max),
        ];
        probes.into_iter().flat_map(move |(side, line, lo, hi)| {
            let v = &self.by_side[side as usize];
            let line = line + 0.0;
            // entries on this line ending after `lo`: from the first one starting at or after
            // `lo`, stepped back by one (the run's first may start before `lo`)
            let first = v.partition_point(|e| e.0.total_cmp(&line).then(e.1.total_cmp(&lo)).is_lt());
            let first = if first > 0 && v[first - 1].0 == line && v[first - 1].2 > lo { first - 1 } else { first };
            v[first..]
                .iter()
                .take_while(move |e| e.0 == line && e.1 < hi)
                .filter(move |e| e.2 > lo)
                .map(move |e| (side, e.3))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Thesis Tables 5.1/5.3: 8 points, cells Z1, Z2, Z3 (P4 is a T-junction on Z3's top edge).
    pub(crate) fn thesis_mesh(degree: Degree) -> TMesh {
        let st = [(0., 2.), (1., 2.), (2., 2.), (0., 1.), (1., 1.), (2., 1.), (0., 0.), (2., 0.)];
        let points = st.iter().map(|&(s, t)| ControlPoint { s, t, x: s, y: t, z: 0.0, w: 1.0 }).collect();
        TMesh::from_cells(degree, points, vec![[0, 1, 3, 4], [1, 2, 4, 5], [3, 5, 6, 7]]).unwrap()
    }

    #[test]
    fn table_5_3_cells_and_queries() {
        let m = thesis_mesh(Degree::Linear);
        // Table 5.3 rectangles (A20: Z2 is (1,1)-(2,2), the thesis prints (1,1)-(2,1)).
        assert_eq!(m.cells[0].rect, Rect::new(0., 1., 1., 2.));
        assert_eq!(m.cells[1].rect, Rect::new(1., 1., 2., 2.));
        assert_eq!(m.cells[2].rect, Rect::new(0., 0., 2., 1.));
        assert_eq!(m.bounds(), Rect::new(0., 0., 2., 2.));
        assert_eq!(m.cells_at(1.0, 1.0), vec![0, 1, 2]);
        assert_eq!(m.cells_at(1.5, 0.5), vec![2]);
        assert!(m.contains(2.0, 2.0) && !m.contains(2.0001, 1.0));
        assert_eq!(m.neighbours(2), vec![(Side::North, 0), (Side::North, 1)]);
        assert_eq!(m.neighbours(0), vec![(Side::East, 1), (Side::South, 2)]);
        assert_eq!(m.leaves_in(Rect::new(1.2, 1.2, 1.3, 1.3)), vec![1]);
    }

    #[test]
    fn rejects_broken_meshes() {
        let p = |s, t| ControlPoint { s, t, x: s, y: t, z: 0.0, w: 1.0 };
        // not a rectangle
        let e = TMesh::from_cells(Degree::Linear, vec![p(0., 1.), p(1., 1.), p(0., 0.), p(2., 0.)], vec![[0, 1, 2, 3]]);
        assert!(e.is_err());
        // overlapping cells
        let pts = vec![p(0., 1.), p(1., 1.), p(0., 0.), p(1., 0.), p(0.5, 1.), p(1.5, 1.), p(0.5, 0.), p(1.5, 0.)];
        assert!(TMesh::from_cells(Degree::Linear, pts, vec![[0, 1, 2, 3], [4, 5, 6, 7]]).is_err());
        // bad index
        assert!(TMesh::from_cells(Degree::Linear, vec![p(0., 0.)], vec![[0, 1, 2, 3]]).is_err());
    }

    #[test]
    fn split_shares_points_and_keeps_parent() {
        let mut m = TMesh::grid(Degree::Linear, 0.0, 0.0, 4.0, 2, 1);
        let n0 = m.points.len();
        let mut g = |s: f64, t: f64| (s, t, 0.0);
        m.split(0, &mut g);
        assert_eq!(m.points.len(), n0 + 5);
        m.split(1, &mut g);
        // the shared edge mid-point (4, 2) is reused: only 4 new points
        assert_eq!(m.points.len(), n0 + 9);
        assert_eq!(m.leaf_count(), 8);
        // parents stay in the cell list (history), point queries find the leaves only
        assert!(m.cells[0].children.is_some());
        assert!(!m.cells_at(1.0, 1.0).contains(&0));
        assert!(m.cells_at(1.0, 1.0).iter().all(|&c| m.cells[c as usize].is_leaf()));
        m.coarsen(0).unwrap();
        assert_eq!(m.leaf_count(), 5);
        assert!(m.cells[0].is_leaf());
        assert_eq!(m.cells_at(1.0, 1.0), vec![0]);
    }

    #[test]
    fn repair_enforces_balance_and_rule_2() {
        let mut m = TMesh::grid(Degree::Linear, 0.0, 0.0, 8.0, 3, 1);
        let mut g = |s: f64, t: f64| (s, t, 0.0);
        let kids = m.split(0, &mut g);
        m.split(kids[1], &mut g); // a size-2 cell next to the size-8 cell 1 → 1:4
        m.repair(1.0, &mut g);
        for c in m.leaves().collect::<Vec<_>>() {
            assert!(!m.needs_repair(c), "cell {c} still violates the rules");
        }
        // cell 1 (size 8) must have been split
        assert!(!m.cells[1].is_leaf());
    }

    #[test]
    fn merge_two_meshes_with_a_seam() {
        let a = TMesh::grid(Degree::Linear, 0.0, 0.0, 1.0, 2, 2);
        let b = TMesh::grid(Degree::Linear, 2.0, 0.0, 1.0, 2, 2);
        let m = a.merge(&b).unwrap();
        assert_eq!(m.leaf_count(), 8);
        assert_eq!(m.points.len(), 15);
        // overlapping meshes are refused
        let c = TMesh::grid(Degree::Linear, 1.0, 0.0, 1.0, 2, 2);
        assert!(a.merge(&c).is_err());
    }
    /// The repair loop as it was before the batched first round (every check an R-tree
    /// neighbour query): the oracle of [`TMesh::repair`].
    fn repair_one_by_one(m: &mut TMesh, min_size: f64, geom: &mut dyn FnMut(f64, f64) -> (f64, f64, f64)) -> usize {
        let mut splits = 0;
        let mut todo: Vec<CellId> = m.leaves().collect();
        while !todo.is_empty() {
            let mut next = Vec::new();
            todo.sort_unstable();
            todo.dedup();
            for c in todo {
                if !m.cells[c as usize].is_leaf() {
                    continue;
                }
                let r = m.cells[c as usize].rect;
                if r.width().min(r.height()) < 2.0 * min_size || !m.needs_repair(c) {
                    continue;
                }
                let nbrs: Vec<CellId> = m.neighbours(c).into_iter().map(|(_, n)| n).collect();
                let kids = m.split(c, geom);
                splits += 1;
                next.extend(nbrs);
                next.extend(kids);
            }
            todo = next;
        }
        splits
    }

    /// The side index gives every leaf the neighbours that the R-tree query gives.
    fn assert_side_index_finds_neighbours(m: &TMesh) {
        let sides = SideIndex::new(m);
        let key = |(side, r): (Side, Rect)| {
            (side as u8, r.s_min.to_bits(), r.t_min.to_bits(), r.s_max.to_bits(), r.t_max.to_bits())
        };
        for c in m.leaves() {
            let mut got: Vec<_> = sides.neighbours(&m.cells[c as usize].rect).map(key).collect();
            let mut want: Vec<_> =
                m.neighbours(c).into_iter().map(|(side, n)| key((side, m.cells[n as usize].rect))).collect();
            got.sort_unstable();
            want.sort_unstable();
            assert_eq!(got, want, "cell {c}");
        }
    }

    #[test]
    fn side_index_on_a_mesh_with_a_long_cell() {
        // the thesis mesh: Z3 is the south neighbour of Z2 and starts before it (step back)
        assert_side_index_finds_neighbours(&thesis_mesh(Degree::Linear));
    }

    /// Random unrepaired refinements (1:4 and rule-2 violations, coarsened parents, a merged
    /// mesh with a gap): the batched checks equal the per-leaf ones, and the repair makes the
    /// same splits in the same order as the one-by-one loop (same points, same cells).
    #[test]
    fn batched_repair_equals_one_by_one() {
        let mut seed = 23u64;
        let mut rnd = move || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let base = TMesh::grid(Degree::Cubic, -16.0, 0.0, 16.0, 5, 4)
            .merge(&TMesh::grid(Degree::Cubic, 96.0, 16.0, 16.0, 2, 2))
            .unwrap();
        let mut g = |s: f64, t: f64| (s, t, s * t);
        let mut checked = 0;
        for trial in 0..6 {
            let mut m = base.clone();
            for _ in 0..4 {
                for c in m.leaves().collect::<Vec<_>>() {
                    if rnd() < 0.25 && m.cells[c as usize].rect.width() >= 2.0 {
                        m.split(c, &mut g);
                    }
                }
                if trial % 2 == 1 {
                    let parents: Vec<CellId> = m.leaves().filter_map(|c| m.cells[c as usize].parent).collect();
                    if let Some(&p) = parents.get(parents.len() / 2) {
                        m.coarsen(p).unwrap();
                    }
                }
            }
            assert_side_index_finds_neighbours(&m);
            let batch = m.leaves_needing_repair();
            for c in m.leaves() {
                assert_eq!(batch[c as usize], m.repair_need(c), "trial {trial}, cell {c}");
                checked += usize::from(batch[c as usize].any());
            }
            let mut want = m.clone();
            let n_want = repair_one_by_one(&mut want, 1.0, &mut g);
            let n_got = m.repair(1.0, &mut g);
            assert_eq!(n_got, n_want, "trial {trial}");
            assert!(n_want > 0);
            assert_eq!(m.points, want.points, "trial {trial}");
            let cells = |m: &TMesh| {
                m.cells.iter().map(|c| (c.corners, c.rect, c.parent, c.children, c.alive)).collect::<Vec<_>>()
            };
            assert_eq!(cells(&m), cells(&want), "trial {trial}");
        }
        assert!(checked > 10, "the meshes had leaves to repair");
    }

    /// A 2-split makes two rectangles and the two mid-points of the sides its cut crosses,
    /// shared with the neighbour that already has one; a later split back after coarsening
    /// reuses the recorded direction.
    #[test]
    fn two_splits_make_rectangles() {
        let mut m = TMesh::grid(Degree::Cubic, 0.0, 0.0, 4.0, 2, 1);
        let mut g = |s: f64, t: f64| (s, t, 0.0);
        let n0 = m.points.len();
        let k = m.split_dir(0, SplitDir::T, &mut g);
        assert_eq!(k.as_slice().len(), 2);
        assert_eq!(m.cells[k.as_slice()[0] as usize].rect, Rect::new(0.0, 0.0, 4.0, 2.0));
        assert_eq!(m.cells[k.as_slice()[1] as usize].rect, Rect::new(0.0, 2.0, 4.0, 4.0));
        assert_eq!(m.points.len(), n0 + 2); // (0, 2) and (4, 2)
                                            // the east cell across s: (6, 0) and (6, 4) are new, (4, 2) is a hanging vertex of it
        let k2 = m.split_dir(1, SplitDir::S, &mut g);
        assert_eq!(m.points.len(), n0 + 4);
        assert_eq!(m.cells[k2.as_slice()[0] as usize].rect, Rect::new(4.0, 0.0, 6.0, 4.0));
        assert_eq!(m.leaf_count(), 4);
        // every leaf has its four corners at its rectangle's corners
        for c in m.leaves() {
            let cell = &m.cells[c as usize];
            let r = cell.rect;
            let want = [(r.s_min, r.t_max), (r.s_max, r.t_max), (r.s_min, r.t_min), (r.s_max, r.t_min)];
            for (p, w) in cell.corners.iter().zip(want) {
                assert_eq!((m.points[*p as usize].s, m.points[*p as usize].t), w);
            }
        }
        // the written form round-trips (from_cells accepts it: no overlaps, no I-points)
        let c = m.compacted();
        assert_eq!(c.leaf_count(), 4);
        m.coarsen(0).unwrap();
        assert_eq!(m.cells[0].split_as, SplitDir::T);
        assert_eq!(m.leaf_count(), 3);
        // the merged west cell is as high as the east halves: balanced
        assert!(m.leaves().all(|c| !m.needs_repair(c)));
    }

    /// The anisotropic repair on random 2- and 4-split meshes: afterwards no leaf has a
    /// neighbour more than twice as fine along a shared side, none has hanging vertices on two
    /// opposite sides, and no cell is longer than MAX_ASPECT times its width (or vice versa).
    #[test]
    fn aniso_repair_keeps_balance_and_rule_2_on_rectangles() {
        for seed in [1u64, 2, 3, 4] {
            let m = crate::testing::aniso_mesh(Degree::Cubic, seed, 4);
            let mut two = 0;
            for c in m.leaves() {
                let r = m.cells[c as usize].rect;
                let need = m.repair_need(c);
                // a side at the minimum (1: children would undercut the sample spacing) may keep its need
                assert!(
                    !((need.s && r.width() >= 2.0) || (need.t && r.height() >= 2.0)),
                    "seed {seed}: cell {c} {r:?} still needs {need:?}"
                );
                assert!(
                    r.width() <= MAX_ASPECT * r.height() && r.height() <= MAX_ASPECT * r.width(),
                    "seed {seed}: {r:?}"
                );
                two += usize::from(r.width() != r.height());
            }
            assert!(two > 10, "seed {seed}: the mesh has rectangles ({two})");
            // the written form is a valid T-mesh
            m.compacted();
        }
    }

    /// Quad meshes: the per-direction need is the old single verdict (either direction).
    #[test]
    fn quad_repair_is_unchanged_by_the_directional_need() {
        let mut m = TMesh::grid(Degree::Linear, 0.0, 0.0, 8.0, 3, 1);
        let mut g = |s: f64, t: f64| (s, t, 0.0);
        let kids = m.split(0, &mut g);
        m.split(kids[1], &mut g);
        // cell 1 (8 wide) has a west neighbour of height 2: t must be halved, not s
        assert_eq!(m.repair_need(1), RepairNeed { s: false, t: true });
        assert!(m.needs_repair(1));
    }
}
