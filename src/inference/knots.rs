//! The fitted data-driven factors at their knots, with bands: the NDF of a model with
//! `+ndf` ([`crate::bsdf::ndf`]: D at each knot's angle), the highlight's Fresnel curve
//! of one with `+fresnel` ([`crate::bsdf::fresnel`]: k_s F e^s per channel at each knot's
//! θd) and the diffuse body's profile of one with `+body` ([`crate::bsdf::body`]: ρ(θ) at
//! each knot's θ), each with the standard uncertainty of its logarithm propagated from the
//! fit's covariance with the smoothness prior's information, and whether the data see the
//! lobe (or the body) there or the prior sets it. With Monte Carlo replicas (`fit --mc`),
//! each knot also gets the replicas' spread ([`KnotMc`], [`mc_bands`]).

use crate::bsdf::ndf::{knot_angle, NdfTable, KNOTS};
use crate::bsdf::Model;
use crate::data::{Dataset, Kind};
use crate::inference::covariance::Covariance;
use crate::inference::mc_summary::{shortest_interval, COVERAGE};
use std::ops::Range;

/// Which tabulated factor a [`Factor`] is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FactorKind {
    Ndf,
    Fresnel,
    Body,
}

/// One tabulated factor of a model, located in its flat parameter vector: its knots'
/// stem (`ndf`, `lobe.ndf`, `ndf_c`; `fresnel`, `lobe.fresnel`, `fresnel_c`; `body`,
/// `base.body`), the channel for a per-channel Fresnel curve, and the flat indices its
/// value at the knots depends on.
#[derive(Clone, Debug)]
pub struct Factor {
    pub kind: FactorKind,
    pub name: String,
    pub channel: Option<usize>,
    /// The amplitude whose part of the fitted value is the factor's signal (k_s, k_c or
    /// the body's albedo ρ, all channels); empty for a transmission lobe, which has none
    /// of its own: its part is the model's whole value (with `+diffuse`, the floor's too).
    amplitude: Range<usize>,
    /// A transmission lobe's η (flat index): its samples' half vector is the refraction
    /// one, −(ωi + η ωo) normalised (Walter 2007, Eq. 16), not ωi + ωo.
    refraction_eta: Option<usize>,
    inputs: Inputs,
}

/// The flat indices a factor's value at its knots is computed from.
#[derive(Clone, Debug)]
enum Inputs {
    /// α, then the knots 1..K (knot 0 is 0 by the table's normalisation).
    Ndf { alpha: usize, knots: Vec<usize> },
    /// The amplitude k_s (this channel), η of the reference curve (a coat's is F ≡ 1),
    /// then the knots 1..K.
    Fresnel {
        ks: usize,
        eta: Option<usize>,
        knots: Vec<usize>,
    },
    /// The knots 1..K (ρ(0) = 1).
    Body { knots: Vec<usize> },
}

