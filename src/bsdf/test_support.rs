//! Checks the model files' unit tests share.

use super::Model;
use glam::DVec3;
use rand::{Rng, SeedableRng};

/// A unit direction at polar angle θ and azimuth φ (radians).
pub fn dir(theta: f64, phi: f64) -> DVec3 {
    DVec3::new(
        theta.sin() * phi.cos(),
        theta.sin() * phi.sin(),
        theta.cos(),
    )
}

/// `spec+suffix` at its new parameters' neutral 0 is `spec`, value for value (bit for
/// bit: a data-driven factor is exp(0) = 1 there), at random parameters of `spec` in 3
/// channels and random directions. Returns the extended model.
pub fn assert_suffix_embeds(spec: &str, suffix: &str, seed: u64) -> Model {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let m = Model::parse(spec, 3).unwrap();
    let x = Model::parse(&format!("{spec}+{suffix}"), 3).unwrap();
    let names = m.flat_names();
    for _ in 0..20 {
        let unit: Vec<f64> = (0..m.dim).map(|_| rng.random_range(0.05..0.95)).collect();
        let pm = m.from_unit(&unit);
        let px: Vec<f64> = x
            .flat_names()
            .iter()
            .map(|n| names.iter().position(|q| q == n).map_or(0.0, |j| pm[j]))
            .collect();
        for c in 0..3 {
            let (wi, wo) = (
                dir(rng.random_range(0.0..1.5), 0.0),
                dir(rng.random_range(0.0..1.5), rng.random_range(0.0..6.3)),
            );
            let (a, b) = (m.eval(&pm, c, wi, wo), x.eval(&px, c, wi, wo));
            assert_eq!(a, b, "{spec}+{suffix} channel {c} at {wi} {wo}");
        }
    }
    x
}
