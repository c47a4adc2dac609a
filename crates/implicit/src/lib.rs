//! Implicit surfaces by Discrete Smooth Interpolation (DSI) on adaptive tetrahedral meshes
//! (seed 003, T. Frank: "Implizites Modellieren und Co-Visualisierung mittels Tetraedergittern").
//!
//! Pipeline: points ([`points`]) → adaptive conforming mesh ([`mesh`]) → optional fault cuts
//! ([`fault`]) → DSI constraints and the normal system solved by preconditioned CG ([`dsi`]) →
//! a saved [`model::Model`] that can be re-interpolated with base + float constraints (seed §3) →
//! iso-surfaces, sections and CSG by marching tetrahedra ([`contour`]) → VTK ([`vtk`]).
//!
//! # Examples
//!
//! Points with normals on a unit sphere become a field whose zero surface is closed and
//! encloses about the sphere's volume:
//!
//! ```
//! use implicit::{contour, generate, model};
//! let points = generate::sphere(800, [0.0; 3], 1.0, 0.0, 0.0, 1);
//! let (m, report) = model::build(&points, &[], &[], &model::BuildOptions::default(), &mut |_| {}).unwrap();
//! assert!(report.misfit_max < report.cell);
//! let surface = contour::iso_surface(&m.mesh, &m.phi, 0.0, None);
//! assert!(surface.is_closed());
//! let sphere = 4.0 / 3.0 * std::f64::consts::PI;
//! assert!((surface.volume().abs() - sphere).abs() < 0.1 * sphere, "{}", surface.volume());
//! ```

pub mod contour;
pub mod dsi;
pub mod fault;
pub mod generate;
pub mod geom;
pub mod mesh;
pub mod model;
pub mod noise;
pub mod points;
pub mod vtk;

/// Everything that can go wrong, each with enough context for one clear message.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{file}:{line}: {msg}")]
    Parse { file: String, line: usize, msg: String },
    #[error("{0}")]
    BadInput(String),
    #[error("fault `{0}` does not cut the model domain: no mesh face between two tetrahedra crosses it (check its coordinates against the points' bounding box)")]
    FaultOutsideDomain(String),
    #[error("conjugate gradients did not converge within {iterations} iterations (relative residual {residual:.3e} > tolerance {tol:.1e}); raise --max-iter, loosen --tol, or coarsen the mesh with a larger --cell")]
    NotConverged { iterations: usize, residual: f64, tol: f64 },
    #[error("model file: {0}")]
    Model(String),
}
#[cfg(test)]
mod tests;
