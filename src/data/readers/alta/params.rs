//! ALTA's input and output parametrizations, the value kinds of `--alta-values`, and the
//! direction conversions (see the parent module's documentation for the definitions).

use glam::DVec3;

/// The input parametrizations this reader converts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamIn {
    IsotropicTlTvProjDphi,
    IsotropicTvTlDphi,
    RusinThTdPd,
    RusinThPhTdPd,
    SphericalTlPlTvPv,
    Cartesian,
}

impl ParamIn {
    pub const ALL: [ParamIn; 6] = [
        ParamIn::IsotropicTlTvProjDphi,
        ParamIn::IsotropicTvTlDphi,
        ParamIn::RusinThTdPd,
        ParamIn::RusinThPhTdPd,
        ParamIn::SphericalTlPlTvPv,
        ParamIn::Cartesian,
    ];

    /// ALTA's name of the parametrization.
    pub fn name(self) -> &'static str {
        match self {
            ParamIn::IsotropicTlTvProjDphi => "ISOTROPIC_TL_TV_PROJ_DPHI",
            ParamIn::IsotropicTvTlDphi => "ISOTROPIC_TV_TL_DPHI",
            ParamIn::RusinThTdPd => "RUSIN_TH_TD_PD",
            ParamIn::RusinThPhTdPd => "RUSIN_TH_PH_TD_PD",
            ParamIn::SphericalTlPlTvPv => "SPHERICAL_TL_PL_TV_PV",
            ParamIn::Cartesian => "CARTESIAN",
        }
    }

    pub fn parse(s: &str) -> Option<ParamIn> {
        ParamIn::ALL.into_iter().find(|p| p.name() == s)
    }

    /// Number of input columns.
    pub fn dim(self) -> usize {
        match self {
            ParamIn::IsotropicTlTvProjDphi | ParamIn::IsotropicTvTlDphi | ParamIn::RusinThTdPd => 3,
            ParamIn::RusinThPhTdPd | ParamIn::SphericalTlPlTvPv => 4,
            ParamIn::Cartesian => 6,
        }
    }

    /// Whether the parametrization assumes an isotropic BRDF (no absolute azimuth).
    pub fn isotropic(self) -> bool {
        matches!(
            self,
            ParamIn::IsotropicTlTvProjDphi | ParamIn::IsotropicTvTlDphi | ParamIn::RusinThTdPd
        )
    }

    /// ALTA's `to_cartesian`: the (V, L) = (ωo, ωi) of the coordinates `x` (radians),
    /// as written (not normalised or checked).
    pub fn to_cartesian(self, x: &[f64]) -> (DVec3, DVec3) {
        let dir = |t: f64, p: f64| DVec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos());
        match self {
            ParamIn::IsotropicTlTvProjDphi => {
                let theta = x[1].hypot(x[2]);
                let v = if theta > 0.0 {
                    DVec3::new(
                        x[1] / theta * theta.sin(),
                        x[2] / theta * theta.sin(),
                        theta.cos(),
                    )
                } else {
                    DVec3::Z
                };
                (v, dir(x[0], 0.0))
            }
            ParamIn::IsotropicTvTlDphi => (dir(x[0], 0.0), dir(x[1], x[2])),
            ParamIn::RusinThTdPd => half_to_cartesian(x[0], 0.0, x[1], x[2]),
            ParamIn::RusinThPhTdPd => half_to_cartesian(x[0], x[1], x[2], x[3]),
            ParamIn::SphericalTlPlTvPv => (dir(x[2], x[3]), dir(x[0], x[1])),
            ParamIn::Cartesian => (DVec3::new(x[0], x[1], x[2]), DVec3::new(x[3], x[4], x[5])),
        }
    }
}

/// Rusinkiewicz half/difference angles to (V, L) as ALTA defines it: V = Rz(φh)·Ry(θh)·D,
/// L = 2(V·H)H − V.
pub fn half_to_cartesian(theta_h: f64, phi_h: f64, theta_d: f64, phi_d: f64) -> (DVec3, DVec3) {
    let h = DVec3::new(
        theta_h.sin() * phi_h.cos(),
        theta_h.sin() * phi_h.sin(),
        theta_h.cos(),
    );
    let d = DVec3::new(
        theta_d.sin() * phi_d.cos(),
        theta_d.sin() * phi_d.sin(),
        theta_d.cos(),
    );
    let v = rot_z(rot_y(d, theta_h), phi_h);
    let l = 2.0 * v.dot(h) * h - v;
    (v, l)
}

/// Right-handed rotation by `a` about +y.
pub(crate) fn rot_y(v: DVec3, a: f64) -> DVec3 {
    let (s, c) = a.sin_cos();
    DVec3::new(c * v.x + s * v.z, v.y, -s * v.x + c * v.z)
}

/// Right-handed rotation by `a` about +z.
pub(crate) fn rot_z(v: DVec3, a: f64) -> DVec3 {
    let (s, c) = a.sin_cos();
    DVec3::new(c * v.x - s * v.y, s * v.x + c * v.y, v.z)
}

