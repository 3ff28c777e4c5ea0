//! The randomized battery (`bsdfit battery`): how often `diagnose` names an effect hidden
//! in data nobody chose by hand, and how often it names one that is not there.
//!
//! Each case draws a random truth. For a hidden effect E: a geometry (in-plane, two
//! planes, or the hemisphere, with points near the mirror and retro directions; normal
//! and oblique incidence for a BTDF), one or three channels, 200–20,000 samples, noise of
//! 1–5 % with a floor; a start model S0 from the catalogue that E can extend, and a truth
//! S1 among S0's extensions that add E ([`super::extensions`], so the battery follows the
//! effect table: a new effect or rule is tested without new code); S0's parameters drawn
//! from their declared ranges (one of them on a bound in some cases, as fitted real data
//! show), S1's new parameters drawn too (a narrow lobe of 1–5° in some cases), then
//! scaled towards their neutral values until the effect's signal has a drawn size (the
//! RMS over the samples of (S1 − S0)/u before any fit). A null case synthesizes S0 itself.
//!
//! `diagnose` then runs from S0. A hidden effect is **detected** when it is named and the
//! final fit is consistent with the uncertainties; a case has a **false effect** when a
//! null case gets any effect, or a hidden case gets another effect named first or named
//! besides E. Rates are reported against the signal-to-noise the start model actually
//! shows, SNR = √(χ²_red − 1) of its fit (the RMS misfit beyond the noise, in units of the
//! stated uncertainties).

use super::extensions::{embed, extensions};
use super::misspecified;
use super::score::new_param_indices;
use super::{diagnose, DiagnoseOptions, Effect};
use crate::bsdf::{every_spec, LobePart, Model, ParamDecl, Scale};
use crate::data::{Dataset, Kind};
use crate::engine::Backend;
use crate::workflows::synth::{synthesize, Noise};
use anyhow::{anyhow, Result};
use rand::seq::IndexedRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

/// What a battery runs.
#[derive(Clone, Debug)]
pub struct BatteryOptions {
    /// Cases per hidden effect.
    pub cases: usize,
    /// Cases with nothing hidden.
    pub nulls: usize,
    /// Misspecified null cases: isotropic truths outside the catalogue
    /// ([`super::misspecified`]), diagnosed from `fa(lambert)`; they cycle through the
    /// families, at one incidence azimuth and then at several.
    pub misspecified: usize,
    /// Misspecified transmission cases: rough dielectrics whose NDF is outside the BTDF
    /// catalogue ([`super::misspecified::BTDF_FAMILIES`]), diagnosed from `btdf(tr)`,
    /// drawn after the reflection ones and cycling the same way.
    pub misspecified_btdf: usize,
    pub seed: u64,
    /// The effects to hide (default: every effect of the table).
    pub effects: Vec<Effect>,
    /// The range the effect's pre-fit signal is drawn from (log-uniform).
    pub signal: (f64, f64),
    /// The range of sample counts (log-uniform).
    pub samples: (usize, usize),
    /// The diagnosis's options.
    pub diagnose: DiagnoseOptions,
    /// Run only this case (its id in the full battery's order), with its diagnosis log.
    pub only: Option<usize>,
}

impl Default for BatteryOptions {
    fn default() -> Self {
        BatteryOptions {
            cases: 20,
            nulls: 40,
            misspecified: 10,
            misspecified_btdf: 4,
            seed: 1,
            effects: Effect::all().filter(|e| !e.is_data_driven()).collect(),
            signal: (1.0, 30.0),
            samples: (200, 20_000),
            // The catalogue's effects: no data-driven round (its truths come from the
            // catalogue; a misspecified one would spend most of its time there).
            diagnose: DiagnoseOptions {
                data_driven: false,
                ..DiagnoseOptions::default()
            },
            only: None,
        }
    }
}

