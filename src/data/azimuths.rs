//! Which incidence azimuths a data set holds, and so whether it can tell an anisotropic
//! surface from an isotropic one whose lobe has another shape.
//!
//! An isotropic BSDF depends on θi, θo and the relative azimuth φo − φi only, and it is
//! mirror-symmetric about the plane of incidence. Measured at one incidence azimuth, each
//! sample has its own (θi, θo, φo − φi), so any anisotropic lobe whose tangent frame lies
//! on or across that plane (mirror-symmetric about it too) is matched by some isotropic
//! BSDF: an anisotropic lobe aligned with the plane is only one more way of making the
//! lobe narrower across the plane than along it. There anisotropy shows only as a break
//! of the mirror symmetry (a frame turned off the plane), which `diagnose` tests.
//! Incidence on two planes, or normal incidence seen on two planes, measures the same
//! (θi, θo, φo − φi) at two orientations of the surface: there anisotropy shows directly.

use super::Dataset;

/// Below this polar angle (degrees) a direction counts as the normal: its azimuth means
/// nothing.
const NORMAL_DEG: f64 = 0.5;

/// Azimuths are grouped in sectors of this width (degrees, modulo 180°): two incidence
/// planes closer than this are one plane here, and data whose incidence azimuths are
/// spread at random fill many sectors.
const SECTOR_DEG: f64 = 15.0;

/// The fewest samples a plane must hold to count: 10, and a twentieth of the data.
fn min_plane_samples(samples: usize) -> usize {
    10usize.max(samples.div_ceil(20))
}

/// How the data's incidence azimuths bear on anisotropy.
#[derive(Clone, Debug, PartialEq)]
pub enum AzimuthCoverage {
    /// Incidence on at least two planes (modulo 180°) with [`min_plane_samples`] each, a
    /// sample at normal incidence counted on the plane of its outgoing direction; or
    /// normal incidence only, seen on two or more planes (an isotropic surface is then
    /// invariant under every rotation about the normal). Anisotropy shows directly.
    Planes(Vec<f64>),
    /// One incidence azimuth, in degrees in [0, 180): anisotropy shows only as a break of
    /// the mirror symmetry about this plane.
    One(f64),
    /// Every direction in one plane: an anisotropic lobe is not determined at all.
    InPlane,
}

impl AzimuthCoverage {
    /// The plane of incidence when there is one only.
    pub fn one_azimuth(&self) -> Option<f64> {
        match self {
            AzimuthCoverage::One(phi) => Some(*phi),
            _ => None,
        }
    }
}

/// An azimuth in degrees modulo 180°, in [0, 180).
fn mod180(phi_rad: f64) -> f64 {
    let d = phi_rad.to_degrees().rem_euclid(180.0);
    if d >= 180.0 - 1e-9 {
        0.0
    } else {
        d
    }
}

/// Per sector: the samples and the sum of (cos 2φ, sin 2φ), whose angle is the sector's
/// mean plane.
#[derive(Clone, Copy, Default)]
struct Sector {
    count: usize,
    oblique: usize,
    c: f64,
    s: f64,
}

impl Sector {
    fn add(&mut self, phi_deg: f64, oblique: bool) {
        let a = (2.0 * phi_deg).to_radians();
        self.count += 1;
        self.oblique += oblique as usize;
        self.c += a.cos();
        self.s += a.sin();
    }
    /// The mean plane, degrees in [0, 180), to 1e-6° (the sums' rounding removed).
    fn plane(&self) -> f64 {
        let d = (self.s.atan2(self.c).to_degrees() / 2.0).rem_euclid(180.0);
        ((d * 1e6).round() / 1e6) % 180.0
    }
}

/// Off-plane samples on each side of the plane of incidence ([`Dataset::mirror_sides`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MirrorSides {
    pub left: usize,
    pub right: usize,
}

impl MirrorSides {
    /// The least share of the off-plane samples the less measured side must hold for a
    /// break of the mirror symmetry to be tested: with fewer, a frame turned off the plane
    /// only reshapes the lobe on the measured side, where nothing mirrors it.
    pub const MIN_SHARE: f64 = 0.2;

    /// Whether both sides are measured well enough to test the mirror symmetry.
    pub fn testable(&self) -> bool {
        let total = self.left + self.right;
        total > 0 && (self.left.min(self.right) as f64) >= Self::MIN_SHARE * total as f64
    }

    /// In words, for messages.
    pub fn describe(&self) -> String {
        format!(
            "{} and {} samples on the two sides of the plane of incidence",
            self.left, self.right
        )
    }
}