impl Factor {
    /// Every tabulated factor of `model`: its NDFs, then its Fresnel curves (channel by
    /// channel), then its body profiles, each in the order of the model's parameters.
    pub fn all(model: &Model) -> Vec<Factor> {
        let find = |name: &str| model.params.iter().find(|p| p.name == name);
        let knots_of = |stem: &str, count: usize| {
            (1..count)
                .map(|k| find(&format!("{stem}{k}")))
                .collect::<Option<Vec<_>>>()
        };
        let range = |p: &crate::bsdf::FlatParam| p.index..p.index + p.width(model.channels);
        // Each tabulated function whose stem is among `stems`, found by its first knot
        // `{prefix}{stem}1`: (the stem's index in `stems`, the role prefix).
        let found = |stems: &[&str]| -> Vec<(usize, String)> {
            let knotted = model.params.iter().filter(|p| p.decl.knot);
            knotted
                .filter_map(|p| {
                    stems.iter().enumerate().find_map(|(i, s)| {
                        Some((i, p.name.strip_suffix(&format!("{s}1"))?.to_string()))
                    })
                })
                .collect()
        };
        let mut out = Vec::new();
        // The lobes: the knots' stem, the roughness and the amplitude (`ggx`, `fa`'s
        // highlight under `lobe.`, and a coat's).
        const NDF_LOBES: [(&str, &str, &str); 2] =
            [("ndf", "alpha", "ks"), ("ndf_c", "alpha_c", "kc")];
        for (i, prefix) in found(&NDF_LOBES.map(|l| l.0)) {
            let (stem, alpha, ks) = NDF_LOBES[i];
            let name = format!("{prefix}{stem}");
            let (Some(alpha), Some(knots)) =
                (find(&format!("{prefix}{alpha}")), knots_of(&name, KNOTS))
            else {
                continue;
            };
            // A reflection lobe's amplitude, or a transmission lobe's η (`btdf(tr)+ndf`).
            let (amplitude, refraction_eta) = match model.kind {
                Kind::Brdf => match find(&format!("{prefix}{ks}")) {
                    Some(ks) => (range(ks), None),
                    None => continue,
                },
                Kind::Btdf => match find(&format!("{prefix}eta")) {
                    Some(eta) => (0..0, Some(eta.index)),
                    None => continue,
                },
            };
            out.push(Factor {
                kind: FactorKind::Ndf,
                name,
                channel: None,
                amplitude,
                refraction_eta,
                inputs: Inputs::Ndf {
                    alpha: alpha.index,
                    knots: knots.iter().map(|q| q.index).collect(),
                },
            });
        }
        // The lobes: the knots' stem, the amplitude and the reference curve's η (`ggx`,
        // `fa`'s highlight under `lobe.`; a coat's reference is F ≡ 1).
        const FRESNEL_LOBES: [(&str, &str, Option<&str>); 2] =
            [("fresnel", "ks", Some("eta")), ("fresnel_c", "kc", None)];
        let fresnel_knots = crate::bsdf::fresnel::KNOTS;
        for (i, prefix) in found(&FRESNEL_LOBES.map(|l| l.0)) {
            let (stem, ks, eta) = FRESNEL_LOBES[i];
            let name = format!("{prefix}{stem}");
            let (Some(ks), Some(knots)) = (
                find(&format!("{prefix}{ks}")),
                knots_of(&name, fresnel_knots),
            ) else {
                continue;
            };
            let eta = eta.and_then(|e| find(&format!("{prefix}{e}")));
            for c in 0..model.channels {
                // A per-channel parameter's value in channel c.
                let at = |q: &crate::bsdf::FlatParam| {
                    q.index + if q.width(model.channels) > 1 { c } else { 0 }
                };
                out.push(Factor {
                    kind: FactorKind::Fresnel,
                    name: name.clone(),
                    channel: Some(c),
                    amplitude: range(ks),
                    refraction_eta: None,
                    inputs: Inputs::Fresnel {
                        ks: at(ks),
                        eta: eta.map(|e| e.index),
                        knots: knots.iter().map(|q| at(q)).collect(),
                    },
                });
            }
        }
        for (_, prefix) in found(&["body"]) {
            let name = format!("{prefix}body");
            if let (Some(rho), Some(knots)) = (
                find(&format!("{prefix}rho")),
                knots_of(&name, crate::bsdf::fresnel::KNOTS),
            ) {
                out.push(Factor {
                    kind: FactorKind::Body,
                    name,
                    channel: None,
                    amplitude: range(rho),
                    refraction_eta: None,
                    inputs: Inputs::Body {
                        knots: knots.iter().map(|q| q.index).collect(),
                    },
                });
            }
        }
        out
    }

    /// The flat indices of the analytic parameters the factor's value depends on besides
    /// its knots (α; k_s and η; none for a body).
    pub fn analytic_inputs(&self) -> Vec<usize> {
        match &self.inputs {
            Inputs::Ndf { alpha, .. } => vec![*alpha],
            Inputs::Fresnel { ks, eta, .. } => std::iter::once(*ks).chain(*eta).collect(),
            Inputs::Body { .. } => vec![],
        }
    }

    /// The flat indices the factor's value depends on.
    fn input_indices(&self) -> Vec<usize> {
        match &self.inputs {
            Inputs::Ndf { alpha, knots } => std::iter::once(*alpha).chain(knots.clone()).collect(),
            Inputs::Fresnel { ks, eta, knots } => std::iter::once(*ks)
                .chain(*eta)
                .chain(knots.clone())
                .collect(),
            Inputs::Body { knots } => knots.clone(),
        }
    }

