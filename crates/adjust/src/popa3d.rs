//! Adjustment of a popa3d model: the parameter net (spec §6.2) that maps the document's
//! observations and conditions onto the generic engine, the datum choices (spec §4.7), and the
//! report (spec §6.1 statistics, Tables 7.2/7.3, §7.6 "not yet measured").
//!
//! Unknowns are the stored geometry values (plane d, normal parameters) plus the set-up unknowns
//! (fixed-point translation, set-up quaternion). Every plane enters equations as its signed normal
//! `plane.sign · (s_x p_a, s_y p_b, s_z p_c)` and its d, so shared parameters and shared normals
//! resolve to the same unknowns and their derivatives sum.
//!
//! Incremental work (spec P20): the adjusted values are written back into the model, so the next
//! run (after `geofit observe` added measurements) starts from the last solution.

use crate::equations::*;
use crate::problem::{Identity, Problem, Slot, UnknownId};
use crate::solve::{adjust, Datum, Options, Solution};
use crate::{AdjustError, Equation, Scalar};
use popa3d_model::{self as pm, Incidence, ObsKind, ObsOrigin, Popa3d};
use serde::Serialize;
use std::collections::BTreeMap;

/// Which datum to use (spec §4.7).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DatumChoice {
    /// Inner constraints over the object geometry (plane d's and normal parameters).
    Free,
    /// Identity observations on every object unknown that has none yet.
    Soft,
    /// Fix a minimal set of object unknowns (chosen automatically: d's first, then parameters).
    Hard,
}

/// Options of [`adjust_model`].
#[derive(Clone, Debug)]
pub struct ModelOptions {
    pub datum: DatumChoice,
    /// σ of added soft-datum identity observations of plane distances (m).
    pub soft_sigma_d: f64,
    /// σ of added soft-datum identity observations of normal parameters.
    pub soft_sigma_param: f64,
    /// Recompute every set-up's starting values by the grid search (spec §4.4, P11).
    pub polar_start: bool,
    pub engine: Options,
}

impl Default for ModelOptions {
    fn default() -> Self {
        ModelOptions { datum: DatumChoice::Free, soft_sigma_d: 1.0, soft_sigma_param: 0.01, polar_start: false, engine: Options::default() }
    }
}

/// Errors of the popa3d mapping.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    #[error("{element}: {message}")]
    Reference { element: String, message: String },
    #[error(transparent)]
    Adjust(#[from] AdjustError),
}

/// One observation (stochastic input) in the report.
#[derive(Clone, Debug, Serialize)]
pub struct ObsReport {
    /// The popa3d observation id.
    pub observation: u32,
    /// Table B.1 class.
    pub class: String,
    pub origin: String,
    pub label: Option<String>,
    /// Component for polar pointings (`Hz`, `V`, `s`), else empty.
    pub component: String,
    pub value: f64,
    pub sigma: f64,
    pub v: f64,
    pub redundancy: f64,
    pub normalised: f64,
    pub controllable: bool,
    pub rejected: bool,
}

/// Per-type statistics (spec Tables 7.2 and 7.3).
#[derive(Clone, Debug, Serialize, Default)]
pub struct TypeStats {
    pub count: usize,
    pub max_misclosure_before: f64,
    pub max_abs_residual: f64,
    pub mean_redundancy: f64,
}

/// The adjustment report.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub datum: String,
    pub unknowns: usize,
    pub conditions: usize,
    pub restrictions: usize,
    pub datum_restrictions: usize,
    pub redundancy: usize,
    pub redundancy_sum: f64,
    pub iterations: usize,
    pub components: usize,
    pub vtpv: f64,
    pub sigma0: Option<f64>,
    pub global_test: Option<crate::GlobalTest>,
    pub critical_w: f64,
    pub largest_suspect: Option<ObsReport>,
    /// Sketch priors with a redundancy number below the controllability threshold: they still
    /// control the geometry, i.e. these parts are not yet measured (spec §7.6, Fig. 7.13).
    pub not_yet_measured: Vec<ObsReport>,
    pub per_type: BTreeMap<String, TypeStats>,
    /// Sorted by normalised residual, largest first.
    pub observations: Vec<ObsReport>,
    /// Largest change of a plane distance (m) by this adjustment.
    pub max_plane_shift: f64,
}

