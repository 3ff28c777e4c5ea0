//! The fitted data-driven factors at their knots, with bands: the NDF of a model with
//! `+ndf` ([`crate::bsdf::ndf`]: D at each knot's angle), the highlight's Fresnel curve
//! of one with `+fresnel` ([`crate::bsdf::fresnel`]: k_s F e^s per channel at each knot's
//! θd) and the diffuse body's profile of one with `+body` ([`crate::bsdf::body`]: ρ(θ) at
//! each knot's θ), each with the standard uncertainty of its logarithm propagated from the
//! fit's covariance with the smoothness prior's information, and whether the data see the
//! lobe (or the body) there or the prior sets it.

use crate::bsdf::ndf::{knot_angle, knot_degrees, NdfTable, KNOTS};
use crate::bsdf::Model;
use crate::data::Dataset;
use crate::inference::covariance::Covariance;

/// One knot of a fitted data-driven NDF, for reports: the normalised D at the knot's
/// angle with its standard uncertainty in ln D, and whether the data see the lobe there.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct KnotBand {
    /// θ_k in degrees.
    pub theta_deg: f64,
    /// D(θ_k) (sr⁻¹), normalised: ∫ D cos θm dω = 1.
    pub d: f64,
    /// Standard uncertainty of ln D(θ_k), linearised from the fit's covariance with the
    /// prior's information ([`Covariance::with_prior`]);
    /// None without it. Where the knot is not measured it is the prior's spread, and a
    /// linearisation of what is only an upper bound.
    pub sigma_ln_d: Option<f64>,
    /// The lobe's own signal near the knot: √Σ (f_lobe/u)² over the samples whose half
    /// vector lies between the knot's neighbours, f_lobe the highlight's part of the
    /// fitted value.
    pub signal: f64,
    /// Whether that signal is at least [`MEASURED_SIGNAL`]: the data see the lobe at this
    /// knot. Else the smoothness prior sets it (no half vectors there, or a lobe too faint
    /// against the uncertainties), and D there is not measured.
    pub measured: bool,
}

/// The lobe's signal near a knot from which D there counts as measured: a 3σ detection.
/// (A weak prior lets a few knots absorb noise where the lobe is absent; such a fitted
/// lobe shows a signal of about 1 to 3, the square root of the few degrees of freedom it
/// took.)
pub const MEASURED_SIGNAL: f64 = 3.0;

