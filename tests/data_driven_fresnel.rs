//! Recovery of the data-driven Fresnel curve (`+fresnel`, docs/models.md): data
//! synthesised here from a GGX highlight whose Fresnel factor is a conductor's (gold's
//! complex index per channel, exact unpolarised formula in `common/truths.rs`), over a
//! Lambertian body seen through a dielectric interface, in three channels with 1 % noise
//! at one incidence azimuth. The dielectric aggregate misfits; the data-driven curve
//! reaches χ²_red within the noise, and at every knot where the data see the highlight the
//! fitted k_s F e^s agrees with gold's curve within 3 propagated standard uncertainties.

mod common;

use bsdfit::bsdf::fresnel::{knot_coordinate, log_factor, KNOTS};
use bsdfit::bsdf::Model;
use bsdfit::data::Dataset;
use bsdfit::inference::fit::Conclusions;
use bsdfit::inference::knots::{fresnel_bands, is_measured};
use bsdfit::math::fresnel_dielectric as dielectric;
use bsdfit::workflows::diagnose::embed;
use common::truths::{
    chi2_red, conductor_fresnel, diagnose_truth, fit_truth, fresnel, ggx, measure_channels,
    Isotropic, RHO,
};
use std::f64::consts::PI;

/// From the dielectric optimum (η at its bound, k_s at 1) the conductor's is far: the
/// start and 15 random restarts, as diagnose tries an extension.
fn fit(model: &Model, data: &Dataset, start: Option<Vec<f64>>) -> Conclusions {
    fit_truth(model, data, start, 16, 5)
}

/// Gold's complex index at 450, 550 and 650 nm (Johnson & Christy 1972, rounded): the
/// data's channels in their order (ascending wavelength).
const GOLD: [(f64, f64); 3] = [(1.47, 1.95), (0.43, 2.45), (0.17, 3.15)];
const WAVELENGTHS: [f64; 3] = [450.0, 550.0, 650.0];

/// The truth in channel `ch`: a GGX highlight with gold's Fresnel curve over a Lambertian
/// body seen through a dielectric interface.
fn gold(lobe: &Isotropic, ch: usize, wi: glam::DVec3, wo: glam::DVec3) -> f64 {
    let (n, k) = GOLD[ch];
    lobe.specular_with(|c| conductor_fresnel(c, n, k), wi, wo)
        + (1.0 - fresnel(wi.z)) * (1.0 - fresnel(wo.z)) * RHO / PI
}