impl BatteryOptions {
    /// The checks made before any case is drawn, for every caller: the ranges of the
    /// signal and of the sample counts. Errors name the options as fields.
    pub fn check(&self) -> Result<()> {
        let (lo, hi) = self.signal;
        if !(lo > 0.0 && hi >= lo) {
            return Err(crate::choice::field_error(format!(
                "{{signal={lo},{hi}}}: 0 < LO ≤ HI"
            )));
        }
        let (lo, hi) = self.samples;
        if !(lo >= 20 && hi >= lo) {
            return Err(crate::choice::field_error(format!(
                "{{samples={lo},{hi}}}: 20 ≤ LO ≤ HI"
            )));
        }
        let planned = self.planned();
        match self.only {
            // An id past the plan would run nothing and print an empty table.
            Some(id) if id >= planned => Err(crate::choice::field_error(format!(
                "{{case={id}}}: this battery has cases 0–{} ({} per effect × {} effects, {} null, {} misspecified, {} misspecified BTDF)",
                planned.saturating_sub(1),
                self.cases,
                self.effects.len(),
                self.nulls,
                self.misspecified,
                self.misspecified_btdf
            ))),
            _ => Ok(()),
        }
    }

    /// The cases the battery runs: one, or every case of the plan.
    pub fn total(&self) -> usize {
        if self.only.is_some() {
            1
        } else {
            self.planned()
        }
    }

    /// The cases of the whole plan, whether or not `only` picks one.
    fn planned(&self) -> usize {
        self.effects.len() * self.cases + self.nulls + self.misspecified + self.misspecified_btdf
    }
}

/// The effects named by `names` (as `diagnose` names them); an unknown name is an error
/// of the `effects` option, listing the known ones.
pub fn effects_named<S: AsRef<str>>(names: &[S]) -> Result<Vec<Effect>> {
    names
        .iter()
        .map(|n| {
            let n = n.as_ref();
            let known = || {
                Effect::all()
                    .filter(|e| !e.is_data_driven())
                    .map(|e| e.name())
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            match Effect::from_name(n.trim()) {
                Some(e) if e.is_data_driven() => Err(crate::choice::field_error(format!(
                    "{{effects}}: '{n}' is a data-driven factor, not an effect the battery can hide in a catalogue truth (it draws: {})",
                    known()
                ))),
                Some(e) => Ok(e),
                None => Err(crate::choice::field_error(format!(
                    "{{effects}}: unknown effect '{n}' (known: {})",
                    known()
                ))),
            }
        })
        .collect()
}

/// One generated case.
#[derive(Clone, Debug, Serialize)]
pub struct Case {
    pub id: usize,
    /// The hidden effect (None: a null case).
    pub hidden: Option<String>,
    /// A misspecified null case's family ([`super::misspecified::FAMILIES`]); its truth
    /// is described in `truth`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub misspecified: Option<String>,
    pub start: String,
    pub truth: String,
    /// The truth's flat parameters (physical).
    pub truth_params: Vec<f64>,
    pub geometry: String,
    pub samples: usize,
    pub channels: usize,
    pub noise_rel: f64,
    /// RMS of (S1 − S0)/u before any fit, where S0 is the truth with the new parameters at
    /// their neutral values (nested) or at the drawn start (swaps).
    pub signal: f64,
    pub seed: u64,
}

/// One case's diagnosis and verdicts.
#[derive(Clone, Debug, Serialize)]
pub struct Outcome {
    pub case: Case,
    pub named: Vec<String>,
    pub final_model: String,
    pub chi2_red_start: f64,
    pub chi2_red_final: f64,
    /// √(χ²_red − 1) of the start fit (0 below 1).
    pub snr: f64,
    pub consistent: bool,
    pub detected: bool,
    pub false_effect: bool,
    /// Anisotropic candidates significant on their F test and identifiable that the frame
    /// test refused (no better than an isotropic lobe of the same shape): anisotropy the
    /// F test alone would have let through.
    pub anisotropy_refused: usize,
    pub seconds: f64,
    /// Set when the diagnosis failed.
    pub error: Option<String>,
    /// The diagnosis's log, kept when the battery runs one case only.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub log: Vec<String>,
}

/// The geometry families a case draws from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Family {
    InPlane,
    TwoPlane,
    Hemisphere,
}