/// The fitted D at the knots of each data-driven NDF of `model` fitted to `data` (one
/// list per lobe `+ndf` made data-driven, named by its knots' stem: `ndf` in `ggx+ndf`,
/// `lobe.ndf` in `fa(B)+ndf`, `ndf_c` for a coat).
pub fn bands(
    model: &Model,
    data: &Dataset,
    flat: &[f64],
    cov: &Covariance,
) -> Vec<(String, Vec<KnotBand>)> {
    let find = |name: &str| model.params.iter().find(|p| p.name == name);
    let mut out = Vec::new();
    // The lobes' names: the knots' stem, the roughness and the amplitude (`ggx`, `fa`'s
    // highlight under `lobe.`, and a coat's).
    const LOBES: [(&str, &str, &str); 2] = [("ndf", "alpha", "ks"), ("ndf_c", "alpha_c", "kc")];
    for p in model.params.iter().filter(|p| p.decl.knot) {
        let Some((stem, alpha, ks, prefix)) = LOBES.iter().find_map(|&(stem, alpha, ks)| {
            let prefix = p.name.strip_suffix(&format!("{stem}1"))?;
            Some((stem, alpha, ks, prefix.to_string()))
        }) else {
            continue;
        };
        let (Some(alpha), Some(ks)) = (
            find(&format!("{prefix}{alpha}")),
            find(&format!("{prefix}{ks}")),
        ) else {
            continue;
        };
        let Some(knots) = (1..KNOTS)
            .map(|k| find(&format!("{prefix}{stem}{k}")).map(|q| q.index))
            .collect::<Option<Vec<usize>>>()
        else {
            continue;
        };
        let name = format!("{prefix}{stem}");
        let params: Vec<usize> = std::iter::once(alpha.index)
            .chain(knots.iter().copied())
            .collect();
        // ln D at every knot from one table of (α, knots).
        let ln_d = |v: &[f64]| -> [f64; KNOTS] {
            let s: [f64; KNOTS] = std::array::from_fn(|i| if i == 0 { 0.0 } else { v[i] });
            let table = NdfTable::new(v[0], s);
            std::array::from_fn(|k| {
                // At 90° D is its limit from above (d is 0 at m.z = 0, below the surface).
                let (c, s2) = knot_angle(k);
                table.d(glam::DVec3::new(s2.sqrt(), 0.0, c.max(1e-9))).ln()
            })
        };
        let values: Vec<f64> = params.iter().map(|&j| flat[j]).collect();
        let at = ln_d(&values);
        // ∂ ln D(θ_k) / ∂ parameter a, by central differences in α and the knots, through N.
        let grad: Vec<[f64; KNOTS]> = (0..params.len())
            .map(|a| {
                let h = 1e-6 * values[a].abs().max(1e-3);
                let (mut up, mut down) = (values.clone(), values.clone());
                up[a] += h;
                down[a] -= h;
                let (up, down) = (ln_d(&up), ln_d(&down));
                std::array::from_fn(|k| (up[k] - down[k]) / (2.0 * h))
            })
            .collect();
        let signal: Vec<(f64, f64)> = lobe_signal(
            model,
            data,
            flat,
            ks.index..ks.index + ks.width(model.channels),
        )
        .into_iter()
        .map(|s| (s.theta_h_deg, s.z))
        .collect();
        let degrees = knot_degrees();
        let rows = (0..KNOTS)
            .map(|k| {
                let g: Vec<(usize, f64)> = params
                    .iter()
                    .enumerate()
                    .map(|(a, &j)| (j, grad[a][k]))
                    .collect();
                let sigma = propagated_sd(cov, &g);
                let (lo, hi) = neighbours(&degrees, k);
                let s2: f64 = signal
                    .iter()
                    .filter(|(deg, _)| *deg >= lo && *deg <= hi)
                    .fold(0.0, |a, (_, z)| a + z * z);
                KnotBand {
                    theta_deg: degrees[k],
                    d: at[k].exp(),
                    sigma_ln_d: sigma,
                    signal: s2.sqrt(),
                    measured: s2.sqrt() >= MEASURED_SIGNAL,
                }
            })
            .collect();
        out.push((name, rows));
    }
    out
}

/// The angles of knot k's neighbours (from the normal for the first, to the last knot for
/// the last): a sample between them counts toward the knot's signal.
fn neighbours(degrees: &[f64], k: usize) -> (f64, f64) {
    (
        degrees[k.saturating_sub(1)],
        degrees[(k + 1).min(degrees.len() - 1)],
    )
}

/// The standard uncertainty of a quantity whose gradient is `grad` ((flat index,
/// derivative) pairs), from the covariance with the prior's information; None without it.
fn propagated_sd(cov: &Covariance, grad: &[(usize, f64)]) -> Option<f64> {
    cov.with_prior.as_ref().map(|m| {
        let mut var = 0.0;
        for &(a, ga) in grad {
            for &(b, gb) in grad {
                var += ga * gb * m[a][b];
            }
        }
        var.max(0.0).sqrt()
    })
}

/// One sample's view of the highlight: the half vector's angle θh and the angle θd
/// between ωi and it (degrees), the sample's channel, and the highlight's part of the
/// fitted value in units of the sample's uncertainty, f − f(k_s = 0) (the lobe is k_s
/// times a kernel; what remains at k_s = 0 is the rest of the model).
struct LobeSample {
    theta_h_deg: f64,
    theta_d_deg: f64,
    channel: usize,
    z: f64,
}

fn lobe_signal(
    model: &Model,
    data: &Dataset,
    flat: &[f64],
    ks: std::ops::Range<usize>,
) -> Vec<LobeSample> {
    let mut off = flat.to_vec();
    off[ks].fill(0.0);
    data.samples
        .iter()
        .map(|s| {
            let (wi, wo) = (s.wi(), s.wo());
            let g = model.group_of(s);
            let lobe = model.eval(flat, g, wi, wo) - model.eval(&off, g, wi, wo);
            let h = wi + wo;
            let cos_d = (wi.dot(h) / h.length().max(1e-300)).clamp(-1.0, 1.0);
            LobeSample {
                theta_h_deg: (h.x.hypot(h.y)).atan2(h.z).to_degrees(),
                theta_d_deg: cos_d.acos().to_degrees(),
                channel: s.channel,
                z: lobe / s.uncertainty,
            }
        })
        .collect()
}

