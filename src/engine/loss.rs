//! Losses of the benchmark (docs/losses.md, paper §2.2 and §2.3.2) and χ².
//!
//! Every loss is a sum over the K (sample, channel) pairs of a per-sample term, then a
//! finalisation. Per sample we precompute a weight `w` (uncertainty weight × geometric
//! factor) and an inner factor `a` (cos θt for the cosine-weighted BTDF metrics), so the
//! CPU and the GPU evaluate the same three term shapes (the GPU sums them per candidate;
//! the finalisation is always the host's, [`LossTerms::finish_sum`]):
//! - `AbsRatio`:   w · |y′ − y| / (|y′| + |y| + ε)                 (SMAPE)
//! - `Square`:     w · (a y′ − a y)²                               (RMSE, Ngan, Löw, f, cosf, χ²)
//! - `LogSquare`:  w · (ln(1 + a y′) − ln(1 + a y))²               (logf, logcosf)

use crate::data::{Dataset, Kind};
use std::fmt;

pub const EPS: f64 = 1e-6;

/// The sample index of a padding row ([`LossTerms::in_rows`]).
pub const NO_SAMPLE: u32 = u32::MAX;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Metric {
    Smape,
    Rmse,
    Ngan,
    Low,
    F,
    Cosf,
    Logf,
    Logcosf,
    Chi2,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Weights {
    /// w = 1
    Uniform,
    /// w = 1/(|u|/(|y|+ε)+ε), the paper's relative-uncertainty weight (BRDF).
    Relunc,
    /// w = 1/u, the paper's BTDF weight.
    Invunc,
}

/// The three per-sample term shapes shared by both backends.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Term {
    AbsRatio,
    Square,
    LogSquare,
}

/// How the sum of terms becomes the loss.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Finish {
    /// (1/K) Σ
    Mean,
    /// sqrt((1/K) Σ)
    SqrtMean,
    /// Σ
    Sum,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct Loss {
    pub metric: Metric,
    pub weights: Weights,
}

impl fmt::Display for Metric {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Metric::Smape => "smape",
            Metric::Rmse => "rmse",
            Metric::Ngan => "ngan",
            Metric::Low => "low",
            Metric::F => "f",
            Metric::Cosf => "cosf",
            Metric::Logf => "logf",
            Metric::Logcosf => "logcosf",
            Metric::Chi2 => "chi2",
        })
    }
}

impl fmt::Display for Weights {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Weights::Uniform => "uniform",
            Weights::Relunc => "relunc",
            Weights::Invunc => "invunc",
        })
    }
}

impl std::str::FromStr for Metric {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Ok(match s.trim().to_ascii_lowercase().as_str() {
            "smape" => Metric::Smape,
            "rmse" => Metric::Rmse,
            "ngan" | "nganl2" => Metric::Ngan,
            "low" | "lowl2" => Metric::Low,
            "f" => Metric::F,
            "cosf" => Metric::Cosf,
            "logf" => Metric::Logf,
            "logcosf" => Metric::Logcosf,
            "chi2" => Metric::Chi2,
            o => {
                return Err(format!(
                    "unknown loss '{o}' (BRDF: smape rmse ngan low; BTDF: f cosf logf logcosf; any: chi2)"
                ))
            }
        })
    }
}

impl std::str::FromStr for Weights {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Ok(match s.trim().to_ascii_lowercase().as_str() {
            "uniform" | "unif" => Weights::Uniform,
            "relunc" | "ru" => Weights::Relunc,
            "invunc" => Weights::Invunc,
            o => return Err(format!("unknown weights '{o}' (uniform, relunc, invunc)")),
        })
    }
}