/// Rotate (ωi, ωo) about the normal so that φi = 0 (exact for an isotropic BRDF). At
/// normal incidence (sin θi ≤ 1e-12, rounding) ωi is set to +z and nothing is rotated.
pub(crate) fn to_phi_i_zero(wi: DVec3, wo: DVec3) -> (DVec3, DVec3) {
    let s = wi.x.hypot(wi.y);
    if s <= 1e-12 {
        return (DVec3::Z, wo);
    }
    let a = -wi.y.atan2(wi.x);
    let (mut i, o) = (rot_z(wi, a), rot_z(wo, a));
    i.y = 0.0; // exactly in the plane φ = 0
    (i, o)
}

/// (θ, φ) in degrees of a unit upper-hemisphere vector, φ in [0, 360) (0 at the pole).
pub(crate) fn angles_deg(w: DVec3) -> (f64, f64) {
    // atan2 keeps full precision near the pole, where acos(z) loses half the digits.
    let theta = w.x.hypot(w.y).atan2(w.z).to_degrees();
    let phi = if w.x == 0.0 && w.y == 0.0 {
        0.0
    } else {
        w.y.atan2(w.x).to_degrees().rem_euclid(360.0)
    };
    (theta, if phi >= 360.0 { 0.0 } else { phi })
}

/// Normalise a direction read from a file; `None` (with the reason) when it is not one.
pub(super) fn checked_unit(w: DVec3, what: &str, strict_length: bool) -> Result<DVec3, String> {
    let n = w.length();
    if !n.is_finite() || n == 0.0 {
        return Err(format!("the {what} direction has length {n}"));
    }
    if strict_length && (n - 1.0).abs() > 1e-3 {
        return Err(format!(
            "the {what} vector ({}, {}, {}) is not of unit length ({n})",
            w.x, w.y, w.z
        ));
    }
    let mut u = w / n;
    if u.z < -1e-9 {
        return Err(format!(
            "the {what} direction is below the surface (z = {:.6}; θ = {:.4}°)",
            u.z,
            u.z.clamp(-1.0, 1.0).acos().to_degrees()
        ));
    }
    if u.z < 0.0 {
        u.z = 0.0;
        u = u.normalize();
    }
    Ok(u)
}

/// The output parametrizations this reader converts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamOut {
    InvSteradian,
    InvSteradianCosineFactor,
    RgbColor,
}

impl ParamOut {
    pub fn name(self) -> &'static str {
        match self {
            ParamOut::InvSteradian => "INV_STERADIAN",
            ParamOut::InvSteradianCosineFactor => "INV_STERADIAN_COSINE_FACTOR",
            ParamOut::RgbColor => "RGB_COLOR",
        }
    }

    pub fn parse(s: &str) -> Option<ParamOut> {
        [
            ParamOut::InvSteradian,
            ParamOut::InvSteradianCosineFactor,
            ParamOut::RgbColor,
        ]
        .into_iter()
        .find(|p| p.name() == s)
    }

    pub(super) fn dim(self) -> usize {
        match self {
            ParamOut::RgbColor => 3,
            _ => 1,
        }
    }

    /// What the values are, in words (for messages).
    pub fn meaning(self) -> &'static str {
        match self {
            ParamOut::InvSteradian => "the BRDF, sr⁻¹",
            ParamOut::InvSteradianCosineFactor => "BRDF × cos θo",
            ParamOut::RgbColor => "R, G, B BRDF values",
        }
    }
}

/// What the values of an ALTA file without `#PARAM_OUT` are (`--alta-values`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum AltaValues {
    /// The values are the BRDF in sr⁻¹ (what `#PARAM_OUT INV_STERADIAN` says).
    Brdf,
    /// The values are BRDF × cos θo, θo the outgoing (view) direction's polar angle; they
    /// are divided by cos θo, rows at grazing θo dropped (what `#PARAM_OUT
    /// INV_STERADIAN_COSINE_FACTOR` says).
    BrdfCos,
}

impl crate::choice::Choice for AltaValues {
    const WHAT: &'static str = "alta_values";
    const TABLE: &'static [(Self, &'static str, &'static str)] = &[
        (
            AltaValues::Brdf,
            "brdf",
            "The values are the BRDF in sr⁻¹ (what `#PARAM_OUT INV_STERADIAN` says)",
        ),
        (
            AltaValues::BrdfCos,
            "brdf-cos",
            "The values are BRDF × cos θo, θo the outgoing (view) direction's polar angle; they are divided by cos θo, rows at grazing θo dropped (what `#PARAM_OUT INV_STERADIAN_COSINE_FACTOR` says)",
        ),
    ];
}
crate::choice::named_choice!(AltaValues);

impl AltaValues {
    /// The word that names the value.
    pub fn name(self) -> &'static str {
        crate::choice::Choice::name(self)
    }

    /// What the values are, in words.
    pub fn meaning(self) -> &'static str {
        ParamOut::from(self).meaning()
    }
}

impl From<AltaValues> for ParamOut {
    fn from(v: AltaValues) -> ParamOut {
        match v {
            AltaValues::Brdf => ParamOut::InvSteradian,
            AltaValues::BrdfCos => ParamOut::InvSteradianCosineFactor,
        }
    }
}
