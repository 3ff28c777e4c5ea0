//! Total integrated scatter of a model: TIS(θi) = ∫ f(ωi, ω) cos θ dω over the
//! hemisphere of the scattered directions (reflected for a BRDF, transmitted for a BTDF),
//! the fraction of the incident power that is scattered.
//!
//! The integral is taken in the spherical coordinates (r, a) about the specular (or
//! directly transmitted) direction s of the Zemax format ([`geometry`]), so a lobe at s is
//! resolved by radial panels graded towards r = 0. For each azimuth a the horizon is
//! reached at r_h(a) = atan2(cos α, −cos a · sin α) (where cos θ = cos r cos α +
//! sin r cos a sin α vanishes): integrating r over [0, r_h(a)] keeps the integrand smooth
//! (it has no kink at the horizon, where a rule over the whole sphere would meet one), so
//! Gauss–Legendre panels in r and the trapezoidal rule in the periodic a converge fast: a
//! Lambertian f = ρ/π integrates to ρ within 1e-12.

use crate::data::readers::zemax::geometry;
use crate::math::special::gauss_legendre;
use glam::DVec3;
use rayon::prelude::*;

/// Radial panels (graded as (k/K)² towards the specular direction), nodes per panel and
/// azimuth nodes (more at grazing incidence, where the horizon r_h(a) turns sharply near
/// a = 180°).
const PANELS: usize = 24;
const NODES: usize = 8;
fn azimuths(aoi: f64) -> usize {
    if aoi <= 60.0 {
        128
    } else if aoi <= 80.0 {
        256
    } else {
        1024
    }
}

/// TIS at incidence α (degrees) from azimuth φi (degrees) of `f(wi, wo, phi_o_deg)`, for a
/// BTDF (`transmitted`) with ωo below the surface.
pub fn tis(
    aoi: f64,
    phi_i: f64,
    transmitted: bool,
    f: &(dyn Fn(DVec3, DVec3, f64) -> f64 + Sync),
) -> f64 {
    let wi = crate::math::direction(aoi.to_radians(), phi_i.to_radians());
    let (sa, ca) = aoi.to_radians().sin_cos();
    let gl = gauss_legendre(NODES, 0.0, 1.0);
    let n = azimuths(aoi);
    let da = 360.0 / n as f64;
    (0..n)
        .into_par_iter()
        .map(|j| {
            let a = j as f64 * da;
            let r_h = ca.atan2(-a.to_radians().cos() * sa);
            let mut sum = 0.0;
            for k in 0..PANELS {
                let (r0, r1) = (
                    r_h * (k as f64 / PANELS as f64).powi(2),
                    r_h * ((k + 1) as f64 / PANELS as f64).powi(2),
                );
                for &(x, w) in &gl {
                    let r = r0 + x * (r1 - r0);
                    let w_up = geometry::scatter_direction(aoi, phi_i, a, r.to_degrees());
                    let cos_o = w_up.z.max(0.0);
                    let wo = if transmitted {
                        DVec3::new(w_up.x, w_up.y, -w_up.z)
                    } else {
                        w_up
                    };
                    let phi_o = w_up.y.atan2(w_up.x).to_degrees().rem_euclid(360.0);
                    sum += w * (r1 - r0) * f(wi, wo, phi_o) * cos_o * r.sin();
                }
            }
            sum * da.to_radians()
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn a_lambertian_integrates_to_its_albedo_at_every_incidence() {
        for aoi in [0.0, 10.0, 45.0, 80.0, 89.0] {
            for transmitted in [false, true] {
                let t = tis(aoi, 90.0, transmitted, &|_, _, _| 0.7 / PI);
                assert!((t - 0.7).abs() < 1e-12, "{aoi} {transmitted}: {t}");
            }
        }
    }

    #[test]
    fn a_narrow_lobe_about_the_specular_direction_is_resolved() {
        // f = A·exp(−(r/w)²)/cos θ: ∫ f cos dω = A·π w² (1 − e^{−(π/w)²}) ≈ A π w² for a
        // lobe of width w = 1°, well inside the horizon at α = 40°.
        let w = 1f64.to_radians();
        let aoi: f64 = 40.0;
        let s = crate::math::direction(aoi.to_radians(), PI + 90f64.to_radians());
        let f = |_: DVec3, wo: DVec3, _: f64| {
            let r = wo.dot(s).clamp(-1.0, 1.0).acos();
            (-(r / w).powi(2)).exp() / wo.z
        };
        let t = tis(aoi, 90.0, false, &f);
        // The exact integral in (r, a): 2π ∫ e^{−(r/w)²} sin r dr.
        let gl = gauss_legendre(200, 0.0, 10.0 * w);
        let exact: f64 = 2.0
            * PI
            * gl.iter()
                .map(|&(r, q)| q * (-(r / w).powi(2)).exp() * r.sin())
                .sum::<f64>();
        assert!((t - exact).abs() < 1e-6 * exact, "{t} vs {exact}");
    }
}
