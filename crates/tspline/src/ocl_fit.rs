//! The least-squares model matrix T (spec §4.5 eq. 4.29) as an OpenCL kernel (spec §6.4, T29),
//! with its CPU twin. One work item computes one row of T — the non-zero rational basis values
//! of one sample and their PB-point indices — for a block of raster rows, in ELL layout
//! ([`MAXNZ`] slots per row); a caller accumulates TᵀT and Tᵀd block by block, so the matrix is
//! never stored whole. The kernel (`fit.cl`) follows [`PbSpline::for_each_basis`] (the CPU
//! twin, used by the fit's assembly): same domain test with the A1 border rule, same candidate
//! order, the basis from the same polynomial pieces ([`PbSpline::poly`]) in the same operation
//! order (FP contraction off), so values agree to rounding (tested to 1e-12).
//!
//! Like `ocl_eval`, nothing here panics when OpenCL is missing: [`OclModel::new`] returns a
//! typed error.

use ocl::Kernel;

use crate::eval::{GridSpec, PbSpline};
use crate::ocl_device::{err, OclDevice, PbBuffers};
use crate::TsplineError;

/// The kernel source, compiled at run time.
pub const KERNEL_SRC: &str = concat!(include_str!("common.cl"), include_str!("fit.cl"));

/// Slots per row (more non-zero basis functions at one point is an error).
pub const MAXNZ: usize = 32;

/// Rows of T in ELL layout: row r has `count[r]` entries `idx/val[r·MAXNZ ..]`; count 0 = the
/// sample lies outside the domain.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelRows {
    pub count: Vec<u32>,
    pub idx: Vec<u32>,
    pub val: Vec<f64>,
}

impl ModelRows {
    pub fn len(&self) -> usize {
        self.count.len()
    }
    pub fn is_empty(&self) -> bool {
        self.count.is_empty()
    }
    /// Column indices and values of row r.
    pub fn row(&self, r: usize) -> (&[u32], &[f64]) {
        let n = self.count[r] as usize;
        (&self.idx[r * MAXNZ..r * MAXNZ + n], &self.val[r * MAXNZ..r * MAXNZ + n])
    }
}

fn too_many(r: usize) -> TsplineError {
    TsplineError::Fit(format!("model-matrix row {r}: more than {MAXNZ} non-zero basis functions"))
}

/// CPU twin: the rows of T at the grid's points through [`PbSpline::for_each_basis`].
pub fn model_rows_cpu(pb: &PbSpline, g: &GridSpec) -> Result<ModelRows, TsplineError> {
    let n = g.ns * g.nt;
    let mut out = ModelRows { count: vec![0; n], idx: vec![0; n * MAXNZ], val: vec![0.0; n * MAXNZ] };
    let mut scratch = Vec::new();
    let mut row: Vec<(u32, f64)> = Vec::with_capacity(MAXNZ);
    for r in 0..n {
        let (s, t) = (g.s0 + (r % g.ns) as f64 * g.ds, g.t0 + (r / g.ns) as f64 * g.dt);
        row.clear();
        if !pb.for_each_basis(s, t, &mut scratch, |q, v| row.push((q, v))) {
            continue;
        }
        if row.len() > MAXNZ {
            return Err(too_many(r));
        }
        for (x, &(q, v)) in row.iter().enumerate() {
            out.idx[r * MAXNZ + x] = q;
            out.val[r * MAXNZ + x] = v;
        }
        out.count[r] = row.len() as u32;
    }
    Ok(out)
}

/// An OpenCL device with the model-matrix kernel built.
pub struct OclModel {
    dev: OclDevice,
}

/// Device buffers of one PB-spline (knots, weights, cells, bucket lists).
pub struct OclModelSpline {
    bufs: PbBuffers,
    grid: crate::eval::BucketGrid,
    k: u32,
}

impl OclModel {
    /// The first device of the first platform that has one, with `fit.cl` built.
    pub fn new() -> Result<OclModel, TsplineError> {
        Ok(OclModel { dev: OclDevice::build(KERNEL_SRC, "fit.cl")? })
    }

