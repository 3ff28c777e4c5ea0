//! Parameter standard uncertainties and correlations at an optimum (DESIGN §5, issue 4):
//! cov = s² (JᵀWJ)⁻¹ with J the Jacobian of the weighted residuals by central differences.
//!
//! - χ² loss (W = 1/u²): s² = 1, the metrological covariance.
//! - other sum-of-squares losses: s² = Σ w r² / (K − P), the usual weighted-least-squares
//!   scaling, since their weights are not 1/u².
//! - SMAPE (not a sum of squares): the χ² form is reported.
//!
//! The inverse is a pseudo-inverse by SVD; a parameter that lies along a direction the
//! data does not determine gets no standard uncertainty and a warning, as does a pair with
//! |correlation| > 0.99 or a standard uncertainty larger than the parameter's range.

use crate::backend::Evaluator;
use crate::dataset::Dataset;
use crate::loss::{Loss, Metric};
use crate::model::Model;
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

/// Weighted residual vectors of a batch of physical parameter vectors.
fn residual_rows(model: &Model, data: &Dataset, loss: Loss, eval: &mut dyn Evaluator, batch: &[f64]) -> anyhow::Result<(Vec<Vec<f64>>, bool)> {
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
    let _ = model;
    Ok((rows, use_loss))
}

pub fn covariance(model: &Model, data: &Dataset, loss: Loss, eval: &mut dyn Evaluator, flat: &[f64]) -> anyhow::Result<Covariance> {
    let p = model.dim;
    let k = data.len();
    let decls = model.flat_decls();
    let unit = model.to_unit(flat);
    // Batch: the point itself, then (+, −) per parameter.
    let mut batch = flat.to_vec();
    let mut steps = Vec::with_capacity(p);
    for j in 0..p {
        let up = (unit[j] + DU).min(1.0);
        let dn = (unit[j] - DU).max(0.0);
        let mut plus = flat.to_vec();
        let mut minus = flat.to_vec();
        plus[j] = decls[j].from_unit(up);
        minus[j] = decls[j].from_unit(dn);
        steps.push(plus[j] - minus[j]);
        batch.extend(plus);
        batch.extend(minus);
    }
    let (rows, scaled) = residual_rows(model, data, loss, eval, &batch)?;
    let r0 = &rows[0];
    let mut jac = DMatrix::<f64>::zeros(k, p);
    for j in 0..p {
        let (plus, minus) = (&rows[1 + 2 * j], &rows[2 + 2 * j]);
        for i in 0..k {
            jac[(i, j)] = if steps[j] != 0.0 { (plus[i] - minus[i]) / steps[j] } else { 0.0 };
        }
    }
    let dof = (k.saturating_sub(p)).max(1) as f64;
    let s2 = if scaled { r0.iter().map(|r| r * r).sum::<f64>() / dof } else { 1.0 };
    let jtj = jac.transpose() * &jac;
    let names = model.flat_names();
    let mut out = Covariance { std: vec![None; p], correlation: vec![vec![None; p]; p], warnings: vec![] };
    if jtj.iter().any(|v| !v.is_finite()) {
        out.warnings.push("the Jacobian is not finite at the optimum; no parameter uncertainties".into());
        return Ok(out);
    }
    let svd = jtj.clone().svd(true, true);
    let (Some(u), Some(vt)) = (svd.u.as_ref(), svd.v_t.as_ref()) else {
        out.warnings.push("SVD failed; no parameter uncertainties".into());
        return Ok(out);
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
    let cov = inv * s2;
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
    let undetermined_names: Vec<&str> = (0..p).filter(|&j| undetermined[j]).map(|j| names[j].as_str()).collect();
    if !undetermined_names.is_empty() {
        out.warnings.push(format!(
            "not determined by the data (singular normal matrix): {}",
            undetermined_names.join(", ")
        ));
    }
    for j in 0..p {
        if let Some(s) = out.std[j] {
            let range = decls[j].hi - decls[j].lo;
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
    Ok(out)
}
