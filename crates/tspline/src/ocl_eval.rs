//! OpenCL host side (spec §6): surface evaluation, knot derivation and dragging vectors on any
//! OpenCL device (PoCL on CPUs in CI). The kernels (`tspline.cl`) mirror the CPU code in
//! `eval.rs` / `knots.rs` operation by operation, in f64, with FP contraction off, so results
//! agree to rounding (tested to 1e-12 relative).
//!
//! Nothing here panics when OpenCL is missing: [`OclEvaluator::new`] checks the platform list
//! through `ocl::core::get_platform_ids` (which returns an error, unlike `Platform::list`) and
//! reports a typed error; a kernel that fails to build is an error too. The caller decides
//! whether to fall back to the CPU (`--device auto`) or to fail (`--device opencl`).

use ocl::{Buffer, Device, Kernel, Platform};

use crate::eval::{GridSpec, PbSpline};
use crate::extraction::Extraction;
use crate::knots::LocalKnots;
use crate::mesh::TMesh;
use crate::ocl_device::{err, OclDevice, PbBuffers};
use crate::TsplineError;

/// Points per work item of the element kernels (`RUN` in `tspline.cl`).
const RUN: usize = 64;

/// The kernel source, compiled at run time.
pub const KERNEL_SRC: &str = concat!(include_str!("common.cl"), include_str!("tspline.cl"));

/// An OpenCL device with the compiled T-spline program.
pub struct OclEvaluator {
    dev: OclDevice,
}

/// Device buffers of one compiled PB-spline.
pub struct OclSpline {
    bufs: PbBuffers,
    pb: PbSplineGrid,
    /// Leaf cells (for [`crate::eval::use_extraction`]).
    ncells: usize,
    /// The element extraction (dense evaluation), `None` after [`OclEvaluator::update_geometry`]
    /// (its blocks depend on the geometry; the PB-spline kernels serve until the next upload)
    /// and for small uploads.
    ext: Option<OclExtraction>,
}

/// Device buffers of an [`Extraction`].
struct OclExtraction {
    data: Buffer<f64>,
    flags: Buffer<u32>,
    start: Buffer<u32>,
    items: Buffer<u32>,
    grid: crate::eval::BucketGrid,
    stride: u32,
}

#[derive(Clone, Copy)]
struct PbSplineGrid {
    s0: f64,
    t0: f64,
    ds: f64,
    dt: f64,
    ns: u32,
    nt: u32,
    k: u32,
}

/// Lists "platform: device" names, or an error when no OpenCL platform exists.
pub fn list_devices() -> Result<Vec<String>, TsplineError> {
    let ids = ocl::core::get_platform_ids().map_err(err)?;
    let mut out = Vec::new();
    for id in ids {
        let p = Platform::new(id);
        let pname = p.name().unwrap_or_default();
        for d in Device::list_all(p).map_err(err)? {
            out.push(format!("{pname}: {}", d.name().unwrap_or_default()));
        }
    }
    Ok(out)
}

impl OclEvaluator {
    /// The first device of the first platform that has one, with the T-spline kernels built.
    pub fn new() -> Result<OclEvaluator, TsplineError> {
        Self::with_source(KERNEL_SRC)
    }

    /// As [`OclEvaluator::new`] with another kernel source (tests feed a broken one).
    pub fn with_source(src: &str) -> Result<OclEvaluator, TsplineError> {
        Ok(OclEvaluator { dev: OclDevice::build(src, "kernel")? })
    }

    pub fn device_name(&self) -> &str {
        &self.dev.name
    }

    fn out_buf(&self, n: usize) -> Result<Buffer<f64>, TsplineError> {
        self.dev.out::<f64>(n)
    }

    /// Uploads a compiled PB-spline and its element extraction (computed here, on the host's
    /// rayon pool: it is a per-cell pass that the dense kernels then amortise).
    pub fn upload(&self, pb: &PbSpline) -> Result<OclSpline, TsplineError> {
        let mut sp = self.upload_pb(pb)?;
        let ex = Extraction::new(pb, true);
        if ex.is_empty() {
            // the element kernels read element 0 as the first hint: keep the PB-spline kernels
            return Ok(sp);
        }
        sp.ext = Some(OclExtraction {
            data: self.dev.buf(&ex.data)?,
            flags: self.dev.buf(&ex.flags)?,
            start: self.dev.buf(&ex.start)?,
            items: self.dev.buf(&ex.items)?,
            grid: ex.grid,
            stride: ex.stride as u32,
        });
        Ok(sp)
    }