/// Rows (θi, φi, θo, φo in degrees) of `family` for `kind`, about `count` of them.
fn rows(kind: Kind, family: Family, count: usize, rng: &mut ChaCha8Rng) -> (String, Vec<[f64; 4]>) {
    let phi: f64 = [0.0, 30.0, 45.0, 90.0][rng.random_range(0..4)];
    let planes: Vec<f64> = match family {
        Family::TwoPlane => vec![phi, phi + 90.0],
        _ => vec![phi],
    };
    let mut out: Vec<[f64; 4]> = Vec::new();
    let mut near: Vec<[f64; 4]> = Vec::new();
    match kind {
        Kind::Brdf => {
            let n_inc = rng.random_range(3..=7);
            let mut incidences: Vec<f64> = (0..n_inc)
                .map(|_| 5.0 * rng.random_range(0..=15) as f64)
                .collect();
            incidences.sort_by(f64::total_cmp);
            incidences.dedup();
            for &ti in &incidences {
                match family {
                    Family::Hemisphere => {
                        let per = (count / incidences.len()).max(20);
                        for _ in 0..per {
                            let to = rng.random::<f64>().sqrt().asin().to_degrees().min(85.0);
                            let po = rng.random_range(0.0..360.0);
                            out.push([ti, phi, to, po]);
                        }
                    }
                    _ => {
                        let per = (count / (incidences.len() * planes.len())).max(17);
                        let step = (170.0 / per as f64).max(0.5);
                        for &p in &planes {
                            let mut to: f64 = -85.0;
                            while to <= 85.0 {
                                out.push([ti, phi, to, p]);
                                to += step;
                            }
                        }
                    }
                }
                // Near the mirror and the retro direction, in the incidence plane.
                for d in [1.0, 2.0, 3.0, 5.0] {
                    for s in [-1.0, 1.0] {
                        near.push([ti, phi, -ti + s * d, phi]);
                        near.push([ti, phi, ti + s * d, phi]);
                    }
                }
            }
        }
        Kind::Btdf => {
            let incidences: Vec<f64> = if rng.random::<f64>() < 0.5 {
                vec![0.0]
            } else {
                vec![0.0, 30.0, 60.0]
            };
            let per = (count / (incidences.len() * planes.len())).max(17);
            let step = (160.0 / per as f64).max(0.25);
            for &ti in &incidences {
                for (k, &p) in planes.iter().enumerate() {
                    let mut t: f64 = -80.0;
                    while t <= 80.0 {
                        if !(k > 0 && t.abs() < 1e-9) {
                            out.push([ti, 0.0, t, p]);
                        }
                        t += step;
                    }
                }
            }
        }
    }
    // Keep the rows above the horizon and off the source; then the count asked for.
    let ok = |r: &[f64; 4]| {
        r[2].abs() <= 88.0 && !((r[3] - r[1]).abs() < 1e-9 && (r[2] - r[0]).abs() < 0.5)
    };
    near.retain(|r| ok(r) || kind == Kind::Btdf);
    out.retain(|r| kind == Kind::Btdf || ok(r));
    while out.len() + near.len() > count && out.len() > 10 {
        let i = rng.random_range(0..out.len());
        out.swap_remove(i);
    }
    out.extend(near);
    let name = match family {
        Family::InPlane => format!("in-plane φ = {phi}°"),
        Family::TwoPlane => format!("two planes φ = {phi}°, {}°", phi + 90.0),
        Family::Hemisphere => "hemisphere".to_string(),
    };
    (name, out)
}

/// The value of `model` at every sample of `data` (its own rows and channels).
fn values(model: &Model, flat: &[f64], data: &Dataset) -> Vec<f64> {
    data.samples
        .iter()
        .map(|s| model.eval(flat, model.group_of(s), s.wi(), s.wo()))
        .collect()
}