struct Net<'a> {
    m: &'a Popa3d,
    inc: Incidence,
    pd: Vec<UnknownId>,
    par: Vec<UnknownId>,
    fp: Vec<[UnknownId; 3]>,
    sq: Vec<[UnknownId; 4]>,
}

impl<'a> Net<'a> {
    fn normal_slots(&self, n: pm::NormalId, sign: f64) -> Vec<Slot> {
        self.m.normal(n).comps.iter().map(|(p, s)| Slot { unknown: self.par[p.idx()], sign: sign * s.f64() }).collect()
    }
    fn plane_normal(&self, p: pm::PlaneId) -> Vec<Slot> {
        let pl = self.m.plane(p);
        self.normal_slots(pl.normal, pl.sign.f64())
    }
    fn plane_slots(&self, p: pm::PlaneId) -> Vec<Slot> {
        let mut s = self.plane_normal(p);
        s.push(self.pd[p.idx()].into());
        s
    }
    fn check<T>(&self, what: &str, id: usize, len: usize, el: &str) -> Result<(), ModelError> {
        if id >= len {
            return Err(ModelError::Reference { element: el.to_string(), message: format!("references {what} {id}, which does not exist") });
        }
        Ok(())
    }
    fn face_plane(&self, f: pm::FaceId, el: &str) -> Result<pm::PlaneId, ModelError> {
        self.check::<()>("face", f.idx(), self.m.faces.len(), el)?;
        let p = self.m.face(f).plane;
        self.check::<()>("plane", p.idx(), self.m.planes.len(), el)?;
        Ok(p)
    }
    fn edge_planes(&self, e: pm::EdgeId, el: &str) -> Result<[pm::PlaneId; 2], ModelError> {
        self.check::<()>("edge", e.idx(), self.m.edges.len(), el)?;
        self.m.edge_planes(&self.inc, e).map_err(|err| ModelError::Reference { element: el.to_string(), message: err.to_string() })
    }
    fn node_planes(&self, n: pm::NodeId, el: &str) -> Result<[pm::PlaneId; 3], ModelError> {
        self.check::<()>("node", n.idx(), self.m.nodes.len(), el)?;
        self.m.node_plane_triple(&self.inc, n).map_err(|err| ModelError::Reference { element: el.to_string(), message: err.to_string() })
    }
    fn setup_slots(&self, s: pm::SetupId, el: &str) -> Result<Vec<Slot>, ModelError> {
        self.check::<()>("setup", s.idx(), self.m.setups.len(), el)?;
        let fpi = self.m.setups[s.idx()].fixed_point.idx();
        self.check::<()>("fixed point", fpi, self.m.fixed_points.len(), el)?;
        Ok(self.sq[s.idx()].iter().chain(self.fp[fpi].iter()).map(|&u| u.into()).collect())
    }
    fn unknown(&self, u: &pm::Unknown, el: &str) -> Result<UnknownId, ModelError> {
        Ok(match *u {
            pm::Unknown::PlaneD(p) => {
                self.check::<()>("plane", p.idx(), self.pd.len(), el)?;
                self.pd[p.idx()]
            }
            pm::Unknown::Param(p) => {
                self.check::<()>("parameter", p.idx(), self.par.len(), el)?;
                self.par[p.idx()]
            }
            pm::Unknown::Translation(f, k) => {
                self.check::<()>("fixed point", f.idx(), self.fp.len(), el)?;
                self.check::<()>("translation component", k as usize, 3, el)?;
                self.fp[f.idx()][k as usize]
            }
            pm::Unknown::Rotation(s, k) => {
                self.check::<()>("setup", s.idx(), self.sq.len(), el)?;
                self.check::<()>("quaternion component", k as usize, 4, el)?;
                self.sq[s.idx()][k as usize]
            }
        })
    }
}