impl Dataset {
    /// The data turned, sample by sample, about the normal so that each sample's plane of
    /// incidence lies at φ = 0 (a sample at normal incidence: its outgoing plane). An
    /// isotropic BSDF takes the same values here; an anisotropic lobe with φ0 = 0 here is
    /// the lobe whose frame turns with each sample's plane of incidence: an isotropic lobe
    /// of another shape, the null against which anisotropy is tested.
    pub fn turned_to_incidence_planes(&self) -> Dataset {
        let mut d = self.clone();
        for s in &mut d.samples {
            let turn = if s.theta_i.to_degrees() > NORMAL_DEG {
                s.phi_i
            } else {
                s.phi_o
            };
            s.phi_i -= turn;
            s.phi_o -= turn;
        }
        d
    }

    /// The samples off the plane of incidence on each side of it (outgoing azimuth
    /// φo − φi in (0°, 180°), then in (180°, 360°)): at one incidence azimuth a mirror
    /// symmetry about that plane can only be tested where both sides are measured
    /// ([`MirrorSides::testable`]). A file that tabulates one half of a plane-symmetric
    /// BSDF (Zemax `PlaneSymmetrical`) holds one side only.
    pub fn mirror_sides(&self) -> MirrorSides {
        let (mut left, mut right) = (0, 0);
        for s in &self.samples {
            let side = (s.phi_o - s.phi_i).sin() * s.theta_o.sin();
            if side > 1e-6 {
                left += 1;
            } else if side < -1e-6 {
                right += 1;
            }
        }
        MirrorSides { left, right }
    }

