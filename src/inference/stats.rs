//! Statistics that judge least-squares fits of K samples with P parameters by
//! χ² = Σ ((y′ − y)/u)²: consistency with the uncertainties, the F test of nested models
//! and the Bayesian information criterion (the distributions are in
//! [`crate::math::special`]).

use crate::math::{chi2_sf, f_sf};

/// P(χ²_ν ≥ χ²) with ν = K − P: the probability of a misfit at least this large if the
/// model were right and the uncertainties Gaussian.
pub fn consistency_p(chi2: f64, dof: usize) -> f64 {
    chi2_sf(chi2, dof as f64)
}

/// The F test of a nested extension: F = (Δχ²/ΔP) / (χ²₁/ν₁) with Δχ² = χ²₀ − χ²₁ (a
/// negative Δχ² counts as 0) and ν₁ = K − P₁ the extension's degrees of freedom, against
/// F(ΔP, ν₁). Returns (F, p).
pub fn f_test(delta_chi2: f64, extra_params: usize, chi2_ext: f64, dof_ext: usize) -> (f64, f64) {
    let f = (delta_chi2.max(0.0) / extra_params as f64) / (chi2_ext / dof_ext as f64);
    (f, f_sf(f, extra_params as f64, dof_ext as f64))
}

/// BIC = χ² + P ln K (χ² in place of −2 ln L).
pub fn bic(chi2: f64, params: usize, samples: usize) -> f64 {
    chi2 + params as f64 * (samples as f64).ln()
}

/// The Akaike information criterion of a fit with χ² `chi2` and `params` fitted
/// parameters: χ² + 2k (the Gaussian likelihood's, up to a constant).
pub fn aic(chi2: f64, params: usize) -> f64 {
    chi2 + 2.0 * params as f64
}

/// BIC(extension) − BIC(current) on the same K samples, both χ² divided by `scale`
/// (1: as is; max(1, χ²_red) of the extension: a misfit both models share does not
/// inflate the difference).
pub fn delta_bic(
    chi2_current: f64,
    chi2_ext: f64,
    extra_params: i64,
    samples: usize,
    scale: f64,
) -> f64 {
    (chi2_ext - chi2_current) / scale + extra_params as f64 * (samples as f64).ln()
}

/// A p-value for prose: `p < 1e-300`, `p = 1.3e-9`, `p = 0.043`.
pub fn format_p(p: f64) -> String {
    if p < 1e-300 {
        "p < 1e-300".into()
    } else if p < 1e-3 {
        format!("p = {p:.1e}")
    } else {
        format!("p = {p:.3}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn criteria_and_tests() {
        // BIC differences: unscaled it is the plain difference of the two BICs.
        let (k, c0, c1) = (200, 450.0, 310.0);
        let d = delta_bic(c0, c1, 3, k, 1.0);
        assert!((d - (bic(c1, 5, k) - bic(c0, 2, k))).abs() < 1e-9, "{d}");
        assert_eq!(delta_bic(c0, c1, 3, k, 2.0), -70.0 + 3.0 * 200f64.ln());
        // F test: F = (140/3)/(310/195); p from the F(3, 195) tail.
        let (f, p) = f_test(c0 - c1, 3, c1, 195);
        assert!((f - (140.0 / 3.0) / (310.0 / 195.0)).abs() < 1e-12);
        assert_eq!(p, f_sf(f, 3.0, 195.0));
        // A worse extension counts as no improvement.
        assert_eq!(f_test(-5.0, 2, 100.0, 90), (0.0, 1.0));
        assert_eq!(
            consistency_p(3.841458820694124, 1),
            chi2_sf(3.841458820694124, 1.0)
        );
        assert_eq!(format_p(0.0), "p < 1e-300");
        assert_eq!(format_p(1.26e-9), "p = 1.3e-9");
        assert_eq!(format_p(0.0431), "p = 0.043");
        // The thresholds are strict: 1e-300 and 1e-3 themselves are printed as numbers.
        assert_eq!(format_p(1e-300), "p = 1.0e-300");
        assert_eq!(format_p(1e-3), "p = 0.001");
        assert_eq!(format_p(9.9e-4), "p = 9.9e-4");
    }

    /// The tails against closed forms written here: P(χ²₂ ≥ x) = exp(−x/2),
    /// P(F(2, ν) ≥ f) = (1 + 2f/ν)^(−ν/2), and the tabulated 5 % points of χ²₁, χ²₁₀
    /// and F(2, 10).
    #[test]
    fn tails_against_closed_forms_and_tables() {
        assert!((consistency_p(4.0, 2) - (-2.0f64).exp()).abs() < 1e-12);
        assert!((consistency_p(3.841458820694124, 1) - 0.05).abs() < 1e-9);
        assert!((consistency_p(18.307038053275146, 10) - 0.05).abs() < 1e-9);
        // Δχ² = 6 for 2 more parameters, χ²₁ = 20 on ν₁ = 10: F = 3/2.
        let (f, p) = f_test(6.0, 2, 20.0, 10);
        assert!((f - 1.5).abs() < 1e-12, "{f}");
        assert!((p - 1.3f64.powf(-5.0)).abs() < 1e-10, "{p}");
        // F(2, 10)'s 5 % point, 4.102821015130399.
        let (_, p) = f_test(2.0 * 4.102821015130399, 2, 10.0, 10);
        assert!((p - 0.05).abs() < 1e-9, "{p}");
        assert_eq!(bic(10.0, 3, 100), 10.0 + 3.0 * 100f64.ln());
    }
}