/// `x − c = 0` (ParameterFix, spec Table B.1).
struct FixTo(f64);
impl Equation for FixTo {
    fn kind(&self) -> &str {
        "ParameterFix"
    }
    fn eval<D: Scalar>(&self, x: &[D], _l: &[D]) -> D {
        x[0] - self.0
    }
}

/// What each engine observation is in the popa3d document.
#[derive(Clone)]
struct ObsOrigin2 {
    obs: usize,
    component: &'static str,
}

/// The engine problem built from a model, with the bookkeeping to write results back.
pub struct Mapped {
    pub problem: Problem,
    pub object_unknowns: Vec<UnknownId>,
    origins: Vec<ObsOrigin2>,
    cond_obs: Vec<usize>,
    plane_d: Vec<UnknownId>,
    params: Vec<UnknownId>,
    fixed: Vec<[UnknownId; 3]>,
    setups: Vec<[UnknownId; 4]>,
}

/// Build the engine problem of a model (spec §6.2 parameter net).
pub fn map_model(m: &Popa3d) -> Result<Mapped, ModelError> {
    let mut p = Problem::new();
    let pd: Vec<UnknownId> = m.planes.iter().enumerate().map(|(i, pl)| p.add_unknown(format!("plane {i} d"), pl.d)).collect();
    let par: Vec<UnknownId> = m.parameters.iter().enumerate().map(|(i, q)| p.add_unknown(format!("parameter {i}"), q.value)).collect();
    let fp: Vec<[UnknownId; 3]> = m.fixed_points.iter().enumerate().map(|(i, f)| [0, 1, 2].map(|k| p.add_unknown(format!("fixedpoint {i} t{}", ["x", "y", "z"][k]), f.t[k]))).collect();
    let sq: Vec<[UnknownId; 4]> = m.setups.iter().enumerate().map(|(i, s)| [0, 1, 2, 3].map(|k| p.add_unknown(format!("setup {i} q{k}"), s.q[k]))).collect();
    for (i, pl) in m.planes.iter().enumerate() {
        if pl.normal.idx() >= m.normals.len() {
            return Err(ModelError::Reference { element: format!("plane {i}"), message: format!("references normal {}, which does not exist", pl.normal.0) });
        }
    }
    for (i, n) in m.normals.iter().enumerate() {
        for (q, _) in &n.comps {
            if q.idx() >= m.parameters.len() {
                return Err(ModelError::Reference { element: format!("normal {i}"), message: format!("references parameter {}, which does not exist", q.0) });
            }
        }
    }
    let net = Net { m, inc: Incidence::new(m), pd: pd.clone(), par: par.clone(), fp: fp.clone(), sq: sq.clone() };
    let object_unknowns: Vec<UnknownId> = pd.iter().chain(par.iter()).copied().collect();
    let mut origins: Vec<ObsOrigin2> = Vec::new();
    let mut cond_obs: Vec<usize> = Vec::new();
    let add_obs = |p: &mut Problem, origins: &mut Vec<ObsOrigin2>, el: &str, i: usize, comp: &'static str, v: f64, s: f64| -> Result<crate::ObsId, ModelError> {
        let o = p.add_observation(format!("{el}{}", if comp.is_empty() { String::new() } else { format!(" {comp}") }), v, s)?;
        origins.push(ObsOrigin2 { obs: i, component: comp });
        Ok(o)
    };
    for (i, ob) in m.observations.iter().enumerate() {
        let el = format!("observation {i} ({})", ob.kind.class_name());
        let el = el.as_str();
        let before = p.condition_count();
        match &ob.kind {
            ObsKind::DistanceFaceFace { a, b, l } => {
                let (pa, pb) = (net.face_plane(*a, el)?, net.face_plane(*b, el)?);
                let o = add_obs(&mut p, &mut origins, el, i, "", l.value, l.sigma)?;
                p.add_condition(el, DistanceFaceFace, [net.plane_slots(pa), net.plane_slots(pb)].concat(), vec![o])?;
            }
            ObsKind::DistanceFaceEdge { a, b, l } => {
                let pa = net.face_plane(*a, el)?;
                let [j, k] = net.edge_planes(*b, el)?;
                let o = add_obs(&mut p, &mut origins, el, i, "", l.value, l.sigma)?;
                p.add_condition(el, DistanceFaceEdge, [net.plane_slots(pa), net.plane_slots(j), net.plane_slots(k)].concat(), vec![o])?;
            }
            ObsKind::DistanceFaceNode { a, b, l } => {
                let pa = net.face_plane(*a, el)?;
                let t = net.node_planes(*b, el)?;
                let o = add_obs(&mut p, &mut origins, el, i, "", l.value, l.sigma)?;
                let x = [net.plane_slots(pa), net.plane_slots(t[0]), net.plane_slots(t[1]), net.plane_slots(t[2])].concat();
                p.add_condition(el, DistanceFaceNode, x, vec![o])?;
            }
            ObsKind::DistanceEdgeEdge { a, b, l } => {
                let (e1, e2) = (net.edge_planes(*a, el)?, net.edge_planes(*b, el)?);
                let o = add_obs(&mut p, &mut origins, el, i, "", l.value, l.sigma)?;
                let x = [e1, e2].iter().flat_map(|e| e.iter().flat_map(|&q| net.plane_slots(q))).collect();
                p.add_condition(el, DistanceEdgeEdge, x, vec![o])?;
            }
            ObsKind::DistanceEdgeNode { a, b, l } => {
                let e = net.edge_planes(*a, el)?;
                let t = net.node_planes(*b, el)?;
                let o = add_obs(&mut p, &mut origins, el, i, "", l.value, l.sigma)?;
                let x = e.iter().chain(t.iter()).flat_map(|&q| net.plane_slots(q)).collect();
                p.add_condition(el, DistanceEdgeNode, x, vec![o])?;
            }
            ObsKind::DistanceNodeNode { a, b, l } => {
                let (t1, t2) = (net.node_planes(*a, el)?, net.node_planes(*b, el)?);
                let o = add_obs(&mut p, &mut origins, el, i, "", l.value, l.sigma)?;
                let x = t1.iter().chain(t2.iter()).flat_map(|&q| net.plane_slots(q)).collect();
                p.add_condition(el, DistanceNodeNode, x, vec![o])?;
            }
            ObsKind::PointOnFace { setup, hz, v, s, .. } | ObsKind::PointOnEdge { setup, hz, v, s, .. } | ObsKind::PointOnNode { setup, hz, v, s, .. } => {
                let planes: Vec<pm::PlaneId> = match &ob.kind {
                    ObsKind::PointOnFace { target, .. } => vec![net.face_plane(*target, el)?],
                    ObsKind::PointOnEdge { target, .. } => net.edge_planes(*target, el)?.to_vec(),
                    ObsKind::PointOnNode { target, .. } => net.node_planes(*target, el)?.to_vec(),
                    _ => unreachable!(),
                };
                let ss = net.setup_slots(*setup, el)?;
                let ih = m.setups[setup.idx()].instrument_height;
                let ohz = add_obs(&mut p, &mut origins, el, i, "Hz", hz.value, hz.sigma)?;
                let ov = add_obs(&mut p, &mut origins, el, i, "V", v.value, v.sigma)?;
                let os = add_obs(&mut p, &mut origins, el, i, "s", s.value, s.sigma)?;
                let class: &'static str = ob.kind.class_name();
                for q in planes {
                    p.add_condition(el, PointOnPlanePolar { ih, class }, [ss.clone(), net.plane_slots(q)].concat(), vec![ohz, ov, os])?;
                }
            }
            ObsKind::ConstraintFaceFace { a, b, l } => {
                let (pa, pb) = (net.face_plane(*a, el)?, net.face_plane(*b, el)?);
                let o = add_obs(&mut p, &mut origins, el, i, "", l.value, l.sigma)?;
                p.add_condition(el, ConstraintFaceFace, [net.plane_normal(pa), net.plane_normal(pb)].concat(), vec![o])?;
            }
            ObsKind::ConstraintFaceEdge { a, b, l } => {
                let pa = net.face_plane(*a, el)?;
                let [j, k] = net.edge_planes(*b, el)?;
                let o = add_obs(&mut p, &mut origins, el, i, "", l.value, l.sigma)?;
                p.add_condition(el, ConstraintFaceEdge, [net.plane_normal(pa), net.plane_normal(j), net.plane_normal(k)].concat(), vec![o])?;
            }
            ObsKind::ConstraintEdgeEdge { a, b, l } => {
                let (e1, e2) = (net.edge_planes(*a, el)?, net.edge_planes(*b, el)?);
                let o = add_obs(&mut p, &mut origins, el, i, "", l.value, l.sigma)?;
                let x = e1.iter().chain(e2.iter()).flat_map(|&q| net.plane_normal(q)).collect();
                p.add_condition(el, ConstraintEdgeEdge, x, vec![o])?;
            }
            ObsKind::RelativeDistancePlanePlane { lower, upper, l } => {
                for q in [lower, upper] {
                    net.check::<()>("plane", q.idx(), m.planes.len(), el)?;
                }
                let o = add_obs(&mut p, &mut origins, el, i, "", l.value, l.sigma)?;
                // d' = sign·d along the normal object's own direction (popa3d-model convention).
                let x = vec![Slot { unknown: pd[lower.idx()], sign: m.plane(*lower).sign.f64() }, Slot { unknown: pd[upper.idx()], sign: m.plane(*upper).sign.f64() }];
                p.add_condition(el, RelativeDistancePlanePlane, x, vec![o])?;
            }
            ObsKind::RelativeAngleNormalNormal { a, b, l } => {
                for q in [a, b] {
                    net.check::<()>("normal", q.idx(), m.normals.len(), el)?;
                }
                let o = add_obs(&mut p, &mut origins, el, i, "", l.value, l.sigma)?;
                p.add_condition(el, RelativeAngleNormalNormal, [net.normal_slots(*a, 1.0), net.normal_slots(*b, 1.0)].concat(), vec![o])?;
            }
            ObsKind::NormNV { normal, sigma } => {
                net.check::<()>("normal", normal.idx(), m.normals.len(), el)?;
                let x = net.normal_slots(*normal, 1.0);
                match sigma {
                    Some(s) => {
                        let o = add_obs(&mut p, &mut origins, el, i, "", 1.0, *s)?;
                        p.add_condition(el, NormNvObs, x, vec![o])?;
                    }
                    None => {
                        p.add_restriction(el, NormNvRestriction, x)?;
                    }
                }
            }
            ObsKind::NormQ { setup } => {
                net.check::<()>("setup", setup.idx(), m.setups.len(), el)?;
                p.add_restriction(el, NormQ, sq[setup.idx()].iter().map(|&u| u.into()).collect())?;
            }
            ObsKind::ParameterFix { unknown, value } => {
                let u = net.unknown(unknown, el)?;
                p.add_restriction(el, FixTo(*value), vec![u.into()])?;
            }
            ObsKind::ParameterObs { unknown, l } => {
                let u = net.unknown(unknown, el)?;
                let o = add_obs(&mut p, &mut origins, el, i, "", l.value, l.sigma)?;
                p.add_condition(el, Identity, vec![u.into()], vec![o])?;
            }
        }
        for _ in before..p.condition_count() {
            cond_obs.push(i);
        }
    }
    // Levelled instruments: q1 = q2 = 0 (T 3.37, spec P3/P8).
    for (i, s) in m.setups.iter().enumerate() {
        if s.levelled {
            for k in [1usize, 2] {
                p.add_restriction(format!("setup {i} levelled (q{k} = 0)"), Levelled, vec![sq[i][k].into()])?;
            }
        }
    }
    Ok(Mapped { problem: p, object_unknowns, origins, cond_obs, plane_d: pd, params: par, fixed: fp, setups: sq })
}

