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
    /// The effective number of fitted parameters, tr(B⁻¹ B_data) with B = B_data +
    /// B_prior the normal matrix with the priors' rows: the parameter count where there
    /// is no prior, less where a prior holds some of them (None without a covariance).
    pub effective_params: Option<f64>,
    /// With the smoothness prior on: the full covariance of the flat parameters (rows
    /// and columns of fixed ones 0), the prior's information included, from a
    /// pseudo-inverse of the Jacobi-scaled normal matrix. A knot the data do not see is
    /// held by the prior alone: its variance is then the prior's, not "undetermined" as
    /// [`Covariance::std`] says (whose judgement compares information across all
    /// parameters in their own units). For the tabulated functions' bands
    /// ([`crate::inference::knots::bands`]).
    pub with_prior: Option<Vec<Vec<f64>>>,
    /// With the smoothness prior on: each flat parameter's data share, B_data,jj /
    /// (B_data,jj + B_prior,jj), the part of its information with the others held that the
    /// data give (1 without a prior row on it, 0 for fixed ones). A knot whose share is
    /// below ½ is held more by its neighbours through the prior than by the data, and the
    /// prior's pull sets its value ([`crate::inference::knots::MEASURED_SHARE`]). (The
    /// diagonal of (B_data + B_prior)⁻¹ B_data, whose trace is the effective number of
    /// parameters, is not a share per parameter: with correlated parameters its terms
    /// leave [0, 1], e.g. −0.6 and 1.5 at neighbouring knots of a fitted NDF.)
    pub data_share: Option<Vec<f64>>,
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
    let k = data.len() + space.prior_rows();
    let decls = &space.decls;
    let (batch, steps) = central_difference_batch(flat, space);
    let (mut jtj, mut meat, chi2) = jacobian_sums(data, loss, eval, &batch, &steps)?;
    let data_jtj = jtj.clone();
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
        effective_params: None,
        with_prior: None,
        data_share: None,
    };
    let slopes = unit_slopes(free, flat, decls);
    let (inv, singular) = match pseudo_inverse(&jtj, &slopes) {
        Ok(found) => found,
        Err(why) => {
            out.warnings.push(why.into());
            return Ok(expand(out, free, model.dim));
        }
    };
    // In one plane an anisotropic lobe shows one combination of its roughnesses and
    // frame: the normal matrix may still be regular (the plane's width, height and
    // masking weigh them differently), but their values would be one of many sets.
    let mut undetermined = singular.clone();
    // (The planes are counted only for such a model: it scans every sample.)
    if free_decls.iter().any(|d| d.needs_planes) && data.direction_planes() < 2 {
        let names_in_plane: Vec<&str> = (0..p)
            .filter(|&c| free_decls[c].needs_planes)
            .inspect(|&c| undetermined[c] = true)
            .map(|c| names[c])
            .collect();
        if !names_in_plane.is_empty() {
            out.warnings.push(format!(
                "not determined by data in one plane of incidence: {} (one plane sees an anisotropic lobe along that plane only, one combination of its two roughnesses and its frame); measure a second plane or out of plane",
                names_in_plane.join(", ")
            ));
        }
    }
    // A frame the data leave free leaves the roughnesses along its axes free with it: the
    // data see the lobe's widths along the measured planes, and which axes those belong
    // to turns with φ0. (At normal incidence on two planes: two widths for three
    // parameters, along a curved ridge; where it runs along φ0 alone, the linearised σ of
    // α_u and α_v would hold φ0 at its fitted value.)
    for [au, av, phi] in model.frames() {
        let at = |j: usize| free.iter().position(|&f| f == j);
        let Some(c) = at(phi).filter(|&c| singular[c]) else {
            continue;
        };
        let pair: Vec<usize> = [au, av]
            .into_iter()
            .filter_map(at)
            .filter(|&k| !undetermined[k])
            .collect();
        if pair.is_empty() {
            continue;
        }
        pair.iter().for_each(|&k| undetermined[k] = true);
        let pair_names: Vec<&str> = pair.iter().map(|&k| names[k]).collect();
        out.warnings.push(format!(
            "not determined: {} along the axes of the frame {}, which the data do not determine (they determine the lobe's widths along the measured planes, and the axes turn with the frame)",
            pair_names.join(", "),
            names[c]
        ));
    }
    out.effective_params = Some((&inv * &data_jtj).trace());
    let cov = &inv * &meat * &inv * birge;
    let with_prior = (space.smooth_sd.is_some()).then(|| {
        let scaled = jacobi_scaled_inverse(&jtj);
        let share: Vec<f64> = (0..p)
            .map(|a| match jtj[(a, a)] {
                b if b > 0.0 => data_jtj[(a, a)] / b,
                _ => 0.0,
            })
            .collect();
        (&scaled * &meat * &scaled * birge, share)
    });
    out.ridges = ridges(&jtj, birge, free, &slopes);
    set_std_and_correlation(&mut out, &cov, &undetermined);
    let warnings = determinacy_warnings(&out, &singular, &names, &free_decls);
    out.warnings.extend(warnings);
    let mut out = expand(out, free, model.dim);
    if let Some((full, share)) = with_prior {
        let mut m = vec![vec![0.0; model.dim]; model.dim];
        let mut shares = vec![0.0; model.dim];
        for (a, &ja) in free.iter().enumerate() {
            shares[ja] = share[a];
            for (b, &jb) in free.iter().enumerate() {
                m[ja][jb] = full[(a, b)];
            }
        }
        out.with_prior = Some(m);
        out.data_share = Some(shares);
    }
    out.warnings
        .extend(one_azimuth_warnings(model, data, flat, &out.std, free));
    Ok(out)
}