    /// The logarithm of the factor at each knot, for the flat parameters `flat`: ln D
    /// (normalised), ln k_s F(θd; η) e^{s(θd)}, or ln ρ(θ) = s(θ).
    pub fn ln_values(&self, flat: &[f64]) -> Vec<f64> {
        // A knot's value, knot 0 being 0 by the tables' normalisation.
        let knot = |knots: &[usize], k: usize| if k == 0 { 0.0 } else { flat[knots[k - 1]] };
        match &self.inputs {
            Inputs::Ndf { alpha, knots } => {
                let s: [f64; KNOTS] = std::array::from_fn(|k| knot(knots, k));
                let table = NdfTable::new(flat[*alpha], s);
                (0..KNOTS)
                    .map(|k| {
                        // At 90° D is its limit from above (d is 0 at m.z = 0, below the
                        // surface).
                        let (c, s2) = knot_angle(k);
                        table.d(glam::DVec3::new(s2.sqrt(), 0.0, c.max(1e-9))).ln()
                    })
                    .collect()
            }
            Inputs::Fresnel { ks, eta, knots } => {
                let count = knots.len() + 1;
                (0..count)
                    .map(|k| {
                        let cos = 1.0 - k as f64 / (count - 1) as f64;
                        // ln F(cos θd; η) of the reference curve (0 for a coat's F ≡ 1).
                        let ln_f =
                            eta.map_or(0.0, |e| crate::math::fresnel_dielectric(cos, flat[e]).ln());
                        flat[*ks].ln() + ln_f + knot(knots, k)
                    })
                    .collect()
            }
            Inputs::Body { knots } => (0..=knots.len()).map(|k| knot(knots, k)).collect(),
        }
    }

    /// Each knot's data share ([`Covariance::data_share`]); None for the first knot (fixed
    /// at 0 by the factor's definition) and without the prior's covariance.
    fn shares(&self, cov: &Covariance) -> Vec<Option<f64>> {
        let knots = match &self.inputs {
            Inputs::Ndf { knots, .. } | Inputs::Fresnel { knots, .. } | Inputs::Body { knots } => {
                knots
            }
        };
        let share = |j: usize| cov.data_share.as_ref().map(|v| v[j]);
        std::iter::once(None)
            .chain(knots.iter().map(|&j| share(j)))
            .collect()
    }

    /// The knots' angles in degrees (θm, θd or θ).
    pub fn degrees(&self) -> Vec<f64> {
        match self.kind {
            FactorKind::Ndf => crate::bsdf::ndf::knot_degrees().to_vec(),
            FactorKind::Fresnel | FactorKind::Body => crate::bsdf::fresnel::knot_degrees().to_vec(),
        }
    }

    /// The values at the knots (`ln_values` exponentiated) with the standard uncertainty
    /// of each one's logarithm propagated from the covariance with the prior's
    /// information (central differences in the factor's inputs).
    fn values_and_sd(&self, flat: &[f64], cov: &Covariance) -> Vec<(f64, Option<f64>)> {
        let at = self.ln_values(flat);
        let grads: Vec<(usize, Vec<f64>)> = self
            .input_indices()
            .into_iter()
            .map(|j| {
                let h = 1e-6 * flat[j].abs().max(1e-3);
                let (mut up, mut down) = (flat.to_vec(), flat.to_vec());
                up[j] += h;
                down[j] -= h;
                let (up, down) = (self.ln_values(&up), self.ln_values(&down));
                (
                    j,
                    up.iter()
                        .zip(&down)
                        .map(|(u, d)| (u - d) / (2.0 * h))
                        .collect(),
                )
            })
            .collect();
        at.iter()
            .enumerate()
            .map(|(k, v)| {
                let g: Vec<(usize, f64)> = grads.iter().map(|(j, d)| (*j, d[k])).collect();
                (v.exp(), propagated_sd(cov, &g))
            })
            .collect()
    }
}