/// RMS of (a − b)/u over the samples, u = √((rel·a)² + abs²).
fn signal(a: &[f64], b: &[f64], noise: Noise) -> f64 {
    let s: f64 = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| {
            let u = ((noise.rel * x).powi(2) + noise.abs.powi(2)).sqrt();
            ((x - y) / u).powi(2)
        })
        .sum();
    (s / a.len().max(1) as f64).sqrt()
}

/// The seed of case `id` of a battery: each case draws from a stream of its own, so one
/// case can be run alone (`--case`).
pub(super) fn case_seed(opts: &BatteryOptions, id: usize) -> u64 {
    opts.seed.wrapping_mul(0x9e37_79b9).wrapping_add(id as u64)
}

/// Draw one case: `hidden` in a random truth, or nothing (null).
pub fn generate(
    hidden: Option<Effect>,
    id: usize,
    opts: &BatteryOptions,
) -> Result<(Case, Dataset)> {
    let seed = case_seed(opts, id);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for _attempt in 0..200 {
        let m = draw_measurement(hidden, opts, &mut rng)?;
        let probe = probe_data(&m, seed)?;
        let pairs = start_truth_pairs(m.kind, hidden, &probe);
        let Some((start, truth)) = pairs.choose(&mut rng).cloned() else {
            continue;
        };
        let m0 = Model::for_data(&start, &probe)?;
        let m1 = Model::for_data(&truth, &probe)?;
        let p0 = draw_start_params(&m0, &mut rng);
        let blend = Blend::draw(&m0, &p0, &m1, &mut rng);
        // Scale the new parameters towards their neutral values (the embedding) until the
        // effect's signal has the drawn size.
        let v0 = values(&m0, &p0, &probe);
        let sig = |x: &[f64]| signal(&values(&m1, x, &probe), &v0, m.noise);
        let want = log_uniform(opts.signal.0, opts.signal.1, &mut rng);
        let truth_params = match hidden {
            None => p0.clone(),
            Some(_) => blend.scaled(sig, want),
        };
        let achieved = if hidden.is_some() {
            sig(&truth_params)
        } else {
            0.0
        };
        if hidden.is_some() && (achieved.is_nan() || achieved <= 0.0) {
            continue; // the effect does not show on these rows
        }
        let truth_model = if hidden.is_some() { &m1 } else { &m0 };
        let data = synthesize_case(truth_model, &truth_params, &m, seed, id)?;
        let case = Case {
            id,
            hidden: hidden.map(|e| e.name().to_string()),
            misspecified: None,
            start,
            truth: truth_model.spec.clone(),
            truth_params,
            geometry: m.geometry,
            samples: data.len(),
            channels: m.channels,
            noise_rel: m.noise.rel,
            signal: achieved,
            seed,
        };
        return Ok((case, data));
    }
    Err(anyhow!("no case could be drawn for {hidden:?}"))
}

/// Where and how a case is measured, drawn before any model.
struct Measurement {
    kind: Kind,
    channels: usize,
    wavelengths: Vec<f64>,
    /// The geometry in words ([`rows`]).
    geometry: String,
    rows: Vec<[f64; 4]>,
    noise: Noise,
}

/// A draw from [lo, hi], log-uniform: sample counts and signal sizes span decades.
pub(super) fn log_uniform(lo: f64, hi: f64, rng: &mut ChaCha8Rng) -> f64 {
    (lo.ln() + rng.random::<f64>() * (hi.ln() - lo.ln())).exp()
}

