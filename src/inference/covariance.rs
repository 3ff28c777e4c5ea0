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
use crate::engine::loss::{Loss, Metric, Term};
use crate::engine::Evaluator;
use crate::inference::constraints::Constraints;
use nalgebra::DMatrix;

#[derive(Clone, Debug, Default)]
pub struct Covariance {
    /// Standard uncertainty per flat parameter; None where undetermined.
    pub std: Vec<Option<f64>>,
    pub correlation: Vec<Vec<Option<f64>>>,
    pub warnings: Vec<String>,
}

/// Unit-box step of the finite differences.
const DU: f64 = 1e-4;
/// Relative singular-value threshold of the pseudo-inverse.
const RCOND: f64 = 1e-10;

/// Weighted residual vectors of a batch, with each sample's w_k σ_k² (see module doc)
/// and the χ² of the first point.
fn residual_rows(
    data: &Dataset,
    loss: Loss,
    eval: &mut dyn Evaluator,
    batch: &[f64],
) -> anyhow::Result<(Vec<Vec<f64>>, Vec<f64>, f64)> {
    let values = eval.values(batch)?;
    let k = data.len();
    let use_loss = loss.is_sum_of_squares() && loss.metric != Metric::Chi2;
    let terms = loss.terms(data);
    let rows = values
        .chunks(k)
        .map(|row| {
            row.iter()
                .enumerate()
                .map(|(j, &v)| {
                    if use_loss {
                        terms.residual(j, v)
                    } else {
                        let s = &data.samples[j];
                        (v - s.value) / s.uncertainty
                    }
                })
                .collect()
        })
        .collect();
    let w_sigma2 = data
        .samples
        .iter()
        .enumerate()
        .map(|(j, s)| {
            if !use_loss {
                return 1.0; // w = 1/u², σ = u
            }
            let slope = match terms.term {
                Term::LogSquare => terms.a[j] / (1.0 + terms.a[j] * s.value),
                _ => terms.a[j],
            };
            terms.w[j] * (slope * s.uncertainty).powi(2)
        })
        .collect();
    let chi2 = crate::engine::loss::chi2(data, &values[..k]);
    Ok((rows, w_sigma2, chi2))
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
    let unit = space.to_unit(flat);
    // Batch: the point itself, then (+, −) per free parameter.
    let mut batch = flat.to_vec();
    let mut steps = Vec::with_capacity(p);
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
    let (rows, mut w_sigma2, chi2) = residual_rows(data, loss, eval, &batch)?;
    let mut jac = DMatrix::<f64>::zeros(k, p);
    for c in 0..p {
        let (plus, minus) = (&rows[1 + 2 * c], &rows[2 + 2 * c]);
        for i in 0..data.len() {
            jac[(i, c)] = if steps[c] != 0.0 {
                (plus[i] - minus[i]) / steps[c]
            } else {
                0.0
            };
        }
    }
    // Prior rows: ∂((θ_j − mean)/sd)/∂θ_j = 1/sd.
    for (q, prior) in space.priors.iter().enumerate() {
        if let Some(c) = free.iter().position(|&j| j == prior.index) {
            jac[(data.len() + q, c)] = 1.0 / prior.sd;
        }
        w_sigma2.push(1.0);
    }
    let chi2 = chi2 + space.prior_chi2(flat);
    let dof = (k.saturating_sub(p)).max(1) as f64;
    let birge = (chi2 / dof).max(1.0);
    let jtj = jac.transpose() * &jac;
    let mut weighted = jac.clone();
    for (i, ws) in w_sigma2.iter().enumerate() {
        weighted.row_mut(i).scale_mut(*ws);
    }
    let meat = jac.transpose() * weighted;
    let all_names = model.flat_names();
    let names: Vec<&str> = free.iter().map(|&j| all_names[j].as_str()).collect();
    let free_decls: Vec<_> = free.iter().map(|&j| decls[j]).collect();
    let mut out = Covariance {
        std: vec![None; p],
        correlation: vec![vec![None; p]; p],
        warnings: vec![],
    };
    if jtj.iter().any(|v| !v.is_finite()) {
        out.warnings
            .push("the Jacobian is not finite at the optimum; no parameter uncertainties".into());
        return Ok(expand(out, free, model.dim));
    }
    let svd = jtj.clone().svd(true, true);
    let (Some(u), Some(vt)) = (svd.u.as_ref(), svd.v_t.as_ref()) else {
        out.warnings
            .push("SVD failed; no parameter uncertainties".into());
        return Ok(expand(out, free, model.dim));
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
    let cov = &inv * meat * &inv * birge;
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
    let undetermined_names: Vec<&str> = (0..p)
        .filter(|&j| undetermined[j])
        .map(|j| names[j])
        .collect();
    if !undetermined_names.is_empty() {
        out.warnings.push(format!(
            "not determined by the data (singular normal matrix): {}",
            undetermined_names.join(", ")
        ));
    }
    for j in 0..p {
        if let Some(s) = out.std[j] {
            let range = free_decls[j].hi - free_decls[j].lo;
            if s > range {
                out.warnings.push(format!(
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
                    out.warnings.push(format!(
                        "{} and {} are not separately determined (correlation {c:+.4})",
                        names[a], names[b]
                    ));
                }
            }
        }
    }
    // A trade-off among three or more parameters can hide behind moderate pairwise
    // correlations: the multiple correlation R_j of each parameter with all the others,
    // R_j² = 1 − 1/(C⁻¹)_jj, exposes it (e.g. α, η_t and S at normal incidence).
    let det: Vec<usize> = (0..p)
        .filter(|&j| out.std[j].is_some_and(|s| s > 0.0))
        .collect();
    if det.len() > 2 {
        let c = DMatrix::from_fn(det.len(), det.len(), |a, b| {
            out.correlation[det[a]][det[b]].unwrap_or(0.0)
        });
        if let Some(ci) = c.try_inverse() {
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
                    let others: Vec<&str> =
                        det.iter().filter(|&&o| o != j).map(|&o| names[o]).collect();
                    out.warnings.push(format!(
                        "{} is not separately determined from {} (multiple correlation {r:.4}): the data constrain only a combination",
                        names[j],
                        others.join(", ")
                    ));
                }
            }
        }
    }
    Ok(expand(out, free, model.dim))
}

/// The covariance of the free parameters laid out over the model's whole flat vector
/// (fixed parameters: no standard uncertainty, no correlation).
fn expand(free_cov: Covariance, free: &[usize], dim: usize) -> Covariance {
    let mut out = Covariance {
        std: vec![None; dim],
        correlation: vec![vec![None; dim]; dim],
        warnings: free_cov.warnings,
    };
    for (a, &ja) in free.iter().enumerate() {
        out.std[ja] = free_cov.std[a];
        for (b, &jb) in free.iter().enumerate() {
            out.correlation[ja][jb] = free_cov.correlation[a][b];
        }
    }
    out
}