/// The spread of a knot's value over Monte Carlo replicas (`fit --mc N`): the standard
/// deviation of its logarithm and the 95 % shortest interval of the value.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct KnotMc {
    /// Standard deviation of the logarithm over the replicas.
    pub sd_ln: f64,
    /// 95 % shortest coverage interval of the value [lo, hi].
    pub interval: [f64; 2],
}

/// Each factor's knots' spread over the refitted replicas `replicas` (flat vectors of
/// `model`), in the order of [`Factor::all`].
pub fn mc_bands(model: &Model, replicas: &[Vec<f64>]) -> Vec<(Factor, Vec<KnotMc>)> {
    Factor::all(model)
        .into_iter()
        .map(|f| {
            let lns: Vec<Vec<f64>> = replicas.iter().map(|r| f.ln_values(r)).collect();
            let knots = (0..lns.first().map_or(0, Vec::len))
                .map(|k| {
                    let mut col: Vec<f64> =
                        lns.iter().map(|v| v[k]).filter(|v| v.is_finite()).collect();
                    let n = col.len() as f64;
                    let mean = col.iter().sum::<f64>() / n;
                    let sd =
                        (col.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
                    col.sort_by(f64::total_cmp);
                    let [lo, hi] = shortest_interval(&col, COVERAGE);
                    KnotMc {
                        sd_ln: sd,
                        interval: [lo.exp(), hi.exp()],
                    }
                })
                .collect();
            (f, knots)
        })
        .collect()
}

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
    /// The knot's data share ([`Covariance::data_share`]): None for the first knot, fixed
    /// by the factor's definition, and without the prior.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data_share: Option<f64>,
    /// Whether the data set the knot ([`is_measured`]): the lobe's signal is at least
    /// [`MEASURED_SIGNAL`] and the knot's data share at least [`MEASURED_SHARE`]. Else the
    /// smoothness prior sets it (no half vectors there, a lobe too faint against the
    /// uncertainties, or data that see the knot only with its neighbours), and D there is
    /// not measured.
    pub measured: bool,
    /// The spread of D(θ_k) over Monte Carlo replicas (`fit --mc N`; absent without).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mc: Option<KnotMc>,
}

/// The lobe's signal near a knot from which D there counts as measured: a 3σ detection.
/// (A weak prior lets a few knots absorb noise where the lobe is absent; such a fitted
/// lobe shows a signal of about 1 to 3, the square root of the few degrees of freedom it
/// took.)
pub const MEASURED_SIGNAL: f64 = 3.0;

/// The data share ([`Covariance::data_share`]) from which a knot counts as measured: the
/// data give at least half of its information with its neighbours held, so they, not the
/// prior's pull toward its neighbours, set its value. (A lobe seen at 3σ near a knot can
/// still leave the knot to the prior under a strong prior, at the edge of the measured
/// range: there the prior's smoothing bias is largest, and the band does not carry it.)
pub const MEASURED_SHARE: f64 = 0.5;

/// Whether a knot counts as measured: the factor's signal near it is at least
/// [`MEASURED_SIGNAL`] and, where the knot is a fitted parameter with the prior's
/// covariance, its data share at least [`MEASURED_SHARE`].
pub fn is_measured(signal: f64, share: Option<f64>) -> bool {
    signal >= MEASURED_SIGNAL && share.is_none_or(|s| s >= MEASURED_SHARE)
}

/// The signal near each knot: √Σ z² over the samples whose angle (`angles` picks the
/// sample's one or two angles, degrees) lies between the knot's neighbours.
fn signal_at_knots(
    degrees: &[f64],
    samples: &[FactorSample],
    angles: impl Fn(&FactorSample) -> [f64; 2],
) -> Vec<f64> {
    (0..degrees.len())
        .map(|k| {
            // From the normal for the first knot, to the last knot for the last.
            let (lo, hi) = (
                degrees[k.saturating_sub(1)],
                degrees[(k + 1).min(degrees.len() - 1)],
            );
            samples
                .iter()
                .filter(|s| angles(s).iter().any(|a| (lo..=hi).contains(a)))
                .fold(0.0, |a, s| a + s.z * s.z)
                .sqrt()
        })
        .collect()
}