/// B⁻¹ through the Jacobi scaling S B S, S = diag(B)^(-1/2), whose singular values
/// measure how collinear the parameters' information is rather than its units; the
/// directions [`pseudo_inverse`] leaves out there (none unless the information is
/// collinear) are left out here too, and a matrix that is not finite gives 0.
fn jacobi_scaled_inverse(b: &DMatrix<f64>) -> DMatrix<f64> {
    let p = b.nrows();
    let scale: Vec<f64> = (0..p)
        .map(|j| {
            if b[(j, j)] > 0.0 {
                1.0 / b[(j, j)].sqrt()
            } else {
                0.0
            }
        })
        .collect();
    let scaled = DMatrix::from_fn(p, p, |i, j| b[(i, j)] * scale[i] * scale[j]);
    let inv = pseudo_inverse(&scaled, &vec![1.0; p])
        .map(|(inv, _)| inv)
        .unwrap_or_else(|_| DMatrix::zeros(p, p));
    DMatrix::from_fn(p, p, |i, j| inv[(i, j)] * scale[i] * scale[j])
}

/// Frames this many standard uncertainties or fewer from the plane of incidence (or
/// across it) count as lying on it.
const ON_PLANE_SIGMAS: f64 = 3.0;

/// On data measured at one incidence azimuth (`crate::data::AzimuthCoverage::One`), what
/// each fitted anisotropic frame means there: a frame on (or across) the plane of
/// incidence is mirror-symmetric about it like an isotropic lobe, so α_u and α_v then
/// measure a lobe shape across the plane against along it that this geometry cannot tell
/// from anisotropy; a frame turned off the plane rests on the mirror symmetry it breaks.
fn one_azimuth_warnings(
    model: &Model,
    data: &Dataset,
    flat: &[f64],
    std: &[Option<f64>],
    free: &[usize],
) -> Vec<String> {
    let frames: Vec<[usize; 3]> = model
        .frames()
        .into_iter()
        .filter(|f| free.contains(&f[2]))
        .collect();
    if frames.is_empty() {
        return vec![];
    }
    let Some(plane) = data.azimuth_coverage().one_azimuth() else {
        return vec![];
    };
    let names = model.flat_names();
    let sides = data.mirror_sides();
    frames
        .iter()
        .map(|&[u, v, phi]| {
            // Distance of the frame from the plane or from across it, in [0°, 45°].
            let r = (flat[phi] - plane).rem_euclid(90.0);
            let off = r.min(90.0 - r);
            let sd = std[phi];
            let frame = match sd {
                Some(s) => format!("{} = {:.1}° ± {s:.1}°", names[phi], flat[phi]),
                None => format!("{} = {:.1}° (undetermined)", names[phi], flat[phi]),
            };
            if sd.is_none_or(|s| off <= ON_PLANE_SIGMAS * s) {
                format!(
                    "measured at one incidence azimuth (φi = {plane:.0}°), the frame {frame} lies on the plane of incidence or across it: so aligned, an anisotropic lobe is mirror-symmetric about that plane like any isotropic lobe, and {} and {} measure a lobe shape across the plane against along it that this geometry cannot tell from anisotropy (`diagnose` does not name anisotropy here); measure at a second incidence azimuth to tell",
                    names[u], names[v]
                )
            } else if !sides.testable() {
                format!(
                    "measured at one incidence azimuth (φi = {plane:.0}°) with {}, the frame {frame} is turned {off:.1}° off the plane of incidence, but where one side is barely measured a turned frame only reshapes the lobe on the measured side: {} and {} and the frame measure a lobe shape that this geometry cannot tell from anisotropy (`diagnose` does not name anisotropy here); measure both sides of the plane, or at a second incidence azimuth",
                    sides.describe(),
                    names[u],
                    names[v]
                )
            } else {
                format!(
                    "measured at one incidence azimuth (φi = {plane:.0}°), the anisotropy rests on the frame {frame} breaking the mirror symmetry about the plane of incidence ({off:.1}° off it); `diagnose` tests whether that break is significant"
                )
            }
        })
        .collect()
}

