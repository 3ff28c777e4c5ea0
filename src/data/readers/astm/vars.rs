//! The `VARS` line of an ASTM E1392 file: which column holds which angle, value and
//! uncertainty, and in what angle unit.

use super::super::text::{blank_tokens, comma_tokens, Token};
use super::Pos;

/// An angle unit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AngleUnit {
    Degrees,
    Radians,
}

impl AngleUnit {
    /// Degrees per unit.
    pub fn to_deg(self) -> f64 {
        match self {
            AngleUnit::Degrees => 1.0,
            AngleUnit::Radians => 180.0 / std::f64::consts::PI,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            AngleUnit::Degrees => "degrees",
            AngleUnit::Radians => "radians",
        }
    }

    /// `deg`, `degree(s)`, `°`, `rad`, `radian(s)`, any case.
    pub fn parse(s: &str) -> Option<AngleUnit> {
        match s.trim().to_ascii_lowercase().as_str() {
            "deg" | "degs" | "degree" | "degrees" | "°" => Some(AngleUnit::Degrees),
            "rad" | "rads" | "radian" | "radians" => Some(AngleUnit::Radians),
            _ => None,
        }
    }
}

/// The four angles, in the order of the format.
pub const ANGLES: [&str; 4] = ["theta_i", "phi_i", "theta_s", "phi_s"];

/// What a value column holds: a wavelength (nm), or a named quantity.
#[derive(Clone, Debug, PartialEq)]
pub enum ValueName {
    Wavelength(f64),
    Named(String),
}

/// A value column: its index among the cells, its name, and its uncertainty column.
#[derive(Clone, Debug)]
pub struct ValueColumn {
    pub index: usize,
    pub name: String,
    pub what: ValueName,
    pub uncertainty: Option<usize>,
    pub at: Pos,
}

/// The checked VARS line.
#[derive(Clone, Debug)]
pub struct Vars {
    /// Cell index of θi, φi (absent: 0), θs, φs.
    pub angles: [Option<usize>; 4],
    pub values: Vec<ValueColumn>,
    /// The unit the angle names declare, if they do, and where.
    pub unit: Option<(AngleUnit, Pos)>,
    pub cells: usize,
}

/// A name's unit suffix split off: `theta_i[deg]`, `theta_i (rad)`, `theta_i_deg`.
fn split_unit(name: &str) -> (String, Option<Option<AngleUnit>>) {
    let n = name.trim();
    for (open, close) in [('(', ')'), ('[', ']')] {
        if let (Some(stripped), Some(i)) = (n.strip_suffix(close), n.rfind(open)) {
            let unit = &stripped[i + 1..];
            return (n[..i].trim().to_string(), Some(AngleUnit::parse(unit)));
        }
    }
    let lower = n.to_ascii_lowercase();
    for (suffix, unit) in [
        ("_deg", AngleUnit::Degrees),
        ("_degrees", AngleUnit::Degrees),
        ("_rad", AngleUnit::Radians),
        ("_radians", AngleUnit::Radians),
    ] {
        if let Some(base) = lower.strip_suffix(suffix) {
            if ANGLES.contains(&base) {
                return (base.to_string(), Some(Some(unit)));
            }
        }
    }
    (n.to_string(), None)
}

/// `550`, `550nm`, `550 nm`, `550.5nm`: a wavelength in nm.
fn wavelength_name(name: &str) -> Option<f64> {
    let n = name.trim();
    let num = n
        .strip_suffix("nm")
        .or_else(|| n.strip_suffix("NM"))
        .unwrap_or(n)
        .trim();
    num.parse::<f64>()
        .ok()
        .filter(|w| w.is_finite() && *w > 0.0)
}

/// The column an uncertainty column `u_X` or `u(X)` is about, if it is one.
fn uncertainty_of(name: &str) -> Option<&str> {
    let n = name.trim();
    if let Some(rest) = n.strip_prefix("u_").or_else(|| n.strip_prefix("U_")) {
        return Some(rest.trim());
    }
    n.strip_prefix("u(")
        .or_else(|| n.strip_prefix("U("))
        .and_then(|r| r.strip_suffix(')'))
        .map(str::trim)
}

/// The cells of a line after `VARS` (or a data line): comma-separated when the line has
/// a comma, blank-separated otherwise.
pub fn cells_of(text: &str) -> Vec<Token<'_>> {
    if text.contains(',') {
        comma_tokens(text)
    } else {
        blank_tokens(text)
    }
}