/// One knot of a fitted data-driven Fresnel curve in one channel, for reports: the
/// highlight's reflectance factor k_s F(θd; η) e^{s(θd)} at the knot's θd with its
/// standard uncertainty in ln, and whether the data see the lobe there.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct FresnelBand {
    /// θd of the knot, degrees.
    pub theta_deg: f64,
    /// k_s F(θd; η) e^{s(θd)}: the highlight's Fresnel factor with its scale.
    pub f: f64,
    /// Standard uncertainty of ln f, as [`KnotBand::sigma_ln_d`].
    pub sigma_ln_f: Option<f64>,
    /// The lobe's own signal in this channel near the knot: √Σ (f_lobe/u)² over the
    /// channel's samples whose θd lies between the knot's neighbours.
    pub signal: f64,
    /// Whether that signal is at least [`MEASURED_SIGNAL`].
    pub measured: bool,
}

/// The fitted Fresnel curve of each lobe `+fresnel` made data-driven, per channel: (the
/// knots' stem — `fresnel`, `lobe.fresnel`, or `fresnel_c` for a coat — the channel, its
/// knots).
pub fn fresnel_bands(
    model: &Model,
    data: &Dataset,
    flat: &[f64],
    cov: &Covariance,
) -> Vec<(String, usize, Vec<FresnelBand>)> {
    use crate::bsdf::fresnel::{knot_degrees, KNOTS};
    let find = |name: &str| model.params.iter().find(|p| p.name == name);
    let degrees = knot_degrees();
    let mut out = Vec::new();
    // The lobes: the knots' stem, the amplitude and the index of the reference curve
    // (`ggx`, `fa`'s highlight under `lobe.`; a coat's reference is F ≡ 1).
    const LOBES: [(&str, &str, Option<&str>); 2] =
        [("fresnel", "ks", Some("eta")), ("fresnel_c", "kc", None)];
    for p in model.params.iter().filter(|p| p.decl.knot) {
        let Some((stem, ks, eta, prefix)) = LOBES.iter().find_map(|&(stem, ks, eta)| {
            let prefix = p.name.strip_suffix(&format!("{stem}1"))?;
            Some((stem, ks, eta, prefix.to_string()))
        }) else {
            continue;
        };
        let Some(ks) = find(&format!("{prefix}{ks}")) else {
            continue;
        };
        let eta = eta.and_then(|e| find(&format!("{prefix}{e}")));
        let Some(knots) = (1..KNOTS)
            .map(|k| find(&format!("{prefix}{stem}{k}")))
            .collect::<Option<Vec<_>>>()
        else {
            continue;
        };
        let signal = lobe_signal(
            model,
            data,
            flat,
            ks.index..ks.index + ks.width(model.channels),
        );
        let eta_v = eta.map(|e| flat[e.index]);
        // ln F(cos θ; η) of the reference curve (0 for a coat's F ≡ 1).
        let ln_fresnel = |c: f64, eta: Option<f64>| {
            eta.map_or(0.0, |eta| crate::math::fresnel_dielectric(c, eta).ln())
        };
        for c in 0..model.channels {
            let at = |q: &crate::bsdf::FlatParam| {
                q.index + if q.width(model.channels) > 1 { c } else { 0 }
            };
            let rows = (0..KNOTS)
                .map(|k| {
                    let cos = 1.0 - k as f64 / (KNOTS - 1) as f64;
                    let s_k = if k == 0 { 0.0 } else { flat[at(knots[k - 1])] };
                    let ks_v = flat[at(ks)];
                    let ln_f = ks_v.ln() + ln_fresnel(cos, eta_v) + s_k;
                    // ∂ ln f: 1/k_s, ∂ ln F/∂η, and 1 for the knot's own value.
                    let mut grad = vec![(at(ks), 1.0 / ks_v)];
                    if let (Some(eta), Some(v)) = (eta, eta_v) {
                        let h = 1e-6 * v;
                        let slope = (ln_fresnel(cos, Some(v + h)) - ln_fresnel(cos, Some(v - h)))
                            / (2.0 * h);
                        grad.push((eta.index, slope));
                    }
                    if k > 0 {
                        grad.push((at(knots[k - 1]), 1.0));
                    }
                    let sigma = propagated_sd(cov, &grad);
                    let (lo, hi) = neighbours(&degrees, k);
                    let s2: f64 = signal
                        .iter()
                        .filter(|s| s.channel == c && s.theta_d_deg >= lo && s.theta_d_deg <= hi)
                        .fold(0.0, |a, s| a + s.z * s.z);
                    FresnelBand {
                        theta_deg: degrees[k],
                        f: ln_f.exp(),
                        sigma_ln_f: sigma,
                        signal: s2.sqrt(),
                        measured: s2.sqrt() >= MEASURED_SIGNAL,
                    }
                })
                .collect();
            out.push((format!("{prefix}{stem}"), c, rows));
        }
    }
    out
}