/// The covariance of every parameter of `model` at the fitted point `flat` (none fixed),
/// from `data` and the fit's loss (`metric` and `weights` as results tables name them),
/// on the CPU reference: what a fit's saved parameters alone let a later stage (a plot)
/// recover.
pub fn at_fitted_point(
    model: &Model,
    data: &Dataset,
    metric: &str,
    weights: &str,
    flat: &[f64],
) -> anyhow::Result<Covariance> {
    use crate::engine::Backend;
    let loss = Loss::new(
        metric.parse::<Metric>().map_err(anyhow::Error::msg)?,
        weights
            .parse::<crate::engine::loss::Weights>()
            .map_err(anyhow::Error::msg)?,
    );
    let cpu = crate::engine::cpu::CpuBackend::new();
    let mut eval = cpu.prepare(crate::engine::Problem { model, data, loss })?;
    covariance(
        model,
        data,
        loss,
        eval.as_mut(),
        flat,
        &Constraints::none(model),
    )
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

/// The priors' rows in B and M: a `--prior`'s ∂((θ_j − mean)/sd)/∂θ_j = 1/sd, a
/// smoothness row's c_j/sd at its knots; each residual with unit variance.
fn add_prior_rows(jtj: &mut DMatrix<f64>, meat: &mut DMatrix<f64>, space: &Constraints) {
    for row in space.prior_gradients() {
        for &(a, ga) in &row {
            for &(b, gb) in &row {
                jtj[(a, b)] += ga * gb;
                meat[(a, b)] += ga * gb;
            }
        }
    }
}

/// B⁺ by SVD, and which parameters lie along a direction the data do not constrain; or
/// why there are no uncertainties. Which parameters a direction involves is judged in the
/// parameters' unit boxes (`slopes`: each one's dθ/du), not in physical units, where a
/// parameter in degrees would dwarf a roughness moving with it along the same ridge (an
/// anisotropic lobe seen at normal incidence on two planes: α_u, α_v and φ0 trade along
/// one direction, which in physical units is almost all φ0).
fn pseudo_inverse(
    jtj: &DMatrix<f64>,
    slopes: &[f64],
) -> Result<(DMatrix<f64>, Vec<bool>), &'static str> {
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
            // A direction the data does not constrain: flag the parameters along it, its
            // components taken in the unit boxes (du = dθ / slope).
            let unit: Vec<f64> = (0..p)
                .map(|j| match slopes[j] {
                    s if s.is_finite() && s > 0.0 => vt[(m, j)] / s,
                    _ => vt[(m, j)],
                })
                .collect();
            let norm = unit.iter().map(|x| x * x).sum::<f64>().sqrt();
            for j in 0..p {
                if unit[j].abs() > 0.1 * norm || vt[(m, j)].abs() > 0.1 {
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
    // A tabulated function's knots (`+ndf`) trade with their neighbours and with the
    // lobe's width by construction; they are reported as the function's values with
    // bands (`crate::inference::knots`), not one by one.
    let knot = |j: usize| decls[j].knot;
    let undetermined_names: Vec<&str> = (0..p)
        .filter(|&j| undetermined[j] && !knot(j))
        .map(|j| names[j])
        .collect();
    if !undetermined_names.is_empty() {
        warnings.push(format!(
            "not determined by the data (singular normal matrix): {}",
            undetermined_names.join(", ")
        ));
    }
    for j in (0..p).filter(|&j| !knot(j)) {
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
    for a in (0..p).filter(|&j| !knot(j)) {
        for b in (a + 1..p).filter(|&j| !knot(j)) {
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
    let plain: Vec<bool> = (0..p).map(|j| !knot(j)).collect();
    warnings.extend(multiple_correlation_warnings(out, names, &plain));
    warnings
}

/// A trade-off among three or more parameters can hide behind moderate pairwise
/// correlations: the multiple correlation R_j of each parameter with all the others,
/// R_j² = 1 − 1/(C⁻¹)_jj, exposes it (e.g. α, η_t and S at normal incidence). A warning
/// per parameter with R_j > 0.99 and no pairwise correlation above 0.99, among the
/// parameters `judged` (knots are not: see [`determinacy_warnings`]).
fn multiple_correlation_warnings(out: &Covariance, names: &[&str], judged: &[bool]) -> Vec<String> {
    let p = names.len();
    let mut warnings = Vec::new();
    let det: Vec<usize> = (0..p)
        .filter(|&j| judged[j] && out.std[j].is_some_and(|s| s > 0.0))
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

/// The unit-box slopes dθ/du of the free parameters at `flat` ([`unit_slope`]).
fn unit_slopes(free: &[usize], flat: &[f64], decls: &[crate::bsdf::ParamDecl]) -> Vec<f64> {
    free.iter()
        .map(|&j| unit_slope(&decls[j], flat[j]))
        .collect()
}

/// The weak directions of the normal matrix `jtj` (free parameters, physical units) in
/// the parameters' unit boxes: the eigenvectors of D·JᵀJ·D (D = `d`, the slopes) whose
/// standard uncertainty √(birge/λ) exceeds [`RIDGE_UNIT_STD`], mapped to flat indices.
fn ridges(jtj: &DMatrix<f64>, birge: f64, free: &[usize], d: &[f64]) -> Vec<Ridge> {
    let p = free.len();
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
        effective_params: free_cov.effective_params,
        with_prior: None,
        data_share: None,
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
#[path = "covariance_tests.rs"]
mod tests;
