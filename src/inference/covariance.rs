//! Parameter standard uncertainties and correlations at an optimum (docs/losses.md, issue 4).
//!
//! With r_k = √w_k (g(y′_k) − g(y_k)) the loss's weighted residuals and J their Jacobian
//! (central differences), the estimator's covariance propagated from the measurement
//! uncertainties is the sandwich
//!     cov = B⁺ M B⁺,  B = JᵀJ,  M = Jᵀ diag(w_k σ_k²) J,  σ_k = |g′(y_k)| u_k,
//! which reduces to the textbook (JᵀWJ)⁻¹ for the χ² loss (w = 1/u², g = identity). For
//! the paper's other weightings (uniform, relunc, 1/u) this propagates the stated
//! uncertainties correctly, where the plain (JᵀWJ)⁻¹ would not even carry the right
//! units. When the model misses the data (χ²_red > 1) the covariance is scaled by χ²_red
//! (the Birge ratio squared). SMAPE is not a sum of squares: its fits report the χ² form.
//!
//! B⁺ is a pseudo-inverse by SVD: a parameter along a direction the data does not
//! determine gets no standard uncertainty and a warning, as does a pair with
//! |correlation| > 0.99 or a standard uncertainty larger than the parameter's range.

use crate::bsdf::Model;
use crate::data::Dataset;
use crate::engine::loss::{Loss, Metric, Term, NO_SAMPLE};
use crate::engine::Evaluator;
use crate::inference::constraints::Constraints;
use nalgebra::DMatrix;
use rayon::prelude::*;

#[derive(Clone, Debug, Default)]
pub struct Covariance {
    /// Standard uncertainty per flat parameter; None where undetermined.
    pub std: Vec<Option<f64>>,
    pub correlation: Vec<Vec<Option<f64>>>,
    pub warnings: Vec<String>,
    /// The directions of parameter space along which the data constrain the fit weakly
    /// (a ridge of the loss): each a unit vector in the parameters' unit boxes, as (flat
    /// index, component) for its components of at least 0.2 in size, with its standard
    /// uncertainty in the unit box (at least [`RIDGE_UNIT_STD`]; infinite where the data
    /// do not constrain it at all). Weakest first.
    pub ridges: Vec<Ridge>,
}

/// One weakly determined direction ([`Covariance::ridges`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Ridge {
    pub components: Vec<(usize, f64)>,
    pub unit_std: f64,
}

/// A direction whose standard uncertainty in the unit box exceeds this is a ridge: the
/// data locate the fit along it to no better than a tenth of the parameters' ranges.
pub const RIDGE_UNIT_STD: f64 = 0.1;

impl Ridge {
    /// "+0.71 lobe.eta − 0.70 base.rho[0]".
    pub fn words(&self, names: &[String]) -> String {
        let mut s = String::new();
        for (k, &(j, c)) in self.components.iter().enumerate() {
            let sign = if c < 0.0 { '−' } else { '+' };
            if k == 0 {
                s += &format!(
                    "{}{:.2} {}",
                    if c < 0.0 { "−" } else { "" },
                    c.abs(),
                    names[j]
                );
            } else {
                s += &format!(" {sign} {:.2} {}", c.abs(), names[j]);
            }
        }
        s
    }
}

/// The derivative of a parameter's physical value with respect to its unit-box
/// coordinate at `value` (central differences, one-sided at the box's edges).
pub fn unit_slope(decl: &crate::bsdf::ParamDecl, value: f64) -> f64 {
    let u = decl.to_unit(value);
    let (lo, hi) = ((u - 1e-4).max(0.0), (u + 1e-4).min(1.0));
    (decl.from_unit(hi) - decl.from_unit(lo)) / (hi - lo)
}

/// A standard uncertainty in the parameter's unit box (its share of the declared range,
/// as the optimizers see it).
pub fn unit_std(decl: &crate::bsdf::ParamDecl, value: f64, std: f64) -> f64 {
    std / unit_slope(decl, value).abs().max(1e-300)
}

/// Unit-box step of the finite differences.
const DU: f64 = 1e-4;
/// Relative singular-value threshold of the pseudo-inverse.
const RCOND: f64 = 1e-10;

/// The Jacobian's sums over the data rows, streamed over the evaluator's value windows
/// (nothing of length samples × parameters is held): B = JᵀJ and M = Jᵀ diag(w σ²) J of
/// the weighted residuals (see the module doc) by central differences, from a batch of
/// the point and its (+, −) neighbours along each of p free parameters whose physical
/// steps are `steps`, and the point's χ².
fn jacobian_sums(
    data: &Dataset,
    loss: Loss,
    eval: &mut dyn Evaluator,
    batch: &[f64],
    steps: &[f64],
) -> anyhow::Result<(DMatrix<f64>, DMatrix<f64>, f64)> {
    let p = steps.len();
    let use_loss = loss.is_sum_of_squares() && loss.metric != Metric::Chi2;
    let mut jtj = DMatrix::<f64>::zeros(p, p);
    let mut meat = DMatrix::<f64>::zeros(p, p);
    let mut chi2 = 0.0;
    let owners = vec![0; 2 * p + 1];
    eval.value_windows(&owners, batch, &mut |w| {
        let parts = w.parts;
        if parts.is_empty() {
            return Ok(());
        }
        let rows = &w.rows[parts[0].problem];
        let t = &rows.terms;
        let values: Vec<_> = parts.iter().map(|part| w.values_of(part)).collect();
        let range = parts[0].rows.clone();
        // Each chunk of rows in parallel, then the chunks' sums in order.
        let starts: Vec<usize> = (range.start..range.end).step_by(1024).collect();
        let partial: Vec<(DMatrix<f64>, DMatrix<f64>, f64)> = starts
            .par_iter()
            .map(|&from| {
                let mut b = DMatrix::<f64>::zeros(p, p);
                let mut m = DMatrix::<f64>::zeros(p, p);
                let mut c2 = 0.0;
                let mut row = vec![0.0; p];
                for r in from..(from + 1024).min(range.end) {
                    let k = rows.sample[r];
                    if k == NO_SAMPLE {
                        continue;
                    }
                    let s = &data.samples[k as usize];
                    let i = r - range.start;
                    let residual = |v: f64| {
                        if use_loss {
                            t.residual(r, v)
                        } else {
                            (v - s.value) / s.uncertainty
                        }
                    };
                    for (c, j) in row.iter_mut().enumerate() {
                        *j = if steps[c] != 0.0 {
                            (residual(values[1 + 2 * c].at(i)) - residual(values[2 + 2 * c].at(i)))
                                / steps[c]
                        } else {
                            0.0
                        };
                    }
                    let ws = if use_loss {
                        let slope = match t.term {
                            Term::LogSquare => t.a[r] / (1.0 + t.a[r] * s.value),
                            _ => t.a[r],
                        };
                        t.w[r] * (slope * s.uncertainty).powi(2)
                    } else {
                        1.0 // w = 1/u², σ = u
                    };
                    for a in 0..p {
                        for bb in 0..p {
                            let x = row[a] * row[bb];
                            b[(a, bb)] += x;
                            m[(a, bb)] += ws * x;
                        }
                    }
                    let z = (values[0].at(i) - s.value) / s.uncertainty;
                    c2 += z * z;
                }
                (b, m, c2)
            })
            .collect();
        for (b, m, c2) in partial {
            jtj += b;
            meat += m;
            chi2 += c2;
        }
        Ok(())
    })?;
    Ok((jtj, meat, chi2))
}