impl Metric {
    pub fn term(self) -> Term {
        match self {
            Metric::Smape => Term::AbsRatio,
            Metric::Logf | Metric::Logcosf => Term::LogSquare,
            _ => Term::Square,
        }
    }
    pub fn finish(self) -> Finish {
        match self {
            Metric::Rmse => Finish::SqrtMean,
            Metric::Smape | Metric::Ngan | Metric::Low => Finish::Mean,
            _ => Finish::Sum,
        }
    }
    /// The kinds of data the metric was defined for.
    pub fn applies_to(self, kind: Kind) -> bool {
        match self {
            Metric::Smape | Metric::Rmse | Metric::Ngan | Metric::Low => kind == Kind::Brdf,
            Metric::F | Metric::Cosf | Metric::Logf | Metric::Logcosf => kind == Kind::Btdf,
            Metric::Chi2 => true,
        }
    }
    /// Metrics of the paper for a kind of data, in the paper's order.
    pub fn for_kind(kind: Kind) -> &'static [Metric] {
        match kind {
            Kind::Brdf => &[Metric::Smape, Metric::Rmse, Metric::Ngan, Metric::Low],
            Kind::Btdf => &[Metric::F, Metric::Cosf, Metric::Logf, Metric::Logcosf],
        }
    }
}

impl Weights {
    /// The uncertainty-aware weighting the paper uses for a kind of data.
    pub fn uncertainty_for(kind: Kind) -> Weights {
        match kind {
            Kind::Brdf => Weights::Relunc,
            Kind::Btdf => Weights::Invunc,
        }
    }
}

impl fmt::Display for Loss {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.metric, self.weights)
    }
}

/// What turns a sum of a loss's terms into the loss: its term shape, its finish and the
/// number of samples it is finished over; a few bytes per problem, where the terms
/// themselves are five numbers per sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Finisher {
    pub term: Term,
    pub finish: Finish,
    pub count: usize,
}

impl Finisher {
    /// The loss from the sum of its terms: Σ/K, √(Σ/K) or Σ.
    pub fn finish_sum(&self, sum: f64) -> f64 {
        let k = self.count.max(1) as f64;
        match self.finish {
            Finish::Mean => sum / k,
            Finish::SqrtMean => (sum / k).max(0.0).sqrt(),
            Finish::Sum => sum,
        }
    }

    /// The sum of the terms from the loss (the inverse of [`Self::finish_sum`]).
    pub fn sum_of(&self, loss: f64) -> f64 {
        let k = self.count.max(1) as f64;
        match self.finish {
            Finish::Sum => loss,
            Finish::Mean => loss * k,
            Finish::SqrtMean => loss * loss * k,
        }
    }

    /// Whether the terms are squared residuals (Levenberg–Marquardt applies).
    pub fn is_sum_of_squares(&self) -> bool {
        self.term != Term::AbsRatio
    }
}

/// Per-sample constants of a loss on a dataset.
#[derive(Clone, Debug)]
pub struct LossTerms {
    pub term: Term,
    pub finish: Finish,
    /// Weight per sample (≥ 0).
    pub w: Vec<f64>,
    /// Inner factor per sample (1, or cos θt).
    pub a: Vec<f64>,
    /// Measured values.
    pub y: Vec<f64>,
    /// g(y_k), the transformed measurement ([`LossTerms::transform`]), computed once.
    pub gy: Vec<f64>,
    /// √w_k, the factor of the weighted residual, computed once.
    pub sqrt_w: Vec<f64>,
    /// K, the samples the loss is finished over (Σ/K, √(Σ/K)). Equal to the length of
    /// the vectors, except for an evaluator's row order with padding rows
    /// ([`LossTerms::in_rows`]), whose constants are all zero.
    pub count: usize,
}

impl Loss {
    pub fn new(metric: Metric, weights: Weights) -> Loss {
        Loss { metric, weights }
    }

    /// Does the loss reduce to a weighted sum of squares (usable by Levenberg–Marquardt)?
    pub fn is_sum_of_squares(&self) -> bool {
        self.metric.term() != Term::AbsRatio
    }

