//! The problem description: unknowns, observations (with their stochastic model), conditions
//! `f(x, l + v) = 0` and restrictions `g(x) = 0` (spec §4.1, §6.1).

use crate::ad::{DynEquation, Equation, Scalar, MAX_VARS};
use crate::AdjustError;
use std::sync::Arc;

/// Index of an unknown in a [`Problem`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct UnknownId(pub usize);

/// Index of an observation in a [`Problem`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ObsId(pub usize);

/// Index of a condition (observation equation) in a [`Problem`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ConditionId(pub usize);

/// An unknown slot of an equation: the slot's value is `sign · x[unknown]`.
///
/// Signed slots are how popa3d's shared normal parameters enter equations (spec §2.3: a normal
/// component may be `−param`); two slots of one equation may name the same unknown, the engine
/// then seeds one gradient direction and the derivatives sum (spec §6.2 "parameter net").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Slot {
    pub unknown: UnknownId,
    pub sign: f64,
}

impl From<UnknownId> for Slot {
    fn from(unknown: UnknownId) -> Self {
        Slot { unknown, sign: 1.0 }
    }
}

impl Slot {
    pub fn neg(unknown: UnknownId) -> Self {
        Slot { unknown, sign: -1.0 }
    }
}

#[derive(Clone, Debug)]
pub(crate) struct UnknownDef {
    pub name: String,
    pub value: f64,
    pub fixed: bool,
}

#[derive(Clone, Debug)]
pub(crate) struct ObsDef {
    pub name: String,
    pub value: f64,
    pub sigma: f64,
    /// Index into `cov_groups` when this observation is part of a full-covariance group.
    pub group: Option<usize>,
}

#[derive(Clone, Debug)]
pub(crate) struct CovGroup {
    pub obs: Vec<ObsId>,
    /// Row-major covariance matrix (σ² units), `obs.len()²` entries.
    pub cov: Vec<f64>,
}

#[derive(Clone)]
pub(crate) struct EquationDef {
    pub name: String,
    pub eq: Arc<dyn DynEquation>,
    pub x: Vec<Slot>,
    pub l: Vec<ObsId>,
}

/// A Gauss–Helmert problem with restrictions.
#[derive(Clone, Default)]
pub struct Problem {
    pub(crate) unknowns: Vec<UnknownDef>,
    pub(crate) obs: Vec<ObsDef>,
    pub(crate) cov_groups: Vec<CovGroup>,
    pub(crate) conditions: Vec<EquationDef>,
    pub(crate) restrictions: Vec<EquationDef>,
}

/// `x − l = 0`: an identity (pseudo-)observation of one unknown (spec §4.7 soft datum, ParameterObs).
pub struct Identity;
impl Equation for Identity {
    fn kind(&self) -> &str {
        "ParameterObs"
    }
    fn eval<D: Scalar>(&self, x: &[D], l: &[D]) -> D {
        x[0] - l[0]
    }
}

impl Problem {
    pub fn new() -> Self {
        Self::default()
    }

    /// Add an unknown with its approximate (starting) value.
    pub fn add_unknown(&mut self, name: impl Into<String>, value: f64) -> UnknownId {
        self.unknowns.push(UnknownDef { name: name.into(), value, fixed: false });
        UnknownId(self.unknowns.len() - 1)
    }

    /// Add an uncorrelated observation with standard deviation `sigma` (> 0, spec MA12).
    pub fn add_observation(&mut self, name: impl Into<String>, value: f64, sigma: f64) -> Result<ObsId, AdjustError> {
        let name = name.into();
        if !(sigma > 0.0 && sigma.is_finite()) {
            return Err(AdjustError::InvalidSigma { observation: name, sigma });
        }
        if !value.is_finite() {
            return Err(AdjustError::NonFinite { what: format!("value of observation {name}") });
        }
        self.obs.push(ObsDef { name, value, sigma, group: None });
        Ok(ObsId(self.obs.len() - 1))
    }