    /// The PB-spline buffers only (reference kernels, knot derivation, dragging): for callers
    /// that change the geometry before evaluating, which drops the extraction anyway.
    pub fn upload_pb(&self, pb: &PbSpline) -> Result<OclSpline, TsplineError> {
        let g = pb.grid;
        Ok(OclSpline {
            bufs: PbBuffers::upload(&self.dev, pb)?,
            pb: PbSplineGrid { s0: g.s0, t0: g.t0, ds: g.ds, dt: g.dt, ns: g.ns, nt: g.nt, k: pb.degree.k() as u32 },
            ncells: pb.cells.len(),
            ext: None,
        })
    }

    /// Replaces the geometry (after a fit step) without re-uploading the rest.
    pub fn update_geometry(&self, sp: &mut OclSpline, pb: &PbSpline) -> Result<(), TsplineError> {
        sp.ext = None;
        sp.bufs.geom.write(pb.geom.as_flattened()).enq().map_err(err)
    }

    /// The dense-evaluation kernel: the element path when the extraction is current and the
    /// batch is dense (the CPU's rule), else the PB-spline kernel `name` (same numbers to 1e-12).
    /// `n`: points; `runs`: work items of the element kernel (each evaluates up to [`RUN`]
    /// consecutive points). No local work size is set: on PoCL, forcing 1, 8, 64 or 256 was
    /// 1.3–2× slower than its own choice (measured with the `ocl_throughput` probe).
    fn dense_kernel<'a>(
        &'a self,
        name: &str,
        sp: &'a OclSpline,
        n: usize,
        runs: usize,
    ) -> Result<ocl::builders::KernelBuilder<'a>, TsplineError> {
        match &sp.ext {
            Some(ex) if crate::eval::use_extraction(n, sp.ncells) => {
                let mut kb = self.kernel(&format!("{name}_ext"), sp, runs)?;
                let eg = ex.grid;
                kb.arg(eg.s0).arg(eg.t0).arg(eg.ds).arg(eg.dt).arg(eg.ns).arg(eg.nt).arg(ex.stride);
                sp.bufs.args(&mut kb);
                kb.arg(&ex.data).arg(&ex.flags).arg(&ex.start).arg(&ex.items);
                Ok(kb)
            }
            _ => {
                let mut kb = self.kernel(name, sp, n)?;
                sp.bufs.args(&mut kb);
                Ok(kb)
            }
        }
    }

    fn kernel(&self, name: &str, sp: &OclSpline, n: usize) -> Result<ocl::builders::KernelBuilder<'_>, TsplineError> {
        let g = sp.pb;
        let mut kb = Kernel::builder();
        kb.program(&self.dev.program).name(name).queue(self.dev.queue.clone()).global_work_size(n.max(1));
        kb.arg(g.s0).arg(g.t0).arg(g.ds).arg(g.dt).arg(g.ns).arg(g.nt).arg(g.k);
        Ok(kb)
    }

    /// Heights at parameter points (NaN outside the domain).
    pub fn eval_points(&self, sp: &OclSpline, st: &[[f64; 2]]) -> Result<Vec<f64>, TsplineError> {
        let n = st.len();
        if n == 0 {
            return Ok(Vec::new());
        }
        let stb = self.dev.buf(st.as_flattened())?;
        let out = self.out_buf(n)?;
        let mut kb = self.dense_kernel("eval_points", sp, n, n.div_ceil(RUN))?;
        kb.arg(&stb).arg(&out).arg(n as u32);
        let k = kb.build().map_err(err)?;
        unsafe { k.enq().map_err(err)? };
        let mut v = vec![0.0; n];
        out.read(&mut v).enq().map_err(err)?;
        Ok(v)
    }

    /// Heights on a regular grid (row-major in t), like [`PbSpline::eval_grid`].
    pub fn eval_grid(&self, sp: &OclSpline, g: &GridSpec) -> Result<Vec<f64>, TsplineError> {
        let n = g.ns * g.nt;
        if n == 0 {
            return Ok(Vec::new());
        }
        let out = self.out_buf(n)?;
        let mut kb = self.dense_kernel("eval_grid", sp, n, g.ns.div_ceil(RUN) * g.nt)?;
        kb.arg(g.s0).arg(g.t0).arg(g.ds).arg(g.dt).arg(g.ns as u32).arg(g.nt as u32).arg(&out);
        let k = kb.build().map_err(err)?;
        unsafe { k.enq().map_err(err)? };
        let mut v = vec![0.0; n];
        out.read(&mut v).enq().map_err(err)?;
        Ok(v)
    }

    /// Dragging vectors δ_i = ref_i − t(s_i, t_i) at the PB points' parameter pairs.
    pub fn drag_vectors(&self, sp: &OclSpline, params: &[[f64; 2]], refz: &[f64]) -> Result<Vec<f64>, TsplineError> {
        let n = params.len();
        let flat: Vec<f64> = params.iter().flatten().copied().collect();
        let pb = self.dev.buf(&flat)?;
        let rb = self.dev.buf(refz)?;
        let out = self.out_buf(n)?;
        let mut kb = self.kernel("drag_vectors", sp, n)?;
        sp.bufs.args(&mut kb);
        kb.arg(&pb).arg(&rb).arg(&out).arg(n as u32);
        let k = kb.build().map_err(err)?;
        unsafe { k.enq().map_err(err)? };
        let mut v = vec![0.0; n];
        out.read(&mut v).enq().map_err(err)?;
        Ok(v)
    }

    /// Knot derivation on the device for every active point of `mesh` (spec §6.4); returns the
    /// PB-spline built from the device's knots.
    pub fn build_pbspline(&self, mesh: &TMesh) -> Result<PbSpline, TsplineError> {
        // The cell bucket grid does not depend on knots: build it with placeholder knots first.
        let active = mesh.active_points();
        let ids: Vec<u32> = (0..mesh.points.len() as u32).filter(|&i| active[i as usize]).collect();
        let zero = LocalKnots { s: [0.0; 5], t: [0.0; 5] };
        let tmp = PbSpline::from_parts(mesh, ids.clone(), vec![zero; ids.len()]);
        let sp = self.upload_pb(&tmp)?;
        let params: Vec<f64> =
            ids.iter().flat_map(|&i| [mesh.points[i as usize].s, mesh.points[i as usize].t]).collect();
        let n = ids.len();
        let pbuf = self.dev.buf(&params)?;
        let out = self.out_buf(10 * n)?;
        let mut kb = self.kernel("derive_knots", &sp, n)?;
        kb.arg(&sp.bufs.cells).arg(&sp.bufs.cstart).arg(&sp.bufs.citems).arg(&pbuf).arg(&out).arg(n as u32);
        let k = kb.build().map_err(err)?;
        unsafe { k.enq().map_err(err)? };
        let mut v = vec![0.0; 10 * n];
        out.read(&mut v).enq().map_err(err)?;
        let knots = v
            .chunks_exact(10)
            .map(|c| {
                let mut s = [0.0; 5];
                let mut t = [0.0; 5];
                s.copy_from_slice(&c[..5]);
                t.copy_from_slice(&c[5..]);
                LocalKnots { s, t }
            })
            .collect();
        Ok(PbSpline::from_parts(mesh, ids, knots))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{Degree, TMesh};

    use crate::testing::lcg;

    use crate::testing::refined_mesh as refined;

    /// Spec acceptance: OpenCL and CPU agree to 1e-12 (f64) on 10^6 random points of a refined
    /// mesh. OpenCL is forced: a missing platform fails this test instead of falling back.
    #[test]
    fn opencl_matches_cpu_on_a_million_points() {
        let ocl = OclEvaluator::new().expect("OpenCL (PoCL) must be available for this test");
        for degree in [Degree::Linear, Degree::Cubic] {
            let m = refined(degree);
            let pb = PbSpline::build(&m);
            let b = m.bounds();
            let mut seed = 11u64;
            let n = if degree == Degree::Cubic { 1_000_000 } else { 200_000 };
            let mut st: Vec<[f64; 2]> = (0..n)
                .map(|_| {
                    [
                        b.s_min - 2.0 + (b.width() + 4.0) * lcg(&mut seed),
                        b.t_min - 2.0 + (b.height() + 4.0) * lcg(&mut seed),
                    ]
                })
                .collect();
            // include vertices and borders
            st.extend(m.points.iter().map(|p| [p.s, p.t]));
            let cpu = pb.eval_z(&st, true);
            let sp = ocl.upload(&pb).unwrap();
            let gpu = ocl.eval_points(&sp, &st).unwrap();
            let mut nan = 0;
            for (i, (a, g)) in cpu.iter().zip(&gpu).enumerate() {
                if a.is_nan() || g.is_nan() {
                    assert!(a.is_nan() && g.is_nan(), "{degree:?} point {:?}: cpu {a} ocl {g}", st[i]);
                    nan += 1;
                    continue;
                }
                assert!((a - g).abs() <= 1e-12 * a.abs().max(1.0), "{degree:?} point {:?}: cpu {a} ocl {g}", st[i]);
            }
            assert!(nan > 0 && nan < st.len() / 2);
            let same =
                cpu.iter().zip(&gpu).filter(|(a, g)| a.to_bits() == g.to_bits() || (a.is_nan() && g.is_nan())).count();
            eprintln!("{degree:?}: {same} of {} bitwise equal", st.len());
            // the PB-spline kernel (used once the geometry changed) gives the same numbers
            let mut sp_ref = ocl.upload(&pb).unwrap();
            ocl.update_geometry(&mut sp_ref, &pb).unwrap();
            let n_ref = if degree == Degree::Cubic { 200_000 } else { st.len() };
            let gpu_ref = ocl.eval_points(&sp_ref, &st[..n_ref]).unwrap();
            for (i, (a, g)) in cpu.iter().zip(&gpu_ref).enumerate() {
                assert!(
                    (a.is_nan() && g.is_nan()) || (a - g).abs() <= 1e-12 * a.abs().max(1.0),
                    "{degree:?} reference kernel at {:?}: cpu {a} ocl {g}",
                    st[i]
                );
            }
            // grid kernel
            let gs = GridSpec { s0: b.s_min, t0: b.t_min, ds: 0.7, dt: 0.9, ns: 150, nt: 100 };
            let a = pb.eval_grid(&gs, false);
            let g = ocl.eval_grid(&sp, &gs).unwrap();
            for (x, y) in a.iter().zip(&g) {
                assert!((x.is_nan() && y.is_nan()) || (x - y).abs() <= 1e-12 * x.abs().max(1.0));
            }
        }
    }

    /// The knot-derivation kernel returns exactly the CPU ray-casting knots.
    #[test]
    fn opencl_knots_equal_cpu_knots() {
        let ocl = OclEvaluator::new().expect("OpenCL (PoCL) must be available for this test");
        for degree in [Degree::Linear, Degree::Cubic] {
            let m = refined(degree);
            let cpu = PbSpline::build(&m);
            let dev = ocl.build_pbspline(&m).unwrap();
            assert_eq!(cpu.point_ids, dev.point_ids);
            for (i, (a, b)) in cpu.knots.iter().zip(&dev.knots).enumerate() {
                assert_eq!(a, b, "{degree:?} point {}", cpu.point_ids[i]);
            }
            // also across a gap (merged meshes, A14)
            let a = TMesh::grid(degree, 0.0, 0.0, 1.0, 3, 3);
            let b = TMesh::grid(degree, 5.0, 1.0, 1.0, 3, 3);
            let mm = a.merge(&b).unwrap();
            assert_eq!(PbSpline::build(&mm).knots, ocl.build_pbspline(&mm).unwrap().knots);
        }
    }

    /// The dragging kernel gives the CPU twin's dragging result (spec §4.6, T29).
    #[test]
    fn opencl_dragging_matches_cpu() {
        use crate::fit::{fit_drag, Backend, Samples};
        let ocl = OclEvaluator::new().expect("OpenCL (PoCL) must be available for this test");
        let m = refined(Degree::Cubic);
        let pb = PbSpline::build(&m);
        let (w, h) = (96usize, 80usize);
        let z: Vec<f64> = (0..w * h).map(|q| ((q % w) as f64 * 0.2).sin() * 5.0 + (q / w) as f64 * 0.1).collect();
        let samples = Samples { width: w, height: h, z: z.into() };
        let a = fit_drag(&pb, &samples, 25, 0.0, &Backend::Cpu).unwrap();
        let b = fit_drag(&pb, &samples, 25, 0.0, &Backend::OpenCl(&ocl)).unwrap();
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() <= 1e-9 * x.abs().max(1.0), "{x} vs {y}");
        }
    }

    /// Where the PoCL time goes (ignored; `cargo test -p tspline --release -- --ignored
    /// --nocapture ocl_throughput`): host-side extraction + upload, the points kernel (10^7
    /// parameter pairs in, heights out), the grid kernel (no input transfer), and the PB-spline
    /// kernel, on the benchmark's mesh shape.
    #[test]
    #[ignore]
    fn ocl_throughput() {
        use std::time::Instant;
        let ocl = OclEvaluator::new().expect("OpenCL");
        let n = 315;
        let (pb, st) = crate::testing::benchmark_surface(n);
        let side = n * 10 + 1;
        // process CPU seconds (utime + stime, all threads incl. PoCL's): robust to a loaded machine
        let cpu = || -> f64 {
            let s = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
            let f: Vec<&str> = s.rsplit(')').next().unwrap_or("").split_whitespace().collect();
            (f.get(11).and_then(|v| v.parse::<f64>().ok()).unwrap_or(f64::NAN)
                + f.get(12).and_then(|v| v.parse::<f64>().ok()).unwrap_or(f64::NAN))
                / 100.0
        };
        let c0 = cpu();
        let t = Instant::now();
        let mut sp = ocl.upload(&pb).unwrap();
        eprintln!("{}: upload incl. extraction {:.3} s", ocl.device_name(), t.elapsed().as_secs_f64());
        let t = Instant::now();
        let a = ocl.eval_points(&sp, &st).unwrap();
        let tp = t.elapsed().as_secs_f64();
        let c1 = cpu();
        eprintln!(
            "eval_points (element kernel): {:.3} s = {:.2} M points/s; {:.2} M points per CPU-second (upload+eval)",
            tp,
            st.len() as f64 / tp / 1e6,
            st.len() as f64 / (c1 - c0) / 1e6
        );
        let gs = GridSpec { s0: 0.0, t0: 0.0, ds: 1.0, dt: 1.0, ns: side, nt: side };
        let t = Instant::now();
        let b = ocl.eval_grid(&sp, &gs).unwrap();
        let tg = t.elapsed().as_secs_f64();
        let c2 = cpu();
        eprintln!(
            "eval_grid (element kernel): {:.3} s = {:.2} M points/s; {:.2} M points per CPU-second",
            tg,
            b.len() as f64 / tg / 1e6,
            b.len() as f64 / (c2 - c1) / 1e6
        );
        ocl.update_geometry(&mut sp, &pb).unwrap();
        let sub = &st[..1_000_000];
        let t = Instant::now();
        let c = ocl.eval_points(&sp, sub).unwrap();
        let tr = t.elapsed().as_secs_f64();
        eprintln!(
            "eval_points (PB-spline kernel): {:.2} M points/s; {:.2} M points per CPU-second",
            sub.len() as f64 / tr / 1e6,
            sub.len() as f64 / (cpu() - c2) / 1e6
        );
        let cpu = pb.eval_z(&st, true);
        for (q, x) in cpu.iter().enumerate() {
            let y = a[q];
            assert!((x.is_nan() && y.is_nan()) || (x - y).abs() <= 1e-12 * x.abs().max(1.0));
            if q < c.len() {
                assert!((x.is_nan() && c[q].is_nan()) || (x - c[q]).abs() <= 1e-12 * x.abs().max(1.0));
            }
        }
    }

    /// A kernel that fails to build is an error (the CLI then falls back with a notice).
    #[test]
    fn broken_kernel_is_an_error_not_a_panic() {
        if ocl::core::get_platform_ids().map(|v| v.is_empty()).unwrap_or(true) {
            return; // nothing to build on; opencl_matches_cpu_on_a_million_points fails instead
        }
        let e = OclEvaluator::with_source("__kernel void f(__global double* x) { x[0] = undefined_symbol; }");
        let msg = e.err().expect("must fail").to_string();
        assert!(msg.contains("kernel build failed"), "{msg}");
    }
}