    /// How the loss's sums are finished on a dataset (without computing its terms).
    pub fn finisher(&self, data: &Dataset) -> Finisher {
        Finisher {
            term: self.metric.term(),
            finish: self.metric.finish(),
            count: data.len(),
        }
    }

    /// Precompute weights and factors for a dataset.
    pub fn terms(&self, data: &Dataset) -> LossTerms {
        let mut w = Vec::with_capacity(data.len());
        let mut a = Vec::with_capacity(data.len());
        for s in &data.samples {
            let y = s.value;
            let u = s.uncertainty;
            let unc_w = match self.weights {
                Weights::Uniform => 1.0,
                Weights::Relunc => 1.0 / (u.abs() / (y.abs() + EPS) + EPS),
                Weights::Invunc => 1.0 / u,
            };
            let (ci, si) = (s.theta_i.cos().max(0.0), s.theta_i.sin());
            let so = s.theta_o.sin();
            let ct = s.theta_o.cos().max(0.0);
            let (geo, inner) = match self.metric {
                Metric::Smape | Metric::F | Metric::Logf => (1.0, 1.0),
                Metric::Rmse => (ci * ci, 1.0),
                Metric::Ngan => (ci * ci * si * so, 1.0),
                Metric::Low => (ci * ci * si, 1.0),
                Metric::Cosf | Metric::Logcosf => (1.0, ct),
                Metric::Chi2 => (1.0 / (u * u), 1.0),
            };
            let uw = if self.metric == Metric::Chi2 {
                1.0
            } else {
                unc_w
            };
            w.push(uw * geo);
            a.push(inner);
        }
        LossTerms::new(
            self.metric.term(),
            self.metric.finish(),
            w,
            a,
            data.samples.iter().map(|s| s.value).collect(),
        )
    }
}

impl LossTerms {
    /// The terms of weights `w`, inner factors `a` and measurements `y` (one per sample),
    /// with g(y) and √w precomputed.
    pub fn new(term: Term, finish: Finish, w: Vec<f64>, a: Vec<f64>, y: Vec<f64>) -> LossTerms {
        let gy = y
            .iter()
            .zip(&a)
            .map(|(&y, &a)| Self::g(term, a, y))
            .collect();
        let sqrt_w = w.iter().map(|w| w.sqrt()).collect();
        LossTerms {
            term,
            finish,
            count: y.len(),
            w,
            a,
            y,
            gy,
            sqrt_w,
        }
    }

    /// The same terms with the samples in the order `order` (sample `order[r]` becomes
    /// sample r): the CPU evaluator's direction order.
    pub fn reordered(&self, order: &[usize]) -> LossTerms {
        self.in_rows(order.iter().map(|&k| k as u32))
    }

    /// The terms in an evaluator's row order: row r holds sample `rows[r]`, or is padding
    /// where that is [`NO_SAMPLE`] (every constant 0, so that a padding row whose model
    /// value is 0 adds exactly 0 to every sum of terms, residuals and their products).
    /// The finish still counts the samples only.
    pub fn in_rows(&self, rows: impl Iterator<Item = u32>) -> LossTerms {
        let n = rows.size_hint().0;
        let mut out = LossTerms {
            term: self.term,
            finish: self.finish,
            w: Vec::with_capacity(n),
            a: Vec::with_capacity(n),
            y: Vec::with_capacity(n),
            gy: Vec::with_capacity(n),
            sqrt_w: Vec::with_capacity(n),
            count: self.count,
        };
        for k in rows {
            let k = k as usize;
            let pick = |v: &[f64]| v.get(k).copied().unwrap_or(0.0);
            out.w.push(pick(&self.w));
            out.a.push(pick(&self.a));
            out.y.push(pick(&self.y));
            out.gy.push(pick(&self.gy));
            out.sqrt_w.push(pick(&self.sqrt_w));
        }
        out
    }

    /// Rows held (samples, and padding rows where the order has them).
    pub fn rows(&self) -> usize {
        self.y.len()
    }