#[test]
fn a_conductors_fresnel_curve_comes_back() {
    let lobe = Isotropic::new(|c| ggx(c, 0.2));
    let truth = |ch: usize, wi, wo| gold(&lobe, ch, wi, wo);
    let data = measure_channels(&[0.0], &WAVELENGTHS, &truth, 7);
    assert_eq!(
        data.channels, WAVELENGTHS,
        "channels in ascending wavelength"
    );
    let analytic_model = Model::for_data("fa(lambert)", &data).unwrap();
    let driven_model = Model::for_data("fa(lambert)+fresnel", &data).unwrap();
    let analytic = fit(&analytic_model, &data, None);
    let driven = fit(
        &driven_model,
        &data,
        Some(embed(&analytic_model, &analytic.flat, &driven_model)),
    );
    let (before, after) = (chi2_red(&analytic), chi2_red(&driven));
    let noise = 4.0 * (2.0 / driven.dof as f64).sqrt();
    eprintln!("gold: χ²_red fa(lambert) {before:.3}, fa(lambert)+fresnel {after:.3} (±{noise:.3})");
    assert!(
        before > 3.0,
        "a dielectric curve fits gold (χ²_red {before})"
    );
    assert!(
        (after - 1.0).abs() < noise,
        "χ²_red {after} beyond the noise ±{noise:.3}"
    );
    assert!(driven.smoothness.is_some(), "the prior's weight is chosen");

    let all = fresnel_bands(&driven_model, &data, &driven.flat, &driven.cov);
    assert_eq!(all.len(), 3, "one curve per channel");
    for (stem, ch, knots) in &all {
        assert_eq!(stem, "lobe.fresnel");
        let (n, k) = GOLD[*ch];
        // The curve lives on 9 knots: what the spline through gold's own log-ratio to the
        // dielectric curve misses between them (θd ≤ 75°, where the data are) shifts the
        // best knots by up to that much, beyond the noise's σ.
        let ratio = |c: f64| (conductor_fresnel(c, n, k) / dielectric(c, 1.5)).ln();
        let exact: [f64; KNOTS] = std::array::from_fn(|j| {
            let c = 1.0 - j as f64 / (KNOTS - 1) as f64;
            ratio(c) - ratio(1.0)
        });
        let resolution = (0..=750)
            .map(|i| (i as f64 / 10.0).to_radians().cos())
            .map(|c| (log_factor(&exact, knot_coordinate(c)) - (ratio(c) - ratio(1.0))).abs())
            .fold(0.0, f64::max);
        eprintln!("  channel {ch}: the spline's resolution of gold's curve {resolution:.4} in ln");
        let mut measured = 0;
        for knot in knots {
            let want = conductor_fresnel(knot.theta_deg.to_radians().cos(), n, k);
            let sigma = knot.sigma_ln_f.expect("a band with the prior on");
            let diff = (knot.f / want).ln();
            eprintln!(
                "  channel {ch} {:>5.1}°: F {:.4} (gold {want:.4}) ln ratio {diff:+.4} σ {sigma:.4} signal {:.1}",
                knot.theta_deg, knot.f, knot.signal
            );
            assert!(knot.f.is_finite() && knot.f > 0.0 && sigma.is_finite());
            assert_eq!(knot.measured, is_measured(knot.signal, knot.data_share));
            if knot.measured {
                measured += 1;
                assert!(
                    diff.abs() <= 3.0 * sigma + resolution,
                    "channel {ch} at {:.1}°: ln F {diff:+.4} from gold's, σ {sigma:.4}, resolution {resolution:.4}",
                    knot.theta_deg
                );
            }
        }
        // The goniometer's θd reach 60°: the normal, 29°, 41°, 51° and 60° are seen.
        assert!(measured >= 4, "channel {ch}: {measured} knots measured");
    }
}

/// The workflow names it: diagnose from `lambert` on the gold-highlight data adds the
/// specular lobe, then, with no analytic effect left significant, the Fresnel curve (and
/// not the highlight's shape: the truth's NDF is GGX), and ends within the noise.
#[test]
fn diagnose_names_the_fresnel_curve_of_a_conductor() {
    use bsdfit::workflows::diagnose::Effect;
    let lobe = Isotropic::new(|c| ggx(c, 0.2));
    let truth = |ch: usize, wi, wo| gold(&lobe, ch, wi, wo);
    let data = measure_channels(&[0.0], &WAVELENGTHS, &truth, 8);
    let d = diagnose_truth("gold", &data, "lambert");
    assert_eq!(
        d.effects.first(),
        Some(&Effect::SpecularLobe),
        "{:?}",
        d.effects
    );
    assert!(
        d.effects.contains(&Effect::HighlightFresnel),
        "{:?}",
        d.effects
    );
    assert!(
        !d.effects.contains(&Effect::HighlightShape),
        "{:?}",
        d.effects
    );
    assert!(!d.effects.contains(&Effect::Anisotropy), "{:?}", d.effects);
    // Within the noise: 1 ± 4√(2/ν), ν ≈ the samples.
    let chi2_red = d.steps.last().unwrap().chi2_red;
    let noise = 4.0 * (2.0 / data.len() as f64).sqrt();
    assert!((chi2_red - 1.0).abs() < noise, "final χ²_red {chi2_red}");
}