/// One knot of a fitted data-driven body profile (`+body`), for reports: ρ(θ) at the
/// knot's θ (the body's value is f_B ρ(θi) ρ(θo), ρ(0) = 1) with its standard
/// uncertainty in ln, and whether the data see the body there.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct BodyBand {
    /// θ of the knot, degrees.
    pub theta_deg: f64,
    /// ρ(θ) = e^{s(θ)}.
    pub rho: f64,
    /// Standard uncertainty of ln ρ, as [`KnotBand::sigma_ln_d`] (0 at the normal, where
    /// ρ = 1 by definition).
    pub sigma_ln_rho: Option<f64>,
    /// The body's own signal near the knot: √Σ (f_body/u)² over the samples whose θi or
    /// θo lies between the knot's neighbours, f_body the diffuse base's part of the
    /// fitted value (f − f at the base's albedo 0).
    pub signal: f64,
    /// Whether that signal is at least [`MEASURED_SIGNAL`].
    pub measured: bool,
}

/// The fitted profile of each diffuse base `+body` reshaped: (the knots' stem — `body`,
/// or `base.body` under a layer — its knots).
pub fn body_bands(
    model: &Model,
    data: &Dataset,
    flat: &[f64],
    cov: &Covariance,
) -> Vec<(String, Vec<BodyBand>)> {
    use crate::bsdf::fresnel::{knot_degrees, KNOTS};
    let find = |name: &str| model.params.iter().find(|p| p.name == name);
    let degrees = knot_degrees();
    let mut out = Vec::new();
    for p in model.params.iter().filter(|p| p.decl.knot) {
        let Some(prefix) = p.name.strip_suffix("body1") else {
            continue;
        };
        let (Some(rho), Some(knots)) = (
            find(&format!("{prefix}rho")),
            (1..KNOTS)
                .map(|k| find(&format!("{prefix}body{k}")).map(|q| q.index))
                .collect::<Option<Vec<usize>>>(),
        ) else {
            continue;
        };
        // The body's part of each sample's value, in units of its uncertainty.
        let mut off = flat.to_vec();
        off[rho.index..rho.index + rho.width(model.channels)].fill(0.0);
        let body: Vec<(f64, f64, f64)> = data
            .samples
            .iter()
            .map(|s| {
                let (wi, wo) = (s.wi(), s.wo());
                let g = model.group_of(s);
                let z = (model.eval(flat, g, wi, wo) - model.eval(&off, g, wi, wo)) / s.uncertainty;
                (
                    s.theta_i.abs().to_degrees(),
                    s.theta_o.abs().to_degrees(),
                    z,
                )
            })
            .collect();
        let rows = (0..KNOTS)
            .map(|k| {
                let s_k = if k == 0 { 0.0 } else { flat[knots[k - 1]] };
                let grad: Vec<(usize, f64)> = if k == 0 {
                    vec![]
                } else {
                    vec![(knots[k - 1], 1.0)]
                };
                let (lo, hi) = neighbours(&degrees, k);
                let near = |t: f64| t >= lo && t <= hi;
                let s2: f64 = body
                    .iter()
                    .filter(|(ti, to, _)| near(*ti) || near(*to))
                    .fold(0.0, |a, (_, _, z)| a + z * z);
                BodyBand {
                    theta_deg: degrees[k],
                    rho: s_k.exp(),
                    sigma_ln_rho: propagated_sd(cov, &grad),
                    signal: s2.sqrt(),
                    measured: s2.sqrt() >= MEASURED_SIGNAL,
                }
            })
            .collect();
        out.push((format!("{prefix}body"), rows));
    }
    out
}
