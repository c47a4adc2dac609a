//! CityJSON's `transform`: integer vertices times `scale` plus `translate`. Read: dequantise;
//! write: quantise to the precision asked for (docs/decisions.md#cityjson-quantisation).

use serde_json::{json, Value};

/// scale and translate of a CityJSON document (identity when the document has none).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transform {
    pub scale: [f64; 3],
    pub translate: [f64; 3],
}

impl Default for Transform {
    fn default() -> Self {
        Transform { scale: [1.0; 3], translate: [0.0; 3] }
    }
}

impl Transform {
    /// From a document's `transform` member (absent: identity).
    pub fn from_json(v: Option<&Value>) -> Result<Transform, String> {
        let Some(v) = v else { return Ok(Transform::default()) };
        let three = |key: &str| -> Result<[f64; 3], String> {
            let a = v.get(key).and_then(Value::as_array).ok_or_else(|| format!("transform has no \"{key}\" array"))?;
            let n: Vec<f64> = a.iter().filter_map(Value::as_f64).collect();
            match n[..] {
                [x, y, z] if a.len() == 3 && n.iter().all(|f| f.is_finite()) => Ok([x, y, z]),
                _ => Err(format!("transform \"{key}\" is not three finite numbers")),
            }
        };
        let t = Transform { scale: three("scale")?, translate: three("translate")? };
        if t.scale.contains(&0.0) {
            return Err("transform \"scale\" has a zero".into());
        }
        Ok(t)
    }

    /// A transform of precision `scale` whose translate is `origin` rounded to that precision.
    pub fn with_origin(scale: f64, origin: [f64; 3]) -> Transform {
        let r = |v: f64| if v.is_finite() { (v / scale).round() * scale } else { 0.0 };
        Transform { scale: [scale; 3], translate: [r(origin[0]), r(origin[1]), r(origin[2])] }
    }

    pub fn to_json(&self) -> Value {
        json!({"scale": self.scale, "translate": self.translate})
    }

    /// The real coordinates of a vertex as stored.
    pub fn apply(&self, v: [f64; 3]) -> [f64; 3] {
        [
            v[0] * self.scale[0] + self.translate[0],
            v[1] * self.scale[1] + self.translate[1],
            v[2] * self.scale[2] + self.translate[2],
        ]
    }

    /// The integer vertex of a real point (rounded to the nearest).
    pub fn quantise(&self, p: [f64; 3]) -> [i64; 3] {
        let q = |i: usize| ((p[i] - self.translate[i]) / self.scale[i]).round() as i64;
        [q(0), q(1), q(2)]
    }

    /// Decimal places that print every dequantised coordinate exactly to the document's
    /// precision (scale 0.001 → 3), at most 9; 6 without a transform.
    pub fn decimals(&self) -> usize {
        if self.scale == [1.0; 3] && self.translate == [0.0; 3] {
            return 6;
        }
        let places = |v: f64| {
            (0..=9).find(|d| ((v * 10f64.powi(*d)).round() - v * 10f64.powi(*d)).abs() < 1e-6).unwrap_or(9) as usize
        };
        self.scale.iter().map(|s| places(*s)).max().unwrap_or(3)
    }
}

/// `v` with `decimals` places, trailing zeros (and a bare point) removed: `12.500` → `12.5`.
pub fn format_number(v: f64, decimals: usize) -> String {
    let mut s = format!("{v:.decimals$}");
    if s.contains('.') {
        while s.ends_with('0') {
            s.pop();
        }
        if s.ends_with('.') {
            s.pop();
        }
    }
    if s == "-0" {
        s = "0".into();
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantise_and_back() {
        let t = Transform::with_origin(0.001, [84983.2971, 447463.655, -0.1]);
        assert_eq!(t.translate[0], 84983.297);
        let q = t.quantise([84990.1234, 447463.655, 2.0]);
        assert_eq!(q, [6826, 0, 2100]);
        let p = t.apply([q[0] as f64, q[1] as f64, q[2] as f64]);
        assert_eq!(format_number(p[0], t.decimals()), "84990.123");
        assert_eq!(t.decimals(), 3);
    }
}
