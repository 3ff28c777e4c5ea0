//! The discrepancy workflow (DESIGN §7, issue #6): fit a start model, decide whether the
//! misfit exceeds the uncertainties, say in words where the model and the measurement
//! disagree, fit every applicable extension of the model from the effect catalogue, adopt
//! the best significant one, name its effect, and repeat until nothing significant remains.
//!
//! Statistics (all on χ² = Σ ((y′ − y)/u)², K samples, P parameters):
//! - Consistency: χ² against the χ² distribution with K − P degrees of freedom; the misfit
//!   exceeds the uncertainties when P(χ²_{K−P} ≥ χ²) < α.
//! - A nested extension (the current model is the extension at some parameter values, e.g.
//!   σ = 0 in `on`, k_s = 0 and η = 1 in `fa(B)`, S = 1 in `+scale`) is tested with the
//!   F statistic F = ((χ²₀ − χ²₁)/ΔP) / (χ²₁/(K − P₁)) against F(ΔP, K − P₁): it uses the
//!   extension's own residual variance, so a model that still misses some other effect
//!   (χ²_red ≫ 1) does not make every extension look significant, as the plain
//!   likelihood-ratio test Δχ² ~ χ²(ΔP) would. The level is Bonferroni-corrected over the
//!   candidates of a round (α/m), and the Bayesian information criterion
//!   BIC = χ² + P ln K, with the χ² scaled by max(1, χ²_red) of the extension, must fall.
//! - A non-nested swap (`beckmann`/`gg` → `tr`) has no F test; it must lower the scaled
//!   BIC by more than 10 (Kass & Raftery's "very strong" evidence).
//! - Among the significant candidates the one with the lowest BIC is adopted. A candidate
//!   whose new parameters the data does not determine (no standard uncertainty, one larger
//!   than its range, or a multiple correlation above 0.999 with the other parameters) is
//!   never adopted: "never add an effect that the data cannot distinguish".
//! - The path is greedy; when it ends with the misfit still exceeding the uncertainties,
//!   each step is revisited once with the best significant candidate of another effect
//!   (see [`diagnose`]).
//!
//! Extension fits start from the current optimum embedded in the larger model ([`embed`]:
//! a nested extension can then only improve) plus seeded, screened random starts, with
//! Levenberg–Marquardt on χ² by default. A round's candidates are fitted on one backend
//! (the GPU when present), each fit sending all its restarts as one batch; the candidates
//! go one after the other (on lavapipe or the CPU backend concurrency only adds
//! contention: 12 s instead of 3.4 s for the 7 extensions of `lambert` on 552 samples),
//! or concurrently with `parallel` (`--parallel`).

use crate::backend::{self, Backend, BackendChoice};
use crate::dataset::{Dataset, Kind, ReadOptions, Sample};
use crate::fit::{fit_outcome, FitOptions, Optimizer};
use crate::loss::{normalised_residuals, Loss, Metric, Weights};
use crate::model::{Ast, Model};
use crate::uncertainty::Covariance;
use anyhow::{Context, Result};
use glam::DVec3;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

// ---------------------------------------------------------------------------------------
// Effects (the contract's names, DESIGN §7)

/// A physical effect a model may be missing (DESIGN §7; the names are a contract).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Effect {
    SpecularLobe,
    Backscatter,
    RetroLobe,
    GrazingDecay,
    Scale,
    Absorption,
    LongTail,
    Anisotropy,
    DiffuseFloor,
}

impl Effect {
    pub const ALL: [Effect; 9] = [
        Effect::SpecularLobe,
        Effect::Backscatter,
        Effect::RetroLobe,
        Effect::GrazingDecay,
        Effect::Scale,
        Effect::Absorption,
        Effect::LongTail,
        Effect::Anisotropy,
        Effect::DiffuseFloor,
    ];

    /// The contract name (`specular_lobe`, …).
    pub fn name(self) -> &'static str {
        match self {
            Effect::SpecularLobe => "specular_lobe",
            Effect::Backscatter => "backscatter",
            Effect::RetroLobe => "retro_lobe",
            Effect::GrazingDecay => "grazing_decay",
            Effect::Scale => "scale",
            Effect::Absorption => "absorption",
            Effect::LongTail => "long_tail",
            Effect::Anisotropy => "anisotropy",
            Effect::DiffuseFloor => "diffuse_floor",
        }
    }

    /// The residual signature DESIGN §7 gives for the effect.
    pub fn signature(self) -> &'static str {
        match self {
            Effect::SpecularLobe => "excess around the mirror direction",
            Effect::Backscatter => "excess toward the retro direction, growing with θi",
            Effect::RetroLobe => "a sharp excess within a few degrees of ωo = ωi",
            Effect::GrazingDecay => "model too bright at large θo",
            Effect::Scale => "one-signed residual everywhere",
            Effect::Absorption => "deficit growing with θt",
            Effect::LongTail => "excess in the tails far from the peak",
            Effect::Anisotropy => "different widths on the two φ axes",
            Effect::DiffuseFloor => "a flat excess far from every lobe",
        }
    }

    pub fn from_name(name: &str) -> Option<Effect> {
        Effect::ALL.into_iter().find(|e| e.name() == name)
    }
}

