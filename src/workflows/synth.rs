//! Synthetic datasets: a model with known parameters, measured on a goniometer geometry,
//! with metrology-like noise (relative + absolute, k = 1 uncertainties in the file).

use crate::bsdf::Model;
use crate::data::{Dataset, Kind, RawRow, ReadOptions};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

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
    use crate::data::readers::merl;
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
            if seen.insert(crate::data::geometry_key(r[0], r[1], r[2], r[3], 0.0)) {
                rows.push(r);
            }
        }
    }
    Ok((kind.expect("split yields at least one name"), rows))
}

/// Noise model: u = sqrt((rel·f)² + abs²), value = f + u·n with n ~ N(0,1) clipped to ±3
/// (so a value is never negative beyond 3u, which a reader would reject).
#[derive(Clone, Copy, Debug)]
pub struct Noise {
    pub rel: f64,
    pub abs: f64,
}

/// Synthesize a dataset from `model` with flat parameters `flat`.
pub fn synthesize(
    model: &Model,
    flat: &[f64],
    rows: &[[f64; 4]],
    wavelengths: &[f64],
    noise: Noise,
    seed: u64,
    material: &str,
) -> Result<Dataset, String> {
    synthesize_angular(model, flat, rows, wavelengths, noise, 0.0, seed, material)
}

/// [`synthesize`] with a goniometer's angular uncertainty: a standard uncertainty of
/// `angle_deg` degrees on θi and on θo propagates as u_θ² = (δ·∂f/∂θi)² + (δ·∂f/∂θo)²
/// (central differences), added in quadrature to the relative and absolute terms — so
/// the uncertainty grows on the flanks of specular and transmission peaks, as in
/// metrology data. With `angle_deg = 0` this is exactly [`synthesize`].
#[allow(clippy::too_many_arguments)]
pub fn synthesize_angular(
    model: &Model,
    flat: &[f64],
    rows: &[[f64; 4]],
    wavelengths: &[f64],
    noise: Noise,
    angle_deg: f64,
    seed: u64,
    material: &str,
) -> Result<Dataset, String> {
    check_request(model, wavelengths, noise, angle_deg)?;
    let raw = placeholder_rows(rows, wavelengths);
    let opts = ReadOptions::default();
    let mut ds = Dataset::from_rows(model.kind, material, &raw, "<synth>", &opts)
        .map_err(|e| e.to_string())?;
    if model.axes.len() > 1 && model.axes != ds.axes {
        return Err(format!(
            "model compiled for planes {:?} but the geometry has {:?}",
            model.axes, ds.axes
        ));
    }
    // Channels come back sorted; map each to the model's channel of the same wavelength.
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let normal = Normal::new(0.0, 1.0).expect("unit normal");
    for s in &mut ds.samples {
        let ch = wavelengths
            .iter()
            .position(|&w| w == s.wavelength_nm)
            .expect("wavelength present");
        let group = if model.axes.len() > 1 {
            s.axis * model.channels + ch
        } else {
            ch
        };
        let f = model.eval(flat, group, s.wi(), s.wo());
        if !f.is_finite() {
            return Err(format!(
                "model {} is not finite at line {}",
                model.spec, s.line
            ));
        }
        let mut u2 = (noise.rel * f).powi(2) + noise.abs.powi(2);
        if angle_deg > 0.0 {
            let ua2 = angular_variance(model, flat, group, s, angle_deg);
            if ua2.is_finite() {
                u2 += ua2;
            }
        }
        let u = u2.sqrt();
        if u <= 0.0 {
            return Err(format!(
                "the model is 0 at θi = {:.1}°, θo = {:.1}°, so the noise gives a zero uncertainty there: use an absolute floor (--noise REL,ABS with ABS > 0)",
                s.theta_i.to_degrees(),
                s.theta_o.to_degrees()
            ));
        }
        let n: f64 = normal.sample(&mut rng);
        s.value = f + u * n.clamp(-3.0, 3.0);
        s.uncertainty = u;
        s.line = 0;
    }
    describe(&mut ds, model, flat, noise, angle_deg, seed, material);
    Ok(ds)
}