/// Covariance of the fitted parameters of `space` at `flat` (fixed parameters get none;
/// each prior is one more residual row (θ − mean)/sd, with unit variance).
pub fn covariance(
    model: &Model,
    data: &Dataset,
    loss: Loss,
    eval: &mut dyn Evaluator,
    flat: &[f64],
    space: &Constraints,
) -> anyhow::Result<Covariance> {
    let free = &space.free;
    let p = free.len();
    let k = data.len() + space.priors.len();
    let decls = &space.decls;
    let (batch, steps) = central_difference_batch(flat, space);
    let (mut jtj, mut meat, chi2) = jacobian_sums(data, loss, eval, &batch, &steps)?;
    add_prior_rows(&mut jtj, &mut meat, space);
    let chi2 = chi2 + space.prior_chi2(flat);
    let dof = (k.saturating_sub(p)).max(1) as f64;
    let birge = (chi2 / dof).max(1.0);
    let all_names = model.flat_names();
    let names: Vec<&str> = free.iter().map(|&j| all_names[j].as_str()).collect();
    let free_decls: Vec<_> = free.iter().map(|&j| decls[j]).collect();
    let mut out = Covariance {
        std: vec![None; p],
        correlation: vec![vec![None; p]; p],
        warnings: vec![],
        ridges: vec![],
    };
    let (inv, undetermined) = match pseudo_inverse(&jtj) {
        Ok(found) => found,
        Err(why) => {
            out.warnings.push(why.into());
            return Ok(expand(out, free, model.dim));
        }
    };
    let cov = &inv * meat * &inv * birge;
    out.ridges = ridges(&jtj, birge, free, flat, decls);
    set_std_and_correlation(&mut out, &cov, &undetermined);
    let warnings = determinacy_warnings(&out, &undetermined, &names, &free_decls);
    out.warnings.extend(warnings);
    Ok(expand(out, free, model.dim))
}

/// The batch of the central differences at `flat`: the point itself, then (+, −) per
/// free parameter, each DU from the point in the unit box (less at its edges); and each
/// free parameter's physical step between its two neighbours.
fn central_difference_batch(flat: &[f64], space: &Constraints) -> (Vec<f64>, Vec<f64>) {
    let free = &space.free;
    let decls = &space.decls;
    let unit = space.to_unit(flat);
    let mut batch = flat.to_vec();
    let mut steps = Vec::with_capacity(free.len());
    for (c, &j) in free.iter().enumerate() {
        let up = (unit[c] + DU).min(1.0);
        let dn = (unit[c] - DU).max(0.0);
        let mut plus = flat.to_vec();
        let mut minus = flat.to_vec();
        plus[j] = decls[j].from_unit(up);
        minus[j] = decls[j].from_unit(dn);
        steps.push(plus[j] - minus[j]);
        batch.extend(plus);
        batch.extend(minus);
    }
    (batch, steps)
}

/// The priors' rows in B and M: ∂((θ_j − mean)/sd)/∂θ_j = 1/sd, with unit variance.
fn add_prior_rows(jtj: &mut DMatrix<f64>, meat: &mut DMatrix<f64>, space: &Constraints) {
    for prior in &space.priors {
        if let Some(c) = space.free.iter().position(|&j| j == prior.index) {
            let d = 1.0 / (prior.sd * prior.sd);
            jtj[(c, c)] += d;
            meat[(c, c)] += d;
        }
    }
}

/// B⁺ by SVD, and which parameters lie along a direction the data do not constrain; or
/// why there are no uncertainties.
fn pseudo_inverse(jtj: &DMatrix<f64>) -> Result<(DMatrix<f64>, Vec<bool>), &'static str> {
    let p = jtj.nrows();
    if jtj.iter().any(|v| !v.is_finite()) {
        return Err("the Jacobian is not finite at the optimum; no parameter uncertainties");
    }
    let svd = jtj.clone().svd(true, true);
    let (Some(u), Some(vt)) = (svd.u.as_ref(), svd.v_t.as_ref()) else {
        return Err("SVD failed; no parameter uncertainties");
    };
    let smax = svd.singular_values.iter().cloned().fold(0.0, f64::max);
    let mut inv = DMatrix::<f64>::zeros(p, p);
    let mut undetermined = vec![false; p];
    for (m, &s) in svd.singular_values.iter().enumerate() {
        if s > RCOND * smax && s > 0.0 {
            inv += (vt.row(m).transpose() * u.column(m).transpose()) / s;
        } else {
            // A direction the data does not constrain: flag the parameters along it.
            for j in 0..p {
                if vt[(m, j)].abs() > 0.1 {
                    undetermined[j] = true;
                }
            }
        }
    }
    Ok((inv, undetermined))
}

