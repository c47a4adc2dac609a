//! The approximation loop (Alg. 3): the heights of the mesh fitted, every cell checked against
//! the tolerance, the leaves that miss it refined; once every cell is within it, coarsening
//! and the check of the mesh as written.

use super::*;

/// One fit's loop: its data and options, the tolerances, the errors per cell kept across
/// iterations and the statistics of the iterations so far.
pub(super) struct Approximation<'a> {
    samples: &'a Samples,
    pts: Option<&'a Scattered>,
    opts: &'a FitOptions,
    backend: &'a Backend<'a>,
    /// The loop's tolerance and the final check's ([`tolerances`]).
    tol: Tolerance,
    tol_final: Tolerance,
    /// Off once a final check failed (rounding beyond the margin: not seen), so that
    /// refinement converges instead of merging the same cells back.
    may_coarsen: bool,
    /// |Δz| per raster cell (or point) of the current surface, kept across iterations (local
    /// updates re-check only the cells whose surface value can have changed).
    errs: Vec<f64>,
    /// The OpenCL model rows of the global assembly ([`FitOptions::opencl_assembly`]).
    asm: Option<crate::ocl_fit::OclModel>,
    iterations: Vec<IterationStats>,
}

/// What a refinement leaves to the next iteration.
#[derive(Default)]
struct Refinement {
    /// The PB-spline before it: the reference of the incremental build and the local update.
    prev: Option<PbSpline>,
    /// Leaves of the mesh before it that it turned into parents (splits and repair).
    split_rects: Vec<Rect>,
    /// Cells it marked and split.
    refined: usize,
}

/// An iteration's surface: its PB-spline with the fitted heights, the local update it was
/// solved by (None: every point, every cell) and the seconds its PB-spline took.
struct Fitted {
    pb: PbSpline,
    local: Option<(Vec<bool>, Region)>,
    t_build: f64,
}

/// How the end of the loop went: the result, or the leaves where the written mesh missed.
enum Finished {
    Done(FitResult),
    Missed { mesh: TMesh, pb: Box<PbSpline>, err: ErrorStats, over: Vec<CellId> },
}

