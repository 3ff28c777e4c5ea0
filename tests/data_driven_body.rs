//! Recovery of the data-driven body profile (`+body`, docs/models.md): data synthesised
//! here from a GGX highlight over a body that is not Lambertian, seen through a
//! dielectric interface, at one incidence azimuth with 1 % noise. Two bodies, each
//! separable in θi and θo as `+body` assumes but of no analytic base's shape: a Minnaert
//! body (planetary photometry's limb darkening, f ∝ (μi μo)^(k−1)) and one that
//! brightens toward grazing (a sheen, ρ(θ) = 1 + b (1 − μ)³). The aggregate with a
//! Lambertian base misfits; with the profile it reaches χ²_red within the noise, and at
//! every knot where the data see the body the fitted ρ(θ) agrees with the truth's within
//! 3 propagated standard uncertainties (plus what the spline on 9 knots cannot follow).

mod common;

use bsdfit::bsdf::fresnel::{knot_coordinate, log_factor, KNOTS};
use bsdfit::bsdf::Model;
use bsdfit::inference::knots::{body_bands, is_measured};
use bsdfit::workflows::diagnose::embed;
use common::truths::{chi2_red, diagnose_truth, fit_truth, fresnel, ggx, measure, Isotropic, RHO};
use std::f64::consts::PI;

/// ln ρ(μ) of the two bodies, 0 at the normal: Minnaert's (μi μo)^(k−1) with k = 1.3,
/// its limb held finite by a floor (μ + 0.1: a real body's value at grazing is not 0).
fn minnaert(mu: f64) -> f64 {
    0.3 * ((mu + 0.1) / 1.1).ln()
}
fn sheen(mu: f64) -> f64 {
    (1.0 + 0.8 * (1.0 - mu).powi(3)).ln()
}

/// The truth: the highlight over the body ρ(θi) ρ(θo) RHO/π seen through the interface.
fn truth(lobe: &Isotropic, ln_rho: fn(f64) -> f64, wi: glam::DVec3, wo: glam::DVec3) -> f64 {
    lobe.specular(wi, wo)
        + (1.0 - fresnel(wi.z)) * (1.0 - fresnel(wo.z)) * RHO / PI
            * (ln_rho(wi.z) + ln_rho(wo.z)).exp()
}

#[test]
fn non_lambertian_bodies_come_back() {
    let lobe = Isotropic::new(|c| ggx(c, 0.2));
    for (name, ln_rho, seed) in [
        ("minnaert", minnaert as fn(f64) -> f64, 11),
        ("sheen", sheen, 12),
    ] {
        let truth = |wi, wo| truth(&lobe, ln_rho, wi, wo);
        let data = measure(&[0.0], &truth, seed);
        let analytic_model = Model::for_data("fa(lambert)", &data).unwrap();
        let driven_model = Model::for_data("fa(lambert)+body", &data).unwrap();
        let analytic = fit_truth(&analytic_model, &data, None, 8, 5);
        let driven = fit_truth(
            &driven_model,
            &data,
            Some(embed(&analytic_model, &analytic.flat, &driven_model)),
            8,
            5,
        );
        let (before, after) = (chi2_red(&analytic), chi2_red(&driven));
        let noise = 4.0 * (2.0 / driven.dof as f64).sqrt();
        eprintln!(
            "{name}: χ²_red fa(lambert) {before:.3}, fa(lambert)+body {after:.3} (±{noise:.3})"
        );
        assert!(
            before > 3.0,
            "{name}: a Lambertian base fits (χ²_red {before})"
        );
        assert!(
            (after - 1.0).abs() < noise,
            "{name}: χ²_red {after} beyond the noise ±{noise:.3}"
        );
        assert!(driven.smoothness.is_some(), "the prior's weight is chosen");

        let all = body_bands(&driven_model, &data, &driven.flat, &driven.cov);
        assert_eq!(all.len(), 1, "one profile");
        let (stem, knots) = &all[0];
        assert_eq!(stem, "base.body");
        // What the spline through the truth's own knots misses between them, where the
        // data are (θ ≤ 80°).
        let exact: [f64; KNOTS] =
            std::array::from_fn(|j| ln_rho(1.0 - j as f64 / (KNOTS - 1) as f64));
        let resolution = (0..=800)
            .map(|i| (i as f64 / 10.0).to_radians().cos())
            .map(|c| (log_factor(&exact, knot_coordinate(c)) - ln_rho(c)).abs())
            .fold(0.0, f64::max);
        eprintln!("  the spline's resolution of the truth {resolution:.4} in ln");
        let mut measured = 0;
        for knot in knots {
            let want = ln_rho(knot.theta_deg.to_radians().cos());
            let sigma = knot.sigma_ln_rho.expect("a band with the prior on");
            let diff = knot.rho.ln() - want;
            eprintln!(
                "  {:>5.1}°: ρ {:.4} (truth {:.4}) ln ratio {diff:+.4} σ {sigma:.4} signal {:.1}",
                knot.theta_deg,
                knot.rho,
                want.exp(),
                knot.signal
            );
            assert!(knot.rho.is_finite() && knot.rho > 0.0 && sigma.is_finite());
            assert_eq!(knot.measured, is_measured(knot.signal, knot.data_share));
            if knot.measured && knot.theta_deg > 0.0 {
                measured += 1;
                assert!(
                    diff.abs() <= 3.0 * sigma + resolution,
                    "{name} at {:.1}°: ln ρ {diff:+.4} from the truth's, σ {sigma:.4}, resolution {resolution:.4}",
                    knot.theta_deg
                );
            }
        }
        // θi reach 70° and θo 80°: the knots to 75.5° are seen.
        assert!(measured >= 6, "{name}: {measured} knots measured");
    }
}