/// Why the wavelengths, noise or angular uncertainty cannot make a data set, if they
/// cannot.
fn check_request(
    model: &Model,
    wavelengths: &[f64],
    noise: Noise,
    angle_deg: f64,
) -> Result<(), String> {
    if !(0.0..10.0).contains(&angle_deg) {
        return Err(format!(
            "angular uncertainty {angle_deg}° must be in [0, 10)"
        ));
    }
    if wavelengths.windows(2).any(|w| w[0] >= w[1]) {
        return Err(
            "give the wavelengths in ascending order (channels are numbered by wavelength)".into(),
        );
    }
    if wavelengths.len() != model.channels {
        return Err(format!(
            "{} wavelengths given for a model compiled for {} channels",
            wavelengths.len(),
            model.channels
        ));
    }
    if !(noise.rel >= 0.0 && noise.abs >= 0.0) || noise.rel + noise.abs <= 0.0 {
        return Err(
            "--noise needs REL,ABS ≥ 0 with at least one positive (uncertainties must be > 0)"
                .into(),
        );
    }
    Ok(())
}

/// One raw row per geometry row and wavelength (line numbers from 1), with placeholder
/// values for the noise to replace.
fn placeholder_rows(rows: &[[f64; 4]], wavelengths: &[f64]) -> Vec<(usize, RawRow)> {
    let mut raw = Vec::new();
    for (i, r) in rows.iter().enumerate() {
        for (c, &wl) in wavelengths.iter().enumerate() {
            raw.push((i * wavelengths.len() + c + 1, RawRow::placeholder(*r, wl)));
        }
    }
    raw
}

/// u_θ² = (δ·∂f/∂θi)² + (δ·∂f/∂θo)² at sample `s` (scalar-view group `group`), δ =
/// `angle_deg`, by central differences of 0.05° (not finite where the model is not).
fn angular_variance(
    model: &Model,
    flat: &[f64],
    group: usize,
    s: &crate::data::Sample,
    angle_deg: f64,
) -> f64 {
    let h = 0.05f64.to_radians();
    let dir = |t: f64, p: f64, below: bool| {
        let mut d = crate::math::direction(t, p);
        if below {
            d.z = -d.z;
        }
        d
    };
    let below = model.kind == Kind::Btdf;
    let at = |ti: f64, to: f64| {
        model.eval(
            flat,
            group,
            dir(ti, s.phi_i, false),
            dir(to, s.phi_o, below),
        )
    };
    let dfo = (at(s.theta_i, s.theta_o + h) - at(s.theta_i, s.theta_o - h)) / (2.0 * h);
    let dfi = (at(s.theta_i + h, s.theta_o) - at(s.theta_i - h, s.theta_o)) / (2.0 * h);
    let d = angle_deg.to_radians();
    (d * dfo).powi(2) + (d * dfi).powi(2)
}

/// The synthetic data set's source, material and header: what made it.
fn describe(
    ds: &mut Dataset,
    model: &Model,
    flat: &[f64],
    noise: Noise,
    angle_deg: f64,
    seed: u64,
    material: &str,
) {
    ds.source = std::path::PathBuf::from(material);
    ds.meta.insert("material".into(), material.into());
    ds.meta.insert("kind".into(), model.kind.to_string());
    ds.meta
        .insert("source".into(), "synthetic (bsdfit synth)".into());
    ds.meta.insert("synth_model".into(), model.spec.clone());
    ds.meta.insert(
        "synth_params".into(),
        model
            .flat_names()
            .iter()
            .zip(flat)
            .map(|(n, v)| format!("{n}={v}"))
            .collect::<Vec<_>>()
            .join(" "),
    );
    let angular = if angle_deg > 0.0 {
        format!(" angle_deg={angle_deg}")
    } else {
        String::new()
    };
    ds.meta.insert(
        "synth_noise".into(),
        format!("rel={} abs={}{angular}", noise.rel, noise.abs),
    );
    ds.meta.insert("synth_seed".into(), seed.to_string());
}