impl<'a> Approximation<'a> {
    pub(super) fn new(
        samples: &'a Samples,
        pts: Option<&'a Scattered>,
        opts: &'a FitOptions,
        backend: &'a Backend<'a>,
    ) -> Result<Approximation<'a>, TsplineError> {
        let (tol, tol_final) = tolerances(samples, pts, opts)?;
        let asm = if opts.opencl_assembly && opts.method == Method::Lsq {
            Some(crate::ocl_fit::OclModel::new()?)
        } else {
            None
        };
        Ok(Approximation {
            samples,
            pts,
            opts,
            backend,
            tol,
            tol_final,
            may_coarsen: opts.coarsen && opts.method == Method::Lsq,
            errs: vec![f64::NAN; pts.map_or(samples.z.len(), |p| p.z.len())],
            asm,
            iterations: Vec::new(),
        })
    }

    /// The loop from `mesh` on; `progress` gets every iteration's statistics.
    pub(super) fn run(
        mut self,
        mut mesh: TMesh,
        progress: &mut dyn FnMut(&IterationStats),
    ) -> Result<FitResult, TsplineError> {
        let mut step = Refinement::default();
        for it in 0.. {
            let t0 = Instant::now();
            let Fitted { mut pb, local, t_build } = self.fit_heights(&mut mesh, &mut step, it)?;
            let t_opt = t0.elapsed().as_secs_f64();
            let (mut err, mut over_leaves) = self.check_iteration(&mesh, &pb, local.as_ref().map(|(_, r)| r))?;
            drop(local);
            let t_check = t0.elapsed().as_secs_f64();
            let st = IterationStats {
                iteration: it,
                control_points: pb.point_ids.len(),
                cells: mesh.leaf_count(),
                refined_cells: step.refined,
                merged_cells: 0,
                error: err.clone(),
                seconds: t0.elapsed().as_secs_f64(),
                seconds_build: t_build,
                seconds_optimise: t_opt - t_build,
                seconds_check: t_check - t_opt,
            };
            progress(&st);
            self.iterations.push(st);
            if err.over_tolerance == 0 {
                match self.finish(mesh, pb, it, &mut *progress)? {
                    Finished::Done(result) => return Ok(result),
                    Finished::Missed { mesh: m, pb: p, err: e, over } => {
                        (mesh, pb, err, over_leaves) = (m, *p, e, over)
                    }
                }
            }
            if it >= self.opts.max_iterations {
                return Ok(self.result(mesh, StopReason::MaxIterations));
            }
            match refine(&mesh, &pb, self.samples, self.opts, over_leaves, &err)? {
                Refined::Stop(stop) => return Ok(self.result(mesh, stop)),
                Refined::Next(next, refined) => {
                    let split_rects = mesh
                        .leaves()
                        .filter(|&c| !next.cells[c as usize].is_leaf())
                        .map(|c| mesh.cells[c as usize].rect)
                        .collect();
                    step = Refinement { prev: Some(pb), split_rects, refined };
                    mesh = next;
                }
            }
        }
        unreachable!("the loop returns")
    }

    /// The PB-spline of `mesh` (built incrementally from the one before the refinement) and
    /// its heights, written into both: least squares, re-solved locally where few points
    /// changed ([`local_update`]), or dragging. The PB-spline before is dropped before the
    /// solve (one of 1.5·10⁵ points is ~70 MiB).
    fn fit_heights(&self, mesh: &mut TMesh, step: &mut Refinement, it: usize) -> Result<Fitted, TsplineError> {
        let (samples, opts, backend) = (self.samples, self.opts, self.backend);
        let t0 = Instant::now();
        let old = step.prev.take();
        release_free_memory(samples.z.len());
        let mut pb = match (&old, backend) {
            (Some(old), Backend::Cpu) => build_pb_incremental(mesh, old, &step.split_rects),
            _ => build_pb(mesh, backend)?,
        };
        let t_build = t0.elapsed().as_secs_f64();
        let local = match (&old, opts.method, opts.local_updates) {
            (Some(old), Method::Lsq, true) if self.pts.is_none() => {
                local_update(old, &pb, mesh.points.len(), samples.width, samples.height)
            }
            _ => None,
        };
        drop(old);
        let z = match (opts.method, &local) {
            (Method::Lsq, Some((free, region))) => fit_lsq_local(
                LsqProblem { free: Some(free), region: Some(region), ..LsqProblem::global(mesh, samples) },
                &pb,
            )?,
            (Method::Lsq, None) => {
                let (z, p) = fit_lsq_released(
                    LsqProblem { pts: self.pts, asm: self.asm.as_ref(), ..LsqProblem::global(mesh, samples) },
                    pb,
                )?;
                pb = p;
                z
            }
            (Method::Drag, _) => fit_drag(&pb, samples, opts.drag_steps, 0.01 * opts.max_error, backend)?,
        };
        if z.iter().any(|v| !v.is_finite()) {
            // the input range check makes this unreachable for sound solvers; a typed error
            // rather than an invalid mesh (which would panic when written) if it happens anyway
            return Err(TsplineError::Fit(format!(
                "iteration {it}: the least-squares solution has non-finite control points"
            )));
        }
        set_z(mesh, &mut pb, &z);
        Ok(Fitted { pb, local, t_build })
    }

    /// The iteration's tolerance check: at the cells of the local update's `region` and, when
    /// none misses there, at every cell (the tolerance is declared only on a fresh check of
    /// every cell). A region of more than half the raster (a large system's local update) is
    /// not checked first: every cell at once gives the same errors and leaves (those outside
    /// it did not change) in one pass instead of up to two.
    fn check_iteration(
        &mut self,
        mesh: &TMesh,
        pb: &PbSpline,
        region: Option<&Region>,
    ) -> Result<(ErrorStats, Vec<CellId>), TsplineError> {
        let region = region.filter(|r| r.len() * 2 <= self.samples.z.len());
        let (err, over) = check(mesh, pb, self.samples, self.pts, region, self.backend, &mut self.errs, &self.tol)?;
        if err.over_tolerance == 0 && region.is_some() {
            return check(mesh, pb, self.samples, self.pts, None, self.backend, &mut self.errs, &self.tol);
        }
        Ok((err, over))
    }

    /// Once every cell is within the tolerance: coarsening (when on), then the acceptance,
    /// the mesh as written evaluated as `geofit eval` evaluates it at every cell (also the
    /// fresh check of a coarsened mesh: docs/decisions.md#one-final-check). No solve follows
    /// unless it fails: the factor's memory goes back first.
    fn finish(
        &mut self,
        mut mesh: TMesh,
        mut pb: PbSpline,
        it: usize,
        progress: &mut dyn FnMut(&IterationStats),
    ) -> Result<Finished, TsplineError> {
        if self.may_coarsen {
            let coarsening = super::coarsen::Coarsening {
                samples: self.samples,
                pts: self.pts,
                opts: self.opts,
                backend: self.backend,
                tol: &self.tol,
            };
            let c = coarsening.run(mesh, pb, &mut self.errs, it + 1, progress)?;
            (mesh, pb) = (c.mesh, c.pb);
            self.iterations.extend(c.rounds);
        }
        sparse_spd::release_workspace();
        let (fin, over, pb) =
            check_written_released(&mesh, pb, self.samples, self.pts, &mut self.errs, &self.tol_final)?;
        if fin.over_tolerance == 0 {
            if let Some(last) = self.iterations.last_mut() {
                last.error = fin;
            }
            return Ok(Finished::Done(self.result(mesh, StopReason::ToleranceReached)));
        }
        // beyond the margin, or a coarsened mesh that misses (not seen: the rounds check what
        // they change): refine where the written mesh misses, coarsening off, so that
        // refinement converges instead of merging the same cells back (no copy of the
        // pre-coarsening mesh is kept: docs/decisions.md#coarsening-decides-before-it-writes)
        self.may_coarsen = false;
        Ok(Finished::Missed { mesh, pb: Box::new(pb), err: fin, over })
    }

    fn result(&mut self, mesh: TMesh, stop: StopReason) -> FitResult {
        FitResult { mesh, iterations: std::mem::take(&mut self.iterations), stop }
    }
}
