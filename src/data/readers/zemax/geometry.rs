//! The four angles of a Zemax tabular BSDF cell and bsdfit's (θi, φi, θo, φo)
//! (docs/data-formats.md, "Zemax tabular BSDF", gives the definitions this rests on: the
//! Zemax knowledge-base articles on the tabular BSDF format, paraphrased there).
//!
//! - **Sample rotation ψ** is defined as the angle from the sample's local +X axis to the
//!   normal of the plane of incidence: the plane of incidence is perpendicular to the
//!   azimuth ψ, so the incident direction lies at the azimuth **φi = ψ + 90°** of the
//!   sample's frame (ψ = 0: incidence in the YZ plane, Zemax's meridional plane).
//! - **AngleOfIncidence α** is, by the definition's own note, the angle of the specular
//!   (reflected or transmitted) direction rather than of the incident ray. For a BRDF the
//!   specular direction is the mirror of ωi, so θi = α; for a BTDF of a sample measured
//!   in air (what bsdfit's BTDFs are, docs/conventions.md) the direct transmission is
//!   undeviated, at θt = θi = α. In bsdfit's angles both are **s = (θ = α, φ = φi + 180°)**,
//!   θ of a BTDF measured from −n.
//! - **ScatterRadial r** and **ScatterAzimuth a** are spherical coordinates about s: the
//!   radial angle is 0 at s and grows outwards from it; the azimuth is 0 on the side of s
//!   that faces the sample normal and grows counter-clockwise. So r is the angle between
//!   the scattered direction and s, and a its azimuth about s, from the great circle
//!   through s and the normal (on the normal's side), increasing from +x towards +y of the
//!   sample's frame (counter-clockwise seen from the illuminated side, the usual view of a
//!   hemisphere plot). In the frame e₃ = s, e₁ = the tangent at s pointing at the normal,
//!   e₂ = e₃×e₁:
//!
//!   ω = cos r · s + sin r · (cos a · e₁ + sin a · e₂),
//!
//!   s = (−sin α cos φi, −sin α sin φi, cos α), e₁ = (cos α cos φi, cos α sin φi, sin α),
//!   e₂ = (−sin φi, cos φi, 0). A BTDF's transmitted direction is ω with z negated
//!   (bsdfit's θt, φt are the angles of ω).

use glam::DVec3;

/// φi = ψ + this (degrees): the plane of incidence is perpendicular to the sample
/// rotation's azimuth.
pub const INCIDENCE_FROM_ROTATION_DEG: f64 = 90.0;

/// Below this cosine of the outgoing polar angle a cell is beyond the horizon (or on it).
pub const HORIZON_COS: f64 = 1e-9;

/// A cell in bsdfit's convention, degrees: θo is θt (from −n) for a BTDF. `cos_o` is
/// the cosine of the outgoing polar angle; a cell with `cos_o` ≤ [`HORIZON_COS`] is
/// beyond the horizon (θo ≥ 90°) and has no bsdfit geometry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CellGeometry {
    pub theta_i: f64,
    pub phi_i: f64,
    pub theta_o: f64,
    pub phi_o: f64,
    pub cos_o: f64,
}

/// The incident azimuth (degrees, in [0, 360)) of sample rotation `rotation` (degrees).
pub fn incident_azimuth(rotation: f64) -> f64 {
    reduce_deg(rotation + INCIDENCE_FROM_ROTATION_DEG)
}

/// The sample rotation (degrees, in [0, 360)) whose incident azimuth is `phi_i`.
pub fn rotation_of(phi_i: f64) -> f64 {
    reduce_deg(phi_i - INCIDENCE_FROM_ROTATION_DEG)
}

fn reduce_deg(x: f64) -> f64 {
    let r = x.rem_euclid(360.0) + 0.0;
    if r >= 360.0 {
        0.0
    } else {
        r
    }
}

/// The specular frame (s, e₁, e₂) of incidence α at azimuth φi (degrees).
fn frame(aoi: f64, phi_i: f64) -> (DVec3, DVec3, DVec3) {
    let (sa, ca) = aoi.to_radians().sin_cos();
    let (sp, cp) = phi_i.to_radians().sin_cos();
    (
        DVec3::new(-sa * cp, -sa * sp, ca),
        DVec3::new(ca * cp, ca * sp, sa),
        DVec3::new(-sp, cp, 0.0),
    )
}

/// The scattered direction ω of a cell (all angles in degrees), in the frame where the
/// illuminated side is +z (a BTDF's ω is its transmitted direction mirrored to z > 0).
pub fn scatter_direction(aoi: f64, phi_i: f64, azimuth: f64, radial: f64) -> DVec3 {
    let (s, e1, e2) = frame(aoi, phi_i);
    let (sr, cr) = radial.to_radians().sin_cos();
    let (sa, ca) = azimuth.to_radians().sin_cos();
    cr * s + sr * (ca * e1 + sa * e2)
}

/// The cell (rotation ψ, incidence α, azimuth a, radial r; degrees) in bsdfit's angles.
pub fn cell_geometry(rotation: f64, aoi: f64, azimuth: f64, radial: f64) -> CellGeometry {
    let phi_i = incident_azimuth(rotation);
    let w = scatter_direction(aoi, phi_i, azimuth, radial);
    let rho = w.x.hypot(w.y);
    CellGeometry {
        theta_i: aoi,
        phi_i,
        theta_o: rho.atan2(w.z).to_degrees(),
        phi_o: if rho < 1e-15 {
            0.0
        } else {
            reduce_deg(w.y.atan2(w.x).to_degrees())
        },
        cos_o: w.z,
    }
}