/// Starting values of every set-up by the spec's grid search (§4.4, P11) over its face pointings
/// (edge/node pointings contribute all their planes), with the planes' current values held fixed.
/// With `all == false` only set-ups whose quaternion is not a unit quaternion are searched.
pub fn polar_starting_values(m: &mut Popa3d, all: bool) {
    let inc = Incidence::new(m);
    for si in 0..m.setups.len() {
        if !all && (m.setups[si].q.iter().map(|v| v * v).sum::<f64>() - 1.0).abs() <= 1e-6 {
            continue;
        }
        let mut pts = Vec::new();
        for ob in &m.observations {
            let (setup, planes, hz, v, s) = match &ob.kind {
                ObsKind::PointOnFace { setup, target, hz, v, s } => (setup, vec![m.face(*target).plane], hz, v, s),
                ObsKind::PointOnEdge { setup, target, hz, v, s } => match m.edge_planes(&inc, *target) {
                    Ok(p) => (setup, p.to_vec(), hz, v, s),
                    Err(_) => continue,
                },
                ObsKind::PointOnNode { setup, target, hz, v, s } => match m.node_plane_triple(&inc, *target) {
                    Ok(p) => (setup, p.to_vec(), hz, v, s),
                    Err(_) => continue,
                },
                _ => continue,
            };
            if setup.idx() != si {
                continue;
            }
            let planes = planes
                .into_iter()
                .map(|q| {
                    let pv = m.plane_value(q);
                    let n = pv.n;
                    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                    ([n[0] / len, n[1] / len, n[2] / len], pv.d / len)
                })
                .collect();
            pts.push(Pointing { hz_gon: hz.value, v_gon: v.value, s: s.value, planes });
        }
        if pts.is_empty() {
            continue;
        }
        let ih = m.setups[si].instrument_height;
        if let Some((q, t, _)) = polar_start(&pts, ih) {
            m.setups[si].q = q;
            let fp = m.setups[si].fixed_point.idx();
            if fp < m.fixed_points.len() {
                m.fixed_points[fp].t = t;
            }
        }
    }
}