/// Parse the names of the VARS line (`names`: its cells after the keyword).
pub fn parse(names: &[Token], line: usize) -> Result<Vars, (Pos, String)> {
    let mut angles: [Option<usize>; 4] = [None; 4];
    let mut unit: Option<(AngleUnit, Pos)> = None;
    let mut values: Vec<ValueColumn> = Vec::new();
    let mut uncertainties: Vec<(usize, &str, Pos)> = Vec::new();
    for (i, t) in names.iter().enumerate() {
        let at = (line, t.column);
        if t.text.is_empty() {
            return Err((at, "an empty name in VARS".into()));
        }
        if let Some(of) = uncertainty_of(t.text) {
            uncertainties.push((i, of, at));
            continue;
        }
        let (base, u) = split_unit(t.text);
        if let Some(k) = ANGLES.iter().position(|a| a.eq_ignore_ascii_case(&base)) {
            if angles[k].is_some() {
                return Err((at, format!("VARS names {} twice", ANGLES[k])));
            }
            angles[k] = Some(i);
            match u {
                Some(None) => {
                    return Err((at, format!("VARS '{}': the unit is not deg or rad", t.text)))
                }
                Some(Some(u)) => match unit {
                    Some((u0, p0)) if u0 != u => {
                        return Err((
                            at,
                            format!(
                                "VARS '{}' says {} but column {} of this line says {}",
                                t.text,
                                u.name(),
                                p0.1,
                                u0.name()
                            ),
                        ))
                    }
                    _ => unit = Some((u, at)),
                },
                None => {}
            }
            continue;
        }
        let what = match wavelength_name(t.text) {
            Some(w) => ValueName::Wavelength(w),
            None => ValueName::Named(t.text.trim().to_string()),
        };
        if let Some(v) = values
            .iter()
            .find(|v| v.what == what || v.name.eq_ignore_ascii_case(t.text.trim()))
        {
            return Err((
                at,
                format!("VARS names '{}' twice (first at column {})", t.text, v.at.1),
            ));
        }
        values.push(ValueColumn {
            index: i,
            name: t.text.trim().to_string(),
            what,
            uncertainty: None,
            at,
        });
    }
    for (k, name) in ANGLES.iter().enumerate() {
        if angles[k].is_none() && *name != "phi_i" {
            let end = names.last().map_or(1, |t| t.column);
            return Err(((line, end), format!(
                "VARS has no {name} column (it needs theta_i, phi_i, theta_s, phi_s — phi_i may be left out — then the values)"
            )));
        }
    }
    if values.is_empty() {
        let end = names.last().map_or(1, |t| t.column);
        return Err((
            (line, end),
            "VARS names no value column after the angles".into(),
        ));
    }
    for (i, of, at) in uncertainties {
        let v = values
            .iter_mut()
            .find(|v| v.name.eq_ignore_ascii_case(of))
            .ok_or_else(|| {
                (
                    at,
                    format!("VARS: uncertainty column of '{of}', which is not a value column"),
                )
            })?;
        if v.uncertainty.is_some() {
            return Err((at, format!("VARS: a second uncertainty column of '{of}'")));
        }
        v.uncertainty = Some(i);
    }
    check_value_names(&values)?;
    Ok(Vars {
        angles,
        values,
        unit,
        cells: names.len(),
    })
}

/// Wavelength columns, or R, G, B, or X, Y, Z, or one column of any other name.
fn check_value_names(values: &[ValueColumn]) -> Result<(), (Pos, String)> {
    let named: Vec<&ValueColumn> = values
        .iter()
        .filter(|v| matches!(v.what, ValueName::Named(_)))
        .collect();
    if named.is_empty() || values.len() == 1 {
        return Ok(());
    }
    let upper: Vec<String> = named.iter().map(|v| v.name.to_ascii_uppercase()).collect();
    let set = |s: [&str; 3]| {
        named.len() == values.len()
            && s.iter().all(|c| upper.iter().any(|u| u == c))
            && values.len() == 3
    };
    if set(["R", "G", "B"]) || set(["X", "Y", "Z"]) {
        return Ok(());
    }
    let v = named[0];
    Err((v.at, format!(
        "VARS value column '{}': with several value columns each must be a wavelength (550 or 550nm), or they must be R, G, B or X, Y, Z",
        v.name
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vars(line: &str) -> Result<Vars, (Pos, String)> {
        parse(&cells_of(line), 3)
    }

    #[test]
    fn names_units_and_uncertainties() {
        let v = vars("theta_i,phi_i,theta_s,phi_s,400nm,410,u_400nm").unwrap();
        assert_eq!(v.angles, [Some(0), Some(1), Some(2), Some(3)]);
        assert_eq!(v.values[0].what, ValueName::Wavelength(400.0));
        assert_eq!(v.values[1].what, ValueName::Wavelength(410.0));
        assert_eq!(v.values[0].uncertainty, Some(6));
        assert!(v.unit.is_none());
        let v = vars("theta_i [deg], theta_s (deg), phi_s_deg, BRDF").unwrap();
        assert_eq!(v.angles[1], None);
        assert_eq!(v.unit.unwrap().0, AngleUnit::Degrees);
        let e = vars("theta_i(deg),phi_i,theta_s(rad),phi_s,BRDF").unwrap_err();
        assert!(e.1.contains("says radians"), "{e:?}");
        let e = vars("theta_i,phi_i,theta_s,phi_s,BRDF,BTDF").unwrap_err();
        assert_eq!(e.0, (3, 29));
        assert!(vars("theta_i,phi_i,theta_s,phi_s,R,G,B").is_ok());
        let e = vars("theta_i,phi_i,phi_s,BRDF").unwrap_err();
        assert!(e.1.contains("theta_s"), "{e:?}");
        let e = vars("theta_i,phi_i,theta_s,phi_s,550,u_600").unwrap_err();
        assert!(e.1.contains("not a value column"), "{e:?}");
    }
}