    /// Give a set of observations a full covariance matrix (row-major, σ² units). Replaces the
    /// individual σ of those observations; the matrix must be symmetric positive definite.
    pub fn set_covariance(&mut self, obs: &[ObsId], cov: Vec<f64>) -> Result<(), AdjustError> {
        let n = obs.len();
        let names = || {
            obs.iter()
                .map(|o| self.obs.get(o.0).map_or(format!("#{}", o.0), |d| d.name.clone()))
                .collect::<Vec<_>>()
                .join(", ")
        };
        if cov.len() != n * n {
            return Err(AdjustError::InvalidCovariance {
                observations: names(),
                reason: format!("expected {} entries, got {}", n * n, cov.len()),
            });
        }
        for o in obs {
            match self.obs.get(o.0) {
                None => return Err(AdjustError::UnknownObservation { equation: "covariance group".into(), id: o.0 }),
                Some(d) if d.group.is_some() => {
                    return Err(AdjustError::InvalidCovariance {
                        observations: names(),
                        reason: format!("{} is already in a covariance group", d.name),
                    })
                }
                _ => {}
            }
        }
        let m = nalgebra::DMatrix::from_row_slice(n, n, &cov);
        if (&m - m.transpose()).amax() > 1e-12 * m.amax().max(1e-300) || m.iter().any(|v| !v.is_finite()) {
            return Err(AdjustError::InvalidCovariance {
                observations: names(),
                reason: "matrix is not symmetric and finite".into(),
            });
        }
        if m.clone().cholesky().is_none() {
            return Err(AdjustError::InvalidCovariance {
                observations: names(),
                reason: "matrix is not positive definite".into(),
            });
        }
        let g = self.cov_groups.len();
        for (i, o) in obs.iter().enumerate() {
            self.obs[o.0].group = Some(g);
            self.obs[o.0].sigma = cov[i * n + i].sqrt();
        }
        self.cov_groups.push(CovGroup { obs: obs.to_vec(), cov });
        Ok(())
    }

    fn check_slots(&self, name: &str, x: &[Slot], l: &[ObsId]) -> Result<(), AdjustError> {
        for s in x {
            if s.unknown.0 >= self.unknowns.len() {
                return Err(AdjustError::UnknownUnknown { equation: name.to_string(), id: s.unknown.0 });
            }
            if !s.sign.is_finite() {
                return Err(AdjustError::NonFinite { what: format!("slot sign in {name}") });
            }
        }
        for o in l {
            if o.0 >= self.obs.len() {
                return Err(AdjustError::UnknownObservation { equation: name.to_string(), id: o.0 });
            }
        }
        let mut distinct: Vec<usize> = x.iter().map(|s| s.unknown.0).collect();
        distinct.sort_unstable();
        distinct.dedup();
        let mut dl: Vec<usize> = l.iter().map(|o| o.0).collect();
        dl.sort_unstable();
        dl.dedup();
        if distinct.len() + dl.len() > MAX_VARS {
            return Err(AdjustError::TooManyVariables { equation: name.to_string(), count: distinct.len() + dl.len() });
        }
        Ok(())
    }

    /// Add a condition `f(x, l + v) = 0`. Returns its id.
    pub fn add_condition<E: Equation>(
        &mut self,
        name: impl Into<String>,
        eq: E,
        x: Vec<Slot>,
        l: Vec<ObsId>,
    ) -> Result<ConditionId, AdjustError> {
        self.add_condition_arc(name, Arc::new(eq), x, l)
    }

    /// [`Problem::add_condition`] with a shared equation object.
    pub fn add_condition_arc(
        &mut self,
        name: impl Into<String>,
        eq: Arc<dyn DynEquation>,
        x: Vec<Slot>,
        l: Vec<ObsId>,
    ) -> Result<ConditionId, AdjustError> {
        let name = name.into();
        self.check_slots(&name, &x, &l)?;
        self.conditions.push(EquationDef { name, eq, x, l });
        Ok(ConditionId(self.conditions.len() - 1))
    }