/// Draw a case's measurement: a kind the hidden effect has rules for, a geometry family
/// that can show it, one or three channels (a BTDF one), about a log-uniform number of
/// samples in `opts.samples`, and the noise.
fn draw_measurement(
    hidden: Option<Effect>,
    opts: &BatteryOptions,
    rng: &mut ChaCha8Rng,
) -> Result<Measurement> {
    let kind = *kinds(hidden)
        .choose(rng)
        .ok_or_else(|| anyhow!("no rule"))?;
    let family = match (kind, min_planes(hidden, kind)) {
        (_, 2) => Family::TwoPlane,
        (Kind::Btdf, _) => [Family::InPlane, Family::TwoPlane][rng.random_range(0..2)],
        _ => [Family::InPlane, Family::TwoPlane, Family::Hemisphere][rng.random_range(0..3)],
    };
    let channels = match kind {
        Kind::Brdf if rng.random::<f64>() < 0.5 => 3,
        _ => 1,
    };
    let wavelengths: Vec<f64> = if channels == 3 {
        vec![450.0, 550.0, 650.0]
    } else {
        vec![550.0]
    };
    let (lo, hi) = (opts.samples.0.max(20) as f64, opts.samples.1.max(20) as f64);
    let target = log_uniform(lo, hi, rng) as usize;
    let (geometry, rows) = rows(kind, family, target / channels, rng);
    let noise = Noise {
        rel: rng.random_range(0.01..0.05),
        abs: rng.random_range(1e-4..1e-3),
    };
    Ok(Measurement {
        kind,
        channels,
        wavelengths,
        geometry,
        rows,
        noise,
    })
}

/// The kinds of data some model adds the effect on (any kind for a null case).
fn kinds(hidden: Option<Effect>) -> Vec<Kind> {
    hidden.map_or_else(|| vec![Kind::Brdf, Kind::Btdf], Effect::kinds)
}

/// The fewest φ planes on which some model adds the effect to data of `kind` (1 for a
/// null case): an effect that shows only between planes is hidden in two-plane data.
fn min_planes(hidden: Option<Effect>, kind: Kind) -> usize {
    hidden.map_or(1, |e| e.min_planes(kind))
}

/// A data set on the case's rows, to see which models parse and extend here.
fn probe_data(m: &Measurement, seed: u64) -> Result<Dataset> {
    // The catalogue's first model of the kind: every case's data can carry it.
    let probe_spec = crate::bsdf::catalogue(m.kind)
        .into_iter()
        .next()
        .ok_or_else(|| anyhow!("no {} model in the catalogue", m.kind))?;
    let probe_model = Model::parse(&probe_spec, m.channels)?;
    synthesize(
        &probe_model,
        &probe_model.defaults(),
        &m.rows,
        &m.wavelengths,
        m.noise,
        seed,
        "probe",
    )
    .map_err(|e| anyhow!(e))
}

/// Every (start S0, truth S1) pair the catalogue offers on the probe's rows: each model of
/// `kind` that fits there (and that its rows determine: no anisotropic lobe on data in
/// one plane), with each of its extensions that adds `hidden`
/// ([`extensions`]), or itself for a null case.
fn start_truth_pairs(kind: Kind, hidden: Option<Effect>, probe: &Dataset) -> Vec<(String, String)> {
    let mut pairs: Vec<(String, String)> = Vec::new();
    let one_plane = probe.direction_planes() < 2;
    for s0 in every_spec(kind) {
        let Ok(m0) = Model::for_data(&s0, probe) else {
            continue;
        };
        // A start model the data can determine: not an anisotropic lobe in one plane; and a
        // truth of the catalogue's families, not a data-driven factor (random knots are no
        // material).
        if one_plane && m0.params.iter().any(|p| p.decl.needs_planes) {
            continue;
        }
        if m0.params.iter().any(|p| p.decl.knot) {
            continue;
        }
        match hidden {
            None => pairs.push((s0.clone(), s0)),
            Some(e) => {
                for c in extensions(&s0, probe).unwrap_or_default() {
                    if c.effect == e {
                        pairs.push((s0.clone(), c.spec));
                    }
                }
            }
        }
    }
    pairs
}

/// S0's parameters: inside their ranges, one on a bound in some cases (as fitted real
/// data show).
fn draw_start_params(m0: &Model, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let mut u0: Vec<f64> = (0..m0.dim).map(|_| rng.random_range(0.1..0.9)).collect();
    if rng.random::<f64>() < 0.15 {
        let j = rng.random_range(0..m0.dim);
        u0[j] = if rng.random::<bool>() { 0.0 } else { 1.0 };
    }
    m0.from_unit(&u0)
}

