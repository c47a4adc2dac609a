//! Argument groups and checks shared by several subcommands, so that the same option has the same
//! name, default, help text and validation everywhere (`citygml2popa3d` and `obj2popa3d` both
//! normalize; `adjust`, `heal`, `popa3d2citygml` ... all check positive numbers the same way).

use clap::Args as ClapArgs;

use crate::error::CliError;
use normalize::Tolerances;

/// The input document and `-o/--output` of the commands that turn one document into another
/// (`adjust`, `citygml2popa3d`, `heal`, `obj2popa3d`), so `-` means stdin / stdout the same way
/// everywhere; each command's help says which formats they are.
#[derive(ClapArgs, Debug, Clone)]
pub struct InputOutput {
    /// Input document, `-` for stdin.
    pub input: String,
    /// Output document (stdout when missing or `-`).
    #[arg(short, long)]
    pub output: Option<String>,
}

/// The normalization tolerances (spec §3.1/§3.2; defaults decided in [`normalize::Tolerances`]),
/// flattened into the commands that turn polygons into a popa3d model.
#[derive(ClapArgs, Debug, Clone)]
pub struct NormalizeArgs {
    /// Snap tolerance: points closer than this are one node (m).
    #[arg(long, default_value_t = 0.001)]
    pub snap: f64,
    /// Reject faces whose vertices lie further than this from their best-fitting plane (m).
    #[arg(long, default_value_t = 0.1)]
    pub planarity: f64,
    /// Merge normals within this angle into one normal object (degrees).
    #[arg(long, default_value_t = 0.01)]
    pub normal_angle: f64,
    /// Merge planes on one normal whose distances differ by less than this (m).
    #[arg(long, default_value_t = 0.001)]
    pub plane_distance: f64,
    /// Share parameters between orthogonal normals ((a,b,c) and (−b,a,c)); snaps near-zero components.
    #[arg(long)]
    pub share_orthogonal: bool,
}

impl NormalizeArgs {
    /// The checked tolerances: every length and angle must be a positive number.
    pub fn tolerances(&self) -> Result<Tolerances, CliError> {
        require_positive(&[
            ("snap", self.snap),
            ("planarity", self.planarity),
            ("normal-angle", self.normal_angle),
            ("plane-distance", self.plane_distance),
        ])?;
        Ok(Tolerances {
            snap: self.snap,
            planarity: self.planarity,
            normal_angle_deg: self.normal_angle,
            plane_distance: self.plane_distance,
            share_orthogonal: self.share_orthogonal,
        })
    }
}

/// A usage error (exit 2) naming the first option that is not a finite positive number.
pub fn require_positive(options: &[(&str, f64)]) -> Result<(), CliError> {
    match options.iter().find(|(_, v)| !(v.is_finite() && *v > 0.0)) {
        Some((name, v)) => Err(CliError::usage(format!("--{name} must be a positive number, got {v}"))),
        None => Ok(()),
    }
}

/// A usage error (exit 2) naming the first option that is not a finite number ≥ 0.
pub fn require_non_negative(options: &[(&str, f64)]) -> Result<(), CliError> {
    match options.iter().find(|(_, v)| !(v.is_finite() && *v >= 0.0)) {
        Some((name, v)) => Err(CliError::usage(format!("--{name} must be a number ≥ 0, got {v}"))),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_bad_option_is_named() {
        assert!(require_positive(&[("a", 1.0), ("b", 2.0)]).is_ok());
        let e = require_positive(&[("a", 1.0), ("b", 0.0), ("c", f64::NAN)]).unwrap_err();
        assert!(e.to_string().contains("--b must be a positive number, got 0"), "{e}");
        assert!(require_positive(&[("c", f64::INFINITY)]).is_err());
        assert!(require_non_negative(&[("a", 0.0)]).is_ok());
        let e = require_non_negative(&[("a", -1e-9)]).unwrap_err();
        assert!(e.to_string().contains("--a must be a number ≥ 0"), "{e}");
    }
}