/// The standard uncertainties (none for undetermined parameters or a variance that is
/// not a finite non-negative number) and the correlations between those above 0.
fn set_std_and_correlation(out: &mut Covariance, cov: &DMatrix<f64>, undetermined: &[bool]) {
    let p = undetermined.len();
    for j in 0..p {
        let v = cov[(j, j)];
        if !undetermined[j] && v.is_finite() && v >= 0.0 {
            out.std[j] = Some(v.sqrt());
        }
    }
    for a in 0..p {
        for b in 0..p {
            if let (Some(sa), Some(sb)) = (out.std[a], out.std[b]) {
                if sa > 0.0 && sb > 0.0 {
                    out.correlation[a][b] = Some((cov[(a, b)] / (sa * sb)).clamp(-1.0, 1.0));
                }
            }
        }
    }
}

/// What the data do not determine: parameters along unconstrained directions, standard
/// uncertainties beyond a parameter's range, and pairs and groups of parameters
/// determined only in combination.
fn determinacy_warnings(
    out: &Covariance,
    undetermined: &[bool],
    names: &[&str],
    decls: &[crate::bsdf::ParamDecl],
) -> Vec<String> {
    let p = names.len();
    let mut warnings = Vec::new();
    let undetermined_names: Vec<&str> = (0..p)
        .filter(|&j| undetermined[j])
        .map(|j| names[j])
        .collect();
    if !undetermined_names.is_empty() {
        warnings.push(format!(
            "not determined by the data (singular normal matrix): {}",
            undetermined_names.join(", ")
        ));
    }
    for j in 0..p {
        if let Some(s) = out.std[j] {
            let range = decls[j].hi - decls[j].lo;
            if s > range {
                warnings.push(format!(
                    "{} is not determined by the data: std {s:.3e} exceeds its range {range}",
                    names[j]
                ));
            }
        }
    }
    for a in 0..p {
        for b in a + 1..p {
            if let Some(c) = out.correlation[a][b] {
                if c.abs() > 0.99 {
                    warnings.push(format!(
                        "{} and {} are not separately determined (correlation {c:+.4})",
                        names[a], names[b]
                    ));
                }
            }
        }
    }
    warnings.extend(multiple_correlation_warnings(out, names));
    warnings
}

/// A trade-off among three or more parameters can hide behind moderate pairwise
/// correlations: the multiple correlation R_j of each parameter with all the others,
/// R_j² = 1 − 1/(C⁻¹)_jj, exposes it (e.g. α, η_t and S at normal incidence). A warning
/// per parameter with R_j > 0.99 and no pairwise correlation above 0.99.
fn multiple_correlation_warnings(out: &Covariance, names: &[&str]) -> Vec<String> {
    let p = names.len();
    let mut warnings = Vec::new();
    let det: Vec<usize> = (0..p)
        .filter(|&j| out.std[j].is_some_and(|s| s > 0.0))
        .collect();
    if det.len() <= 2 {
        return warnings;
    }
    let c = DMatrix::from_fn(det.len(), det.len(), |a, b| {
        out.correlation[det[a]][det[b]].unwrap_or(0.0)
    });
    let Some(ci) = c.try_inverse() else {
        return warnings;
    };
    for (a, &j) in det.iter().enumerate() {
        let vif = ci[(a, a)];
        let r = if vif > 1.0 {
            (1.0 - 1.0 / vif).sqrt()
        } else {
            0.0
        };
        let pairwise = det
            .iter()
            .any(|&o| o != j && out.correlation[j][o].is_some_and(|c| c.abs() > 0.99));
        if r > 0.99 && !pairwise {
            let others: Vec<&str> = det.iter().filter(|&&o| o != j).map(|&o| names[o]).collect();
            warnings.push(format!(
                "{} is not separately determined from {} (multiple correlation {r:.4}): the data constrain only a combination",
                names[j],
                others.join(", ")
            ));
        }
    }
    warnings
}

/// The weak directions of the normal matrix `jtj` (free parameters, physical units) in
/// the parameters' unit boxes: the eigenvectors of D·JᵀJ·D (D the unit-box slopes) whose
/// standard uncertainty √(birge/λ) exceeds [`RIDGE_UNIT_STD`], mapped to flat indices.
fn ridges(
    jtj: &DMatrix<f64>,
    birge: f64,
    free: &[usize],
    flat: &[f64],
    decls: &[crate::bsdf::ParamDecl],
) -> Vec<Ridge> {
    let p = free.len();
    let d: Vec<f64> = free
        .iter()
        .map(|&j| unit_slope(&decls[j], flat[j]))
        .collect();
    let scaled = DMatrix::from_fn(p, p, |a, b| jtj[(a, b)] * d[a] * d[b]);
    if scaled.iter().any(|v| !v.is_finite()) {
        return vec![];
    }
    let eig = scaled.symmetric_eigen();
    let lmax = eig.eigenvalues.iter().cloned().fold(0.0, f64::max);
    let mut out: Vec<Ridge> = (0..p)
        .filter_map(|m| {
            let l = eig.eigenvalues[m];
            let unit_std = if l > RCOND * lmax && l > 0.0 {
                (birge / l).sqrt()
            } else {
                f64::INFINITY
            };
            if unit_std < RIDGE_UNIT_STD {
                return None;
            }
            let v = eig.eigenvectors.column(m);
            let mut components: Vec<(usize, f64)> = (0..p)
                .filter(|&a| v[a].abs() >= 0.2)
                .map(|a| (free[a], v[a]))
                .collect();
            components.sort_by(|x, y| y.1.abs().total_cmp(&x.1.abs()));
            Some(Ridge {
                components,
                unit_std,
            })
        })
        .collect();
    out.sort_by(|a, b| b.unit_std.total_cmp(&a.unit_std));
    out
}