/// The way from S0 to a truth S1 that adds parameters: S0 embedded in S1 (the new
/// parameters at their neutral values) at one end, the new parameters drawn at the other.
struct Blend {
    /// S0's parameters embedded in S1.
    base: Vec<f64>,
    /// `base` with S1's new parameters drawn from their ranges.
    drawn: Vec<f64>,
    /// Which of S1's parameters are new.
    fresh: Vec<usize>,
    /// S1's parameter declarations.
    decls: Vec<ParamDecl>,
}

impl Blend {
    /// Embed S0's parameters `p0` in S1 and draw S1's new parameters (a narrow lobe of
    /// 1–5° in some cases).
    fn draw(m0: &Model, p0: &[f64], m1: &Model, rng: &mut ChaCha8Rng) -> Blend {
        let base = embed(m0, p0, m1);
        let decls = m1.flat_decls();
        let fresh = new_param_indices(m0, m1);
        let narrow = rng.random::<f64>() < 0.3;
        let mut drawn = base.clone();
        // An anisotropic lobe's two roughnesses (pairs of new parameters determined only
        // across planes, on a log scale): a ratio up to 4 either way about the isotropic
        // value, so that the effect is the anisotropy and not a change of the mean width
        // that S0 absorbs when it is refitted.
        let mut paired = Vec::new();
        for w in fresh.windows(2) {
            let (a, b) = (&decls[w[0]], &decls[w[1]]);
            if a.needs_planes && b.needs_planes && a.scale == Scale::Log && b.scale == Scale::Log {
                let ratio = rng.random_range(-(4.0f64.ln())..4.0f64.ln()).exp().sqrt();
                let mean = (base[w[0]] * base[w[1]]).sqrt();
                drawn[w[0]] = (mean * ratio).clamp(a.lo, a.hi);
                drawn[w[1]] = (mean / ratio).clamp(b.lo, b.hi);
                paired.extend([w[0], w[1]]);
            }
        }
        for &j in fresh.iter().filter(|j| !paired.contains(j)) {
            let d = &decls[j];
            drawn[j] = match d.lobe {
                LobePart::Width if narrow => {
                    (rng.random_range(1.0f64..5.0).to_radians() / 1.3).clamp(d.lo, d.hi)
                }
                _ => d.from_unit(rng.random_range(0.2..0.9)),
            };
        }
        Blend {
            base,
            drawn,
            fresh,
            decls,
        }
    }

    /// S1's parameters a fraction `t` of the way from the neutral values to the drawn
    /// ones, in each parameter's unit box.
    fn at(&self, t: f64) -> Vec<f64> {
        let mut x = self.base.clone();
        for &j in &self.fresh {
            let d = &self.decls[j];
            let (a, b) = (d.to_unit(self.base[j]), d.to_unit(self.drawn[j]));
            x[j] = d.from_unit(a + t * (b - a));
        }
        x
    }