impl std::fmt::Display for Effect {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

// ---------------------------------------------------------------------------------------
// Candidate extensions of a spec

/// One extension of the current model that would add an effect.
#[derive(Clone, Debug, PartialEq)]
pub struct Candidate {
    /// The extended spec (parses with [`Model::parse`]).
    pub spec: String,
    pub effect: Effect,
    /// Whether the current model is the extension at some parameter values (F test), or a
    /// swap that is not (BIC only).
    pub nested: bool,
}

/// Spec text of a syntax tree (the inverse of [`Ast::parse`]).
pub fn render_spec(ast: &Ast) -> String {
    match ast {
        Ast::Term { name, arg: None } => name.clone(),
        Ast::Term { name, arg: Some(a) } => format!("{name}({})", render_spec(a)),
        Ast::Suffix { inner, name } => format!("{}+{name}", render_spec(inner)),
    }
}

/// Split a spec into its core term and its suffixes (left to right).
fn peel(ast: &Ast) -> (Ast, Vec<String>) {
    let mut suffixes = Vec::new();
    let mut cur = ast;
    while let Ast::Suffix { inner, name } = cur {
        suffixes.push(name.clone());
        cur = inner;
    }
    suffixes.reverse();
    (cur.clone(), suffixes)
}

fn with_suffixes(core: &str, suffixes: &[String]) -> String {
    let mut s = core.to_string();
    for x in suffixes {
        s.push('+');
        s.push_str(x);
    }
    s
}

const DIFFUSE_BASES: [&str; 4] = ["lambert", "on", "eon", "vmf"];
const BASES: [&str; 5] = ["lambert", "on", "eon", "vmf", "ggx"];

/// Every applicable extension of `spec` for `data` (DESIGN §7's effect → extension table),
/// each checked to parse for the data's channels and planes.
///
/// BRDF, for a core term M (suffixes such as `+retro` are kept):
/// - `backscatter`: `lambert` → `on`, `eon`, `vmf` (also inside `fa`, `dmg`, `rmg`);
/// - `specular_lobe`: a diffuse base B → `fa(B)`;
/// - `diffuse_floor`: `ggx` → `fa(lambert)` (a Lambertian term under the lobe);
/// - `grazing_decay`: a base B → `dmg(B)`, `rmg(B)`;
/// - `retro_lobe`: M → `M+retro`.
///
/// BTDF, `btdf(N)` with suffixes: `scale` → `+scale`, `absorption` → `+absorb`,
/// `diffuse_floor` → `+diffuse`, `anisotropy` → `+peraxis` (only with ≥ 2 φ planes),
/// `long_tail` → `beckmann`/`gg` → `tr` (a swap, not nested), `tr` → `gtr` (γ = 2 is TR).
pub fn extensions(spec: &str, data: &Dataset) -> Result<Vec<Candidate>> {
    let clean: String = spec.chars().filter(|c| !c.is_whitespace()).collect();
    let ast = Ast::parse(&clean)?;
    let (core, suffixes) = peel(&ast);
    let Ast::Term { name, arg } = &core else {
        unreachable!("peel returns a term")
    };
    let arg_name = match arg.as_deref() {
        Some(Ast::Term { name, arg: None }) => Some(name.as_str()),
        _ => None,
    };
    let mut out: Vec<Candidate> = Vec::new();
    let mut push = |core: String, sfx: &[String], effect: Effect, nested: bool| {
        out.push(Candidate {
            spec: with_suffixes(&core, sfx),
            effect,
            nested,
        });
    };
    match data.kind {
        Kind::Brdf => {
            let n = name.as_str();
            if arg.is_none() && BASES.contains(&n) {
                if n == "lambert" {
                    for alt in ["on", "eon", "vmf"] {
                        push(alt.into(), &suffixes, Effect::Backscatter, true);
                    }
                }
                if DIFFUSE_BASES.contains(&n) {
                    push(format!("fa({n})"), &suffixes, Effect::SpecularLobe, true);
                }
                if n == "ggx" {
                    push("fa(lambert)".into(), &suffixes, Effect::DiffuseFloor, true);
                }
                for comb in ["dmg", "rmg"] {
                    push(
                        format!("{comb}({n})"),
                        &suffixes,
                        Effect::GrazingDecay,
                        true,
                    );
                }
            } else if matches!(n, "fa" | "dmg" | "rmg") && arg_name == Some("lambert") {
                for alt in ["on", "eon", "vmf"] {
                    push(format!("{n}({alt})"), &suffixes, Effect::Backscatter, true);
                }
            }
            if !suffixes.iter().any(|s| s == "retro") {
                let mut sfx = suffixes.clone();
                sfx.push("retro".into());
                push(render_spec(&core), &sfx, Effect::RetroLobe, true);
            }
        }
        Kind::Btdf => {
            if name == "btdf" {
                match arg_name {
                    Some("beckmann") | Some("gg") => {
                        push("btdf(tr)".into(), &suffixes, Effect::LongTail, false)
                    }
                    Some("tr") => push("btdf(gtr)".into(), &suffixes, Effect::LongTail, true),
                    _ => {}
                }
            }
            let core_s = render_spec(&core);
            let mut add = |sfx_name: &str, effect: Effect| {
                if !suffixes.iter().any(|s| s == sfx_name) {
                    let mut sfx = suffixes.clone();
                    sfx.push(sfx_name.into());
                    push(core_s.clone(), &sfx, effect, true);
                }
            };
            add("scale", Effect::Scale);
            add("absorb", Effect::Absorption);
            add("diffuse", Effect::DiffuseFloor);
            if data.axes.len() > 1 {
                add("peraxis", Effect::Anisotropy);
            }
        }
    }
    // Every generated spec must parse for this data (channels, planes).
    out.retain(|c| Model::for_data(&c.spec, data).is_ok());
    Ok(out)
}

/// The extension's parameters at which it reproduces the current model (or a good start
/// for a swap): shared names are copied (a wrapped base's `base.x` from `x`, a lobe's
/// `lobe.x` from `x`), per-plane copies replicate a shared value, and the new parameters
/// take their neutral values (σ = r = 0, k_s = 0 and η = 1, k_r = 0, S = 1, τ = 0,
/// k_d = 0, γ = 2, τ0 at its lower bound with Lambertian-like grains (η_g = 1) as bright
/// as the base).
pub fn embed(old: &Model, old_flat: &[f64], new: &Model) -> Vec<f64> {
    let ch = new.channels;
    let mut flat = new.defaults();
    let find = |name: &str| old.params.iter().find(|q| q.name == name);
    let alias = |name: &str| -> Option<&'static str> {
        match (new.kind, name) {
            (Kind::Btdf, "alpha") => Some("beta"),
            (Kind::Btdf, "beta") => Some("alpha"),
            _ => None,
        }
    };
    for p in &new.params {
        let w = p.width(ch);
        let mut source = find(&p.name)
            .or_else(|| p.name.strip_prefix("base.").and_then(find))
            .or_else(|| p.name.strip_prefix("lobe.").and_then(find))
            .or_else(|| alias(&p.name).and_then(find));
        if p.name == "rho_g" && source.is_none() {
            // Grains as bright as the base: dmg(lambert) is then lambert for any τ0.
            source = find("rho").or_else(|| find("base.rho"));
        }
        let slot = &mut flat[p.index..p.index + w];
        match source {
            Some(q) => {
                let src = &old_flat[q.index..q.index + q.width(old.channels)];
                for (k, v) in slot.iter_mut().enumerate() {
                    *v = src[k % src.len()].clamp(p.decl.lo, p.decl.hi);
                }
            }
            None => {
                let neutral = match p.name.as_str() {
                    "sigma" | "base.sigma" | "r" | "base.r" | "lobe.ks" | "kr" | "tau" | "kd"
                    | "base.rho" | "rho_g" => Some(0.0),
                    // η = 1: no Fresnel reflection, so fa's lobe and rmg's grain specular vanish.
                    "lobe.eta" | "eta_g" => Some(1.0),
                    "scale" => Some(1.0),
                    "gamma" => Some(2.0),
                    // The thinnest layer of the flattest grains: w ≈ τ0 at every angle.
                    "tau0" => Some(p.decl.lo),
                    "beta" if new.kind == Kind::Brdf => Some(p.decl.lo),
                    _ => None,
                };
                if let Some(v) = neutral {
                    slot.fill(v.clamp(p.decl.lo, p.decl.hi));
                }
            }
        }
    }
    flat
}

// ---------------------------------------------------------------------------------------
// Distributions: regularized incomplete gamma and beta (Numerical Recipes §6.2, §6.4)

