//! The adjustment report of a popa3d model: per-observation and per-type statistics and the
//! plane that moved most, from the engine solution.

use super::*;

/// The plane that moved most (see [`Report::max_plane_shift`]): |Δd − ⟨Δn, x⟩| (m) over the
/// plane's nodes x (its reference point when it has none), from the values before (`before`) and
/// now (`m`).
pub(super) fn largest_plane_shift(
    m: &Popa3d,
    before: &[pm::geometry::PlaneValue],
    nodes: &[Vec<[f64; 3]>],
    refs: &[[f64; 3]],
) -> Option<PlaneShift> {
    let mut best: Option<(usize, f64, [f64; 3])> = None;
    for (i, b) in before.iter().enumerate() {
        let a = m.plane_value(pm::PlaneId::from(i));
        let dn = [a.n[0] - b.n[0], a.n[1] - b.n[1], a.n[2] - b.n[2]];
        let xs: &[[f64; 3]] = if nodes[i].is_empty() { std::slice::from_ref(&refs[i]) } else { &nodes[i] };
        for x in xs {
            let s = ((a.d - b.d) - dot(dn, *x)).abs();
            // NaN counts as the largest shift, so a broken solution cannot hide behind it.
            if best.is_none_or(|(_, w, _)| s > w || (s.is_nan() && !w.is_nan())) {
                best = Some((i, s, *x));
            }
        }
    }
    let (i, shift, c) = best?;
    let face = m.faces.iter().position(|f| f.plane.idx() == i);
    let (polygon, solid) = match face {
        Some(f) => {
            let fc = &m.faces[f];
            let solid = [fc.front, fc.back]
                .iter()
                .filter_map(|s| m.solids.get(s.idx()))
                .find(|s| s.kind != pm::SolidKind::Exterior)
                .and_then(|s| s.name.clone());
            (fc.source.as_ref().map(|s| s.polygon.clone()), solid)
        }
        None => (None, None),
    };
    Some(PlaneShift {
        plane: i as u32,
        shift,
        at: [c[0] + m.origin[0], c[1] + m.origin[1], c[2] + m.origin[2]],
        face: face.map(|f| f as u32),
        polygon,
        solid,
    })
}

pub(super) fn build_report(
    m: &Popa3d,
    mapped: &Mapped,
    sol: &Solution,
    misclosures: &[f64],
    datum: &str,
    shift_at: Option<PlaneShift>,
) -> Report {
    let p = &mapped.problem;
    let mut obs: Vec<ObsReport> = Vec::with_capacity(sol.obs.len());
    for (k, r) in sol.obs.iter().enumerate() {
        let o = &mapped.origins[k];
        let (class, origin, label) = if o.obs == usize::MAX {
            (
                o.class.unwrap_or("ParameterObs").to_string(),
                "datum".to_string(),
                Some(p.observation_name(crate::ObsId(k)).to_string()),
            )
        } else {
            let ob = &m.observations[o.obs];
            (o.class.unwrap_or(ob.kind.class_name()).to_string(), ob.origin.as_str().to_string(), ob.label.clone())
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
    let not_yet_measured: Vec<ObsReport> =
        obs.iter().filter(|o| o.origin == ObsOrigin::Sketch.as_str() && !o.controllable).cloned().collect();
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
        max_plane_shift: shift_at.as_ref().map_or(0.0, |s| s.shift),
        max_plane_shift_at: shift_at,
    }
}