/// The workflow names it: diagnose from `lambert` on data of a highlight over each body
/// adds the specular lobe and, once no analytic effect is significant, the body's
/// profile, and ends within the noise. The analytic effects adopted before it that only
/// stood in for the profile (a retro lobe and its falloff for the darkening body,
/// micrograins for the brightening one) are dropped by the backward elimination.
#[test]
fn diagnose_names_the_bodys_profile() {
    use bsdfit::workflows::diagnose::Effect;
    let lobe = Isotropic::new(|c| ggx(c, 0.2));
    for (name, ln_rho, seed) in [
        ("minnaert", minnaert as fn(f64) -> f64, 13),
        ("sheen", sheen, 14),
    ] {
        let truth = |wi, wo| truth(&lobe, ln_rho, wi, wo);
        let data = measure(&[0.0], &truth, seed);
        let d = diagnose_truth(name, &data, "lambert");
        assert!(
            d.effects.contains(&Effect::SpecularLobe),
            "{name}: {:?}",
            d.effects
        );
        assert!(
            d.effects.contains(&Effect::BodyProfile),
            "{name}: {:?}",
            d.effects
        );
        for false_effect in [
            Effect::RetroLobe,
            Effect::RetroFalloff,
            Effect::GrazingDecay,
            Effect::Anisotropy,
        ] {
            assert!(
                !d.effects.contains(&false_effect),
                "{name}: {:?}",
                d.effects
            );
        }
        if name == "minnaert" {
            assert_eq!(d.final_model, "fa(lambert)+body", "{name}");
        }
        report_pictures_the_profile(&data, &d);
        // Within the noise: 1 ± 4√(2/ν), ν ≈ the samples.
        let chi2_red = d.steps.last().unwrap().chi2_red;
        let noise = 4.0 * (2.0 / data.len() as f64).sqrt();
        assert!(
            (chi2_red - 1.0).abs() < noise,
            "{name}: final χ²_red {chi2_red}"
        );
    }
}

/// The diagnosis's report pictures the tabulated factors of each step that has any
/// (`factors_<step>.svg`, with the smoothness prior's weight stated beside it) and of no
/// other step; at a step with `+body` the body's panel holds the knots the data see, their
/// band, and the analytic reference ρ ≡ 1 of the base. (A path may take `+fresnel` before
/// `+body`: that step's picture shows the Fresnel curve.)
fn report_pictures_the_profile(
    data: &bsdfit::data::Dataset,
    d: &bsdfit::workflows::diagnose::Diagnosis,
) {
    use bsdfit::workflows::diagnose::{factor_panels, write_report};
    let dir = tempfile::tempdir().unwrap();
    write_report(dir.path(), data, d).unwrap();
    let html = std::fs::read_to_string(dir.path().join("index.html")).unwrap();
    for (i, s) in d.steps.iter().enumerate() {
        let picture = dir.path().join(format!("factors_{i}.svg"));
        let has_factors = ["+body", "+fresnel", "+ndf"]
            .iter()
            .any(|f| s.model.contains(f));
        assert_eq!(picture.exists(), has_factors, "step {i}: {}", s.model);
        if !has_factors {
            continue;
        }
        assert!(html.contains(&format!("factors_{i}.svg")));
        assert!(html.contains("σ_s = "), "the prior's weight is stated");
        if !s.model.contains("+body") {
            continue;
        }
        let svg = std::fs::read_to_string(&picture).unwrap();
        assert!(svg.contains("profile"), "step {i}: the panel's title");
        let panels = factor_panels(data, &s.fit, None);
        let bodies: Vec<_> = panels
            .iter()
            .filter(|p| p.title.ends_with("the body's profile"))
            .collect();
        assert_eq!(bodies.len(), 1, "one body, one panel, in {}", s.model);
        let series = &bodies[0].series;
        let measured = &series[0].points;
        assert!(measured.len() >= 6, "{} knots measured", measured.len());
        // The +2σ band over the measured knots, above them.
        let upper = &series[2].curve;
        assert_eq!(
            upper.len(),
            measured.len(),
            "a band over the measured knots"
        );
        assert!(upper
            .iter()
            .zip(measured)
            .all(|(b, m)| b.1 >= m.1 && b.1.is_finite()));
        let reference = &series.last().unwrap().curve;
        assert!(!reference.is_empty() && reference.iter().all(|p| p.1 == 1.0));
    }
}