    #[inline]
    fn g(term: Term, a: f64, v: f64) -> f64 {
        match term {
            Term::LogSquare => (a * v).ln_1p(),
            _ => a * v,
        }
    }

    /// g(v) of the term shape, for sample k.
    #[inline]
    pub fn transform(&self, k: usize, v: f64) -> f64 {
        Self::g(self.term, self.a[k], v)
    }

    /// The per-sample term for model value `yp` at sample k.
    #[inline]
    pub fn term_at(&self, k: usize, yp: f64) -> f64 {
        match self.term {
            Term::AbsRatio => {
                let y = self.y[k];
                self.w[k] * (yp - y).abs() / (yp.abs() + y.abs() + EPS)
            }
            Term::Square | Term::LogSquare => {
                let d = self.transform(k, yp) - self.gy[k];
                self.w[k] * d * d
            }
        }
    }

    /// Weighted residual r_k with Σ r_k² = the sum the loss finishes (sum-of-squares losses).
    #[inline]
    pub fn residual(&self, k: usize, yp: f64) -> f64 {
        self.sqrt_w[k] * (self.transform(k, yp) - self.gy[k])
    }

    /// [`Self::residual`] of a whole row of model values (samples 0..K), into `out`: the
    /// term's shape is matched once, not per value, so the square terms vectorise.
    /// The values may be f32 (a device's, read back): each is widened to f64 here.
    pub fn residuals_into<V: Copy + Into<f64>>(&self, values: &[V], out: &mut Vec<f64>) {
        let rows = values.iter().zip(&self.a).zip(&self.gy).zip(&self.sqrt_w);
        match self.term {
            Term::LogSquare => {
                out.extend(rows.map(|(((&v, &a), &gy), &sw)| sw * ((a * v.into()).ln_1p() - gy)))
            }
            _ => out.extend(rows.map(|(((&v, &a), &gy), &sw)| sw * (a * v.into() - gy))),
        }
    }

    pub fn finish_sum(&self, sum: f64) -> f64 {
        self.finisher().finish_sum(sum)
    }

    /// How the sums of these terms become the loss.
    pub fn finisher(&self) -> Finisher {
        Finisher {
            term: self.term,
            finish: self.finish,
            count: self.count,
        }
    }

    /// Σr² of the model values `values` (samples 0..K) after the best common rescaling
    /// s·values with s ∈ [1/max_scale, max_scale], or unscaled where that is lower: how
    /// well the values' *shape* matches the data. s minimises the linear residual
    /// √w·a·(s·y′ − y) in closed form; the logarithmic terms use the same s. NaN if Σr²
    /// of the unscaled values is NaN.
    ///
    /// Why: it ranks the random points that become LM's starts. A level that is off is
    /// what LM corrects most easily (albedos, k_s, S, τ), a shape that is off is not; and
    /// where much of the box gives a model ≈ 0 (a strong absorption, a needle-sharp NDF),
    /// raw Σr² prefers those dead points to any that overshoots, while their Jacobian
    /// vanishes (in f32 it is exactly 0) and LM cannot leave them.
    pub fn rescaled_sum_squares(&self, values: &[f64], max_scale: f64) -> f64 {
        let (mut fy, mut ff) = (0.0, 0.0);
        for (k, &f) in values.iter().enumerate() {
            let c2 = self.w[k] * self.a[k] * self.a[k];
            fy += c2 * f * self.y[k];
            ff += c2 * f * f;
        }
        let sum_squares = |s: f64| -> f64 {
            values
                .iter()
                .enumerate()
                .map(|(k, &f)| self.residual(k, s * f).powi(2))
                .sum()
        };
        let unscaled = sum_squares(1.0);
        if !(ff > 0.0 && fy > 0.0) || unscaled.is_nan() {
            return unscaled;
        }
        let s = (fy / ff).clamp(1.0 / max_scale, max_scale);
        unscaled.min(sum_squares(s))
    }

