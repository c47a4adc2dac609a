//! Header column names: one table of every name either dialect recognises, with the role it
//! has in each. The dialects disagree on purpose: in terrain soundings a `value` column is the
//! elevation (z) and geographic names (`lon`, `lat`) are accepted; in LoopStructural samples
//! `value` is the scalar field φ and rows may carry a normal (`nx ny nz`).

/// What a column holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    X,
    Y,
    Z,
    /// The scalar field value φ (LoopStructural dialect only).
    Value,
    Nx,
    Ny,
    Nz,
}

/// Which reading of a point file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dialect {
    /// Terrain soundings and lidar returns: x y z.
    Terrain,
    /// LoopStructural samples: x y z, an optional value φ, an optional normal.
    LoopStructural,
}

use Role::*;

/// Every recognised name (lower case): its role in the terrain dialect, then in the
/// LoopStructural one (`None`: not a column name there).
const COLUMN_NAMES: &[(&str, Option<Role>, Option<Role>)] = &[
    ("x", Some(X), Some(X)),
    ("easting", Some(X), Some(X)),
    ("east", Some(X), Some(X)),
    ("lon", Some(X), None),
    ("long", Some(X), None),
    ("longitude", Some(X), None),
    ("e", Some(X), None),
    ("rechtswert", Some(X), None),
    ("y", Some(Y), Some(Y)),
    ("northing", Some(Y), Some(Y)),
    ("north", Some(Y), Some(Y)),
    ("lat", Some(Y), None),
    ("latitude", Some(Y), None),
    ("n", Some(Y), None),
    ("hochwert", Some(Y), None),
    ("z", Some(Z), Some(Z)),
    ("elevation", Some(Z), Some(Z)),
    ("depth", Some(Z), Some(Z)),
    ("height", Some(Z), Some(Z)),
    ("elev", Some(Z), None),
    ("h", Some(Z), None),
    ("alt", Some(Z), None),
    ("altitude", Some(Z), None),
    ("hoehe", Some(Z), None),
    ("höhe", Some(Z), None),
    ("tiefe", Some(Z), None),
    ("value", Some(Z), Some(Value)),
    ("val", Some(Z), Some(Value)),
    ("v", None, Some(Value)),
    ("phi", None, Some(Value)),
    ("scalar", None, Some(Value)),
    ("nx", None, Some(Nx)),
    ("ny", None, Some(Ny)),
    ("nz", None, Some(Nz)),
];

/// The role of a header field in `dialect` (surrounding blanks and double quotes ignored, any
/// case).
pub fn role_of(field: &str, dialect: Dialect) -> Option<Role> {
    let name = field.trim().trim_matches('"').to_lowercase();
    let (_, terrain, loop_structural) = COLUMN_NAMES.iter().find(|(n, ..)| *n == name)?;
    match dialect {
        Dialect::Terrain => *terrain,
        Dialect::LoopStructural => *loop_structural,
    }
}

/// The index of the first header field with `role` in `dialect`.
pub fn find_column(fields: &[&str], role: Role, dialect: Dialect) -> Option<usize> {
    fields.iter().position(|f| role_of(f, dialect) == Some(role))
}

/// A header name without a unit in brackets (`Depth (m)`, `Easting [m]`).
fn without_unit(field: &str) -> &str {
    field.split(['(', '[']).next().unwrap_or(field).trim()
}

