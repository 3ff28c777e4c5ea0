//! Named goniometer geometries (`inplane10`, `hemi`, `grid:5`, …): the rows of signed
//! (θi, φi, θo, φo) in degrees at which `synth` measures a model, `eval --geometry`
//! evaluates a fit and an RGL material is sampled, and their unions (`specular+offplane`).

use super::Kind;

/// A named goniometer geometry: rows of signed (θi, φi, θo, φo) in degrees.
pub struct Geometry {
    pub name: &'static str,
    pub kind: Kind,
    pub doc: &'static str,
}

pub const GEOMETRIES: &[Geometry] = &[
    Geometry { name: "inplane10", kind: Kind::Brdf, doc: "in-plane, θi 0…70° and θo −80…80° in 10° steps (the paper's BRDF sampling), retro point omitted" },
    Geometry { name: "inplane5", kind: Kind::Brdf, doc: "in-plane, θi 0…70° in 10° steps, θo −85…85° in 5° steps" },
    Geometry { name: "specular", kind: Kind::Brdf, doc: "inplane10 plus near-specular θo = −θi ± 1, 2, 3, 5°" },
    Geometry { name: "hemi", kind: Kind::Brdf, doc: "out-of-plane: θi 0, 20, 40, 60°; θo 10…80° by 10°; φo every 30°" },
    Geometry { name: "azimuths", kind: Kind::Brdf, doc: "anisotropic materials: θi 20, 40, 60° at φi 0…150° by 30°; θo 10…80° by 10°, φo every 30° (both azimuths vary)" },
    Geometry { name: "offplane", kind: Kind::Brdf, doc: "sparse out-of-plane set: θi 20, 40, 60°; θo 20…80° by 20°; φo 45, 90, 135° (combine: specular+offplane)" },
    Geometry { name: "retro", kind: Kind::Brdf, doc: "inplane10 plus near-retro θo = θi ± 1, 2, 3° (retroreflective materials)" },
    Geometry { name: "ptb5", kind: Kind::Btdf, doc: "normal incidence, θt −20…20° in 5° steps, φt = 0 (PTB set 1)" },
    Geometry { name: "ptb1", kind: Kind::Btdf, doc: "normal incidence, θt −20…20° in 1° steps on φt = 0 and 90° (PTB, anisotropic samples A, D)" },
    Geometry { name: "csic", kind: Kind::Btdf, doc: "normal incidence, θt 0…80° in 10° steps (CSIC set 2)" },
    Geometry { name: "oblique", kind: Kind::Btdf, doc: "θi 0, 30, 60°; θt −80…80° in 2.5° steps, in plane" },
    Geometry { name: "grid", kind: Kind::Brdf, doc: "dense isotropic grid: θi and θo 0…85° and φo 0…180° (φi = 0) in steps of 5°, or of STEP° as grid:STEP (grid:2.5: 89,000 directions)" },
    Geometry { name: "merl", kind: Kind::Brdf, doc: "every cell centre of a full MERL table (90 θh × 90 θd × 180 φd) with both directions above the horizon: 1.1 million directions" },
];

fn steps(from: f64, to: f64, step: f64) -> Vec<f64> {
    let n = ((to - from) / step).round() as i64;
    (0..=n).map(|i| from + i as f64 * step).collect()
}

/// The rows of a named geometry (`grid` may name its step: `grid:2.5`).
pub fn geometry(name: &str) -> Result<(Kind, Vec<[f64; 4]>), String> {
    let (name, step) = geometry_name(name)?;
    let g = GEOMETRIES.iter().find(|g| g.name == name).ok_or_else(|| {
        format!(
            "unknown geometry '{name}' (known: {})",
            GEOMETRIES
                .iter()
                .map(|g| g.name)
                .collect::<Vec<_>>()
                .join(", ")
        )
    })?;
    let rows = match g.name {
        "inplane10" => inplane(&steps(-80.0, 80.0, 10.0)),
        "inplane5" => inplane(&steps(-85.0, 85.0, 5.0)),
        "specular" | "retro" => near_mirror_or_source(g.name == "specular"),
        "hemi" => hemi(),
        "azimuths" => {
            let mut rows = Vec::new();
            for pi in steps(0.0, 150.0, 30.0) {
                for ti in [20.0, 40.0, 60.0] {
                    for to in steps(10.0, 80.0, 10.0) {
                        for po in steps(0.0, 330.0, 30.0) {
                            // Not the source direction (the detector hides it).
                            if !(po == pi && (to - ti).abs() < 0.5) {
                                rows.push([ti, pi, to, po]);
                            }
                        }
                    }
                }
            }
            rows
        }
        "offplane" => {
            let mut rows = Vec::new();
            for ti in [20.0, 40.0, 60.0] {
                for to in [20.0, 40.0, 60.0, 80.0] {
                    rows.extend([45.0, 90.0, 135.0].map(|po| [ti, 0.0, to, po]));
                }
            }
            rows
        }
        "ptb5" => steps(-20.0, 20.0, 5.0)
            .into_iter()
            .map(|t| [0.0, 0.0, t, 0.0])
            .collect(),
        "ptb1" => {
            let mut rows = Vec::new();
            for phi in [0.0, 90.0] {
                rows.extend(
                    steps(-20.0, 20.0, 1.0)
                        .into_iter()
                        .filter(|&t| phi == 0.0 || t != 0.0)
                        .map(|t| [0.0, 0.0, t, phi]),
                );
            }
            rows
        }
        "csic" => steps(0.0, 80.0, 10.0)
            .into_iter()
            .map(|t| [0.0, 0.0, t, 0.0])
            .collect(),
        "oblique" => {
            let mut rows = Vec::new();
            for ti in [0.0, 30.0, 60.0] {
                rows.extend(
                    steps(-80.0, 80.0, 2.5)
                        .into_iter()
                        .map(|t| [ti, 0.0, t, 0.0]),
                );
            }
            rows
        }
        "grid" => grid(step),
        "merl" => merl_rows(),
        _ => unreachable!("every listed geometry has rows"),
    };
    Ok((g.kind, rows))
}

