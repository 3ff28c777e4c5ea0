//! Synthetic datasets: a model with known parameters, measured on a goniometer geometry,
//! with metrology-like noise (relative + absolute, k = 1 uncertainties in the file).

use crate::bsdf::Model;
use crate::data::{Dataset, Kind, RawRow, ReadOptions};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

pub use crate::data::geometries::{geometry, geometry_expr, Geometry, GEOMETRIES};

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

/// The model `spec` with the parameters `params` (`name=value,…`, as `synth`; the others at
/// their defaults) at the geometries `rows` (signed θi, φi, θo, φo in degrees; θo the
/// transmission angle for a BTDF), at one wavelength, evaluated by `backend`: one value per
/// row, in order. The rows are checked as a data file's are (angles in range, finite).
pub fn evaluate(
    spec: &str,
    params: &str,
    rows: &[[f64; 4]],
    backend: &dyn crate::engine::Backend,
) -> anyhow::Result<Vec<f64>> {
    use crate::engine::loss::{Loss, Metric, Weights};
    let kind = crate::bsdf::spec_kind(spec)?;
    if rows.is_empty() {
        return Ok(Vec::new());
    }
    const WAVELENGTH: f64 = 550.0;
    let raw = placeholder_rows(rows, &[WAVELENGTH]);
    let data = Dataset::from_rows(kind, "evaluate", &raw, "geometry", &ReadOptions::default())?;
    let model = Model::for_data(spec, &data)?;
    let flat = model.params_from_assignments(params)?;
    let loss = Loss::new(Metric::Chi2, Weights::Uniform);
    let mut eval = backend.prepare(crate::engine::Problem {
        model: &model,
        data: &data,
        loss,
    })?;
    let values = eval.values(&flat)?;
    // Samples keep their row's 1-based line: put each value back in its row's place.
    let mut out = vec![f64::NAN; rows.len()];
    for (s, v) in data.samples.iter().zip(values) {
        out[s.line as usize - 1] = v;
    }
    Ok(out)
}
