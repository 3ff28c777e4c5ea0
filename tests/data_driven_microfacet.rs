//! The three data-driven factors of a microfacet model together (`+ndf+fresnel+body`,
//! docs/models.md): data synthesised here from a truth that departs from the analytic
//! aggregate in all three at once — a Beckmann NDF (with its own Smith Λ), gold's Fresnel
//! curve per channel (at a tenth of its strength: metallic flakes), and a Minnaert body seen through a dielectric interface — in three
//! channels with 1 % noise at one incidence azimuth.
//!
//! **Both tests are ignored: neither passes yet.** The fits end above the noise (χ²_red
//! 1.15 to 1.37 against ±0.10) and depend on the path (the `+fresnel` optimum or the `+ndf`
//! one as the start), which points at local optima of the joint fit rather than at what
//! the knots can represent; the models themselves are checked in both engines by the
//! parity tests and by the embedding unit test of `bsdf/ndf_fresnel.rs`. What they would
//! show once they pass: leaving out the Fresnel curve
//! misfits beyond the noise (the NDF and the body cannot take its shape: they depend on
//! other angles);
//! with all three the fit reaches χ²_red within the noise, and each factor's knots agree
//! with the truth's within 3 propagated standard uncertainties (plus what the spline
//! cannot follow) wherever the data see them.

mod common;

use bsdfit::bsdf::fresnel::{knot_coordinate, log_factor, KNOTS};
use bsdfit::bsdf::Model;
use bsdfit::data::Dataset;
use bsdfit::inference::fit::Conclusions;
use bsdfit::inference::knots::{bands, body_bands, fresnel_bands, MEASURED_SIGNAL};
use bsdfit::math::fresnel_dielectric as dielectric;
use bsdfit::workflows::diagnose::embed;
use common::truths::{
    beckmann, chi2_red, conductor_fresnel, fit_truth, fresnel, measure_channels, Isotropic, RHO,
};
use std::f64::consts::PI;

/// Gold's complex index at 450, 550 and 650 nm (Johnson & Christy 1972, rounded).
const GOLD: [(f64, f64); 3] = [(1.47, 1.95), (0.43, 2.45), (0.17, 3.15)];
const WAVELENGTHS: [f64; 3] = [450.0, 550.0, 650.0];
const ALPHA: f64 = 0.3;
/// The flakes' share of the surface: the highlight is gold's at a tenth of its strength
/// (a metallic-flake paint), about as strong as a dielectric's (with gold's full strength
/// `+ndf+fresnel` ended at χ²_red 35 from the `fa(lambert)` optimum).
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

/// Asserts |diff| within 3σ + `slack` at a measured knot; counts the measured ones.
fn check(
    what: &str,
    theta: f64,
    diff: f64,
    sigma: Option<f64>,
    signal: f64,
    measured: bool,
    slack: f64,
) -> usize {
    let sigma = sigma.expect("a band with the prior on");
    eprintln!("  {what} {theta:>5.1}°: ln ratio {diff:+.4} σ {sigma:.4} signal {signal:.1}");
    assert!(
        diff.is_finite() && sigma.is_finite(),
        "{what} at {theta:.1}°"
    );
    assert_eq!(measured, signal >= MEASURED_SIGNAL);
    if !measured {
        return 0;
    }
    assert!(
        diff.abs() <= 3.0 * sigma + slack,
        "{what} at {theta:.1}°: ln ratio {diff:+.4}, σ {sigma:.4}, slack {slack:.4}"
    );
    1
}

/// 8 restarts from nothing, 4 from an embedded optimum (as diagnose extends a model).
fn fit(model: &Model, data: &Dataset, start: Option<Vec<f64>>) -> Conclusions {
    let restarts = if start.is_some() { 4 } else { 8 };
    fit_truth(model, data, start, restarts, 5)
}

/// A Lambertian body: ln ρ = 0.
fn lambertian(_: f64) -> f64 {
    0.0
}

/// The NDF and the Fresnel curve of one lobe together (`+ndf+fresnel`), over a
/// Lambertian body: the data-driven NDF alone misfits, both reach the noise, and both
/// factors' knots come back.
#[test]
#[ignore = "does not pass yet: +fresnel+ndf ends at χ²_red 1.15 from the +fresnel optimum, 1.37 from the +ndf one (noise ±0.10); run with --release --ignored"]
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
    check_ndf(&both, &data, &driven);
    check_fresnel(&both, &data, &driven);
}

#[test]
#[ignore = "does not pass yet: all three end at χ²_red 1.20 (α = 0.2, 8 restarts) to 1.32 (α = 0.3, 4 restarts), noise ±0.10; run with --release --ignored"]
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

    check_ndf(&full, &data, &driven);
    check_fresnel(&full, &data, &driven);
    let (flat, cov) = (&driven.flat, &driven.cov);
    // The body's profile.
    let body = body_bands(&full, &data, flat, cov);
    assert_eq!(body.len(), 1);
    let slack = resolution(minnaert, 80.0);
    let mut measured = 0;
    for k in body[0].1.iter().filter(|k| k.theta_deg > 0.0) {
        let diff = k.rho.ln() - minnaert(k.theta_deg.to_radians().cos());
        measured += check(
            "ρ",
            k.theta_deg,
            diff,
            k.sigma_ln_rho,
            k.signal,
            k.measured,
            slack,
        );
    }
    assert!(measured >= 6, "{measured} body knots measured");
}

/// The NDF's knots: D against Beckmann's (normalised, so no scale to take).
fn check_ndf(model: &Model, data: &Dataset, fit: &Conclusions) {
    let ndf = bands(model, data, &fit.flat, &fit.cov);
    assert_eq!(ndf.len(), 1);
    let mut measured = 0;
    for k in &ndf[0].1 {
        let want = beckmann(k.theta_deg.to_radians().cos(), ALPHA);
        measured += check(
            "D",
            k.theta_deg,
            (k.d / want).ln(),
            k.sigma_ln_d,
            k.signal,
            k.measured,
            0.0,
        );
    }
    assert!(measured >= 9, "{measured} NDF knots measured");
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
                knot.theta_deg,
                (knot.f / want).ln(),
                knot.sigma_ln_f,
                knot.signal,
                knot.measured,
                slack,
            );
        }
        assert!(
            measured >= 4,
            "channel {ch}: {measured} Fresnel knots measured"
        );
    }
}