/// The columns of x, y and z a terrain header names (a unit in brackets after a name is
/// ignored): `Ok(None)` when it names none of them; a header naming some but not all, or two
/// columns for one role (`lon,lat,x,y,z`: which x?), is refused, except that a `value`/`val`
/// column gives way to a z named as such (`X,Y,Z,val`: the val is an attribute).
pub fn terrain_xyz(fields: &[&str]) -> Result<Option<[usize; 3]>, String> {
    let mut out = [0; 3];
    let role = |i: usize| role_of(without_unit(fields[i]), Dialect::Terrain);
    if !(0..fields.len()).any(|i| matches!(role(i), Some(X | Y | Z))) {
        return Ok(None);
    }
    for (k, r) in [X, Y, Z].into_iter().enumerate() {
        let axis = ["x", "y", "z"][k];
        let mut found: Vec<usize> = (0..fields.len()).filter(|&i| role(i) == Some(r)).collect();
        if found.len() > 1 && r == Z {
            let weak = |i: &usize| {
                matches!(without_unit(fields[*i]).trim_matches('"').to_ascii_lowercase().as_str(), "value" | "val")
            };
            if found.iter().any(|i| !weak(i)) {
                found.retain(|i| !weak(i));
            }
        }
        match found.as_slice() {
            [] => {
                return Err(format!(
                    "the header names no {axis} column (found: {}); name the columns x, y, z",
                    fields.join(", ")
                ))
            }
            [i] => out[k] = *i,
            many => {
                let names: Vec<&str> = many.iter().map(|&i| fields[i]).collect();
                return Err(format!(
                    "the header names {} columns for {axis} ({}): keep one",
                    many.len(),
                    names.join(", ")
                ));
            }
        }
    }
    Ok(Some(out))
}

/// Whether a header name says longitude or latitude (the points are then in degrees).
pub fn is_geographic_name(field: &str) -> bool {
    matches!(
        field.trim().trim_matches('"').to_ascii_lowercase().as_str(),
        "lon" | "long" | "longitude" | "lat" | "latitude"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn value_is_z_in_terrain_and_phi_in_loop_structural() {
        assert_eq!(role_of(" \"Value\" ", Dialect::Terrain), Some(Z));
        assert_eq!(role_of("value", Dialect::LoopStructural), Some(Value));
        assert_eq!(role_of("lon", Dialect::LoopStructural), None);
        assert_eq!(role_of("nx", Dialect::Terrain), None);
    }

    #[test]
    fn first_matching_column_wins() {
        let header = ["id", "Easting", "x", "NORTH", "depth"];
        assert_eq!(find_column(&header, X, Dialect::Terrain), Some(1));
        assert_eq!(find_column(&header, Y, Dialect::LoopStructural), Some(3));
        assert_eq!(find_column(&header, Value, Dialect::LoopStructural), None);
    }

    #[test]
    fn terrain_roles_are_unambiguous() {
        assert_eq!(terrain_xyz(&["id", "Easting", "Northing", "Depth"]), Ok(Some([1, 2, 3])));
        assert_eq!(terrain_xyz(&["", "X", "Y", "Z", "val"]), Ok(Some([1, 2, 3])));
        assert_eq!(terrain_xyz(&["lat", "lon", "value"]), Ok(Some([1, 0, 2])));
        assert_eq!(terrain_xyz(&["a", "b", "c"]), Ok(None));
        assert_eq!(
            terrain_xyz(&["lon", "lat", "x", "y", "z"]).unwrap_err(),
            "the header names 2 columns for x (lon, x): keep one"
        );
        assert!(terrain_xyz(&["x", "y", "z", "depth"]).unwrap_err().contains("2 columns for z"));
        assert!(is_geographic_name(" \"Longitude\"") && !is_geographic_name("x"));
        // units in brackets, German names, and headers that name only some axes
        assert_eq!(terrain_xyz(&["ID", "Easting [m]", "Northing [m]", "Depth (m)"]), Ok(Some([1, 2, 3])));
        assert_eq!(terrain_xyz(&["Punkt", "Rechtswert", "Hochwert", "Höhe"]), Ok(Some([1, 2, 3])));
        let e = terrain_xyz(&["ID", "Easting", "Northing", "Sounding"]).unwrap_err();
        assert_eq!(
            e,
            "the header names no z column (found: ID, Easting, Northing, Sounding); name the columns x, y, z"
        );
    }
}