    /// Add a restriction `g(x) = 0` (no observation, no residual; spec §4.1).
    pub fn add_restriction<E: Equation>(
        &mut self,
        name: impl Into<String>,
        eq: E,
        x: Vec<Slot>,
    ) -> Result<usize, AdjustError> {
        let name = name.into();
        self.check_slots(&name, &x, &[])?;
        self.restrictions.push(EquationDef { name, eq: Arc::new(eq), x, l: vec![] });
        Ok(self.restrictions.len() - 1)
    }

    /// Hard datum (spec §4.7.3): keep this unknown at its current value. Implemented by removing
    /// it from the unknowns, which is the exact solution of the restriction `x − x0 = 0`.
    pub fn fix(&mut self, id: UnknownId) {
        self.unknowns[id.0].fixed = true;
    }

    /// Soft datum / ParameterObs (spec §4.7.2): the identity observation `x0 + v = x` with σ.
    pub fn add_identity_observation(&mut self, id: UnknownId, sigma: f64) -> Result<ObsId, AdjustError> {
        let name = format!("identity({})", self.unknowns.get(id.0).map_or("?", |u| u.name.as_str()));
        let value = self.unknowns.get(id.0).map(|u| u.value).unwrap_or(f64::NAN);
        let o = self.add_observation(name.clone(), value, sigma)?;
        self.add_condition(name, Identity, vec![id.into()], vec![o])?;
        Ok(o)
    }

    pub fn unknown_count(&self) -> usize {
        self.unknowns.len()
    }
    pub fn observation_count(&self) -> usize {
        self.obs.len()
    }
    pub fn condition_count(&self) -> usize {
        self.conditions.len()
    }
    pub fn restriction_count(&self) -> usize {
        self.restrictions.len()
    }
    pub fn unknown_name(&self, id: UnknownId) -> &str {
        &self.unknowns[id.0].name
    }
    pub fn observation_name(&self, id: ObsId) -> &str {
        &self.obs[id.0].name
    }
    pub fn condition_name(&self, id: ConditionId) -> &str {
        &self.conditions[id.0].name
    }
    pub fn condition_kind(&self, id: ConditionId) -> &str {
        self.conditions[id.0].eq.kind()
    }
    pub fn condition_observations(&self, id: ConditionId) -> &[ObsId] {
        &self.conditions[id.0].l
    }
    pub fn unknown_value(&self, id: UnknownId) -> f64 {
        self.unknowns[id.0].value
    }
    pub fn set_unknown_value(&mut self, id: UnknownId, value: f64) {
        self.unknowns[id.0].value = value;
    }
    pub fn is_fixed(&self, id: UnknownId) -> bool {
        self.unknowns[id.0].fixed
    }
    pub fn observation_value(&self, id: ObsId) -> f64 {
        self.obs[id.0].value
    }
    pub fn observation_sigma(&self, id: ObsId) -> f64 {
        self.obs[id.0].sigma
    }

    /// Misclosure of every condition at the current approximations and v = 0 (spec Table 7.2
    /// "max misclosure before adjustment").
    pub fn misclosures(&self) -> Vec<f64> {
        self.conditions
            .iter()
            .map(|c| {
                let x: Vec<f64> = c.x.iter().map(|s| s.sign * self.unknowns[s.unknown.0].value).collect();
                let l: Vec<f64> = c.l.iter().map(|o| self.obs[o.0].value).collect();
                c.eq.value(&x, &l)
            })
            .collect()
    }
}

impl Problem {
    /// Replace an observation's value (incremental work: a re-measured value).
    pub fn set_observation_value(&mut self, id: ObsId, value: f64) {
        self.obs[id.0].value = value;
    }
}