    pub fn device_name(&self) -> &str {
        &self.dev.name
    }

    /// Uploads the PB-spline's knots, weights, leaf cells and bucket lists.
    pub fn upload(&self, pb: &PbSpline) -> Result<OclModelSpline, TsplineError> {
        Ok(OclModelSpline { bufs: PbBuffers::upload(&self.dev, pb)?, grid: pb.grid, k: pb.degree.k() as u32 })
    }

    /// The rows of T at the grid's points (one work item per row).
    pub fn model_rows(&self, sp: &OclModelSpline, g: &GridSpec) -> Result<ModelRows, TsplineError> {
        let n = g.ns * g.nt;
        if n == 0 {
            return Ok(ModelRows { count: vec![], idx: vec![], val: vec![] });
        }
        let idx = self.dev.out::<u32>(n * MAXNZ)?;
        let count = self.dev.out::<u32>(n)?;
        let val = self.dev.out::<f64>(n * MAXNZ)?;
        let gr = sp.grid;
        let mut kb = Kernel::builder();
        kb.program(&self.dev.program).name("model_rows").queue(self.dev.queue.clone()).global_work_size(n);
        sp.bufs.args(&mut kb);
        let k = kb
            .arg(gr.s0)
            .arg(gr.t0)
            .arg(gr.ds)
            .arg(gr.dt)
            .arg(gr.ns)
            .arg(gr.nt)
            .arg(sp.k)
            .arg(g.s0)
            .arg(g.t0)
            .arg(g.ds)
            .arg(g.dt)
            .arg(g.ns as u32)
            .arg(g.nt as u32)
            .arg(&idx)
            .arg(&val)
            .arg(&count)
            .build()
            .map_err(err)?;
        unsafe { k.enq().map_err(err)? };
        let mut rows = ModelRows { count: vec![0; n], idx: vec![0; n * MAXNZ], val: vec![0.0; n * MAXNZ] };
        count.read(&mut rows.count).enq().map_err(err)?;
        idx.read(&mut rows.idx).enq().map_err(err)?;
        val.read(&mut rows.val).enq().map_err(err)?;
        if let Some(r) = rows.count.iter().position(|&c| c as usize > MAXNZ) {
            return Err(too_many(r));
        }
        // slots past the count are unspecified on the device: clear them for comparisons
        for r in 0..n {
            for x in rows.count[r] as usize..MAXNZ {
                rows.idx[r * MAXNZ + x] = 0;
                rows.val[r * MAXNZ + x] = 0.0;
            }
        }
        Ok(rows)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{Degree, Rect, TMesh};

    use crate::testing::lcg;

    /// A refined mesh with T-junctions and non-unit weights (the rational form matters).
    fn mesh(degree: Degree) -> TMesh {
        let mut m = TMesh::grid(degree, -4.0, -4.0, 16.0, 4, 3);
        let mut g = |s: f64, t: f64| (s, t, 0.0);
        for (s, t) in [(5.0, 5.0), (6.0, 3.0), (30.0, 20.0), (31.0, 21.0), (13.0, 9.0)] {
            let c = m.leaves_in(Rect::new(s, t, s, t))[0];
            m.split(c, &mut g);
        }
        m.repair(1.0, &mut g);
        let mut seed = 3u64;
        for p in &mut m.points {
            p.z = 10.0 * lcg(&mut seed);
            p.w = 0.5 + 1.5 * lcg(&mut seed);
        }
        m
    }

    /// The CPU twin is the model matrix: T · z reproduces the surface.
    #[test]
    fn cpu_rows_reproduce_the_surface() {
        for degree in [Degree::Linear, Degree::Cubic] {
            let pb = PbSpline::build(&mesh(degree));
            let g = GridSpec { s0: -5.0, t0: -5.0, ds: 0.75, dt: 0.625, ns: 90, nt: 80 };
            let rows = model_rows_cpu(&pb, &g).unwrap();
            let mut inside = 0;
            for r in 0..rows.len() {
                let (s, t) = (g.s0 + (r % g.ns) as f64 * g.ds, g.t0 + (r / g.ns) as f64 * g.dt);
                let z = pb.point(s, t)[2];
                let (ix, v) = rows.row(r);
                if ix.is_empty() {
                    assert!(z.is_nan(), "{degree:?} ({s}, {t}): no row but z = {z}");
                    continue;
                }
                inside += 1;
                let tz: f64 = ix.iter().zip(v).map(|(&q, &v)| v * pb.geom[q as usize][2]).sum();
                assert!((tz - z).abs() <= 1e-12 * z.abs().max(1.0), "{degree:?} ({s}, {t}): T·z {tz} vs {z}");
            }
            assert!(inside > 4000);
        }
    }

    /// The device, or None with a printed skip where there is no OpenCL; in CI (`CI=true`,
    /// where make setup installs PoCL) a missing device is a failure, not a skip.
    fn device() -> Option<OclModel> {
        match OclModel::new() {
            Ok(o) => Some(o),
            Err(e) if std::env::var("CI").is_ok_and(|v| v == "true" || v == "1") => panic!("OpenCL missing in CI: {e}"),
            Err(e) => {
                eprintln!("skipped: {e}");
                None
            }
        }
    }

    /// Least squares with the kernel's rows gives the CPU assembly's solution (to rounding of
    /// the summation order), on a raster with holes.
    #[test]
    fn opencl_assembly_solves_like_the_cpu() {
        let Some(o) = device() else { return };
        for degree in [Degree::Linear, Degree::Cubic] {
            let mut m = mesh(degree);
            for p in &mut m.points {
                p.w = 1.0;
            }
            let pb = PbSpline::build(&m);
            let (w, h) = (58, 42);
            let z: Vec<f64> = (0..w * h)
                .map(|q| {
                    let (x, y) = ((q % w) as f64, (q / w) as f64);
                    if (x - 20.0).powi(2) + (y - 15.0).powi(2) < 30.0 {
                        f64::NAN
                    } else {
                        (x * 0.2).sin() * 5.0 + 0.1 * x * y / 10.0
                    }
                })
                .collect();
            let samples = crate::fit::Samples { width: w, height: h, z: z.into() };
            let cpu = crate::fit::fit_lsq(&m, &pb, &samples).unwrap();
            let dev = crate::fit::fit_lsq_with(&m, &pb, &samples, Some(&o)).unwrap();
            let worst = cpu.iter().zip(&dev).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            assert!(worst < 1e-8, "{degree:?}: max |Δz| {worst}");
        }
    }

    /// The OpenCL kernel agrees with the CPU twin: same rows, same columns, values to 1e-12,
    /// on interior points, mesh lines, T-junction edges, the domain border and outside.
    #[test]
    fn opencl_rows_match_cpu_twin() {
        let Some(o) = device() else { return };
        for degree in [Degree::Linear, Degree::Cubic] {
            let pb = PbSpline::build(&mesh(degree));
            // steps of 0.5 hit mesh lines, T-junction edges and the border exactly
            let g = GridSpec { s0: -5.0, t0: -5.0, ds: 0.5, dt: 0.5, ns: 140, nt: 110 };
            let cpu = model_rows_cpu(&pb, &g).unwrap();
            let sp = o.upload(&pb).unwrap();
            let dev = o.model_rows(&sp, &g).unwrap();
            if let Some(r) = (0..cpu.len()).find(|&r| cpu.row(r).0 != dev.row(r).0) {
                let (s, t) = (g.s0 + (r % g.ns) as f64 * g.ds, g.t0 + (r / g.ns) as f64 * g.dt);
                panic!("{degree:?} row {r} at ({s}, {t}): cpu {:?} device {:?}", cpu.row(r), dev.row(r));
            }
            let mut worst = 0.0f64;
            for (a, b) in cpu.val.iter().zip(&dev.val) {
                worst = worst.max((a - b).abs());
            }
            assert!(worst <= 1e-12, "{degree:?}: max |Δ| {worst}");
            assert!(cpu.count.iter().filter(|&&c| c == 0).count() > 0 && cpu.count.iter().any(|&c| c > 4));
        }
    }
}