    /// The loss of a whole vector of model values.
    pub fn loss(&self, values: &[f64]) -> f64 {
        let s: f64 = values
            .iter()
            .enumerate()
            .map(|(k, &v)| self.term_at(k, v))
            .sum();
        self.finish_sum(s)
    }
}

/// χ² = Σ ((y′ − y)/u)².
pub fn chi2(data: &Dataset, values: &[f64]) -> f64 {
    data.samples
        .iter()
        .zip(values)
        .map(|(s, &v)| {
            let z = (v - s.value) / s.uncertainty;
            z * z
        })
        .sum()
}

/// Normalised residuals z = (y′ − y)/u.
pub fn normalised_residuals(data: &Dataset, values: &[f64]) -> Vec<f64> {
    data.samples
        .iter()
        .zip(values)
        .map(|(s, &v)| (v - s.value) / s.uncertainty)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn terms(term: Term) -> LossTerms {
        LossTerms::new(
            term,
            Finish::Sum,
            vec![1.0, 2.0, 0.5, 1.0],
            vec![1.0, 0.9, 0.7, 0.5],
            vec![0.2, 0.5, 1.0, 0.4],
        )
    }

    fn raw(t: &LossTerms, values: &[f64]) -> f64 {
        values
            .iter()
            .enumerate()
            .map(|(k, &v)| t.residual(k, v).powi(2))
            .sum()
    }

    /// Five samples at assorted angles (degrees: θi, θo), values and uncertainties.
    fn five(kind: Kind) -> Dataset {
        use crate::data::{RawRow, ReadOptions};
        let rows: Vec<(usize, RawRow)> = [
            (10.0, 20.0, 0.8, 0.05),
            (35.0, 5.0, 0.3, 0.02),
            (60.0, 45.0, 1.7, 0.3),
            (0.0, 70.0, 0.05, 0.01),
            (75.0, 30.0, 2.5, 0.4),
        ]
        .iter()
        .enumerate()
        .map(|(i, &(ti, to, value, uncertainty))| {
            let row = RawRow {
                theta_i: ti,
                phi_i: 0.0,
                theta_o: to,
                phi_o: 90.0,
                wavelength_nm: 550.0,
                value,
                uncertainty,
            };
            (i + 1, row)
        })
        .collect();
        Dataset::from_rows(kind, "five", &rows, "five.csv", &ReadOptions::default()).unwrap()
    }

    /// Model values beside the five samples' (one of them 0).
    const MODEL: [f64; 5] = [0.9, 0.25, 2.0, 0.0, 2.2];

    /// Every loss of docs/losses.md written out from its definition, for every weighting:
    /// SMAPE, RMSE, Ngan and Löw (BRDF: means over K, angular factors inside the sum),
    /// the BTDF sums of g(f) = f, cosθt·f, ln(1 + f), ln(1 + cosθt·f), and χ² (which
    /// ignores the weighting). The loss, its terms summed and finished, and its residuals'
    /// squares summed must all give it.
    #[test]
    fn every_loss_is_its_definition() {
        const E: f64 = 1e-6;
        let k = MODEL.len() as f64;
        for kind in [Kind::Brdf, Kind::Btdf] {
            let data = five(kind);
            let metrics = [Metric::for_kind(kind), &[Metric::Chi2]].concat();
            for metric in metrics {
                for weights in [Weights::Uniform, Weights::Relunc, Weights::Invunc] {
                    let mut sum = 0.0;
                    for (s, &yp) in data.samples.iter().zip(&MODEL) {
                        let (y, u) = (s.value, s.uncertainty);
                        let w = match weights {
                            Weights::Uniform => 1.0,
                            Weights::Relunc => 1.0 / (u.abs() / (y.abs() + E) + E),
                            Weights::Invunc => 1.0 / u,
                        };
                        let (ci, si, so) = (s.theta_i.cos(), s.theta_i.sin(), s.theta_o.sin());
                        let ct = s.theta_o.cos();
                        sum += match metric {
                            Metric::Smape => w * (yp - y).abs() / (yp.abs() + y.abs() + E),
                            Metric::Rmse => w * (yp - y).powi(2) * ci * ci,
                            Metric::Ngan => w * (yp - y).powi(2) * ci * ci * si * so,
                            Metric::Low => w * (yp - y).powi(2) * ci * ci * si,
                            Metric::F => w * (yp - y).powi(2),
                            Metric::Cosf => w * (ct * yp - ct * y).powi(2),
                            Metric::Logf => w * ((1.0 + yp).ln() - (1.0 + y).ln()).powi(2),
                            Metric::Logcosf => {
                                w * ((1.0 + ct * yp).ln() - (1.0 + ct * y).ln()).powi(2)
                            }
                            Metric::Chi2 => ((yp - y) / u).powi(2),
                        };
                    }
                    let want = match metric {
                        Metric::Smape | Metric::Ngan | Metric::Low => sum / k,
                        Metric::Rmse => (sum / k).sqrt(),
                        _ => sum,
                    };
                    let loss = Loss::new(metric, weights);
                    let t = loss.terms(&data);
                    let close = |got: f64| (got - want).abs() <= 1e-12 * want.abs();
                    let what = format!("{kind:?} {loss}");
                    assert!(want > 0.0, "{what}");
                    assert!(
                        close(t.loss(&MODEL)),
                        "{what}: {} vs {want}",
                        t.loss(&MODEL)
                    );
                    let terms: f64 = (0..5).map(|i| t.term_at(i, MODEL[i])).sum();
                    assert!(close(t.finish_sum(terms)), "{what}");
                    assert!(close(loss.finisher(&data).finish_sum(terms)), "{what}");
                    assert!(
                        (t.finisher().sum_of(want) - terms).abs() <= 1e-12 * terms,
                        "{what}"
                    );
                    if loss.is_sum_of_squares() {
                        let r2: f64 = (0..5).map(|i| t.residual(i, MODEL[i]).powi(2)).sum();
                        assert!(close(t.finish_sum(r2)), "{what}");
                        let mut rows = Vec::new();
                        t.residuals_into(&MODEL, &mut rows);
                        let r2: f64 = rows.iter().map(|r| r * r).sum();
                        assert!(close(t.finish_sum(r2)), "{what}");
                    } else {
                        assert_eq!(metric, Metric::Smape);
                    }
                    if metric == Metric::Chi2 {
                        assert!(close(chi2(&data, &MODEL)), "{what}");
                        let z = normalised_residuals(&data, &MODEL);
                        assert!(close(z.iter().map(|z| z * z).sum()), "{what}");
                        for ((z, s), yp) in z.iter().zip(&data.samples).zip(MODEL) {
                            assert_eq!(*z, (yp - s.value) / s.uncertainty);
                        }
                    }
                }
            }
        }
    }

    /// Each metric applies to the kind of data it was defined for; LM applies to all but
    /// SMAPE; a loss's name reads back as itself.
    #[test]
    fn metrics_kinds_and_names() {
        for kind in [Kind::Brdf, Kind::Btdf] {
            for &m in Metric::for_kind(kind) {
                assert!(m.applies_to(kind) && Metric::Chi2.applies_to(kind), "{m}");
                let other = if kind == Kind::Brdf {
                    Kind::Btdf
                } else {
                    Kind::Brdf
                };
                assert!(!m.applies_to(other), "{m}");
                assert_eq!(m.to_string().parse::<Metric>(), Ok(m));
                let loss = Loss::new(m, Weights::uncertainty_for(kind));
                assert_eq!(loss.is_sum_of_squares(), m != Metric::Smape);
                assert_eq!(
                    loss.finisher(&five(kind)).is_sum_of_squares(),
                    m != Metric::Smape
                );
            }
        }
        assert_eq!(Weights::uncertainty_for(Kind::Brdf), Weights::Relunc);
        assert_eq!(Weights::uncertainty_for(Kind::Btdf), Weights::Invunc);
        for w in [Weights::Uniform, Weights::Relunc, Weights::Invunc] {
            assert_eq!(w.to_string().parse::<Weights>(), Ok(w));
        }
        assert!("nope".parse::<Metric>().is_err() && "nope".parse::<Weights>().is_err());
        assert_eq!(
            Loss::new(Metric::Ngan, Weights::Relunc).to_string(),
            "ngan/relunc"
        );
        // The paper's metrics per kind, in its order.
        use Metric::*;
        assert_eq!(Metric::for_kind(Kind::Brdf), [Smape, Rmse, Ngan, Low]);
        assert_eq!(Metric::for_kind(Kind::Btdf), [F, Cosf, Logf, Logcosf]);
    }

    /// An evaluator's row order: each row the constants of its sample, padding rows all
    /// 0 (so a padding row adds 0 to every sum), the finish still over the K samples.
    #[test]
    fn rows_in_an_evaluators_order_carry_their_samples_and_pad_with_zeros() {
        let t = Loss::new(Metric::Logcosf, Weights::Invunc).terms(&five(Kind::Btdf));
        let order = [3u32, NO_SAMPLE, 0, 4, 1, 2, NO_SAMPLE];
        let r = t.in_rows(order.iter().copied());
        assert_eq!((r.rows(), r.count, t.rows(), t.count), (7, 5, 5, 5));
        for (row, &k) in order.iter().enumerate() {
            let got = [r.w[row], r.a[row], r.y[row], r.gy[row], r.sqrt_w[row]];
            if k == NO_SAMPLE {
                assert_eq!(got, [0.0; 5]);
                assert_eq!(r.residual(row, 0.0), 0.0);
            } else {
                let k = k as usize;
                assert_eq!(got, [t.w[k], t.a[k], t.y[k], t.gy[k], t.sqrt_w[k]]);
                assert_eq!(r.residual(row, 0.7), t.residual(k, 0.7));
            }
        }
        let back = t.reordered(&[4, 3, 2, 1, 0]);
        assert_eq!(back.y, [t.y[4], t.y[3], t.y[2], t.y[1], t.y[0]]);
        assert_eq!(back.gy, [t.gy[4], t.gy[3], t.gy[2], t.gy[1], t.gy[0]]);
        assert_eq!(r.finish_sum(10.0), t.finish_sum(10.0));
    }

    #[test]
    fn a_rescaled_shape_outranks_a_dead_model_that_raw_sum_squares_prefers() {
        for term in [Term::Square, Term::LogSquare] {
            let t = terms(term);
            let dead = [0.0; 4];
            // The data's shape at 4× its level: raw Σr² ranks it below the dead model.
            let loud: Vec<f64> = t.y.iter().map(|y| 4.0 * y).collect();
            assert!(raw(&t, &loud) > raw(&t, &dead), "{term:?}");
            let (r_loud, r_dead) = (
                t.rescaled_sum_squares(&loud, 100.0),
                t.rescaled_sum_squares(&dead, 100.0),
            );
            assert!(r_loud < 1e-3 * r_dead, "{term:?}: {r_loud} vs {r_dead}");
            assert_eq!(r_dead, raw(&t, &dead));
            // A level beyond the allowed rescaling is only partly forgiven.
            let far: Vec<f64> = t.y.iter().map(|y| 1e4 * y).collect();
            let r_far = t.rescaled_sum_squares(&far, 100.0);
            assert!(r_far > 1e3 * r_loud && r_far < raw(&t, &far), "{term:?}");
        }
    }

    /// s = Σ w a² f y / Σ w a² f² (the least-squares level of the linear residual),
    /// held in [1/max, max], applied to the values before the terms; the lower of the
    /// rescaled and the raw Σr². Values whose level cannot be fitted (Σ w a² f y ≤ 0) are
    /// judged raw.
    #[test]
    fn the_rescaling_is_the_least_squares_level() {
        let values = [0.3, 0.1, 2.0, 0.2];
        for term in [Term::Square, Term::LogSquare] {
            let t = terms(term);
            let (w, a, y) = (
                [1.0, 2.0, 0.5, 1.0],
                [1.0, 0.9, 0.7, 0.5],
                [0.2, 0.5, 1.0, 0.4],
            );
            let g = |k: usize, v: f64| match term {
                Term::LogSquare => (1.0 + a[k] * v).ln(),
                _ => a[k] * v,
            };
            let ss = |s: f64| -> f64 {
                (0..4)
                    .map(|k| w[k] * (g(k, s * values[k]) - g(k, y[k])).powi(2))
                    .sum()
            };
            let fy: f64 = (0..4).map(|k| w[k] * a[k] * a[k] * values[k] * y[k]).sum();
            let ff: f64 = (0..4)
                .map(|k| w[k] * a[k] * a[k] * values[k] * values[k])
                .sum();
            let s = fy / ff;
            assert!(s > 0.2 && s < 0.9, "{s}");
            let got = t.rescaled_sum_squares(&values, 100.0);
            assert!((got - ss(s).min(ss(1.0))).abs() < 1e-12, "{term:?}: {got}");
            if term == Term::Square {
                // The linear residual's own optimum: well below the raw Σr².
                assert!(got < 0.9 * ss(1.0), "{term:?}");
            }
            // Held at 1/max_scale = 1/1.25 = 0.8 where s is below it.
            let got = t.rescaled_sum_squares(&values, 1.25);
            assert!(
                (got - ss(0.8).min(ss(1.0))).abs() < 1e-12,
                "{term:?}: {got}"
            );
            if term == Term::Square {
                assert!(got < ss(1.0) && got > ss(s), "{term:?}");
            }
            // Held at max_scale where s is above it.
            let small: Vec<f64> = values.iter().map(|v| v / 10.0).collect();
            let raw = |v: &[f64]| -> f64 { (0..4).map(|k| t.residual(k, v[k]).powi(2)).sum() };
            let got = t.rescaled_sum_squares(&small, 2.0);
            let twice: Vec<f64> = small.iter().map(|v| 2.0 * v).collect();
            assert!(
                (got - raw(&twice).min(raw(&small))).abs() < 1e-12,
                "{term:?}"
            );
            assert!(got < raw(&small), "{term:?}");
        }
        // Values only where the data are 0 (Σ w a² f y = 0): judged raw, not scaled
        // down towards the zeros.
        let zeros = LossTerms::new(
            Term::Square,
            Finish::Sum,
            vec![1.0; 2],
            vec![1.0; 2],
            vec![0.0, 0.5],
        );
        assert_eq!(zeros.rescaled_sum_squares(&[1.0, 0.0], 100.0), 1.25);
        // Values against the data's sign (Σ w a² f y < 0): no level is fitted.
        let t = terms(Term::Square);
        let against = [-0.3, -0.1, -2.0, -0.2];
        let raw: f64 = (0..4).map(|k| t.residual(k, against[k]).powi(2)).sum();
        assert_eq!(t.rescaled_sum_squares(&against, 100.0), raw);
    }

    #[test]
    fn rescaling_never_ranks_worse_than_raw_and_keeps_nan() {
        let t = terms(Term::Square);
        for values in [
            [0.3, 0.1, 2.0, 0.0],
            [0.2, 0.5, 1.0, 0.4],
            [-1.0, 0.2, 0.1, 0.3],
        ] {
            let r = t.rescaled_sum_squares(&values, 100.0);
            assert!(r.is_finite() && r <= raw(&t, &values) + 1e-15, "{values:?}");
        }
        let r = t.rescaled_sum_squares(&[0.3, f64::NAN, 2.0, 0.1], 100.0);
        assert!(r.is_nan());
    }
}