/// Adjust a model in place: write the estimated unknowns back and return the report.
pub fn adjust_model(m: &mut Popa3d, opts: &ModelOptions) -> Result<Report, ModelError> {
    // Set-ups without a valid rotation yet (a fresh sketch, or a set-up just added by `observe`)
    // get the spec's grid-search starting values (P11); the others start from the last solution.
    if m.setups.iter().any(|s| (s.q.iter().map(|v| v * v).sum::<f64>() - 1.0).abs() > 1e-6) || opts.polar_start {
        polar_starting_values(m, opts.polar_start);
    }
    let mut mapped = map_model(m)?;
    let misclosures = mapped.problem.misclosures();
    let mut eng = opts.engine.clone();
    let datum_name = match opts.datum {
        DatumChoice::Free => {
            eng.datum = Datum::Free { subset: mapped.object_unknowns.clone() };
            "free"
        }
        DatumChoice::Soft => {
            let mut has = vec![false; mapped.problem.unknown_count()];
            for ob in &m.observations {
                if let ObsKind::ParameterObs { unknown, .. } = &ob.kind {
                    let u = match *unknown {
                        pm::Unknown::PlaneD(p) => mapped.plane_d.get(p.idx()).copied(),
                        pm::Unknown::Param(p) => mapped.params.get(p.idx()).copied(),
                        _ => None,
                    };
                    if let Some(u) = u {
                        has[u.0] = true;
                    }
                }
            }
            for (k, &u) in mapped.object_unknowns.clone().iter().enumerate() {
                if !has[u.0] {
                    let s = if k < mapped.plane_d.len() { opts.soft_sigma_d } else { opts.soft_sigma_param };
                    let o = mapped.problem.add_identity_observation(u, s)?;
                    mapped.origins.push(ObsOrigin2 { obs: usize::MAX, component: "" });
                    let _ = o;
                    mapped.cond_obs.push(usize::MAX);
                }
            }
            "soft"
        }
        DatumChoice::Hard => {
            for u in crate::solve::hard_datum_choice(&mapped.problem, &mapped.object_unknowns, &eng)? {
                mapped.problem.fix(u);
            }
            "hard"
        }
    };
    let sol = adjust(&mapped.problem, &eng)?;
    // Write back.
    let mut max_shift = 0.0f64;
    for (i, &u) in mapped.plane_d.iter().enumerate() {
        max_shift = max_shift.max((m.planes[i].d - sol.x[u.0]).abs());
        m.planes[i].d = sol.x[u.0];
    }
    for (i, &u) in mapped.params.iter().enumerate() {
        m.parameters[i].value = sol.x[u.0];
    }
    for (i, t) in mapped.fixed.iter().enumerate() {
        for k in 0..3 {
            m.fixed_points[i].t[k] = sol.x[t[k].0];
        }
    }
    for (i, q) in mapped.setups.iter().enumerate() {
        for k in 0..4 {
            m.setups[i].q[k] = sol.x[q[k].0];
        }
    }
    Ok(build_report(m, &mapped, &sol, &misclosures, datum_name, max_shift))
}