/// The fitted D at the knots of each data-driven NDF of `model` fitted to `data` (one
/// list per lobe `+ndf` made data-driven, named by its knots' stem: `ndf` in `ggx+ndf`,
/// `lobe.ndf` in `fa(B)+ndf`, `ndf_c` for a coat).
pub fn bands(
    model: &Model,
    data: &Dataset,
    flat: &[f64],
    cov: &Covariance,
) -> Vec<(String, Vec<KnotBand>)> {
    Factor::all(model)
        .into_iter()
        .filter(|f| f.kind == FactorKind::Ndf)
        .map(|f| {
            let samples = factor_samples(model, data, flat, &f);
            let signal = signal_at_knots(&f.degrees(), &samples, |s| [s.theta_h_deg; 2]);
            let rows = f
                .values_and_sd(flat, cov)
                .into_iter()
                .zip(f.degrees())
                .zip(signal)
                .zip(f.shares(cov))
                .map(|((((d, sigma), theta_deg), signal), share)| KnotBand {
                    theta_deg,
                    d,
                    sigma_ln_d: sigma,
                    signal,
                    data_share: share,
                    measured: is_measured(signal, share),
                    mc: None,
                })
                .collect();
            (f.name, rows)
        })
        .collect()
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

/// One sample's view of a factor: the half vector's angle θh (the refraction half vector
/// for a transmission lobe), the angle θd between ωi and it, |θi| and |θo| (degrees), the
/// sample's channel, and the factor's part of the fitted value in units of the sample's
/// uncertainty, f − f(amplitude = 0) (the lobe is k_s times a kernel, the body ρ times
/// one; what remains at 0 is the rest of the model; a transmission lobe's part is f).
#[derive(Clone, Copy)]
struct FactorSample {
    theta_h_deg: f64,
    theta_d_deg: f64,
    theta_i_deg: f64,
    theta_o_deg: f64,
    channel: usize,
    z: f64,
}

fn factor_samples(model: &Model, data: &Dataset, flat: &[f64], f: &Factor) -> Vec<FactorSample> {
    let mut off = flat.to_vec();
    off[f.amplitude.clone()].fill(0.0);
    let whole = f.amplitude.is_empty();
    let eta = f.refraction_eta.map(|e| flat[e]);
    data.samples
        .iter()
        .map(|s| {
            let (wi, wo) = (s.wi(), s.wo());
            let g = model.group_of(s);
            let value = model.eval(flat, g, wi, wo);
            let part = if whole {
                value
            } else {
                value - model.eval(&off, g, wi, wo)
            };
            let h = match eta {
                // Walter's m = −(ωi + η ωo), on the side of the normal.
                Some(eta) => {
                    let m = -(wi + eta * wo);
                    if m.z < 0.0 {
                        -m
                    } else {
                        m
                    }
                }
                None => wi + wo,
            };
            let cos_d = (wi.dot(h) / h.length().max(1e-300)).clamp(-1.0, 1.0);
            FactorSample {
                theta_h_deg: (h.x.hypot(h.y)).atan2(h.z).to_degrees(),
                theta_d_deg: cos_d.acos().to_degrees(),
                theta_i_deg: s.theta_i.abs().to_degrees(),
                theta_o_deg: s.theta_o.abs().to_degrees(),
                channel: s.channel,
                z: part / s.uncertainty,
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
    /// The knot's data share ([`Covariance::data_share`]): None for the first knot, fixed
    /// by the factor's definition, and without the prior.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data_share: Option<f64>,
    /// Whether the data set the knot ([`is_measured`]).
    pub measured: bool,
    /// The spread of f over Monte Carlo replicas, as [`KnotBand::mc`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mc: Option<KnotMc>,
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
    let factors: Vec<Factor> = Factor::all(model)
        .into_iter()
        .filter(|f| f.kind == FactorKind::Fresnel)
        .collect();
    // One evaluation of the lobe's part per lobe, shared by its channels.
    let mut samples: Option<(String, Vec<FactorSample>)> = None;
    factors
        .into_iter()
        .map(|f| {
            let c = f.channel.unwrap_or(0);
            if samples.as_ref().is_none_or(|(n, _)| *n != f.name) {
                let s = factor_samples(model, data, flat, &f);
                samples = Some((f.name.clone(), s));
            }
            let own: Vec<FactorSample> = samples
                .as_ref()
                .map(|(_, s)| s.iter().filter(|s| s.channel == c).copied().collect())
                .unwrap_or_default();
            let signal = signal_at_knots(&f.degrees(), &own, |s| [s.theta_d_deg; 2]);
            let rows = f
                .values_and_sd(flat, cov)
                .into_iter()
                .zip(f.degrees())
                .zip(signal)
                .zip(f.shares(cov))
                .map(|((((v, sigma), theta_deg), signal), share)| FresnelBand {
                    theta_deg,
                    f: v,
                    sigma_ln_f: sigma,
                    signal,
                    data_share: share,
                    measured: is_measured(signal, share),
                    mc: None,
                })
                .collect();
            (f.name, c, rows)
        })
        .collect()
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
    /// The knot's data share ([`Covariance::data_share`]): None for the first knot, fixed
    /// by the factor's definition, and without the prior.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data_share: Option<f64>,
    /// Whether the data set the knot ([`is_measured`]).
    pub measured: bool,
    /// The spread of ρ over Monte Carlo replicas, as [`KnotBand::mc`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mc: Option<KnotMc>,
}

/// The fitted profile of each diffuse base `+body` reshaped: (the knots' stem — `body`,
/// or `base.body` under a layer — its knots).
pub fn body_bands(
    model: &Model,
    data: &Dataset,
    flat: &[f64],
    cov: &Covariance,
) -> Vec<(String, Vec<BodyBand>)> {
    Factor::all(model)
        .into_iter()
        .filter(|f| f.kind == FactorKind::Body)
        .map(|f| {
            let samples = factor_samples(model, data, flat, &f);
            let signal =
                signal_at_knots(&f.degrees(), &samples, |s| [s.theta_i_deg, s.theta_o_deg]);
            let rows = f
                .values_and_sd(flat, cov)
                .into_iter()
                .zip(f.degrees())
                .zip(signal)
                .zip(f.shares(cov))
                .map(|((((rho, sigma), theta_deg), signal), share)| BodyBand {
                    theta_deg,
                    rho,
                    sigma_ln_rho: sigma,
                    signal,
                    data_share: share,
                    measured: is_measured(signal, share),
                    mc: None,
                })
                .collect();
            (f.name, rows)
        })
        .collect()
}

/// The largest standard uncertainty of a knot's logarithm at which the data determine the
/// factor there: its value known within a factor e^0.5 ≈ 1.65 either way.
pub const DETERMINED_LN_SD: f64 = 0.5;

/// The knots of one tabulated factor that the data determine ([`determined_knots`]).
#[derive(Clone, Debug)]
pub struct DeterminedKnots {
    /// The knots' stem (`lobe.fresnel`, `ndf_c`, `base.body`, …).
    pub stem: String,
    /// The channel of a Fresnel curve.
    pub channel: Option<usize>,
    /// The angles (degrees) of the knots determined.
    pub degrees: Vec<f64>,
}

/// The knots the data determine, per tabulated factor of a fit: those that are measured
/// (the data see the factor there, [`MEASURED_SIGNAL`]) with σ(ln) ≤ [`DETERMINED_LN_SD`]
/// under the covariance with the prior's information. A knot the prior alone holds, or
/// one fixed by the factor's definition (the body's ρ(0) = 1), never counts. None
/// without the prior's covariance.
pub fn determined_knots(
    model: &Model,
    data: &Dataset,
    flat: &[f64],
    cov: &Covariance,
) -> Option<Vec<DeterminedKnots>> {
    cov.with_prior.as_ref()?;
    let keep = |measured: bool, sd: Option<f64>| {
        measured && sd.is_some_and(|s| s > 0.0 && s <= DETERMINED_LN_SD)
    };
    let mut out = Vec::new();
    let mut push = |stem: String, channel: Option<usize>, degrees: Vec<f64>| {
        out.push(DeterminedKnots {
            stem,
            channel,
            degrees,
        })
    };
    for (name, rows) in bands(model, data, flat, cov) {
        let at = rows.iter().filter(|r| keep(r.measured, r.sigma_ln_d));
        push(name, None, at.map(|r| r.theta_deg).collect());
    }
    for (name, c, rows) in fresnel_bands(model, data, flat, cov) {
        let at = rows.iter().filter(|r| keep(r.measured, r.sigma_ln_f));
        push(name, Some(c), at.map(|r| r.theta_deg).collect());
    }
    for (name, rows) in body_bands(model, data, flat, cov) {
        let at = rows.iter().filter(|r| keep(r.measured, r.sigma_ln_rho));
        push(name, None, at.map(|r| r.theta_deg).collect());
    }
    Some(out)
}

/// Whether flat parameter `name` is a knot of the factor whose knots' stem is `stem`
/// (`lobe.fresnel3[0]` of `lobe.fresnel`, `ndf_c5` of `ndf_c`, not of `ndf`).
pub fn is_knot_of(name: &str, stem: &str) -> bool {
    name.strip_prefix(stem).is_some_and(|rest| {
        let digits = rest.bytes().take_while(u8::is_ascii_digit).count();
        digits > 0 && (rest.len() == digits || rest[digits..].starts_with('['))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn knots_belong_to_their_own_stem_only() {
        assert!(is_knot_of("lobe.fresnel3[0]", "lobe.fresnel"));
        assert!(is_knot_of("ndf_c5", "ndf_c"));
        assert!(is_knot_of("ndf12", "ndf"));
        assert!(!is_knot_of("ndf_c5", "ndf"));
        assert!(!is_knot_of("lobe.ndf1", "ndf"));
        assert!(!is_knot_of("base.body", "base.body"));
        assert!(!is_knot_of("fresnel_c1[0]", "fresnel"));
    }

    /// Replicas whose knots alternate ± δ about the fit give each knot's logarithm the
    /// spread δ √(n/(n − 1)): the NDF's through its table, each Fresnel channel's its own
    /// (channel 1 twice channel 0's), the body's, and 0 where the tables fix the value
    /// (the body's ρ(0) = 1).
    #[test]
    fn monte_carlo_spread_of_each_factor_follows_its_knots() {
        let model = Model::parse("fa(lambert)+fresnel+body", 2).unwrap();
        let mut best = vec![0.0; model.dim];
        for p in &model.params {
            let w = p.width(model.channels);
            let v = if p.decl.knot {
                0.0
            } else {
                0.5 * (p.decl.lo + p.decl.hi)
            };
            best[p.index..p.index + w].fill(v);
        }
        let n = 40;
        let delta = 0.1;
        let replicas: Vec<Vec<f64>> = (0..n)
            .map(|r| {
                let sign = if r % 2 == 0 { 1.0 } else { -1.0 };
                let mut flat = best.clone();
                for p in model.params.iter().filter(|p| p.decl.knot) {
                    for c in 0..p.width(model.channels) {
                        flat[p.index + c] = sign * delta * (1 + c) as f64;
                    }
                }
                flat
            })
            .collect();
        let bands = mc_bands(&model, &replicas);
        let kinds: Vec<(FactorKind, &str, Option<usize>)> = bands
            .iter()
            .map(|(f, _)| (f.kind, f.name.as_str(), f.channel))
            .collect();
        assert_eq!(
            kinds,
            [
                (FactorKind::Fresnel, "lobe.fresnel", Some(0)),
                (FactorKind::Fresnel, "lobe.fresnel", Some(1)),
                (FactorKind::Body, "base.body", None),
            ]
        );
        let expected = delta * (n as f64 / (n as f64 - 1.0)).sqrt();
        for (f, knots) in &bands {
            let scale = (1 + f.channel.unwrap_or(0)) as f64;
            for (k, m) in knots.iter().enumerate() {
                let want = if k == 0 { 0.0 } else { expected * scale };
                assert!(
                    (m.sd_ln - want).abs() < 1e-9,
                    "{} {:?} knot {k}: {} against {want}",
                    f.name,
                    f.channel,
                    m.sd_ln
                );
                let centre = f.ln_values(&best)[k];
                assert!(m.interval[0] <= centre.exp() && centre.exp() <= m.interval[1]);
            }
        }
    }
}