    /// The parameters on the way whose signal (`sig`) is `want`, by bisection; the drawn
    /// ones where even they show less (or nothing is new).
    fn scaled(&self, sig: impl Fn(&[f64]) -> f64, want: f64) -> Vec<f64> {
        if sig(&self.at(1.0)) <= want || self.fresh.is_empty() {
            return self.at(1.0);
        }
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..30 {
            let mid = 0.5 * (lo + hi);
            if sig(&self.at(mid)) < want {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        self.at(hi)
    }
}

/// The case's data: the truth on the case's rows with its noise (a seed apart from the
/// probe's).
fn synthesize_case(
    truth: &Model,
    params: &[f64],
    m: &Measurement,
    seed: u64,
    id: usize,
) -> Result<Dataset> {
    let mut data = synthesize(
        truth,
        params,
        &m.rows,
        &m.wavelengths,
        m.noise,
        seed ^ 0x5eed,
        &format!("battery case {id}"),
    )
    .map_err(|e| anyhow!(e))?;
    data.material = format!("battery case {id}");
    Ok(data)
}

/// Diagnose one case and judge it (keeping its diagnosis log when the battery runs one
/// case only).
pub fn run_case(
    case: Case,
    data: &Dataset,
    backend: &dyn Backend,
    opts: &BatteryOptions,
) -> Outcome {
    let t0 = std::time::Instant::now();
    let verbose = opts.only.is_some();
    let mut log = Vec::new();
    let d = diagnose(data, &case.start, backend, &opts.diagnose, &mut |l| {
        if verbose {
            log.push(l);
        }
    });
    let seconds = t0.elapsed().as_secs_f64();
    match d {
        Ok(d) => {
            let named: Vec<String> = d.effects.iter().map(|e| e.name().to_string()).collect();
            let first = d.steps.first().map(|s| s.chi2_red).unwrap_or(f64::NAN);
            let last = d.steps.last().expect("a step");
            let consistent = last.fit.p_consistent() >= opts.diagnose.alpha;
            let (detected, false_effect) = match &case.hidden {
                None if case.misspecified.is_some() => {
                    (false, misspecified::names_a_false_effect(&d.effects))
                }
                None => (false, !named.is_empty()),
                Some(h) => (
                    named.contains(h) && consistent,
                    named.first().is_some_and(|n| n != h) || named.iter().any(|n| n != h),
                ),
            };
            let anisotropy_refused = d
                .steps
                .iter()
                .flat_map(|s| &s.candidates)
                .filter(|c| {
                    c.confounded()
                        && c.identifiable
                        && c.delta_bic_scaled < 0.0
                        && c.p_nominal.is_some_and(|p| p < c.level)
                })
                .count();
            Outcome {
                named,
                anisotropy_refused,
                final_model: d.final_model.clone(),
                chi2_red_start: first,
                chi2_red_final: last.chi2_red,
                snr: (first - 1.0).max(0.0).sqrt(),
                consistent,
                detected,
                false_effect,
                seconds,
                error: None,
                log,
                case,
            }
        }
        Err(e) => Outcome {
            seconds,
            log,
            ..Outcome::failed(case, &e)
        },
    }
}

impl Outcome {
    /// A case that could not be drawn or diagnosed: `error` says why.
    fn failed(case: Case, error: &anyhow::Error) -> Outcome {
        Outcome {
            case,
            named: vec![],
            final_model: String::new(),
            chi2_red_start: f64::NAN,
            chi2_red_final: f64::NAN,
            snr: f64::NAN,
            consistent: false,
            detected: false,
            false_effect: false,
            anisotropy_refused: 0,
            seconds: 0.0,
            error: Some(format!("{error:#}")),
            log: vec![],
        }
    }
}

/// Every case of the battery: `cases` per effect of `opts.effects`, then `nulls` null
/// cases, each drawn and diagnosed in turn; `progress` receives each outcome.
pub fn run_battery(
    opts: &BatteryOptions,
    backend: &dyn Backend,
    progress: &mut dyn FnMut(&Outcome),
) -> Vec<Outcome> {
    /// What a case of the plan draws.
    #[derive(Clone, Copy)]
    enum Draw {
        Hidden(Option<Effect>),
        Misspecified((&'static str, bool)),
    }
    let mut plan: Vec<Draw> = Vec::new();
    for &e in &opts.effects {
        plan.extend(std::iter::repeat_n(Draw::Hidden(Some(e)), opts.cases));
    }
    plan.extend(std::iter::repeat_n(Draw::Hidden(None), opts.nulls));
    plan.extend(
        (0..opts.misspecified)
            .map(misspecified::family_of)
            .chain((0..opts.misspecified_btdf).map(misspecified::btdf_family_of))
            .map(Draw::Misspecified),
    );
    let mut out = Vec::with_capacity(plan.len());
    for (id, draw) in plan.into_iter().enumerate() {
        if opts.only.is_some_and(|o| o != id) {
            continue;
        }
        let drawn = match draw {
            Draw::Hidden(hidden) => generate(hidden, id, opts),
            Draw::Misspecified(family) => misspecified::generate(family, id, opts),
        };
        let outcome = match drawn {
            Ok((case, data)) => run_case(case, &data, backend, opts),
            Err(e) => {
                let (hidden, misspecified) = match draw {
                    Draw::Hidden(h) => (h.map(|e| e.name().to_string()), None),
                    Draw::Misspecified((family, _)) => (None, Some(family.to_string())),
                };
                let case = Case {
                    id,
                    hidden,
                    misspecified,
                    start: String::new(),
                    truth: String::new(),
                    truth_params: vec![],
                    geometry: String::new(),
                    samples: 0,
                    channels: 0,
                    noise_rel: 0.0,
                    signal: 0.0,
                    seed: 0,
                };
                Outcome::failed(case, &e)
            }
        };
        progress(&outcome);
        out.push(outcome);
    }
    out
}

/// The SNR bins of the rates table: [lo, hi).
pub const SNR_BINS: [(f64, f64); 5] = [
    (0.0, 1.0),
    (1.0, 2.0),
    (2.0, 4.0),
    (4.0, 8.0),
    (8.0, f64::INFINITY),
];

/// "k/n" with the share, or "–" for no case.
pub(super) fn rate(k: usize, n: usize) -> String {
    if n == 0 {
        "–".into()
    } else {
        format!("{k}/{n} ({:.0} %)", 100.0 * k as f64 / n as f64)
    }
}

/// The rates as a markdown table: per hidden effect, detection in each SNR bin and in
/// all, false effects; then the null cases; then false effects over every case.
pub fn rates_table(outcomes: &[Outcome]) -> String {
    let mut s = String::from("| hidden effect |");
    for (lo, hi) in SNR_BINS {
        if hi.is_finite() {
            s += &format!(" SNR {lo}–{hi} |");
        } else {
            s += &format!(" SNR ≥ {lo} |");
        }
    }
    s += " all | false effects |\n|---|";
    s += &"---|".repeat(SNR_BINS.len() + 2);
    s += "\n";
    let mut names: Vec<String> = Vec::new();
    for o in outcomes {
        if let Some(h) = &o.case.hidden {
            if !names.contains(h) {
                names.push(h.clone());
            }
        }
    }
    for name in &names {
        let cases: Vec<&Outcome> = outcomes
            .iter()
            .filter(|o| o.case.hidden.as_ref() == Some(name) && o.error.is_none())
            .collect();
        s += &format!("| `{name}` |");
        for (lo, hi) in SNR_BINS {
            let bin: Vec<&&Outcome> = cases.iter().filter(|o| o.snr >= lo && o.snr < hi).collect();
            s += &format!(
                " {} |",
                rate(bin.iter().filter(|o| o.detected).count(), bin.len())
            );
        }
        s += &format!(
            " {} | {} |\n",
            rate(cases.iter().filter(|o| o.detected).count(), cases.len()),
            rate(cases.iter().filter(|o| o.false_effect).count(), cases.len())
        );
    }
    let nulls: Vec<&Outcome> = outcomes
        .iter()
        .filter(|o| o.case.hidden.is_none() && o.case.misspecified.is_none() && o.error.is_none())
        .collect();
    s += &format!(
        "| none (null cases) |{} – | {} |\n",
        " |".repeat(SNR_BINS.len()),
        rate(nulls.iter().filter(|o| o.false_effect).count(), nulls.len())
    );
    let done: Vec<&Outcome> = outcomes
        .iter()
        .filter(|o| o.error.is_none() && o.case.misspecified.is_none())
        .collect();
    let failed = outcomes.iter().filter(|o| o.error.is_some()).count();
    s += &format!(
        "\nFalse effects over every case: {}.{}\n",
        rate(done.iter().filter(|o| o.false_effect).count(), done.len()),
        if failed > 0 {
            format!(" {failed} case(s) could not be drawn or diagnosed (listed in the JSON).")
        } else {
            String::new()
        }
    );
    s += &misspecified::table(outcomes);
    s
}