fn build_report(m: &Popa3d, mapped: &Mapped, sol: &Solution, misclosures: &[f64], datum: &str, max_shift: f64) -> Report {
    let p = &mapped.problem;
    let mut obs: Vec<ObsReport> = Vec::with_capacity(sol.obs.len());
    for (k, r) in sol.obs.iter().enumerate() {
        let o = &mapped.origins[k];
        let (class, origin, label) = if o.obs == usize::MAX {
            ("ParameterObs".to_string(), "datum".to_string(), Some(p.observation_name(crate::ObsId(k)).to_string()))
        } else {
            let ob = &m.observations[o.obs];
            (ob.kind.class_name().to_string(), ob.origin.as_str().to_string(), ob.label.clone())
        };
        obs.push(ObsReport {
            observation: if o.obs == usize::MAX { u32::MAX } else { o.obs as u32 },
            class,
            origin,
            label,
            component: o.component.to_string(),
            value: p.observation_value(crate::ObsId(k)),
            sigma: p.observation_sigma(crate::ObsId(k)),
            v: r.v,
            redundancy: r.redundancy,
            normalised: r.normalised,
            controllable: r.controllable,
            rejected: r.rejected,
        });
    }
    let mut per_type: BTreeMap<String, TypeStats> = BTreeMap::new();
    for (c, &w) in misclosures.iter().enumerate() {
        let kind = p.condition_kind(crate::ConditionId(c)).to_string();
        let e = per_type.entry(kind).or_default();
        e.max_misclosure_before = e.max_misclosure_before.max(w.abs());
    }
    for o in &obs {
        let e = per_type.entry(o.class.clone()).or_default();
        e.count += 1;
        e.max_abs_residual = e.max_abs_residual.max(o.v.abs());
        e.mean_redundancy += o.redundancy;
    }
    for e in per_type.values_mut() {
        if e.count > 0 {
            e.mean_redundancy /= e.count as f64;
        }
    }
    let not_yet_measured: Vec<ObsReport> = obs
        .iter()
        .filter(|o| o.origin == ObsOrigin::Sketch.as_str() && !o.controllable)
        .cloned()
        .collect();
    let largest_suspect = sol.largest_suspect.map(|o| obs[o.0].clone());
    let mut sorted = obs;
    sorted.sort_by(|a, b| b.normalised.total_cmp(&a.normalised).then(a.observation.cmp(&b.observation)));
    let _ = &mapped.cond_obs;
    Report {
        datum: datum.to_string(),
        unknowns: (0..p.unknown_count()).filter(|&u| !p.is_fixed(UnknownId(u))).count(),
        conditions: p.condition_count(),
        restrictions: p.restriction_count(),
        datum_restrictions: sol.datum_restrictions,
        redundancy: sol.redundancy,
        redundancy_sum: sol.redundancy_sum,
        iterations: sol.iterations,
        components: sol.components,
        vtpv: sol.vtpv,
        sigma0: sol.sigma0_post,
        global_test: sol.global_test.clone(),
        critical_w: sol.critical_w,
        largest_suspect,
        not_yet_measured,
        per_type,
        observations: sorted,
        max_plane_shift: max_shift,
    }
}