/// The covariance of the free parameters laid out over the model's whole flat vector
/// (fixed parameters: no standard uncertainty, no correlation).
fn expand(free_cov: Covariance, free: &[usize], dim: usize) -> Covariance {
    let mut out = Covariance {
        std: vec![None; dim],
        correlation: vec![vec![None; dim]; dim],
        warnings: free_cov.warnings,
        ridges: free_cov.ridges,
    };
    for (a, &ja) in free.iter().enumerate() {
        out.std[ja] = free_cov.std[a];
        for (b, &jb) in free.iter().enumerate() {
            out.correlation[ja][jb] = free_cov.correlation[a][b];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    //! Oracles written here from the definitions (module doc): for Lambert, f = ρ/π is
    //! linear in ρ, so every loss's weighted residual has the Jacobian J_k = √w_k g′(ρ/π)/π
    //! in closed form, and the sandwich B⁻¹MB⁻¹ is a ratio of sums; the helpers are checked
    //! on matrices whose inverses, eigenvectors and correlations are worked out by hand.
    use super::*;
    use crate::bsdf::ParamDecl;
    use crate::data::{Kind, RawRow, ReadOptions};
    use crate::engine::cpu::CpuBackend;
    use crate::engine::loss::Weights;
    use crate::engine::{Backend, Problem};
    use crate::inference::constraints::Prior;

    /// Eight BRDF samples at one wavelength per entry of `wavelengths` (θi, θo in
    /// degrees, value, uncertainty), with their scatter about ρ/π ≈ 0.1 scaled by
    /// `scatter`.
    fn data(wavelengths: &[f64], scatter: f64) -> Dataset {
        let base = [
            (10.0, 20.0, 0.004, 0.006),
            (25.0, 40.0, -0.010, 0.008),
            (40.0, 15.0, 0.007, 0.005),
            (55.0, 60.0, -0.002, 0.012),
            (70.0, 35.0, 0.012, 0.010),
            (15.0, 75.0, -0.006, 0.007),
            (30.0, 50.0, 0.001, 0.009),
            (65.0, 5.0, -0.008, 0.006),
        ];
        let mut rows = Vec::new();
        for (c, &nm) in wavelengths.iter().enumerate() {
            for &(ti, to, dev, u) in &base {
                let row = RawRow {
                    theta_i: ti,
                    phi_i: 0.0,
                    theta_o: to,
                    phi_o: 180.0,
                    wavelength_nm: nm,
                    value: 0.1 + 0.01 * c as f64 + scatter * dev,
                    uncertainty: u,
                };
                rows.push((rows.len() + 1, row));
            }
        }
        Dataset::from_rows(Kind::Brdf, "d", &rows, "d.csv", &ReadOptions::default()).unwrap()
    }

    fn lambert(data: &Dataset) -> Model {
        Model::for_data("lambert", data).unwrap()
    }

    fn cov_of(data: &Dataset, loss: Loss, flat: &[f64], space: &Constraints) -> Covariance {
        let model = lambert(data);
        let cpu = CpuBackend::new();
        let problem = Problem {
            model: &model,
            data,
            loss,
        };
        let mut eval = cpu.prepare(problem).unwrap();
        covariance(&model, data, loss, eval.as_mut(), flat, space).unwrap()
    }

    /// The per-sample weight w and inner factor a of a loss, from docs/losses.md.
    fn w_and_a(loss: Loss, s: &crate::data::Sample) -> (f64, f64) {
        const E: f64 = 1e-6;
        let (y, u) = (s.value, s.uncertainty);
        let w = match loss.weights {
            Weights::Uniform => 1.0,
            Weights::Relunc => 1.0 / (u.abs() / (y.abs() + E) + E),
            Weights::Invunc => 1.0 / u,
        };
        let (ci, si, so, co) = (
            s.theta_i.cos(),
            s.theta_i.sin(),
            s.theta_o.sin(),
            s.theta_o.cos(),
        );
        match loss.metric {
            Metric::Chi2 => (1.0 / (u * u), 1.0),
            Metric::Smape | Metric::F | Metric::Logf => (w, 1.0),
            Metric::Rmse => (w * ci * ci, 1.0),
            Metric::Ngan => (w * ci * ci * si * so, 1.0),
            Metric::Low => (w * ci * ci * si, 1.0),
            Metric::Cosf | Metric::Logcosf => (w, co),
        }
    }

    /// χ² of ρ on one channel's samples.
    fn chi2_at(data: &Dataset, rho: f64) -> f64 {
        let f = rho / std::f64::consts::PI;
        data.samples
            .iter()
            .map(|s| ((f - s.value) / s.uncertainty).powi(2))
            .sum()
    }

    /// σ(ρ) of Lambert at `rho` on one channel: B = Σ J², M = Σ J² w σ², σ_k = g′(y_k) u_k,
    /// var = M/B² times the Birge factor max(1, χ²/(K − 1)). SMAPE reports the χ² form.
    fn sigma_by_hand(data: &Dataset, loss: Loss, rho: f64) -> f64 {
        let pi = std::f64::consts::PI;
        let loss = if loss.metric == Metric::Smape {
            Loss::new(Metric::Chi2, Weights::Uniform)
        } else {
            loss
        };
        let log = loss.metric.term() == Term::LogSquare;
        let slope = |a: f64, v: f64| if log { a / (1.0 + a * v) } else { a };
        let (mut b, mut m) = (0.0, 0.0);
        for s in &data.samples {
            let (w, a) = w_and_a(loss, s);
            let j = w.sqrt() * slope(a, rho / pi) / pi;
            b += j * j;
            m += j * j * w * (slope(a, s.value) * s.uncertainty).powi(2);
        }
        let birge = (chi2_at(data, rho) / (data.len() - 1) as f64).max(1.0);
        (m / (b * b) * birge).sqrt()
    }

    /// Every loss's standard uncertainty of a linear model is the sandwich of its
    /// weighted residuals (the plain (JᵀWJ)⁻¹ for χ²), scaled by χ²_red where that
    /// exceeds 1 and not where it is below.
    #[test]
    fn lambert_sigma_is_the_sandwich_of_every_loss() {
        let losses = [
            Loss::new(Metric::Chi2, Weights::Uniform),
            Loss::new(Metric::Smape, Weights::Relunc),
            Loss::new(Metric::Rmse, Weights::Uniform),
            Loss::new(Metric::Ngan, Weights::Relunc),
            Loss::new(Metric::Low, Weights::Invunc),
            Loss::new(Metric::F, Weights::Invunc),
            Loss::new(Metric::Cosf, Weights::Uniform),
            Loss::new(Metric::Logf, Weights::Relunc),
            Loss::new(Metric::Logcosf, Weights::Invunc),
        ];
        for scatter in [0.2, 3.0] {
            let d = data(&[550.0], scatter);
            let space = Constraints::none(&lambert(&d));
            let red = chi2_at(&d, 0.31) / 7.0;
            assert!((scatter < 1.0) == (red < 1.0), "χ²_red {red}");
            for loss in losses {
                let got = cov_of(&d, loss, &[0.31], &space).std[0].unwrap();
                let want = sigma_by_hand(&d, loss, 0.31);
                assert!(
                    (got / want - 1.0).abs() < 1e-6,
                    "{loss}, χ²_red {red}: σ {got} vs {want}"
                );
            }
        }
    }

    /// χ² over all channels at `flat` (one ρ per channel).
    fn chi2_flat(data: &Dataset, flat: &[f64]) -> f64 {
        let pi = std::f64::consts::PI;
        (data.samples.iter())
            .map(|s| ((flat[s.channel] / pi - s.value) / s.uncertainty).powi(2))
            .sum()
    }

    /// χ²'s σ is the textbook 1/√(Σ J²) (times √χ²_red where that exceeds 1), each
    /// channel's ρ from its own samples only, uncorrelated with the others; a fixed
    /// parameter has no σ and no correlation and leaves one more degree of freedom; a
    /// prior is one more residual (θ − mean)/sd: Σ J² + 1/sd², its χ² counted in χ²_red
    /// over K + 1 − P.
    #[test]
    fn chi2_channels_fixed_parameters_and_priors() {
        let pi = std::f64::consts::PI;
        let d = data(&[450.0, 550.0, 650.0], 3.0);
        let model = lambert(&d);
        let chi2 = Loss::new(Metric::Chi2, Weights::Uniform);
        let flat = [0.32, 0.34, 0.36];
        let k = d.len() as f64;
        let textbook = |c: usize, free: f64| {
            let b: f64 = (d.samples.iter())
                .filter(|s| s.channel == c)
                .map(|s| (1.0 / (pi * s.uncertainty)).powi(2))
                .sum();
            let birge = (chi2_flat(&d, &flat) / (k - free)).max(1.0);
            (birge / b).sqrt()
        };
        assert!(chi2_flat(&d, &flat) / (k - 3.0) > 1.2);
        let all = cov_of(&d, chi2, &flat, &Constraints::none(&model));
        for c in 0..3 {
            let got = all.std[c].unwrap();
            assert!((got / textbook(c, 3.0) - 1.0).abs() < 1e-9, "{c}: {got}");
            for o in 0..3 {
                let want = if o == c { 1.0 } else { 0.0 };
                assert!((all.correlation[c][o].unwrap() - want).abs() < 1e-9);
            }
        }
        assert!(all.warnings.is_empty(), "{:?}", all.warnings);

        let mut held = Constraints::none(&model);
        held.fixed[1] = Some(0.34);
        held.free = vec![0, 2];
        let some = cov_of(&d, chi2, &flat, &held);
        assert_eq!(some.std[1], None);
        assert!(
            (0..3).all(|o| some.correlation[1][o].is_none() && some.correlation[o][1].is_none())
        );
        for c in [0, 2] {
            let got = some.std[c].unwrap();
            assert!((got / textbook(c, 2.0) - 1.0).abs() < 1e-9, "{c}: {got}");
        }
        assert!((some.correlation[0][2].unwrap()).abs() < 1e-9);

        // A prior on ρ: 0.3 ± 0.002, off the data's ρ by several sd, so that χ²_red
        // (with the prior's residual, over K + 1 − P) exceeds 1.
        let one = data(&[550.0], 0.2);
        let mut prior = Constraints::none(&lambert(&one));
        let sd = 0.002;
        prior.priors.push(Prior {
            name: "rho".into(),
            index: 0,
            mean: 0.3,
            sd,
        });
        let rho = 0.31;
        let b: f64 = (one.samples.iter())
            .map(|s| (1.0 / (pi * s.uncertainty)).powi(2))
            .sum::<f64>()
            + 1.0 / (sd * sd);
        let chi2_total = chi2_at(&one, rho) + ((rho - 0.3) / sd).powi(2);
        let red = chi2_total / (one.len() + 1 - 1) as f64;
        assert!(red > 1.5, "{red}");
        let got = cov_of(&one, chi2, &[rho], &prior).std[0].unwrap();
        let want = (red / b).sqrt();
        assert!((got / want - 1.0).abs() < 1e-9, "σ {got} vs {want}");
    }

    /// 9,000 samples: more than one of the CPU evaluator's windows (8,192 rows) and
    /// many of the Jacobian's chunks (1,024 rows), every row still counted once.
    #[test]
    fn chi2_sigma_over_several_windows() {
        let pi = std::f64::consts::PI;
        let mut rows = Vec::new();
        for ti in 0..60 {
            for to in 1..76 {
                for po in [0.0, 90.0] {
                    let k = rows.len();
                    let row = RawRow {
                        theta_i: ti as f64,
                        phi_i: 0.0,
                        theta_o: to as f64,
                        phi_o: po,
                        wavelength_nm: 550.0,
                        value: 0.1 + 0.002 * ((k * 7919) % 11) as f64 / 10.0,
                        uncertainty: 0.005 + 0.001 * (k % 7) as f64,
                    };
                    rows.push((k + 1, row));
                }
            }
        }
        let d =
            Dataset::from_rows(Kind::Brdf, "w", &rows, "w.csv", &ReadOptions::default()).unwrap();
        assert_eq!(d.len(), 9000);
        let space = Constraints::none(&lambert(&d));
        let chi2 = Loss::new(Metric::Chi2, Weights::Uniform);
        let b: f64 = (d.samples.iter())
            .map(|s| (1.0 / (pi * s.uncertainty)).powi(2))
            .sum();
        let birge = (chi2_at(&d, 0.32) / (d.len() - 1) as f64).max(1.0);
        let want = (birge / b).sqrt();
        let got = cov_of(&d, chi2, &[0.32], &space).std[0].unwrap();
        assert!((got / want - 1.0).abs() < 1e-9, "σ {got} vs {want}");
        // The same through a sum-of-squares loss other than χ² (the loss's residuals).
        let rmse = Loss::new(Metric::Rmse, Weights::Uniform);
        let got = cov_of(&d, rmse, &[0.32], &space).std[0].unwrap();
        let want = sigma_by_hand(&d, rmse, 0.32);
        assert!((got / want - 1.0).abs() < 1e-6, "σ {got} vs {want}");
    }

    #[test]
    fn central_differences_step_du_in_the_unit_box_and_stop_at_its_edges() {
        let d = data(&[550.0], 0.2);
        let space = Constraints::none(&lambert(&d));
        let (batch, steps) = central_difference_batch(&[0.3], &space);
        assert_eq!(batch.len(), 3);
        assert_eq!(batch[0], 0.3);
        assert!((batch[1] - (0.3 + DU)).abs() < 1e-14 && (batch[2] - (0.3 - DU)).abs() < 1e-14);
        assert!((steps[0] - 2.0 * DU).abs() < 1e-14);
        let (batch, steps) = central_difference_batch(&[1.0], &space);
        assert_eq!(batch[1], 1.0);
        assert!((batch[2] - (1.0 - DU)).abs() < 1e-14 && (steps[0] - DU).abs() < 1e-14);
        let (batch, steps) = central_difference_batch(&[0.0], &space);
        assert_eq!(batch[2], 0.0);
        assert!((batch[1] - DU).abs() < 1e-14 && (steps[0] - DU).abs() < 1e-14);
    }

    #[test]
    fn priors_add_one_over_sd_squared_to_their_diagonal() {
        let d = data(&[450.0, 550.0, 650.0], 0.2);
        let mut space = Constraints::none(&lambert(&d));
        space.fixed[0] = Some(0.3);
        space.free = vec![1, 2];
        space.priors.push(Prior {
            name: "rho".into(),
            index: 2,
            mean: 0.3,
            sd: 0.5,
        });
        space.priors.push(Prior {
            name: "rho".into(),
            index: 0,
            mean: 0.3,
            sd: 0.25,
        });
        let (mut b, mut m) = (DMatrix::from_element(2, 2, 1.0), DMatrix::zeros(2, 2));
        add_prior_rows(&mut b, &mut m, &space);
        assert_eq!(b, DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 1.0, 5.0]));
        assert_eq!(m, DMatrix::from_row_slice(2, 2, &[0.0, 0.0, 0.0, 4.0]));
    }

    #[test]
    fn the_pseudo_inverse_inverts_what_is_determined_and_flags_the_rest() {
        let close =
            |a: &DMatrix<f64>, b: &[f64]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12);
        // [[4, 2], [2, 3]]⁻¹ = [[3, −2], [−2, 4]]/8.
        let (inv, und) =
            pseudo_inverse(&DMatrix::from_row_slice(2, 2, &[4.0, 2.0, 2.0, 3.0])).unwrap();
        assert!(close(&inv, &[0.375, -0.25, -0.25, 0.5]), "{inv}");
        assert_eq!(und, [false, false]);
        // [[1, 1], [1, 1]] = 2vvᵀ, v = (1, 1)/√2: B⁺ = vvᵀ/2; both lie along the null space.
        let (inv, und) = pseudo_inverse(&DMatrix::from_element(2, 2, 1.0)).unwrap();
        assert!(close(&inv, &[0.25; 4]), "{inv}");
        assert_eq!(und, [true, true]);
        // Singular values below 1e-10 of the largest count as 0, those above do not.
        let diag = |a: f64, b: f64| DMatrix::from_row_slice(2, 2, &[a, 0.0, 0.0, b]);
        let (inv, und) = pseudo_inverse(&diag(4.0, 1e-10)).unwrap();
        assert!(close(&inv, &[0.25, 0.0, 0.0, 0.0]), "{inv}");
        assert_eq!(und, [false, true]);
        // Exactly 1e-10 of the largest is not above it.
        let (_, und) = pseudo_inverse(&diag(1.0, 1e-10)).unwrap();
        assert_eq!(und, [false, true]);
        let (inv, und) = pseudo_inverse(&diag(4.0, 1e-9)).unwrap();
        assert!(
            (inv[(1, 1)] / 1e9 - 1.0).abs() < 1e-9 && und == [false, false],
            "{inv}"
        );
        let (inv, und) = pseudo_inverse(&diag(0.0, 0.0)).unwrap();
        assert!(close(&inv, &[0.0; 4]) && und == [true, true]);
        assert!(pseudo_inverse(&diag(f64::NAN, 1.0)).is_err());
        assert!(pseudo_inverse(&diag(1.0, f64::INFINITY)).is_err());
    }

    fn empty(p: usize) -> Covariance {
        Covariance {
            std: vec![None; p],
            correlation: vec![vec![None; p]; p],
            warnings: vec![],
            ridges: vec![],
        }
    }

    #[test]
    fn standard_uncertainties_and_correlations_from_the_covariance() {
        let cov = DMatrix::from_row_slice(
            4,
            4,
            &[
                4.0, 1.2, 0.0, 3.0, //
                1.2, 9.0, 0.0, 0.0, //
                0.0, 0.0, -1.0, 0.0, //
                3.0, 0.0, 0.0, 0.0,
            ],
        );
        let mut out = empty(4);
        set_std_and_correlation(&mut out, &cov, &[false; 4]);
        // A negative variance has no σ; a zero one has σ = 0 and no correlation.
        assert_eq!(out.std, [Some(2.0), Some(3.0), None, Some(0.0)]);
        let c = |a: usize, b: usize| out.correlation[a][b];
        assert_eq!((c(0, 0), c(1, 1)), (Some(1.0), Some(1.0)));
        assert!((c(0, 1).unwrap() - 0.2).abs() < 1e-15 && c(0, 1) == c(1, 0));
        assert!((0..4).all(|o| c(2, o).is_none() && c(o, 2).is_none()));
        assert!((0..4).all(|o| c(3, o).is_none() && c(o, 3).is_none()));
        // An undetermined parameter has no σ even where its variance is finite.
        let mut out = empty(4);
        set_std_and_correlation(&mut out, &cov, &[false, true, false, false]);
        assert_eq!(out.std, [Some(2.0), None, None, Some(0.0)]);
        assert_eq!(out.correlation[0][1], None);
    }

    fn decl(lo: f64, hi: f64) -> ParamDecl {
        ParamDecl::rgb("p", lo, hi, lo, "test")
    }

    #[test]
    fn warnings_name_undetermined_parameters_wide_sigmas_and_tight_pairs() {
        let names = ["a", "b", "c"];
        let decls = [decl(1.0, 2.0), decl(0.0, 2.0), decl(0.0, 1.0)];
        let mut out = empty(3);
        out.std = vec![Some(1.5), Some(1.5), None];
        for a in 0..2 {
            for b in 0..2 {
                out.correlation[a][b] = Some(if a == b { 1.0 } else { -0.995 });
            }
        }
        let w = determinacy_warnings(&out, &[false, false, true], &names, &decls);
        assert_eq!(w.len(), 3, "{w:?}");
        assert!(w[0].contains("singular") && w[0].ends_with(": c"), "{w:?}");
        // σ 1.5 exceeds a's range 1, not b's range 2.
        assert!(
            w[1].starts_with("a is not determined") && w[1].contains("range 1"),
            "{w:?}"
        );
        assert!(
            w[2].starts_with("a and b are not separately determined"),
            "{w:?}"
        );
        // |correlation| 0.99 itself and σ equal to the range pass.
        out.std = vec![Some(1.0), Some(2.0), None];
        out.correlation[0][1] = Some(0.99);
        out.correlation[1][0] = Some(0.99);
        let w = determinacy_warnings(&out, &[false; 3], &names, &decls);
        assert!(w.is_empty(), "{w:?}");
    }

    /// C = [[1, 0, r], [0, 1, r], [r, r, 1]]: every pairwise |correlation| ≤ r, while
    /// (C⁻¹)₃₃ = 1/(1 − 2r²) and (C⁻¹)₁₁ = (1 − r²)/(1 − 2r²), so R₃² = 2r² and
    /// R₁² = r²/(1 − r²): at r = 0.705 all three exceed 0.99², at r = 0.7 none does
    /// (R₃ = 0.98995).
    #[test]
    fn a_three_way_trade_off_warns_on_its_multiple_correlation() {
        let names = ["a", "b", "c"];
        let with = |r: f64, ab: f64| {
            let mut out = empty(3);
            out.std = vec![Some(1.0); 3];
            let c = [[1.0, ab, r], [ab, 1.0, r], [r, r, 1.0]];
            out.correlation = (c.iter())
                .map(|row| row.iter().map(|&v| Some(v)).collect())
                .collect();
            out
        };
        let w = multiple_correlation_warnings(&with(0.705, 0.0), &names);
        assert_eq!(w.len(), 3, "{w:?}");
        assert!(
            w[2].starts_with("c is not separately determined from a, b"),
            "{w:?}"
        );
        let r3: f64 = w[2]
            .split("multiple correlation ")
            .nth(1)
            .and_then(|s| s.split(')').next())
            .and_then(|s| s.parse().ok())
            .unwrap();
        assert!((r3 - (2.0f64 * 0.705 * 0.705).sqrt()).abs() < 1e-4, "{r3}");
        assert!(multiple_correlation_warnings(&with(0.7, 0.0), &names).is_empty());
        // A parameter with a pairwise |correlation| above 0.99 is left to that warning.
        let w = multiple_correlation_warnings(&with(0.1, 0.995), &names);
        assert!(w.is_empty(), "{w:?}");
        // A parameter with σ = 0 (no correlations) takes no part.
        let mut four = empty(4);
        let three = with(0.705, 0.0);
        four.std = vec![Some(1.0), Some(1.0), Some(1.0), Some(0.0)];
        for a in 0..3 {
            four.correlation[a][..3].copy_from_slice(&three.correlation[a]);
        }
        let w = multiple_correlation_warnings(&four, &["a", "b", "c", "d"]);
        assert_eq!(w.len(), 3, "{w:?}");
        // Fewer than three determined parameters: nothing to add.
        let mut two = with(0.705, 0.0);
        two.std[2] = None;
        assert!(multiple_correlation_warnings(&two, &names).is_empty());
    }

    #[test]
    fn ridges_are_the_weak_eigenvectors_in_the_unit_box() {
        let decls = [decl(0.0, 1.0), decl(0.0, 1.0), decl(0.0, 4.0)];
        let flat = [0.5, 0.5, 2.0];
        // [[a, b], [b, a]] with a = 200.5, b = −199.5: eigenvalue a − b = 400 along
        // (1, −1)/√2 (σ 0.05: no ridge) and a + b = 1 along (1, 1)/√2 (σ 1: a ridge).
        let jtj = DMatrix::from_row_slice(2, 2, &[200.5, -199.5, -199.5, 200.5]);
        let r = ridges(&jtj, 1.0, &[0, 1], &flat, &decls);
        assert_eq!(r.len(), 1, "{r:?}");
        assert!((r[0].unit_std - 1.0).abs() < 1e-12, "{r:?}");
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let [(i, a), (j, b)] = r[0].components[..] else {
            panic!("{r:?}")
        };
        assert!((i, j) == (0, 1) || (i, j) == (1, 0), "{r:?}");
        assert!((a.abs() - h).abs() < 1e-9 && (a - b).abs() < 1e-9, "{r:?}");
        // χ²_red scales the standard uncertainty by its root.
        let r = ridges(&jtj, 4.0, &[0, 1], &flat, &decls);
        assert!((r[0].unit_std - 2.0).abs() < 1e-12, "{r:?}");
        // The weakest direction first: one the data do not constrain at all (σ ∞), then
        // σ = 1/√50 along the first parameter.
        let jtj = DMatrix::from_row_slice(2, 2, &[50.0, 0.0, 0.0, 0.0]);
        let r = ridges(&jtj, 1.0, &[0, 2], &flat, &decls);
        assert_eq!(r.len(), 2, "{r:?}");
        assert!(r[0].unit_std.is_infinite() && r[0].components.len() == 1);
        assert_eq!(r[0].components[0].0, 2);
        assert!(
            (r[1].unit_std - 50f64.sqrt().recip()).abs() < 1e-12,
            "{r:?}"
        );
        assert_eq!(r[1].components[0].0, 0);
        // In unit-box terms: the third parameter's range is 4, so JᵀJ = 1 in physical
        // units is 16 in the box (σ 0.25), and 400 on the first σ 0.05 (no ridge).
        let jtj = DMatrix::from_row_slice(2, 2, &[400.0, 0.0, 0.0, 1.0]);
        let r = ridges(&jtj, 1.0, &[0, 2], &flat, &decls);
        assert_eq!(r.len(), 1, "{r:?}");
        assert!((r[0].unit_std - 0.25).abs() < 1e-9, "{r:?}");
        assert_eq!(r[0].components.len(), 1);
        assert_eq!(r[0].components[0].0, 2);
        // Components below 0.2 in size are left out, the rest sorted by size.
        let (c, s) = (0.95f64, (1.0 - 0.95f64 * 0.95).sqrt());
        let (l1, l2) = (1.0, 1e4);
        let m = [
            c * c * l1 + s * s * l2,
            c * s * (l1 - l2),
            c * s * (l1 - l2),
            s * s * l1 + c * c * l2,
        ];
        let r = ridges(
            &DMatrix::from_row_slice(2, 2, &m),
            1.0,
            &[0, 1],
            &flat,
            &decls,
        );
        assert_eq!(r.len(), 1, "{r:?}");
        assert_eq!(r[0].components.len(), 2, "{r:?}");
        assert_eq!(r[0].components[0].0, 0, "{r:?}");
        let c = 0.99f64;
        let s = (1.0 - c * c).sqrt();
        let m = [
            c * c * l1 + s * s * l2,
            c * s * (l1 - l2),
            c * s * (l1 - l2),
            s * s * l1 + c * c * l2,
        ];
        let r = ridges(
            &DMatrix::from_row_slice(2, 2, &m),
            1.0,
            &[0, 1],
            &flat,
            &decls,
        );
        assert_eq!(r[0].components.len(), 1, "{r:?}");
        let jtj = DMatrix::from_row_slice(2, 2, &[400.0, 0.0, 0.0, 1600.0]);
        assert!(ridges(&jtj, 1.0, &[0, 2], &flat, &decls).is_empty());
        let jtj = DMatrix::from_row_slice(2, 2, &[f64::NAN, 0.0, 0.0, 1.0]);
        assert!(ridges(&jtj, 1.0, &[0, 2], &flat, &decls).is_empty());
        // A standard uncertainty of exactly 0.1 (λ = 100) is a ridge ("at least" 0.1).
        let jtj = DMatrix::from_row_slice(2, 2, &[400.0, 0.0, 0.0, 100.0]);
        let r = ridges(&jtj, 1.0, &[0, 1], &flat, &decls);
        assert_eq!(r.len(), 1, "{r:?}");
        assert_eq!((r[0].unit_std, r[0].components[0].0), (0.1, 1));
        // An eigenvalue of exactly 1e-10 of the largest is no constraint at all; nor is
        // one above 0 but below that.
        let jtj = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, 1e-10]);
        let r = ridges(&jtj, 1.0, &[0, 1], &flat, &decls);
        assert!(
            r[0].unit_std.is_infinite() && r[0].components[0].0 == 1,
            "{r:?}"
        );
        let jtj = DMatrix::from_row_slice(2, 2, &[50.0, 0.0, 0.0, 3e-12]);
        let r = ridges(&jtj, 1.0, &[0, 1], &flat, &decls);
        assert!(
            r[0].unit_std.is_infinite() && r[0].components[0].0 == 1,
            "{r:?}"
        );
    }

    #[test]
    fn unit_slopes_of_linear_and_log_parameters() {
        let lin = decl(0.0, 4.0);
        assert!((unit_slope(&lin, 1.0) - 4.0).abs() < 1e-9);
        assert!((unit_slope(&lin, 0.0) - 4.0).abs() < 1e-9);
        assert!((unit_slope(&lin, 4.0) - 4.0).abs() < 1e-9);
        assert!((unit_std(&lin, 1.0, 0.2) - 0.05).abs() < 1e-9);
        // v = lo (hi/lo)^u: dv/du = v ln(hi/lo).
        let log = decl(0.01, 1.0).log();
        let want = 0.1 * 100f64.ln();
        assert!((unit_slope(&log, 0.1) / want - 1.0).abs() < 1e-6);
        assert!((unit_std(&log, 0.1, 0.01) - 0.01 / want).abs() < 1e-9);
    }

    #[test]
    fn the_free_parameters_are_laid_out_over_the_flat_vector() {
        let mut free = empty(2);
        free.std = vec![Some(1.0), Some(2.0)];
        free.correlation = vec![vec![Some(1.0), Some(0.5)], vec![Some(0.5), Some(1.0)]];
        free.warnings = vec!["w".into()];
        let out = expand(free, &[0, 2], 3);
        assert_eq!(out.std, [Some(1.0), None, Some(2.0)]);
        assert_eq!(out.correlation[0][2], Some(0.5));
        assert_eq!(out.correlation[2][2], Some(1.0));
        assert!((0..3).all(|o| out.correlation[1][o].is_none()));
        assert_eq!(out.warnings, ["w"]);
    }

    #[test]
    fn ridge_words() {
        let names: Vec<String> = ["a", "b", "c"].iter().map(|s| s.to_string()).collect();
        let r = Ridge {
            components: vec![(2, -0.71), (0, 0.7), (1, -0.2)],
            unit_std: 1.0,
        };
        assert_eq!(r.words(&names), "−0.71 c + 0.70 a − 0.20 b");
    }
}