/// A geometry's name and its step (degrees): `grid:STEP` names the grid's, which must lie
/// in [0.25, 45]; every other name has 5.
fn geometry_name(name: &str) -> Result<(&str, f64), String> {
    match name.split_once(':') {
        Some(("grid", step)) => {
            let step: f64 = step
                .trim()
                .parse()
                .ok()
                .filter(|s: &f64| (0.25..=45.0).contains(s))
                .ok_or_else(|| format!("grid:{step}: a step in degrees in [0.25, 45]"))?;
            Ok(("grid", step))
        }
        _ => Ok((name, 5.0)),
    }
}

/// In-plane rows: θi 0…70° by 10°, θo each of `to_list`, the exact retro direction
/// omitted (the detector cannot sit on the source).
fn inplane(to_list: &[f64]) -> Vec<[f64; 4]> {
    let mut rows = Vec::new();
    for ti in steps(0.0, 70.0, 10.0) {
        for &to in to_list {
            if (to - ti).abs() < 0.5 {
                continue;
            }
            rows.push([ti, 0.0, to, 0.0]);
        }
    }
    rows
}

/// `inplane10` plus the directions a few degrees from the mirror direction (`specular`)
/// or from the source (`retro`) that it does not already hold.
fn near_mirror_or_source(specular: bool) -> Vec<[f64; 4]> {
    let mut rows = inplane(&steps(-80.0, 80.0, 10.0));
    for ti in steps(10.0, 70.0, 10.0) {
        let offsets: &[f64] = if specular {
            &[-5.0, -3.0, -2.0, -1.0, 1.0, 2.0, 3.0, 5.0]
        } else {
            &[-3.0, -2.0, -1.0, 1.0, 2.0, 3.0]
        };
        for d in offsets {
            let to = if specular { -ti + d } else { ti + d };
            if to.abs() <= 89.0 && (to.round() as i64) % 10 != 0 {
                rows.push([ti, 0.0, to, 0.0]);
            }
        }
    }
    rows
}

/// Out of plane: θi 0, 20, 40, 60°; θo 10…80° by 10°; φo every 30° (not on the source).
fn hemi() -> Vec<[f64; 4]> {
    let mut rows = Vec::new();
    for ti in [0.0, 20.0, 40.0, 60.0] {
        for to in steps(10.0, 80.0, 10.0) {
            for po in steps(0.0, 330.0, 30.0) {
                if po == 0.0 && (to - ti).abs() < 0.5 {
                    continue;
                }
                rows.push([ti, 0.0, to, po]);
            }
        }
    }
    rows
}

/// The dense isotropic grid: θi and θo 0…85° and φo 0…180° (φi = 0) by `step` degrees.
fn grid(step: f64) -> Vec<[f64; 4]> {
    let mut rows = Vec::new();
    // Polar angles up to 85°: the last multiple of the step there.
    let polar = steps(0.0, (85.0 / step).floor() * step, step);
    for &ti in &polar {
        for &to in &polar {
            // At θo = 0 every azimuth is one direction: keep it once.
            let azimuths = if to == 0.0 {
                vec![0.0]
            } else {
                steps(0.0, 180.0, step)
            };
            for po in azimuths {
                // The detector cannot sit on the source.
                if po == 0.0 && (to - ti).abs() < 1e-9 {
                    continue;
                }
                rows.push([ti, 0.0, to, po]);
            }
        }
    }
    rows
}

/// The directions of every MERL cell centre above the horizon, in the table's order, as
/// (θi, φi, θo, φo) in degrees: a synthetic set shaped like a full measured table.
fn merl_rows() -> Vec<[f64; 4]> {
    use super::readers::merl;
    let deg = |v: glam::DVec3| {
        let theta = v.z.clamp(-1.0, 1.0).acos().to_degrees();
        let phi = v.y.atan2(v.x).to_degrees().rem_euclid(360.0);
        (theta, if theta == 0.0 { 0.0 } else { phi })
    };
    (0..merl::CELLS)
        .filter_map(|idx| {
            let (th, td, pd) = merl::cell_angles(idx);
            let (wi, wo) = merl::cell_directions(th, td, pd)?;
            let ((ti, pi), (to, po)) = (deg(wi), deg(wo));
            // Reading the rows back must keep both directions above the horizon.
            (ti < 90.0 && to < 90.0).then_some([ti, pi, to, po])
        })
        .collect()
}

/// Rows of a geometry expression: one name, or names joined by `+` (their union; a
/// geometry listed twice, after the signed-angle convention, is kept once).
pub fn geometry_expr(expr: &str) -> Result<(Kind, Vec<[f64; 4]>), String> {
    let mut kind = None;
    let mut rows: Vec<[f64; 4]> = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for name in expr.split('+').map(str::trim) {
        let (k, part) = geometry(name)?;
        if kind.is_some_and(|k0| k0 != k) {
            return Err(format!("'{expr}' mixes BRDF and BTDF geometries"));
        }
        kind = Some(k);
        for r in part {
            if seen.insert(super::geometry_key(r[0], r[1], r[2], r[3], 0.0)) {
                rows.push(r);
            }
        }
    }
    Ok((kind.expect("split yields at least one name"), rows))
}
