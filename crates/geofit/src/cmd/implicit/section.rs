//! `geofit implicit section`: a saved model cut by a plane, coloured by φ or its attribute.

use clap::Args as ClapArgs;
use implicit::contour;

use super::{read_model, write_surfaces};
use crate::config::Config;
use crate::error::{CliError, CmdResult, Exit};

#[derive(ClapArgs)]
pub struct SectionArgs {
    /// Saved model (`.gfim`).
    pub model: String,
    /// The plane: `x=V`, `y=V`, `z=V` or `PX,PY,PZ,NX,NY,NZ` (point and normal, world coordinates).
    #[arg(long)]
    pub plane: String,
    /// Colour by the model's attribute instead of φ.
    #[arg(long)]
    pub attribute: bool,
    /// Output section (.obj or .glb; stdout = OBJ).
    #[arg(short, long)]
    pub output: Option<String>,
}

fn parse_plane(s: &str) -> Result<([f64; 3], [f64; 3]), CliError> {
    let bad = || CliError::usage(format!("--plane `{s}`: use x=V, y=V, z=V or PX,PY,PZ,NX,NY,NZ"));
    if let Some((axis, v)) = s.split_once('=') {
        let v: f64 = v.trim().parse().map_err(|_| bad())?;
        let k = match axis.trim() {
            "x" | "X" => 0,
            "y" | "Y" => 1,
            "z" | "Z" => 2,
            _ => return Err(bad()),
        };
        let mut p = [0.0; 3];
        let mut n = [0.0; 3];
        p[k] = v;
        n[k] = 1.0;
        return if v.is_finite() { Ok((p, n)) } else { Err(bad()) };
    }
    let f: Vec<f64> = s.split(',').map(|x| x.trim().parse::<f64>()).collect::<Result<_, _>>().map_err(|_| bad())?;
    if f.len() != 6 || f.iter().any(|x| !x.is_finite()) {
        return Err(bad());
    }
    let n = implicit::geom::normalize([f[3], f[4], f[5]]).ok_or_else(bad)?;
    Ok(([f[0], f[1], f[2]], n))
}

pub(super) fn run(a: SectionArgs, config: &Config) -> CmdResult {
    let (p, n) = parse_plane(&a.plane)?;
    let m = read_model(&a.model)?;
    if a.attribute && m.attribute.is_none() {
        return Err(CliError::usage(format!("--attribute: {} has no attribute", a.model)));
    }
    let s = contour::section(&m, p, n, a.attribute);
    if s.tris.is_empty() {
        return Err(CliError::findings(format!("the plane {} does not cross the model's domain", a.plane)));
    }
    write_surfaces(&a.output, &[("section".to_string(), s)], config)?;
    Ok(Exit::Ok)
}