/// The inverse of [`scatter_direction`]: (radial r in [0, 180], azimuth a in [0, 360))
/// in degrees of the direction (θo, φo) at incidence α, azimuth φi (degrees; a BTDF's θt
/// from −n). At r = 0 the azimuth is 0.
pub fn cell_of(aoi: f64, phi_i: f64, theta_o: f64, phi_o: f64) -> (f64, f64) {
    let (s, e1, e2) = frame(aoi, phi_i);
    let w = crate::math::direction(theta_o.to_radians(), phi_o.to_radians());
    let radial = w.cross(s).length().atan2(w.dot(s)).to_degrees();
    let (x, y) = (w.dot(e1), w.dot(e2));
    let azimuth = if x.hypot(y) < 1e-15 {
        0.0
    } else {
        reduce_deg(y.atan2(x).to_degrees())
    };
    (radial, azimuth)
}

/// ∫ f cos θo dω of one table (values `f[j·radials.len() + k]` at azimuth j, radial k; 0
/// where masked) by the trapezoidal rule on the table's own grid in (r, a), zero beyond
/// the horizon and beyond the last radial angle. `plane_symmetric`: the azimuths cover
/// 0–180° of a table symmetric about the plane of incidence (the integral is doubled);
/// otherwise the azimuths go round the circle and the last interval closes it. `None`
/// when the angles are not increasing (no such rule).
pub fn table_integral(
    aoi: f64,
    phi_i: f64,
    azimuths: &[f64],
    radials: &[f64],
    f: &[f64],
    plane_symmetric: bool,
) -> Option<f64> {
    let increasing = |v: &[f64]| v.windows(2).all(|w| w[1] > w[0]);
    if !increasing(azimuths) || !increasing(radials) || azimuths.is_empty() || radials.is_empty() {
        return None;
    }
    let nr = radials.len();
    // g(j, k) = f cos θo sin r, the integrand in (a, r).
    let g = |j: usize, k: usize| {
        let w = scatter_direction(aoi, phi_i, azimuths[j], radials[k]);
        f[j * nr + k] * w.z.max(0.0) * radials[k].to_radians().sin()
    };
    // ∫ dr along each azimuth.
    let along: Vec<f64> = (0..azimuths.len())
        .map(|j| {
            (1..nr)
                .map(|k| 0.5 * (g(j, k - 1) + g(j, k)) * (radials[k] - radials[k - 1]).to_radians())
                .sum()
        })
        .collect();
    let mut total: f64 = (1..azimuths.len())
        .map(|j| 0.5 * (along[j - 1] + along[j]) * (azimuths[j] - azimuths[j - 1]).to_radians())
        .sum();
    if plane_symmetric {
        total *= 2.0;
    } else {
        let last = azimuths.len() - 1;
        let gap = 360.0 - (azimuths[last] - azimuths[0]);
        if gap > 1e-9 {
            total += 0.5 * (along[last] + along[0]) * gap.to_radians();
        }
    }
    Some(total)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_definitions_hold_at_their_landmarks() {
        // Radial 0 is the specular direction: θ = α on the side opposite the source.
        let c = cell_geometry(0.0, 30.0, 123.0, 0.0);
        assert_eq!(c.phi_i, 90.0);
        assert!((c.theta_o - 30.0).abs() < 1e-12 && (c.phi_o - 270.0).abs() < 1e-12);
        // Azimuth 0 points from the specular direction towards the normal.
        let c = cell_geometry(0.0, 30.0, 0.0, 10.0);
        assert!((c.theta_o - 20.0).abs() < 1e-12 && (c.phi_o - 270.0).abs() < 1e-12);
        // Azimuth 180 points away from it, along the plane of incidence.
        let c = cell_geometry(0.0, 30.0, 180.0, 10.0);
        assert!((c.theta_o - 40.0).abs() < 1e-12 && (c.phi_o - 270.0).abs() < 1e-12);
        // Azimuth 90: counter-clockwise seen from above, i.e. from +x towards +y: with
        // φi = 0 (ψ = −90°) the specular point is on −x and a = 90° moves towards +y.
        let w = scatter_direction(30.0, 0.0, 90.0, 5.0);
        assert!(w.y > 0.0 && w.x < 0.0, "{w:?}");
        // The sample rotation turns the plane of incidence with it.
        assert_eq!(incident_azimuth(-90.0), 0.0);
        assert_eq!(rotation_of(incident_azimuth(37.0)), 37.0);
    }

    #[test]
    fn cell_of_inverts_cell_geometry() {
        for &(aoi, rot, a, r) in &[
            (0.0, 0.0, 45.0, 30.0),
            (15.0, 10.0, 170.0, 80.0),
            (60.0, 200.0, 300.0, 25.0),
            (75.0, 0.0, 90.0, 5.0),
        ] {
            let c = cell_geometry(rot, aoi, a, r);
            let (r2, a2) = cell_of(aoi, c.phi_i, c.theta_o, c.phi_o);
            assert!(
                (r2 - r).abs() < 1e-9 && (a2 - a).abs() < 1e-9,
                "{aoi} {rot} {a} {r}: {r2} {a2}"
            );
        }
    }

    #[test]
    fn a_lambertian_table_integrates_to_its_albedo() {
        let az: Vec<f64> = (0..=36).map(|k| k as f64 * 5.0).collect();
        let rad: Vec<f64> = (0..=360).map(|k| k as f64 * 0.5).collect();
        let f = vec![0.5 / std::f64::consts::PI; az.len() * rad.len()];
        let t = table_integral(20.0, 90.0, &az, &rad, &f, true).unwrap();
        assert!((t - 0.5).abs() < 2e-3, "{t}");
    }
}
