//! The OpenCL device that both kernel families run on (evaluation `tspline.cl` in
//! [`crate::ocl_eval`], the model matrix `fit.cl` in [`crate::ocl_fit`]): platform and device
//! choice, program build and buffer creation in one place, so both report missing platforms and
//! failed builds the same way. Nothing here panics when OpenCL is missing or a kernel does not
//! compile: every step returns [`TsplineError::OpenCl`].

use ocl::builders::KernelBuilder;
use ocl::{flags, Buffer, Context, Device, Platform, Program, Queue};

use crate::eval::PbSpline;
use crate::TsplineError;

pub(crate) fn err(e: impl std::fmt::Display) -> TsplineError {
    TsplineError::OpenCl(e.to_string())
}

/// The first `n` non-empty lines of a compiler log, joined (a build log can be pages long).
pub(crate) fn first_lines(s: &str, n: usize) -> String {
    s.lines().filter(|l| !l.trim().is_empty()).take(n).collect::<Vec<_>>().join(" | ")
}

/// A queue on the first device of the first platform that has one, with one program built.
pub(crate) struct OclDevice {
    pub queue: Queue,
    pub program: Program,
    /// "platform / device", for reports.
    pub name: String,
}

impl OclDevice {
    /// Chooses the device and builds `src` (OpenCL C 1.2); `what` names the source in a build
    /// error ("kernel", "fit.cl").
    pub fn build(src: &str, what: &str) -> Result<OclDevice, TsplineError> {
        // ICD loaders and PoCL are not reliable when several threads enumerate at once.
        static INIT: std::sync::Mutex<()> = std::sync::Mutex::new(());
        let _guard = INIT.lock().unwrap_or_else(|e| e.into_inner());
        let ids = ocl::core::get_platform_ids().map_err(|e| err(format!("no OpenCL platform available ({e})")))?;
        let mut chosen = None;
        let mut last_err = String::new();
        for id in ids {
            let p = Platform::new(id);
            match Device::list_all(p) {
                Ok(devs) => {
                    if let Some(d) = devs.into_iter().next() {
                        chosen = Some((p, d));
                        break;
                    }
                }
                Err(e) => last_err = e.to_string(),
            }
        }
        let (platform, device) =
            chosen.ok_or_else(|| err(format!("no OpenCL platform with a device found {last_err}")))?;
        let context = Context::builder().platform(platform).devices(device).build().map_err(err)?;
        let queue = Queue::new(&context, device, None).map_err(err)?;
        let program = Program::builder()
            .src(src)
            .devices(device)
            .cmplr_opt("-cl-std=CL1.2")
            .build(&context)
            .map_err(|e| err(format!("{what} build failed: {}", first_lines(&e.to_string(), 6))))?;
        let name = format!("{} / {}", platform.name().unwrap_or_default(), device.name().unwrap_or_default());
        Ok(OclDevice { queue, program, name })
    }

    /// A read-only device copy of `data` (OpenCL refuses zero-sized buffers: an empty slice
    /// becomes one default element).
    pub fn buf<T: ocl::OclPrm>(&self, data: &[T]) -> Result<Buffer<T>, TsplineError> {
        let pad = [T::default()];
        let data = if data.is_empty() { &pad[..] } else { data };
        Buffer::<T>::builder()
            .queue(self.queue.clone())
            .flags(flags::MEM_READ_ONLY)
            .len(data.len())
            .copy_host_slice(data)
            .build()
            .map_err(err)
    }

    /// A write-only output buffer of `len` elements (at least one).
    pub fn out<T: ocl::OclPrm>(&self, len: usize) -> Result<Buffer<T>, TsplineError> {
        Buffer::<T>::builder()
            .queue(self.queue.clone())
            .flags(flags::MEM_WRITE_ONLY)
            .len(len.max(1))
            .build()
            .map_err(err)
    }
}

/// Device copies of a compiled PB-spline's arrays, as both kernel families take them: knots
/// (10 per point), polynomial pieces (40), geometry (x, y, z, w), leaf cells, and the bucket lists
/// of points and cells.
pub(crate) struct PbBuffers {
    pub knots: Buffer<f64>,
    pub poly: Buffer<f64>,
    pub geom: Buffer<f64>,
    pub cells: Buffer<f64>,
    pub pstart: Buffer<u32>,
    pub pitems: Buffer<u32>,
    pub cstart: Buffer<u32>,
    pub citems: Buffer<u32>,
}

impl PbBuffers {
    /// Uploads from flat views of the arrays (no intermediate copies: the pieces alone are
    /// 320 B per point).
    pub fn upload(dev: &OclDevice, pb: &PbSpline) -> Result<PbBuffers, TsplineError> {
        Ok(PbBuffers {
            knots: dev.buf(pb.knots.as_flattened())?,
            poly: dev.buf(&pb.poly_40())?,
            geom: dev.buf(pb.geom.as_flattened())?,
            cells: dev.buf(pb.cells.as_flattened())?,
            pstart: dev.buf(&pb.pt_start)?,
            pitems: dev.buf(&pb.pt_items)?,
            cstart: dev.buf(&pb.cell_start)?,
            citems: dev.buf(&pb.cell_items)?,
        })
    }

    /// Appends the eight buffers as kernel arguments, in the order above.
    pub fn args<'b>(&'b self, kb: &mut KernelBuilder<'b>) {
        kb.arg(&self.knots).arg(&self.poly).arg(&self.geom).arg(&self.cells);
        kb.arg(&self.pstart).arg(&self.pitems).arg(&self.cstart).arg(&self.citems);
    }
}