/// ln Γ(x), x > 0 (Lanczos, g = 7, n = 9; relative error < 1e-14).
pub fn ln_gamma(x: f64) -> f64 {
    const G: f64 = 7.0;
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection.
        let pi = std::f64::consts::PI;
        return (pi / (pi * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + G + 0.5;
    for (i, &c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// Regularized upper incomplete gamma Q(a, x) = Γ(a, x)/Γ(a).
pub fn gamma_q(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    let gln = ln_gamma(a);
    if x < a + 1.0 {
        // Series for P.
        let (mut ap, mut sum) = (a, 1.0 / a);
        let mut del = sum;
        for _ in 0..100_000 {
            ap += 1.0;
            del *= x / ap;
            sum += del;
            if del.abs() < sum.abs() * 1e-15 {
                break;
            }
        }
        (1.0 - sum * (-x + a * x.ln() - gln).exp()).clamp(0.0, 1.0)
    } else {
        // Continued fraction for Q (modified Lentz).
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..100_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-15 {
                break;
            }
        }
        ((-x + a * x.ln() - gln).exp() * h).clamp(0.0, 1.0)
    }
}

fn beta_cf(a: f64, b: f64, x: f64) -> f64 {
    let tiny = 1e-300;
    let (qab, qap, qam) = (a + b, a + 1.0, a - 1.0);
    let mut c = 1.0;
    let mut d = 1.0 - qab * x / qap;
    if d.abs() < tiny {
        d = tiny;
    }
    d = 1.0 / d;
    let mut h = d;
    for m in 1..100_000 {
        let m = m as f64;
        let m2 = 2.0 * m;
        let aa = m * (b - m) * x / ((qam + m2) * (a + m2));
        d = 1.0 + aa * d;
        if d.abs() < tiny {
            d = tiny;
        }
        c = 1.0 + aa / c;
        if c.abs() < tiny {
            c = tiny;
        }
        d = 1.0 / d;
        h *= d * c;
        let aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
        d = 1.0 + aa * d;
        if d.abs() < tiny {
            d = tiny;
        }
        c = 1.0 + aa / c;
        if c.abs() < tiny {
            c = tiny;
        }
        d = 1.0 / d;
        let del = d * c;
        h *= del;
        if (del - 1.0).abs() < 1e-15 {
            break;
        }
    }
    h
}

/// Regularized incomplete beta I_x(a, b).
pub fn beta_i(a: f64, b: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let ln_front = ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln();
    if x < (a + 1.0) / (a + b + 2.0) {
        (ln_front.exp() * beta_cf(a, b, x) / a).clamp(0.0, 1.0)
    } else {
        (1.0 - ln_front.exp() * beta_cf(b, a, 1.0 - x) / b).clamp(0.0, 1.0)
    }
}

/// P(χ²_k ≥ x): the p-value of a χ² with k degrees of freedom.
pub fn chi2_sf(x: f64, k: f64) -> f64 {
    gamma_q(0.5 * k, 0.5 * x)
}

/// P(F(d1, d2) ≥ f): the p-value of an F statistic.
pub fn f_sf(f: f64, d1: f64, d2: f64) -> f64 {
    if f <= 0.0 {
        return 1.0;
    }
    beta_i(0.5 * d2, 0.5 * d1, d2 / (d2 + d1 * f))
}

fn fmt_p(p: f64) -> String {
    if p < 1e-300 {
        "p < 1e-300".into()
    } else if p < 1e-3 {
        format!("p = {p:.1e}")
    } else {
        format!("p = {p:.3}")
    }
}

// ---------------------------------------------------------------------------------------
// Fitting

/// Options of a diagnosis.
#[derive(Clone, Debug)]
pub struct DiagnoseOptions {
    /// The loss that drives each fit (χ² unless told otherwise); the tests always use χ².
    pub loss: Loss,
    pub optimizer: Optimizer,
    /// Random restarts per fit (the embedded current optimum is one more start).
    pub restarts: usize,
    pub seed: u64,
    /// Random draws per restart, screened to the best `restarts` (as `fit`).
    pub screen: usize,
    /// Significance level of the consistency test and (Bonferroni-corrected) of the F tests.
    pub alpha: f64,
    /// Most effects to add.
    pub max_steps: usize,
    /// Stop as soon as χ²_red is consistent with the uncertainties (DESIGN §7). Turning it
    /// off makes every round fit and test the candidates anyway (used to measure the false
    /// positive rate of the F/BIC gates on their own).
    pub stop_when_consistent: bool,
    /// When the greedy path ends inconsistent, revisit each step once with the best
    /// candidate of another effect and keep the path with the lowest final BIC.
    pub backtrack: bool,
    /// Fit a round's candidates concurrently (one thread each) on the shared backend;
    /// otherwise one after the other, each fit batching all its restarts.
    pub parallel: bool,
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        DiagnoseOptions {
            loss: Loss::new(Metric::Chi2, Weights::Uniform),
            optimizer: Optimizer::Lm,
            restarts: 16,
            seed: 1,
            screen: 8,
            alpha: 0.01,
            max_steps: 4,
            stop_when_consistent: true,
            backtrack: true,
            parallel: false,
        }
    }
}

/// One fitted model (χ² statistics, parameters, residuals).
#[derive(Clone, Debug)]
pub struct FitResult {
    pub model: Model,
    pub flat: Vec<f64>,
    /// Model values at the samples.
    pub values: Vec<f64>,
    /// Normalized residuals z = (y′ − y)/u.
    pub z: Vec<f64>,
    pub chi2: f64,
    pub dof: usize,
    pub chi2_red: f64,
    /// Best value of the driving loss.
    pub loss: f64,
    pub cov: Covariance,
    pub seconds: f64,
}

impl FitResult {
    pub fn spec(&self) -> &str {
        &self.model.spec
    }
    /// P(χ²_{K−P} ≥ χ²).
    pub fn p_consistent(&self) -> f64 {
        chi2_sf(self.chi2, self.dof as f64)
    }
}

/// Multi-start fit of `model` with extra starting points `seeds` (physical parameters).
pub fn fit_model(
    model: &Model,
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    seeds: &[Vec<f64>],
) -> Result<FitResult> {
    anyhow::ensure!(
        data.len() > model.dim,
        "{} cannot determine the {} parameters of {}",
        crate::dataset::count(data.len(), "sample", "samples"),
        model.dim,
        model.spec
    );
    // SMAPE is not a sum of squares: LM cannot fit it, compass can.
    let optimizer = if opts.optimizer == Optimizer::Lm && !opts.loss.is_sum_of_squares() {
        Optimizer::Compass
    } else {
        opts.optimizer
    };
    let fit_opts = FitOptions {
        optimizer,
        restarts: opts.restarts.max(1),
        seed: opts.seed,
        screen: opts.screen,
        initial_points: seeds.to_vec(),
        ..Default::default()
    };
    let o = fit_outcome(model, data, opts.loss, backend, &fit_opts, &mut |_| {})?;
    let dof = data.len() - model.dim;
    Ok(FitResult {
        model: model.clone(),
        z: normalised_residuals(data, &o.values),
        flat: o.flat,
        values: o.values,
        chi2: o.chi2,
        dof,
        chi2_red: o.chi2 / dof as f64,
        loss: o.loss,
        cov: o.cov,
        seconds: o.seconds,
    })
}

// ---------------------------------------------------------------------------------------
// Where the model and the measurement disagree

/// Mean and RMS of z over one angular region (optionally restricted in θi).
#[derive(Clone, Debug)]
pub struct RegionStat {
    /// The region in words, e.g. "within 15° of the mirror direction for θi ≥ 30°".
    pub words: String,
    pub n: usize,
    pub mean: f64,
    pub rms: f64,
    /// Fraction of the region's residuals with the sign of the mean.
    pub same_sign: f64,
    mask: Vec<bool>,
}

impl RegionStat {
    /// mean·√n: the mean's significance if the z were independent N(0, 1).
    pub fn t(&self) -> f64 {
        self.mean * (self.n as f64).sqrt()
    }
}

fn angle_deg(a: DVec3, b: DVec3) -> f64 {
    a.normalize()
        .dot(b.normalize())
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

fn stat(words: String, mask: Vec<bool>, z: &[f64]) -> Option<RegionStat> {
    let zs: Vec<f64> = z
        .iter()
        .zip(&mask)
        .filter(|(_, &m)| m)
        .map(|(&v, _)| v)
        .collect();
    if zs.is_empty() {
        return None;
    }
    let n = zs.len();
    let mean = zs.iter().sum::<f64>() / n as f64;
    let rms = (zs.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
    let same_sign = zs.iter().filter(|v| v.signum() == mean.signum()).count() as f64 / n as f64;
    Some(RegionStat {
        words,
        n,
        mean,
        rms,
        same_sign,
        mask,
    })
}

/// The statistics of z over every angular region of DESIGN §7 that the data covers:
/// BRDF — near the mirror and the retro direction (5° and 15°), the source (backscatter)
/// side, the forward side away from the mirror, grazing θo ≥ 60°, the tails more than 30°
/// from the mirror; BTDF — near the transmission peak (the brightest sample of each
/// incidence and plane), its flanks (5–50 % of the peak) and tails (< 5 %), large θt;
/// both — everywhere and each φ plane; each also for θi ≥ 30° and θi ≥ 60°.
pub fn region_stats(data: &Dataset, z: &[f64]) -> Vec<RegionStat> {
    let k = data.len();
    let mut regions: Vec<(String, Vec<bool>)> = Vec::new();
    let by = |f: &dyn Fn(&Sample) -> bool| data.samples.iter().map(f).collect::<Vec<bool>>();
    match data.kind {
        Kind::Brdf => {
            let mirror = |s: &Sample| angle_deg(s.wo, DVec3::new(-s.wi.x, -s.wi.y, s.wi.z));
            let retro = |s: &Sample| angle_deg(s.wo, s.wi);
            for r in [5.0, 15.0] {
                regions.push((
                    format!("within {r}° of the mirror direction"),
                    by(&|s| mirror(s) <= r + 0.5 && mirror(s) < retro(s)),
                ));
            }
            for r in [5.0, 15.0] {
                regions.push((
                    format!("within {r}° of the retro direction"),
                    by(&|s| retro(s) <= r + 0.5 && retro(s) < mirror(s)),
                ));
            }
            let side = |s: &Sample| s.wo.x * s.wi.x + s.wo.y * s.wi.y;
            regions.push((
                "on the source (backscatter) side".into(),
                by(&|s| side(s) > 1e-9),
            ));
            regions.push((
                "on the forward side away from the mirror direction".into(),
                by(&|s| side(s) < -1e-9 && mirror(s) > 15.5),
            ));
            regions.push((
                "at grazing θo ≥ 60° away from the mirror direction".into(),
                by(&|s| s.theta_o.to_degrees() >= 59.5 && mirror(s) > 15.5),
            ));
            regions.push((
                "in the tails more than 30° from the mirror direction".into(),
                by(&|s| mirror(s) > 30.5),
            ));
        }
        Kind::Btdf => {
            // The peak of each (incidence, plane, channel) curve: its brightest sample.
            let key = |s: &Sample| {
                (
                    (s.theta_i.to_degrees() * 10.0).round() as i64,
                    (s.phi_i.to_degrees() * 10.0).round() as i64,
                    s.axis,
                    s.channel,
                )
            };
            let mut peaks: std::collections::HashMap<_, usize> = Default::default();
            for (j, s) in data.samples.iter().enumerate() {
                let e = peaks.entry(key(s)).or_insert(j);
                if s.value > data.samples[*e].value {
                    *e = j;
                }
            }
            let peak = |s: &Sample| &data.samples[peaks[&key(s)]];
            let ratio = |s: &Sample| s.value / peak(s).value.max(1e-300);
            for r in [5.0, 15.0] {
                regions.push((
                    format!("within {r}° of the transmission peak"),
                    by(&|s| angle_deg(s.wo, peak(s).wo) <= r + 0.5),
                ));
            }
            regions.push((
                "on the flanks of the peak (5–50 % of its value)".into(),
                by(&|s| (0.05..0.5).contains(&ratio(s))),
            ));
            regions.push((
                "in the tails (below 5 % of the peak value)".into(),
                by(&|s| ratio(s) < 0.05),
            ));
            regions.push((
                "at large θt ≥ 50°".into(),
                by(&|s| s.theta_o.to_degrees() >= 49.5),
            ));
            regions.push((
                "at θt ≥ 70°".into(),
                by(&|s| s.theta_o.to_degrees() >= 69.5),
            ));
        }
    }
    regions.push(("everywhere".into(), vec![true; k]));
    if data.axes.len() > 1 {
        for (a, phi) in data.axes.iter().enumerate() {
            regions.push((
                format!("on the φ = {phi}° plane"),
                by(&|s| s.axis == a && s.theta_o > 1e-9),
            ));
        }
    }
    let mut out = Vec::new();
    let ti = |s: &Sample| s.theta_i.to_degrees();
    for (words, mask) in regions {
        if let Some(st) = stat(words.clone(), mask.clone(), z) {
            out.push(st);
        }
        for lim in [30.0, 60.0] {
            let sub: Vec<bool> = mask
                .iter()
                .zip(&data.samples)
                .map(|(&m, s)| m && ti(s) >= lim - 0.5)
                .collect();
            let n_sub = sub.iter().filter(|&&m| m).count();
            let n_all = mask.iter().filter(|&&m| m).count();
            if n_sub > 0 && n_sub < n_all {
                if let Some(st) = stat(format!("{words} for θi ≥ {lim}°"), sub, z) {
                    out.push(st);
                }
            }
        }
    }
    out
}

fn sentence(r: &RegionStat) -> String {
    let dir = if r.mean < 0.0 { "dark" } else { "bright" };
    let sign = if r.words == "everywhere" {
        format!(", {:.0} % of residuals one-signed", 100.0 * r.same_sign)
    } else {
        String::new()
    };
    format!(
        "model {:.1}σ too {dir} {} (n = {}, RMS z = {:.1}{sign})",
        r.mean.abs(),
        r.words,
        r.n,
        r.rms
    )
}

/// Where the residuals say the model misses, in words: up to three regions whose mean z
/// exceeds 1σ in size and 3 in significance (mean·√n), each localized to its most
/// concentrated sub-region, overlapping regions reported once.
pub fn describe_regions(data: &Dataset, z: &[f64]) -> String {
    let stats = region_stats(data, z);
    let passes = |r: &RegionStat| r.n >= 3 && r.mean.abs() >= 1.0 && r.t().abs() >= 3.0;
    let mut order: Vec<&RegionStat> = stats.iter().filter(|r| passes(r)).collect();
    order.sort_by(|a, b| b.t().abs().total_cmp(&a.t().abs()));
    let mut covered = vec![false; z.len()];
    let mut said: Vec<String> = Vec::new();
    for r in order {
        if said.len() == 3 {
            break;
        }
        let overlap = r
            .mask
            .iter()
            .zip(&covered)
            .filter(|(&m, &c)| m && c)
            .count();
        if overlap * 2 > r.n {
            continue;
        }
        // Localize: a sub-region of the same sign with a much larger mean says it better.
        let mut best = r;
        loop {
            let inner = stats
                .iter()
                .filter(|s| passes(s) && s.n < best.n && s.mean.signum() == best.mean.signum())
                .filter(|s| s.mask.iter().zip(&best.mask).all(|(&a, &b)| !a || b))
                .filter(|s| s.mean.abs() >= 1.5 * best.mean.abs())
                .max_by(|a, b| a.mean.abs().total_cmp(&b.mean.abs()));
            match inner {
                Some(s) => best = s,
                None => break,
            }
        }
        if best
            .mask
            .iter()
            .zip(&covered)
            .filter(|(&m, &c)| m && c)
            .count()
            * 2
            > best.n
        {
            continue;
        }
        for (c, &m) in covered.iter_mut().zip(&r.mask) {
            *c |= m;
        }
        said.push(sentence(best));
    }
    if said.is_empty() {
        let (j, zmax) = z.iter().enumerate().fold((0, 0.0f64), |acc, (j, &v)| {
            if v.abs() > acc.1.abs() {
                (j, v)
            } else {
                acc
            }
        });
        let rms = (z.iter().map(|v| v * v).sum::<f64>() / z.len().max(1) as f64).sqrt();
        let s = &data.samples[j];
        format!(
            "no angular region is off by more than 1σ on average (RMS z = {rms:.2}; largest z = {zmax:+.1} at θi = {:.0}°, θo = {:.0}°, φo = {:.0}°)",
            s.theta_i.to_degrees(),
            s.theta_o.to_degrees(),
            s.phi_o.to_degrees()
        )
    } else {
        said.join("; ")
    }
}

// ---------------------------------------------------------------------------------------
// Comparing candidates

/// A fitted candidate and its comparison with the current model.
#[derive(Clone, Debug)]
pub struct Scored {
    pub candidate: Candidate,
    pub fit: Option<FitResult>,
    /// Extra parameters over the current model.
    pub dp: i64,
    pub delta_chi2: f64,
    /// F statistic and its p-value (nested candidates).
    pub f: Option<f64>,
    pub p: Option<f64>,
    /// BIC(candidate) − BIC(current), χ² taken as is.
    pub delta_bic: f64,
    /// The same with both χ² divided by max(1, χ²_red of the candidate).
    pub delta_bic_scaled: f64,
    pub significant: bool,
    pub identifiable: bool,
    pub verdict: String,
}

/// Whether the extension's new parameters are determined: at least one of them has a
/// standard uncertainty within its range and a multiple correlation with the others
/// below 0.999.
fn new_params_determined(old: &Model, fit: &FitResult) -> (bool, String) {
    let old_names: Vec<String> = old.flat_names();
    let names = fit.model.flat_names();
    let decls = fit.model.flat_decls();
    let is_old = |n: &str| {
        old_names.iter().any(|o| {
            o == n || n.strip_prefix("base.") == Some(o) || n.strip_prefix("lobe.") == Some(o)
        })
    };
    let new_idx: Vec<usize> = (0..names.len()).filter(|&j| !is_old(&names[j])).collect();
    if new_idx.is_empty() {
        return (true, String::new());
    }
    let p = names.len();
    let det: Vec<usize> = (0..p)
        .filter(|&j| fit.cov.std[j].is_some_and(|s| s > 0.0))
        .collect();
    let c = nalgebra::DMatrix::from_fn(det.len(), det.len(), |a, b| {
        fit.cov.correlation[det[a]][det[b]].unwrap_or(0.0)
    });
    let ci = c.try_inverse();
    let mut bad = Vec::new();
    let mut ok = false;
    for &j in &new_idx {
        let Some(s) = fit.cov.std[j] else {
            bad.push(format!("{} undetermined", names[j]));
            continue;
        };
        if s > decls[j].hi - decls[j].lo {
            bad.push(format!("{} ± {s:.2e} exceeds its range", names[j]));
            continue;
        }
        let r = match (&ci, det.iter().position(|&d| d == j)) {
            (Some(ci), Some(a)) if ci[(a, a)] > 1.0 => (1.0 - 1.0 / ci[(a, a)]).sqrt(),
            _ => 0.0,
        };
        if r > 0.999 {
            bad.push(format!(
                "{} not separable from the other parameters (multiple correlation {r:.4})",
                names[j]
            ));
            continue;
        }
        ok = true;
    }
    (ok, bad.join(", "))
}

fn score(
    data: &Dataset,
    current: &FitResult,
    candidate: Candidate,
    fit: Result<FitResult>,
    m: usize,
    alpha: f64,
) -> Scored {
    let k = data.len() as f64;
    let fit = match fit {
        Ok(f) => f,
        Err(e) => {
            return Scored {
                candidate,
                fit: None,
                dp: 0,
                delta_chi2: 0.0,
                f: None,
                p: None,
                delta_bic: f64::INFINITY,
                delta_bic_scaled: f64::INFINITY,
                significant: false,
                identifiable: false,
                verdict: format!("fit failed: {e:#}"),
            }
        }
    };
    let dp = fit.model.dim as i64 - current.model.dim as i64;
    let delta_chi2 = current.chi2 - fit.chi2;
    let s = fit.chi2_red.max(1.0);
    let delta_bic = (fit.chi2 - current.chi2) + dp as f64 * k.ln();
    let delta_bic_scaled = (fit.chi2 - current.chi2) / s + dp as f64 * k.ln();
    let (f, p) = if candidate.nested && dp > 0 {
        let fstat = (delta_chi2.max(0.0) / dp as f64) / (fit.chi2 / fit.dof as f64);
        (Some(fstat), Some(f_sf(fstat, dp as f64, fit.dof as f64)))
    } else {
        (None, None)
    };
    let level = alpha / m.max(1) as f64;
    let significant = match p {
        Some(p) => p < level && delta_bic_scaled < 0.0,
        None => delta_bic_scaled < -10.0,
    };
    let (identifiable, why) = new_params_determined(&current.model, &fit);
    let verdict = if !significant {
        match p {
            Some(p) => format!(
                "not significant ({}, need < {level:.1e}; scaled ΔBIC {delta_bic_scaled:+.1})",
                fmt_p(p)
            ),
            None => {
                format!("not significant (swap: scaled ΔBIC {delta_bic_scaled:+.1}, need < −10)")
            }
        }
    } else if !identifiable {
        format!("significant but not identifiable: {why}")
    } else {
        "significant".into()
    };
    Scored {
        candidate,
        fit: Some(fit),
        dp,
        delta_chi2,
        f,
        p,
        delta_bic,
        delta_bic_scaled,
        significant,
        identifiable,
        verdict,
    }
}

// ---------------------------------------------------------------------------------------
// The workflow

/// One step of a diagnosis: the start fit (effect None) or an adopted extension.
#[derive(Clone, Debug)]
pub struct Step {
    pub model: String,
    pub effect: Option<Effect>,
    pub chi2_red: f64,
    pub loss: f64,
    pub evidence: String,
    pub fit: FitResult,
    /// The candidates fitted after this step (empty when the workflow stopped here
    /// before fitting any).
    pub candidates: Vec<Scored>,
}

/// The outcome of [`diagnose`].
#[derive(Clone, Debug)]
pub struct Diagnosis {
    pub start_model: String,
    pub final_model: String,
    pub effects: Vec<Effect>,
    pub steps: Vec<Step>,
    pub alpha: f64,
    pub backend: String,
}

impl Diagnosis {
    /// DESIGN §8: `{start_model, final_model, effects, steps: [{model, effect, chi2_red,
    /// loss, evidence}]}`.
    pub fn to_json(&self) -> Value {
        json!({
            "start_model": self.start_model,
            "final_model": self.final_model,
            "effects": self.effects.iter().map(|e| e.name()).collect::<Vec<_>>(),
            "steps": self.steps.iter().map(|s| json!({
                "model": s.model,
                "effect": s.effect.map(|e| e.name()),
                "chi2_red": num(s.chi2_red),
                "loss": num(s.loss),
                "evidence": s.evidence,
            })).collect::<Vec<_>>(),
        })
    }

    /// Every candidate of every round (for `--report`).
    pub fn candidates_json(&self) -> Value {
        Value::Array(
            self.steps
                .iter()
                .enumerate()
                .map(|(i, s)| {
                    json!({
                        "after_step": i,
                        "current": s.model,
                        "candidates": s.candidates.iter().map(|c| json!({
                            "model": c.candidate.spec,
                            "effect": c.candidate.effect.name(),
                            "nested": c.candidate.nested,
                            "chi2_red": c.fit.as_ref().map(|f| num(f.chi2_red)),
                            "extra_params": c.dp,
                            "delta_chi2": num(c.delta_chi2),
                            "F": c.f.map(num),
                            "p": c.p.map(num),
                            "delta_bic": num(c.delta_bic),
                            "delta_bic_scaled": num(c.delta_bic_scaled),
                            "significant": c.significant,
                            "identifiable": c.identifiable,
                            "verdict": c.verdict,
                        })).collect::<Vec<_>>(),
                    })
                })
                .collect(),
        )
    }
}

fn num(v: f64) -> Value {
    serde_json::Number::from_f64(v)
        .map(Value::Number)
        .unwrap_or(Value::Null)
}

fn consistency(fit: &FitResult, alpha: f64) -> (bool, String) {
    let p = fit.p_consistent();
    let ok = p >= alpha;
    let verdict = if ok {
        "consistent with the uncertainties"
    } else {
        "the misfit exceeds the uncertainties"
    };
    (
        ok,
        format!(
            "χ²_red = {:.3} on {} dof: {verdict} ({}, α = {alpha})",
            fit.chi2_red,
            fit.dof,
            fmt_p(p)
        ),
    )
}

fn fit_all(
    cands: &[Candidate],
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    current: &FitResult,
) -> Vec<Result<FitResult>> {
    let one = |c: &Candidate| -> Result<FitResult> {
        let model = Model::for_data(&c.spec, data)?;
        let seed = embed(&current.model, &current.flat, &model);
        fit_model(&model, data, backend, opts, &[seed])
            .with_context(|| format!("fitting {}", c.spec))
    };
    if opts.parallel && cands.len() > 1 {
        std::thread::scope(|scope| {
            let handles: Vec<_> = cands.iter().map(|c| scope.spawn(move || one(c))).collect();
            handles
                .into_iter()
                .map(|h| {
                    h.join()
                        .unwrap_or_else(|_| Err(anyhow::anyhow!("a candidate fit panicked")))
                })
                .collect()
        })
    } else {
        cands.iter().map(one).collect()
    }
}

/// Build the step that adopts `best` after `current` (its evidence: the test that adopted
/// it, the runner-up of another effect, the consistency verdict and the remaining regions).
fn adopt_step(
    data: &Dataset,
    current: &FitResult,
    best: &Scored,
    scored: &[Scored],
    opts: &DiagnoseOptions,
) -> (Step, bool) {
    let m = scored.len();
    let mut ranked: Vec<&Scored> = scored
        .iter()
        .filter(|s| s.significant && s.identifiable)
        .collect();
    ranked.sort_by(|a, b| a.delta_bic.total_cmp(&b.delta_bic));
    let fit = best.fit.clone().expect("a significant candidate has a fit");
    let effect = best.candidate.effect;
    let test = match (best.f, best.p) {
        (Some(f), Some(p)) => format!(
            "{} over {}: Δχ² = {:.1} for {} more parameter(s), F({}, {}) = {f:.1}, {}, ΔBIC = {:.1}",
            fit.model.spec,
            current.model.spec,
            best.delta_chi2,
            best.dp,
            best.dp,
            fit.dof,
            fmt_p(p),
            best.delta_bic
        ),
        _ => format!(
            "{} instead of {} (not nested, compared by BIC): Δχ² = {:.1}, ΔBIC = {:.1} (scaled {:.1})",
            fit.model.spec, current.model.spec, best.delta_chi2, best.delta_bic, best.delta_bic_scaled
        ),
    };
    let rank = ranked
        .iter()
        .position(|s| s.candidate.spec == best.candidate.spec)
        .unwrap_or(0);
    let other = ranked.iter().find(|s| s.candidate.effect != effect);
    let runner = match other {
        Some(r) if rank == 0 => format!(
            "; next best {} [{}] ΔBIC {:.1} worse",
            r.candidate.spec,
            r.candidate.effect,
            r.delta_bic - best.delta_bic
        ),
        Some(r) => format!(
            "; {} [{}] fitted better at this step (ΔBIC {:.1} lower) but led to a worse final model",
            r.candidate.spec,
            r.candidate.effect,
            best.delta_bic - r.delta_bic
        ),
        None => String::new(),
    };
    let (ok, text) = consistency(&fit, opts.alpha);
    let regions = describe_regions(data, &fit.z);
    let evidence = format!(
        "{} ({}): {test} (best of {m} candidates{runner}). Now {text}. {}",
        effect,
        effect.signature(),
        capitalize(&regions)
    );
    let step = Step {
        model: fit.model.spec.clone(),
        effect: Some(effect),
        chi2_red: fit.chi2_red,
        loss: fit.loss,
        evidence,
        fit,
        candidates: vec![],
    };
    (step, ok)
}

fn log_step(
    log: &mut dyn FnMut(String),
    k: usize,
    step: &Step,
    data: &Dataset,
    opts: &DiagnoseOptions,
) {
    let (_, text) = consistency(&step.fit, opts.alpha);
    log(format!("step {k}: {} — {text}", step.model));
    log(format!(
        "  residuals: {}",
        describe_regions(data, &step.fit.z)
    ));
}

/// Continue a path greedily: fit every extension of its last model, adopt the best
/// significant one, repeat. Returns the path and whether it ended consistent.
fn extend_path(
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    log: &mut dyn FnMut(String),
    mut steps: Vec<Step>,
) -> Result<(Vec<Step>, bool)> {
    loop {
        let current = steps.last().expect("a step").fit.clone();
        if consistency(&current, opts.alpha).0 && opts.stop_when_consistent {
            let last = steps.last_mut().unwrap();
            last.evidence.push_str(if last.effect.is_none() {
                ". Stopped: nothing to add"
            } else {
                ". Stopped: nothing significant remains"
            });
            return Ok((steps, true));
        }
        if steps.len() > opts.max_steps {
            steps.last_mut().unwrap().evidence.push_str(&format!(
                ". Stopped after {} effects (--max-steps)",
                opts.max_steps
            ));
            return Ok((steps, consistency(&current, opts.alpha).0));
        }
        let cands = extensions(&current.model.spec, data)?;
        if cands.is_empty() {
            steps
                .last_mut()
                .unwrap()
                .evidence
                .push_str(". Stopped: the catalogue has no extension of this model");
            return Ok((steps, consistency(&current, opts.alpha).0));
        }
        log(format!(
            "  fitting {} candidate extensions of {} on {}",
            cands.len(),
            current.model.spec,
            backend.id()
        ));
        let fits = fit_all(&cands, data, backend, opts, &current);
        let m = cands.len();
        let scored: Vec<Scored> = cands
            .into_iter()
            .zip(fits)
            .map(|(c, f)| score(data, &current, c, f, m, opts.alpha))
            .collect();
        log(format!(
            "    {:<26} {:<14} {:>10} {:>4} {:>10} {:>10} {:>10} {:>6}  verdict",
            "model", "effect", "χ²_red", "ΔP", "F", "p", "ΔBIC", "s"
        ));
        for s in &scored {
            log(format!(
                "    {:<26} {:<14} {:>10} {:>4} {:>10} {:>10} {:>10.1} {:>6.1}  {}",
                s.candidate.spec,
                s.candidate.effect.name(),
                s.fit
                    .as_ref()
                    .map(|f| format!("{:.3}", f.chi2_red))
                    .unwrap_or("-".into()),
                s.dp,
                s.f.map(|f| format!("{f:.1}")).unwrap_or("-".into()),
                s.p.map(|p| format!("{p:.1e}")).unwrap_or("-".into()),
                s.delta_bic,
                s.fit.as_ref().map(|f| f.seconds).unwrap_or(0.0),
                s.verdict
            ));
        }
        let best = scored
            .iter()
            .filter(|s| s.significant && s.identifiable)
            .min_by(|a, b| a.delta_bic.total_cmp(&b.delta_bic))
            .cloned();
        let Some(best) = best else {
            let why = if scored.iter().any(|s| s.significant) {
                "the only significant extensions add parameters the data does not determine"
            } else {
                "no extension improves the fit significantly; the remaining misfit is not one of the catalogue's effects, or the geometry cannot separate it"
            };
            log(format!("  → stop: {why}"));
            let last = steps.last_mut().unwrap();
            last.evidence.push_str(&format!(". Stopped: {why}"));
            last.candidates = scored;
            return Ok((steps, consistency(&current, opts.alpha).0));
        };
        let (step, _) = adopt_step(data, &current, &best, &scored, opts);
        log(format!(
            "  → adopt {} [{}]",
            step.model, best.candidate.effect
        ));
        log_step(log, steps.len(), &step, data, opts);
        steps.last_mut().unwrap().candidates = scored;
        steps.push(step);
    }
}

/// BIC of a path's final model: χ² + P ln K.
fn path_bic(steps: &[Step], k: usize) -> f64 {
    let f = &steps.last().expect("a step").fit;
    f.chi2 + f.model.dim as f64 * (k as f64).ln()
}

/// Run the discrepancy workflow from `start` on `data`. `log` receives progress lines
/// (the start fit, each round's candidate table, the decision).
///
/// The path is greedy (the best significant extension at each step). When it ends with
/// the misfit still exceeding the uncertainties, each earlier step is revisited once with
/// the best significant candidate of another effect, continued greedily, and the path
/// whose final model has the lowest BIC is reported — the first that ends consistent, if
/// any (an effect can mimic another at first, e.g. rough micrograins a coarsely sampled
/// specular lobe).
pub fn diagnose(
    data: &Dataset,
    start: &str,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    log: &mut dyn FnMut(String),
) -> Result<Diagnosis> {
    let model = Model::for_data(start, data).context("--model")?;
    anyhow::ensure!(
        model.kind == data.kind,
        "model {} is a {} model but the data is {}",
        model.spec,
        model.kind,
        data.kind
    );
    let first = fit_model(&model, data, backend, opts, &[])?;
    let (_, text) = consistency(&first, opts.alpha);
    let regions = describe_regions(data, &first.z);
    let step0 = Step {
        model: model.spec.clone(),
        effect: None,
        chi2_red: first.chi2_red,
        loss: first.loss,
        evidence: format!("{text}. {}", capitalize(&regions)),
        fit: first,
        candidates: vec![],
    };
    log_step(log, 0, &step0, data, opts);
    let (greedy, ok) = extend_path(data, backend, opts, log, vec![step0])?;
    let mut best_path = greedy.clone();
    if !ok && opts.backtrack {
        for r in 0..greedy.len().saturating_sub(1) {
            let adopted = greedy[r + 1].effect;
            let scored = &greedy[r].candidates;
            let alt = scored
                .iter()
                .filter(|s| s.significant && s.identifiable && Some(s.candidate.effect) != adopted)
                .min_by(|a, b| a.delta_bic.total_cmp(&b.delta_bic));
            let Some(alt) = alt else { continue };
            log(format!(
                "  ↺ {} ended with χ²_red = {:.3}: trying {} [{}] instead of {} at step {}",
                greedy.last().unwrap().model,
                greedy.last().unwrap().chi2_red,
                alt.candidate.spec,
                alt.candidate.effect,
                greedy[r + 1].model,
                r + 1
            ));
            let mut steps: Vec<Step> = greedy[..=r].to_vec();
            let (step, _) = adopt_step(data, &steps[r].fit, alt, scored, opts);
            log_step(log, r + 1, &step, data, opts);
            steps.push(step);
            let (path, consistent) = extend_path(data, backend, opts, log, steps)?;
            if path_bic(&path, data.len()) < path_bic(&best_path, data.len()) {
                best_path = path;
                if consistent {
                    break; // nothing significant remains on this path
                }
            }
        }
        if best_path.last().unwrap().model != greedy.last().unwrap().model {
            let g = greedy.last().unwrap();
            let note = format!(
                ". Chosen over the greedy path {} (final χ²_red = {:.3}, BIC {:.1} higher)",
                greedy
                    .iter()
                    .map(|s| s.model.as_str())
                    .collect::<Vec<_>>()
                    .join(" → "),
                g.chi2_red,
                path_bic(&greedy, data.len()) - path_bic(&best_path, data.len())
            );
            log(format!(
                "  ↺ chose {}{note}",
                best_path.last().unwrap().model
            ));
            best_path.last_mut().unwrap().evidence.push_str(&note);
        }
    }
    let steps = best_path;
    Ok(Diagnosis {
        start_model: model.spec.clone(),
        final_model: steps.last().unwrap().model.clone(),
        effects: steps.iter().filter_map(|s| s.effect).collect(),
        steps,
        alpha: opts.alpha,
        backend: backend.name(),
    })
}

fn capitalize(s: &str) -> String {
    let mut c = s.chars();
    match c.next() {
        Some(f) => f.to_uppercase().collect::<String>() + c.as_str(),
        None => String::new(),
    }
}

// ---------------------------------------------------------------------------------------
// Report: residual maps and the χ²_red staircase (SVG via crate::plot)

/// Signed outgoing angle (degrees): negative on the far side of the plane of incidence
/// (BRDF: the mirror side, as in files) or of the sample's measurement plane (BTDF).
fn signed_out(data: &Dataset, s: &Sample) -> f64 {
    let t = s.theta_o.to_degrees();
    let reference = match data.kind {
        Kind::Brdf => s.phi_i,
        Kind::Btdf => data.axes.get(s.axis).copied().unwrap_or(0.0).to_radians(),
    };
    if (s.phi_o - reference).cos() >= -1e-9 {
        t
    } else {
        -t
    }
}

/// The residual map of one fit: z against signed θo per θi (BRDF) or against signed θt
/// per (θi, plane) (BTDF), all channels, with ±3 guides.
pub fn residual_panel(data: &Dataset, fit: &FitResult, title: &str) -> crate::plot::Panel {
    use crate::plot::{Panel, Series, PALETTE};
    let mut keys: Vec<(i64, usize)> = data
        .samples
        .iter()
        .map(|s| {
            (
                (s.theta_i.to_degrees() * 10.0).round() as i64,
                if data.kind == Kind::Btdf { s.axis } else { 0 },
            )
        })
        .collect();
    keys.sort();
    keys.dedup();
    let mut series: Vec<Series> = keys
        .iter()
        .enumerate()
        .map(|(i, &(ti, ax))| {
            let mut label = format!("θi = {}°", ti as f64 / 10.0);
            if data.kind == Kind::Btdf && data.axes.len() > 1 {
                label += &format!(", φ = {}°", data.axes[ax]);
            }
            let points = data
                .samples
                .iter()
                .zip(&fit.z)
                .filter(|(s, _)| {
                    (s.theta_i.to_degrees() * 10.0).round() as i64 == ti
                        && (data.kind == Kind::Brdf || s.axis == ax)
                })
                .map(|(s, &z)| (signed_out(data, s), z, 0.0))
                .collect();
            Series {
                label,
                color: PALETTE[i % PALETTE.len()],
                points,
                ..Default::default()
            }
        })
        .collect();
    let xs: Vec<f64> = data.samples.iter().map(|s| signed_out(data, s)).collect();
    let (x0, x1) = xs
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    for g in [-3.0, 3.0] {
        series.push(Series {
            label: String::new(),
            color: (150, 150, 150),
            curve: vec![(x0, g), (x1, g)],
            dashed: true,
            ..Default::default()
        });
    }
    let x_label = match data.kind {
        Kind::Brdf => "θo (°, negative on the mirror side)",
        Kind::Btdf => "θt (°, signed in its φ plane)",
    };
    Panel {
        title: title.into(),
        x_label: x_label.into(),
        y_label: "z = (y′ − y)/u".into(),
        series,
        log_y: Some(false),
    }
}

/// The χ²_red staircase over the steps (log axis), one labelled point per step.
pub fn staircase_panel(d: &Diagnosis) -> crate::plot::Panel {
    use crate::plot::{Panel, Series, PALETTE};
    let mut stair = Vec::new();
    for (i, s) in d.steps.iter().enumerate() {
        stair.push((i as f64 - 0.45, s.chi2_red));
        stair.push((i as f64 + 0.45, s.chi2_red));
    }
    let mut series = vec![Series {
        label: String::new(),
        color: (60, 60, 60),
        curve: stair,
        ..Default::default()
    }];
    for (i, s) in d.steps.iter().enumerate() {
        let what = match s.effect {
            Some(e) => format!("+{e} → {}", s.model),
            None => s.model.clone(),
        };
        series.push(Series {
            label: format!("{i}: {what} ({:.3})", s.chi2_red),
            color: PALETTE[i % PALETTE.len()],
            points: vec![(i as f64, s.chi2_red, 0.0)],
            ..Default::default()
        });
    }
    // At least 6 steps wide, so that the axis ticks fall on whole steps.
    let n = (d.steps.len() as f64).max(6.0);
    series.push(Series {
        label: "χ²_red = 1".into(),
        color: (150, 150, 150),
        curve: vec![(-0.5, 1.0), (n - 0.5, 1.0)],
        dashed: true,
        ..Default::default()
    });
    Panel {
        title: "χ²_red per step".into(),
        x_label: "step".into(),
        y_label: "χ²_red".into(),
        series,
        log_y: Some(true),
    }
}

/// Write `--report DIR`: `residuals_<k>.svg` per step (step k's map is the "after" of
/// step k and the "before" of step k + 1), `staircase.svg`, `diagnosis.json`,
/// `candidates.json` and an `index.html` tying them together.
pub fn write_report(dir: &Path, data: &Dataset, d: &Diagnosis) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut html = String::from("<!doctype html><meta charset=\"utf-8\"><title>bsdfit diagnose</title><body style=\"font-family:sans-serif;max-width:1100px\">\n");
    html += &format!(
        "<h1>diagnose {}</h1><p>start <code>{}</code> → final <code>{}</code>; effects: {}</p>\n<img src=\"staircase.svg\">\n",
        esc(&data.material),
        esc(&d.start_model),
        esc(&d.final_model),
        if d.effects.is_empty() { "none".to_string() } else { d.effects.iter().map(|e| e.name()).collect::<Vec<_>>().join(", ") }
    );
    for (i, s) in d.steps.iter().enumerate() {
        let title = format!("step {i}: {} (χ²_red = {:.3})", s.model, s.chi2_red);
        let name = format!("residuals_{i}.svg");
        crate::plot::write_svg(
            &dir.join(&name),
            &[residual_panel(data, &s.fit, &title)],
            (900, 480),
        )?;
        html += &format!(
            "<h2>{}</h2><p>{}</p><img src=\"{name}\">\n",
            esc(&title),
            esc(&s.evidence)
        );
    }
    crate::plot::write_svg(
        &dir.join("staircase.svg"),
        &[staircase_panel(d)],
        (700, 420),
    )?;
    std::fs::write(
        dir.join("diagnosis.json"),
        serde_json::to_string_pretty(&d.to_json())?,
    )?;
    std::fs::write(
        dir.join("candidates.json"),
        serde_json::to_string_pretty(&d.candidates_json())?,
    )?;
    std::fs::write(dir.join("index.html"), html + "</body>\n")?;
    Ok(())
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

// ---------------------------------------------------------------------------------------
// CLI

/// `bsdfit diagnose DATA --model START [--json OUT] [--report DIR]`.
#[derive(clap::Args, Clone, Debug)]
pub struct DiagnoseArgs {
    /// Dataset file (bsdfit CSV v1).
    pub data: PathBuf,
    /// Start model spec, e.g. lambert, on, btdf(beckmann).
    #[arg(long)]
    pub model: String,
    /// Loss that drives each fit (the statistics always use χ²).
    #[arg(long, default_value = "chi2")]
    pub loss: String,
    #[arg(long, default_value = "uniform")]
    pub weights: String,
    #[arg(long, value_enum, default_value = "lm")]
    pub optimizer: Optimizer,
    /// Random restarts per fit (plus the current optimum as one more start).
    #[arg(long, default_value_t = 16)]
    pub restarts: usize,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Significance level (consistency test; F tests at α / number of candidates).
    #[arg(long, default_value_t = 0.01)]
    pub alpha: f64,
    /// Most effects to add.
    #[arg(long, default_value_t = 4)]
    pub max_steps: usize,
    #[arg(long, value_enum, default_value = "auto")]
    pub backend: BackendChoice,
    /// Write the diagnosis (DESIGN §8) as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write residual maps, the χ²_red staircase and the candidate tables here.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Keep the channels nearest these wavelengths (nm), e.g. 450,550,650.
    #[arg(long, value_delimiter = ',')]
    pub wavelengths: Option<Vec<f64>>,
    /// Replace zero uncertainties by a floor instead of rejecting them.
    #[arg(long)]
    pub allow_zero_uncertainty: bool,
    #[command(flatten)]
    pub selection: crate::readers::DataSelection,
    /// Keep the greedy path even when it ends with the misfit exceeding the uncertainties
    /// (by default each step is then revisited once with another effect's best candidate).
    #[arg(long)]
    pub no_backtrack: bool,
    /// Fit a round's candidates concurrently, one thread each (pays off on a real GPU; on a
    /// software device such as lavapipe, or the CPU backend, it only adds contention).
    #[arg(long)]
    pub parallel: bool,
}

pub fn run_diagnose(a: &DiagnoseArgs) -> Result<()> {
    let mut ropts = ReadOptions {
        allow_zero_uncertainty: a.allow_zero_uncertainty,
        wavelengths: a.wavelengths.clone(),
        ..Default::default()
    };
    a.selection
        .apply(&mut ropts)
        .map_err(|e| anyhow::anyhow!(e))?;
    let data = crate::readers::load_reporting(&a.data, &ropts)?;
    for n in &data.notices {
        eprintln!("note: {n}");
    }
    let metric: Metric = a
        .loss
        .parse()
        .map_err(|e: String| anyhow::anyhow!("--loss: {e}"))?;
    let weights: Weights = a
        .weights
        .parse()
        .map_err(|e: String| anyhow::anyhow!("--weights: {e}"))?;
    anyhow::ensure!(
        metric.applies_to(data.kind),
        "--loss {metric} is not defined for {} data",
        data.kind
    );
    anyhow::ensure!(a.alpha > 0.0 && a.alpha < 1.0, "--alpha must be in (0, 1)");
    let backend = backend::select(a.backend, &mut |m| eprintln!("{m}"))?;
    let opts = DiagnoseOptions {
        loss: Loss::new(metric, weights),
        optimizer: a.optimizer,
        restarts: a.restarts,
        seed: a.seed,
        alpha: a.alpha,
        max_steps: a.max_steps,
        parallel: a.parallel,
        backtrack: !a.no_backtrack,
        ..Default::default()
    };
    println!(
        "diagnose {} ({} samples, {} channel(s), {} plane(s)) from {}",
        data.material,
        data.len(),
        data.channel_count(),
        data.axes.len(),
        a.model
    );
    let d = diagnose(&data, &a.model, backend.as_ref(), &opts, &mut |line| {
        println!("{line}")
    })?;
    println!(
        "effects: {}\nfinal model: {}",
        if d.effects.is_empty() {
            "none".to_string()
        } else {
            d.effects
                .iter()
                .map(|e| e.name())
                .collect::<Vec<_>>()
                .join(", ")
        },
        d.final_model
    );
    println!(
        "χ²_red: {}",
        d.steps
            .iter()
            .map(|s| format!("{:.3}", s.chi2_red))
            .collect::<Vec<_>>()
            .join(" → ")
    );
    if let Some(path) = &a.json {
        std::fs::write(path, serde_json::to_string_pretty(&d.to_json())?)
            .with_context(|| format!("cannot write {}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    if let Some(dir) = &a.report {
        write_report(dir, &data, &d)?;
        eprintln!("wrote {}", dir.join("index.html").display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::RawRow;

    fn close(a: f64, b: f64, rel: f64) -> bool {
        (a - b).abs() <= rel * b.abs().max(1e-300)
    }

    #[test]
    fn chi2_and_f_tails_match_scipy() {
        // Reference values: scipy.stats 1.17 chi2.sf / f.sf.
        for (x, k, p) in [
            (3.841458820694124, 1.0, 0.05),
            (1050.0, 1000.0, 0.13247405682147703),
            (900.0, 1000.0, 0.9892827619087102),
            (0.5, 3.0, 0.9188914116546758),
        ] {
            let got = chi2_sf(x, k);
            assert!(close(got, p, 1e-9), "chi2_sf({x}, {k}) = {got}, want {p}");
        }
        assert!(chi2_sf(5000.0, 1000.0) < 1e-300);
        for (f, d1, d2, p) in [
            (3.0, 3.0, 20.0, 0.05485861866829506),
            (6.9, 1.0, 100.0, 0.009975476389114826),
            (2.5, 5.0, 2000.0, 0.02888040429829556),
            (50.0, 5.0, 500.0, 5.536126339695859e-42),
            (0.3, 2.0, 10.0, 0.7472581728660572),
        ] {
            let got = f_sf(f, d1, d2);
            assert!(
                close(got, p, 1e-8),
                "f_sf({f}, {d1}, {d2}) = {got}, want {p}"
            );
        }
        assert!(close(ln_gamma(10.0), (362880.0f64).ln(), 1e-13));
        assert!(close(
            ln_gamma(0.5),
            std::f64::consts::PI.sqrt().ln(),
            1e-13
        ));
    }

    fn dataset(kind: Kind, rows: &[[f64; 4]], channels: usize) -> Dataset {
        let wl = [450.0, 550.0, 650.0];
        let mut raw = Vec::new();
        for (i, r) in rows.iter().enumerate() {
            for (c, &w) in wl.iter().take(channels).enumerate() {
                raw.push((
                    i * channels + c + 1,
                    RawRow {
                        theta_i: r[0],
                        phi_i: r[1],
                        theta_o: r[2],
                        phi_o: r[3],
                        wavelength_nm: w,
                        value: 0.1,
                        uncertainty: 0.01,
                    },
                ));
            }
        }
        Dataset::from_rows(kind, "t", &raw, "<t>", &ReadOptions::default()).unwrap()
    }

    fn specs(c: &[Candidate]) -> Vec<(String, &'static str)> {
        c.iter()
            .map(|c| (c.spec.clone(), c.effect.name()))
            .collect()
    }

    #[test]
    fn extensions_follow_the_effect_table() {
        let brdf = dataset(
            Kind::Brdf,
            &crate::synth::geometry("inplane10").unwrap().1,
            3,
        );
        let e = specs(&extensions("lambert", &brdf).unwrap());
        for (s, eff) in [
            ("on", "backscatter"),
            ("eon", "backscatter"),
            ("vmf", "backscatter"),
            ("fa(lambert)", "specular_lobe"),
            ("dmg(lambert)", "grazing_decay"),
            ("rmg(lambert)", "grazing_decay"),
            ("lambert+retro", "retro_lobe"),
        ] {
            assert!(e.contains(&(s.to_string(), eff)), "{s} missing from {e:?}");
        }
        assert_eq!(e.len(), 7);
        let e = specs(&extensions("fa(lambert)+retro", &brdf).unwrap());
        assert_eq!(
            e,
            [
                ("fa(on)+retro".to_string(), "backscatter"),
                ("fa(eon)+retro".into(), "backscatter"),
                ("fa(vmf)+retro".into(), "backscatter")
            ]
        );
        let e = specs(&extensions("ggx", &brdf).unwrap());
        assert!(
            e.contains(&("fa(lambert)".into(), "diffuse_floor")),
            "{e:?}"
        );
        assert!(!e.iter().any(|(s, _)| s == "fa(ggx)"));

        let btdf = dataset(Kind::Btdf, &crate::synth::geometry("oblique").unwrap().1, 1);
        let e = specs(&extensions("btdf(beckmann)+scale", &btdf).unwrap());
        assert_eq!(
            e,
            [
                ("btdf(tr)+scale".to_string(), "long_tail"),
                ("btdf(beckmann)+scale+absorb".into(), "absorption"),
                ("btdf(beckmann)+scale+diffuse".into(), "diffuse_floor"),
            ]
        );
        let e = specs(&extensions("btdf(tr)", &btdf).unwrap());
        assert!(e.contains(&("btdf(gtr)".into(), "long_tail")));
        assert!(
            !e.iter().any(|(_, eff)| *eff == "anisotropy"),
            "one plane: no +peraxis"
        );
        let two = dataset(Kind::Btdf, &crate::synth::geometry("ptb1").unwrap().1, 1);
        assert!(specs(&extensions("btdf(tr)", &two).unwrap())
            .contains(&("btdf(tr)+peraxis".into(), "anisotropy")));
        for c in extensions("btdf(gg)+absorb", &two)
            .unwrap()
            .iter()
            .chain(&extensions("dmg(lambert)", &brdf).unwrap())
        {
            Model::for_data(
                &c.spec,
                if c.spec.starts_with("btdf") {
                    &two
                } else {
                    &brdf
                },
            )
            .unwrap();
        }
    }

    /// Every extension marked nested reproduces the current model at the embedded
    /// parameters (dmg/rmg only in the limit τ0 → 0: within 1 %).
    #[test]
    fn nested_extensions_embed_the_current_model() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let brdf = dataset(Kind::Brdf, &crate::synth::geometry("hemi").unwrap().1, 3);
        let btdf = dataset(Kind::Btdf, &crate::synth::geometry("ptb1").unwrap().1, 1);
        for (start, data) in [
            ("lambert", &brdf),
            ("on", &brdf),
            ("eon", &brdf),
            ("vmf", &brdf),
            ("ggx", &brdf),
            ("fa(lambert)", &brdf),
            ("dmg(lambert)", &brdf),
            ("btdf(tr)", &btdf),
            ("btdf(beckmann)+scale", &btdf),
            ("btdf(gg)", &btdf),
        ] {
            let old = Model::for_data(start, data).unwrap();
            for trial in 0..3 {
                let unit: Vec<f64> = (0..old.dim).map(|_| rng.random_range(0.2..0.8)).collect();
                let flat = old.from_unit(&unit);
                for c in extensions(start, data).unwrap() {
                    let new = Model::for_data(&c.spec, data).unwrap();
                    let nf = embed(&old, &flat, &new);
                    if !c.nested {
                        continue;
                    }
                    let tol = if c.spec.starts_with("dmg") || c.spec.starts_with("rmg") {
                        1e-2
                    } else {
                        1e-6
                    };
                    for s in &data.samples {
                        let a = old.eval(&flat, old.group_of(s), s.wi, s.wo);
                        let b = new.eval(&nf, new.group_of(s), s.wi, s.wo);
                        assert!(
                            (a - b).abs() <= tol * a.abs().max(1e-3),
                            "{start} → {} (trial {trial}): {a} vs {b}",
                            c.spec
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn evidence_names_the_regions() {
        let rows = crate::synth::geometry("inplane10").unwrap().1;
        let data = dataset(Kind::Brdf, &rows, 1);
        // Model too dark near the mirror for θi ≥ 30°, fine elsewhere.
        let z: Vec<f64> = data
            .samples
            .iter()
            .map(|s| {
                let m = angle_deg(s.wo, DVec3::new(-s.wi.x, -s.wi.y, s.wi.z));
                if m <= 15.5 && s.theta_i.to_degrees() >= 29.5 && m < angle_deg(s.wo, s.wi) {
                    -4.0
                } else {
                    0.1
                }
            })
            .collect();
        let e = describe_regions(&data, &z);
        assert!(e.starts_with("model 4.0σ too dark within"), "{e}");
        assert!(e.contains("of the mirror direction for θi ≥ 30°"), "{e}");
        // One sign everywhere.
        let z = vec![2.0; data.len()];
        let e = describe_regions(&data, &z);
        assert!(
            e.contains("model 2.0σ too bright everywhere")
                && e.contains("100 % of residuals one-signed"),
            "{e}"
        );
        // Nothing coherent.
        let z: Vec<f64> = (0..data.len())
            .map(|i| if i % 2 == 0 { 0.5 } else { -0.5 })
            .collect();
        assert!(describe_regions(&data, &z).starts_with("no angular region"));
    }

    #[test]
    fn spec_rendering_round_trips() {
        for s in [
            "lambert",
            "fa(eon)+retro",
            "btdf(gtr)+scale+diffuse",
            "dmg(on)",
            "btdf(tr)+peraxis+absorb",
        ] {
            assert_eq!(render_spec(&Ast::parse(s).unwrap()), s);
        }
    }
}
