//! Recovery of the data-driven NDF (`+ndf`, docs/models.md): data synthesised here from
//! isotropic lobes whose distributions lie outside the analytic families (Beckmann, GTR
//! with γ = 1.5, a two-scale mixture; each with its own Smith Λ integrated from D, in
//! `common/truths.rs`) over a Fresnel-transmitted Lambertian body, measured with 1 % noise
//! at one incidence azimuth, come back: the best GGX aggregate misfits, the data-driven
//! one reaches χ²_red within the noise, and at every knot where the data see the lobe the
//! fitted D agrees with the truth's within 3 propagated standard uncertainties.

mod common;

use bsdfit::bsdf::Model;
use bsdfit::data::Dataset;
use bsdfit::inference::fit::smoothness::GRID;
use bsdfit::inference::fit::Conclusions;
use bsdfit::inference::knots::{bands, MEASURED_SIGNAL};
use bsdfit::workflows::diagnose::embed;
use common::truths::{beckmann, chi2_red, fit_truth, gtr, measure, Isotropic, Ndf};

fn fit(model: &Model, data: &Dataset, start: Option<Vec<f64>>) -> Conclusions {
    let restarts = if start.is_some() { 2 } else { 8 };
    fit_truth(model, data, start, restarts, 3)
}

#[test]
fn data_driven_ndfs_of_truths_outside_the_catalogue_come_back() {
    let truths: [(&str, Ndf); 3] = [
        ("beckmann", |c| beckmann(c, 0.2)),
        ("gtr γ=1.5", |c| gtr(c, 0.15, 1.5)),
        ("two-scale", |c| {
            0.6 * beckmann(c, 0.08) + 0.4 * beckmann(c, 0.35)
        }),
    ];
    let ggx = Model::parse("fa(lambert)", 1).unwrap();
    let ndf = Model::parse("fa(lambert)+ndf", 1).unwrap();
    let mut chosen = Vec::new();
    for (k, (name, d)) in truths.into_iter().enumerate() {
        let lobe = Isotropic::new(d);
        let data = measure(&[0.0], &|wi, wo| lobe.aggregate(wi, wo), 40 + k as u64);
        let analytic = fit(&ggx, &data, None);
        // From the GGX optimum, as diagnose starts an extension (the knots at 0 are it).
        let driven = fit(&ndf, &data, Some(embed(&ggx, &analytic.flat, &ndf)));
        let (before, after) = (chi2_red(&analytic), chi2_red(&driven));
        // χ²_red of a fit within the noise: 1 ± √(2/ν); 4 of those allowed.
        let noise = 4.0 * (2.0 / driven.dof as f64).sqrt();
        eprintln!("{name}: χ²_red fa(lambert) {before:.3}, fa(lambert)+ndf {after:.3}");
        assert!(
            before > 3.0,
            "{name}: GGX fits a truth outside its family (χ²_red {before})"
        );
        assert!(
            (after - 1.0).abs() < noise,
            "{name}: χ²_red {after} beyond the noise ±{noise:.3}"
        );

        // The weight of the smoothness prior was chosen from the data: every σ_s of the
        // grid tried, the smallest AIC kept.
        let choice = driven
            .smoothness
            .as_ref()
            .expect("the smoothness is chosen");
        assert_eq!(choice.tried.len(), GRID.len());
        let least = choice
            .tried
            .iter()
            .map(|t| t.aic)
            .fold(f64::INFINITY, f64::min);
        assert_eq!(choice.chosen.aic, least, "{name}");
        chosen.push(choice.chosen.sd);

        let all = bands(&ndf, &data, &driven.flat, &driven.cov);
        assert_eq!(all.len(), 1);
        assert_eq!(all[0].0, "lobe.ndf");
        let mut measured = 0;
        for knot in &all[0].1 {
            let truth = d(knot.theta_deg.to_radians().cos());
            let sigma = knot.sigma_ln_d.expect("a band with the prior on");
            let diff = (knot.d / truth).ln();
            eprintln!(
                "  {:>5.2}°: D {:.4e} (truth {truth:.4e}) ln ratio {diff:+.4} σ {sigma:.4} signal {:.1}",
                knot.theta_deg, knot.d, knot.signal
            );
            assert!(knot.d.is_finite() && knot.d >= 0.0 && sigma.is_finite());
            assert_eq!(knot.measured, knot.signal >= MEASURED_SIGNAL);
            if knot.measured {
                measured += 1;
                assert!(
                    diff.abs() <= 3.0 * sigma,
                    "{name} at {:.2}°: ln D {:+.4} from the truth, σ {sigma:.4}",
                    knot.theta_deg,
                    diff
                );
            }
        }
        // The lobe is seen from near the normal into its tail.
        assert!(measured >= 9, "{name}: {measured} knots measured");
    }
    // Different truths, different weights: the prior's weight follows the data.
    assert!(chosen.iter().any(|&s| s != chosen[0]), "σ_s {chosen:?}");
}
