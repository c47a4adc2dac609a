//! T-spline surfaces for terrain reduction (Asche 2016; its sections and the decisions A1–A22 are
//! summarised in docs/sources.md#tspline and docs/tspline-decisions.md).
//!
//! - [`mesh`]: the T-mesh in a rectangle R-tree (refinement, repair, merge, coarsen).
//! - [`knots`]: local knot vectors by ray casting, one point at a time or all at once from the
//!   sorted edges of each grid line ([`knots::infer_batch`]).
//! - [`eval`]: the rational T-spline through its PB-spline form, CPU (rayon) evaluation.
//! - [`ocl_eval`]: the same evaluation and the knot derivation as OpenCL kernels.
//! - [`rtree_pages`]: the thesis' Nearest-X int8 page encoding (Tables 5.2, 6.3).
//! - [`format`](mod@format): the T-mesh file format (`xsd/tmesh.xsd`); [`tmb`]: its compact binary twin.
//! - [`sparse`]: the sparse Cholesky (and PCG fallback) of the least-squares solve.
//! - [`fit`]: adaptive approximation (Alg. 3) with sparse least squares or dragging;
//!   `coarsen`: merging back the splits the tolerance did not need; [`tolerance`]: what the
//!   fit accepts per cell; [`blunders`]: spikes found before a fit.
//! - [`seams`]: tiles of a raster plan made C0 across their seams (stitch, continuity).
//! - [`tessellate`]: the surface as a coloured triangle mesh with draped cell edges (glTF/OBJ scene).
//!
//! Where the spec's ambiguities are decided (doc comments there): A1, A2, A15 in [`eval`];
//! A7–A12, A17, A19 in [`fit`]; A13, A14, A22 in [`mesh`]; A16 (formats: GDAL rasters in, the
//! documented `.tmesh` out) in [`format`](mod@format); A18 in `benches/tspline.sh`; A20 in the Table 5.2
//! test of [`rtree_pages`]; A21 below. A3–A6 (PCA mass, warp details, splat footprint,
//! dilation weights) belong to the warp in `raster-proc`; `fit::mean_dilation_fill` follows A6's
//! wave-front reading with equal weights over valued 8-neighbours.
//!
//! Parameterization (A21): parameter units are raster cells. s = column index, t = row index
//! counted from the bottom row, so raster cell centres sit at integer (s, t) and the sample
//! spacing is 1. The affine map to world coordinates is stored with the mesh ([`format::Georef`]).
//!
//! # Examples
//!
//! Reduce a 40×30 raster with a hole to a cubic T-spline whose every valid cell is within 0.05,
//! and evaluate it where the raster has values:
//!
//! ```
//! use tspline::fit::{fit, Backend, FitOptions, Samples, StopReason};
//! use tspline::{Degree, PbSpline};
//! let (w, h) = (40, 30);
//! let height = |s: f64, t: f64| 10.0 + 0.3 * s + 2.0 * (s / 7.0).sin() * (t / 5.0).cos();
//! let mut z: Vec<f64> = (0..w * h).map(|q| height((q % w) as f64, (q / w) as f64)).collect();
//! z[15 * w + 20] = f64::NAN; // no data
//! let samples = Samples { width: w, height: h, z: z.into() };
//! let result = fit(&samples, &FitOptions::new(Degree::Cubic, 0.05), &Backend::Cpu, &mut |_| {}).unwrap();
//! assert_eq!(result.stop, StopReason::ToleranceReached);
//!
//! let surface = PbSpline::build(&result.mesh);
//! let cells: Vec<[f64; 2]> = (0..w * h).map(|q| [(q % w) as f64, (q / w) as f64]).collect();
//! let fitted = surface.eval_z(&cells, false);
//! for (q, v) in samples.z.iter().enumerate().filter(|(_, v)| !v.is_nan()) {
//!     assert!((fitted[q] - v).abs() <= 0.05);
//! }
//! assert!(result.mesh.points.len() < w * h / 2); // fewer control points than cells
//! ```

mod assembly;
pub mod blunders;
pub mod eval;
pub mod extraction;
pub mod fit;
pub mod format;
pub mod knots;
pub mod mesh;
mod ocl_device;
pub mod ocl_eval;
pub mod ocl_fit;
pub mod rtree_pages;
pub mod seams;
pub mod sparse;
pub mod tessellate;
#[cfg(test)]
mod testing;
pub mod tmb;
pub mod tolerance;

pub use eval::{GridSpec, PbSpline};
pub use mesh::{CellId, ControlPoint, Degree, PointId, Rect, TMesh};

/// Errors of the T-spline library.
#[derive(Debug, thiserror::Error)]
pub enum TsplineError {
    #[error("invalid T-mesh: {0}")]
    InvalidMesh(String),
    #[error("T-mesh file, {pos}: {msg}")]
    Format { pos: String, msg: String },
    #[error("OpenCL: {0}")]
    OpenCl(String),
    #[error("fit: {0}")]
    Fit(String),
    /// Data values too large in magnitude for the fit's sums and squares to stay finite
    /// (|z| above [`fit::MAX_ABS_VALUE`]); refused before fitting.
    #[error("values from {min:e} to {max:e} are too large to fit: |z| must stay below {limit:e} so that sums and squares stay finite")]
    ValueRange { min: f64, max: f64, limit: f64 },
    #[error("{0}")]
    Io(#[from] std::io::Error),
}

/// Threads the CPU path uses (rayon's pool; `RAYON_NUM_THREADS=1` gives the single-thread path).
pub fn worker_threads() -> usize {
    rayon::current_num_threads()
}