    /// Whether the data's incidence azimuths can show anisotropy ([`AzimuthCoverage`]).
    pub fn azimuth_coverage(&self) -> AzimuthCoverage {
        if self.direction_planes() < 2 {
            return AzimuthCoverage::InPlane;
        }
        let n = (180.0 / SECTOR_DEG).round() as usize;
        let mut sectors = vec![Sector::default(); n];
        for s in &self.samples {
            let (phi, oblique) = if s.theta_i.to_degrees() > NORMAL_DEG {
                (mod180(s.phi_i), true)
            } else if s.theta_o.to_degrees() > NORMAL_DEG {
                (mod180(s.phi_o), false)
            } else {
                continue;
            };
            // Sectors centred on multiples of their width: a plane at 0° ± noise is one.
            let k = (phi / SECTOR_DEG).round() as usize % n;
            sectors[k].add(phi, oblique);
        }
        let min = min_plane_samples(self.len());
        let populated: Vec<f64> = sectors
            .iter()
            .filter(|s| s.count >= min)
            .map(Sector::plane)
            .collect();
        if populated.len() >= 2 {
            return AzimuthCoverage::Planes(populated);
        }
        match sectors
            .iter()
            .filter(|s| s.oblique > 0)
            .max_by_key(|s| s.oblique)
        {
            Some(s) => AzimuthCoverage::One(s.plane()),
            // Normal incidence only, on two or more planes (direction_planes ≥ 2).
            None => AzimuthCoverage::Planes(
                sectors
                    .iter()
                    .filter(|s| s.count > 0)
                    .map(Sector::plane)
                    .collect(),
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::{Kind, RawRow, ReadOptions};

    fn data(rows: &[[f64; 4]]) -> Dataset {
        let raw: Vec<(usize, RawRow)> = rows
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let row = RawRow {
                    theta_i: r[0],
                    phi_i: r[1],
                    theta_o: r[2],
                    phi_o: r[3],
                    wavelength_nm: 550.0,
                    value: 0.1,
                    uncertainty: 0.01,
                };
                (i + 1, row)
            })
            .collect();
        Dataset::from_rows(Kind::Brdf, "t", &raw, "<t>", &ReadOptions::default()).unwrap()
    }

    fn hemisphere(phi_i: &[f64], theta_i: &[f64]) -> Vec<[f64; 4]> {
        let mut rows = vec![];
        for &pi in phi_i {
            for &ti in theta_i {
                for to in [10.0, 30.0, 50.0, 70.0] {
                    for k in 0..12 {
                        rows.push([ti, pi, to, pi + 30.0 * k as f64]);
                    }
                }
            }
        }
        rows
    }

    #[test]
    fn one_incidence_azimuth_is_one_even_with_the_outgoing_hemisphere() {
        let d = data(&hemisphere(&[30.0], &[20.0, 40.0, 60.0]));
        assert_eq!(d.azimuth_coverage(), AzimuthCoverage::One(30.0));
        // φi = 210° is the same plane (θi signed the other way).
        let d = data(&hemisphere(&[30.0, 210.0], &[20.0, 40.0, 60.0]));
        assert!(matches!(d.azimuth_coverage(), AzimuthCoverage::One(p) if (p - 30.0).abs() < 1e-6));
        // A few normal-incidence samples on many planes do not make it separable.
        let d = data(&hemisphere(&[0.0], &[0.0, 20.0, 40.0, 60.0, 70.0]));
        assert_eq!(d.azimuth_coverage(), AzimuthCoverage::One(0.0));
    }

    /// Turned to their planes of incidence, samples keep their relative azimuth (φo − φi),
    /// and normal-incidence samples land on φ = 0.
    #[test]
    fn turning_to_the_incidence_planes_keeps_the_relative_azimuth() {
        let d = data(&[
            [30.0, 40.0, 50.0, 100.0],
            [0.0, 0.0, 50.0, 70.0],
            [20.0, 200.0, 10.0, 0.0],
        ]);
        let t = d.turned_to_incidence_planes();
        for (a, b) in d.samples.iter().zip(&t.samples) {
            let rel = |s: &crate::data::Sample| (s.phi_o - s.phi_i).to_degrees().rem_euclid(360.0);
            assert!((rel(a) - rel(b)).abs() < 1e-9);
            assert_eq!(
                (a.theta_i, a.theta_o, a.value),
                (b.theta_i, b.theta_o, b.value)
            );
            let incidence = if b.theta_i > 1e-3 { b.phi_i } else { b.phi_o };
            assert!(
                incidence
                    .to_degrees()
                    .rem_euclid(360.0)
                    .min(360.0 - incidence.to_degrees().rem_euclid(360.0))
                    < 1e-9
            );
        }
    }

    #[test]
    fn two_incidence_planes_or_normal_incidence_on_two_planes_are_separable() {
        let d = data(&hemisphere(&[0.0, 90.0], &[20.0, 40.0]));
        assert!(matches!(d.azimuth_coverage(), AzimuthCoverage::Planes(p) if p.len() == 2));
        // The paper's anisotropic diffusers: normal incidence, two planes.
        let mut rows = vec![];
        for phi in [0.0, 90.0] {
            for k in -20..=20 {
                rows.push([0.0, 0.0, k as f64, phi]);
            }
        }
        let d = data(&rows);
        assert_eq!(
            d.azimuth_coverage(),
            AzimuthCoverage::Planes(vec![0.0, 90.0])
        );
        // Too few samples on the second incidence plane: one azimuth.
        let mut rows = hemisphere(&[0.0], &[20.0, 40.0, 60.0]);
        rows.extend(&hemisphere(&[90.0], &[40.0])[..5]);
        assert_eq!(data(&rows).azimuth_coverage(), AzimuthCoverage::One(0.0));
        // In plane: not at all.
        let rows: Vec<[f64; 4]> = (0..20).map(|k| [30.0, 0.0, 4.0 * k as f64, 0.0]).collect();
        assert_eq!(data(&rows).azimuth_coverage(), AzimuthCoverage::InPlane);
    }

    /// The sides of the plane of incidence: in-plane samples (φo − φi = 0° or 180°) and
    /// samples along the normal count on neither; a full hemisphere is balanced, a half
    /// one (φo − φi in [0°, 180°], as a plane-symmetric table holds) is not testable, and
    /// a fifth of the off-plane samples on the less measured side is the least that is.
    #[test]
    fn mirror_sides_count_the_off_plane_samples() {
        let full = data(&hemisphere(&[40.0], &[20.0, 50.0]));
        let sides = full.mirror_sides();
        // 12 azimuths every 30°: 0° and 180° in the plane, 5 on each side.
        assert_eq!((sides.left, sides.right), (40, 40));
        assert!(sides.testable());
        let half: Vec<[f64; 4]> = hemisphere(&[40.0], &[20.0, 50.0])
            .into_iter()
            .filter(|r| r[3] - r[1] <= 180.0)
            .chain([[20.0, 40.0, 0.0, 100.0]])
            .collect();
        let sides = data(&half).mirror_sides();
        assert_eq!((sides.left, sides.right), (40, 0));
        assert!(!sides.testable());
        for (left, right, testable) in [(80, 20, true), (81, 19, false), (0, 0, false)] {
            assert_eq!(
                MirrorSides { left, right }.testable(),
                testable,
                "{left} {right}"
            );
        }
    }
}
