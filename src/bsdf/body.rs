//! `M+body`: the diffuse body's angular profile made data-driven. Every diffuse base of M
//! (`lambert`, `on`, `eon`, `vmf`, bare or under a layer: `fa(B)`, `rmg(B)`, `dmg(B)`)
//! takes
//!
//!   f_B(ωi, ωo) · exp(s(θi) + s(θo)),
//!
//! s a Catmull–Rom spline through K = 9 knots in θ with s = 0 at normal incidence and one
//! free value at each other knot (`body1` … `body8`; `base.body1` … under a layer). The
//! profile is separable, ρ(θi) ρ(θo) with ρ = e^s, so it is reciprocal, and the same in
//! every channel (the base's albedo keeps the colour; a per-channel profile would cost
//! 8 parameters a channel, 248 on a 31-wavelength spectral file). At s = 0 the model is M
//! exactly (diagnose's F test, and a fit starts from M's values).
//!
//! Why: a measured diffuse body departs from the analytic bases in how it brightens or
//! darkens toward grazing — a particulate surface's limb darkening (the Minnaert and
//! Lommel–Seeliger laws of planetary photometry are separable in μi and μo in the same
//! way), a paint's or paper's grazing brightening from its surface sheen, a textile's
//! fibre shadowing. The benchmark's analytic bases (Oren–Nayar, EON, VMF) tie that
//! profile to one roughness; here the data set it. Data-driven fits of measured
//! materials tabulate the body in the same way beside the NDF and the Fresnel factor.
//!
//! The knots are those of `+fresnel` ([`super::fresnel`]): x = 8 (1 − cos θ), knot k at
//! x = k (θ_k = 0, 29.0, 41.4, 51.3, 60.0, 68.0, 75.5, 82.8 and 90 degrees: dense toward
//! grazing, where bodies depart from their analytic shapes), the spline continued
//! linearly past both ends. Only the diffuse base is reshaped: a layer's specular lobe,
//! its Fresnel transmittances and the grains of a micrograin layer keep their forms.
//!
//! Twin: `shaders/bsdf/body.wgsl`.

use super::effect::{Adds, Effect};
use super::fresnel::{factor, KNOTS, KNOTS_WGSL};
use super::kernel::{lanes, Kernel, LaneChildren, LaneDir, Memo};
use super::{Bsdf, Channels, Entry, InCatalogue, Node, ParamDecl, Role, WgslFn};
use crate::data::Kind;
use crate::math::lanes::Real;

const WGSL: (&str, &str) = ("body", include_str!("../../shaders/bsdf/body.wgsl"));

const NAMES: [&str; KNOTS - 1] = [
    "body1", "body2", "body3", "body4", "body5", "body6", "body7", "body8",
];

/// One knot's ln ρ(θ), shared by the channels: 0 is the base's own shape there. ±4 lets
/// the body's value at a grazing pair change by e^±8, more than a measured body needs (a
/// Minnaert body of exponent 1.5 at θ = 82.8° is e^−1.0 per direction).
const KNOT: ParamDecl = ParamDecl::shared(
    "body",
    -4.0,
    4.0,
    0.0,
    "ln of the diffuse body's angular profile rho(theta) at this knot, f = f_B rho(theta_i) rho(theta_o) (0: the base's own shape; the knots' angles are in docs/models.md)",
)
.neutral_at(0.0)
.knot();

/// The profile node: the value of the diffuse base below it times ρ(θi) ρ(θo).
#[derive(Debug, Clone, Copy)]
pub struct BodyProfile;

impl Kernel for BodyProfile {
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], base: LaneChildren<R>, out: &mut [R]) {
        let s: [f64; KNOTS] = std::array::from_fn(|k| if k == 0 { 0.0 } else { p.get(0, k - 1) });
        // A goniometer scans θo at a fixed θi: ρ(θi) is computed once per run.
        let (mut at_i, mut at_o) = (Memo::default(), Memo::default());
        for (d, (wi, wo), out) in lanes(dirs, p.len(), out) {
            let rho_i = at_i.get(
                wi.z,
                #[inline(always)]
                |mu| factor(&s, mu),
            );
            let rho_o = at_o.get(
                wo.z,
                #[inline(always)]
                |mu| factor(&s, mu),
            );
            let profile = rho_i * rho_o;
            for (o, &b) in out.iter_mut().zip(base.at(0, d)) {
                *o = b * profile;
            }
        }
    }
}

impl Bsdf for BodyProfile {
    fn bounded_albedo(&self) -> bool {
        false // ρ = e^s is not bounded by 1 (a body brighter toward grazing)
    }
    fn entry(&self) -> &'static Entry {
        &ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        NAMES.iter().map(|n| KNOT.renamed(n)).collect()
    }
    fn child_roles(&self) -> &'static [&'static str] {
        &[""]
    }
    super::kernel::kernel_methods!();
    fn wgsl(&self) -> WgslFn {
        WgslFn {
            sources: vec![KNOTS_WGSL, WGSL],
            function: "body_eval".into(),
        }
    }
}

/// Registry entry (one line in [`super::registry::REGISTRY`]).
pub const ENTRY: Entry = Entry::suffix(
    "body",
    Some(Kind::Brdf),
    InCatalogue::No,
    "data-driven angular profile of the diffuse base: f_B rho(theta_i) rho(theta_o), ln rho on 9 knots in theta, shared by the channels",
    build,
)
// s = 0 is M: M embeds in M+body (diagnose's F test). Offered once no analytic effect is.
.adding(&[Adds::appended(Effect::BodyProfile)])
// One node whatever the base: the tests that run every spec see it bare, under each layer
// and on each base once, not on all sixteen pairs.
.covered_on(&["lambert", "fa(on)", "dmg(eon)", "rmg(vmf)"]);

/// Wrap every diffuse base of `inner` (a node of role [`Role::DiffuseBase`], wherever it
/// sits) in a profile node; refused on BTDF models, when given twice, and where M has no
/// diffuse base (`ggx`, `rmg(ggx)`).
pub fn build(inner: Node) -> Result<Node, String> {
    if inner.bsdf.kind() != Kind::Brdf {
        return Err("+body applies to BRDF models".into());
    }
    fn wrap(node: Node, count: &mut usize, twice: &mut bool) -> Node {
        if node.bsdf.name() == ENTRY.name {
            *twice = true;
            return node;
        }
        if node.bsdf.entry().role == Role::DiffuseBase {
            *count += 1;
            return Node::with(BodyProfile, vec![node]);
        }
        let children = node
            .children
            .into_iter()
            .map(|c| wrap(c, count, twice))
            .collect();
        Node { children, ..node }
    }
    let (mut count, mut twice) = (0, false);
    let node = wrap(inner, &mut count, &mut twice);
    if twice {
        return Err("+body given twice".into());
    }
    if count == 0 {
        return Err(
            "+body reshapes a diffuse base and needs one: lambert, on, eon or vmf, bare or under a layer (fa(B), rmg(B), dmg(B))"
                .into(),
        );
    }
    Ok(node)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::fresnel::{knot_coordinate, log_factor};
    use crate::bsdf::test_support::{assert_suffix_embeds, dir};
    use crate::bsdf::Model;

    /// At s = 0 the model is M, value for value (the profile is exp(0)·exp(0) = 1).
    #[test]
    fn at_zero_knots_the_model_is_the_analytic_one() {
        for spec in ["lambert", "fa(on)", "rmg(eon)+coat", "dmg(vmf)", "fa(lambert)+fresnel"] {
            let m = Model::parse(spec, 3).unwrap();
            let b = assert_suffix_embeds(spec, "body", 3);
            assert_eq!(b.dim, m.dim + KNOTS - 1, "{spec}");
        }
    }

    /// The profile multiplies the base alone, by ρ(θi) ρ(θo), in every channel: on
    /// `fa(lambert)` at η = 1 (no highlight, no transmittance loss) the value is
    /// ρ_c/π · e^{s(θi) + s(θo)}.
    #[test]
    fn the_profile_multiplies_the_base_by_rho_i_rho_o() {
        let m = Model::parse("fa(lambert)+body", 2).unwrap();
        let mut p = m.defaults();
        let set = |p: &mut Vec<f64>, name: &str, v: &[f64]| {
            let q = m.params.iter().find(|q| q.name == name).unwrap_or_else(|| panic!("{name}"));
            p[q.index..q.index + v.len()].copy_from_slice(v);
        };
        set(&mut p, "lobe.eta", &[1.0]);
        set(&mut p, "base.rho", &[0.4, 0.8]);
        let s: [f64; KNOTS] = std::array::from_fn(|k| -0.2 * (k as f64).powf(1.3));
        for (k, &v) in s.iter().enumerate().skip(1) {
            set(&mut p, &format!("base.body{k}"), &[v]);
        }
        for (ti, to) in [(0.0, 0.3), (0.7, 1.2), (1.5, 1.55)] {
            let (wi, wo) = (dir(ti, 0.0), dir(to, 2.0));
            let profile = (log_factor(&s, knot_coordinate(wi.z))
                + log_factor(&s, knot_coordinate(wo.z)))
            .exp();
            for (c, rho) in [(0, 0.4), (1, 0.8)] {
                let want = rho * std::f64::consts::FRAC_1_PI * profile;
                let got = m.eval(&p, c, wi, wo);
                assert!((got - want).abs() <= 1e-12 * want, "θ {ti} {to} channel {c}: {got} vs {want}");
                assert_eq!(got, m.eval(&p, c, wo, wi), "not reciprocal");
            }
        }
    }

    /// +body finds the diffuse base wherever it sits, once, and refuses models without one.
    #[test]
    fn the_suffix_wraps_the_diffuse_base() {
        for (spec, knot) in [
            ("lambert+body", "body1"),
            ("fa(eon)+body", "base.body8"),
            ("rmg(lambert)+coat+body", "base.body3"),
            ("lambert+mrm+body+falloff", "body2"),
            ("fa(lambert)+fresnel+body", "base.body1"),
        ] {
            let m = Model::parse(spec, 3).unwrap_or_else(|e| panic!("{spec}: {e}"));
            assert!(m.params.iter().any(|p| p.name == knot), "{spec}");
        }
        for spec in ["ggx+body", "rmg(ggx)+body", "lambert+body+body", "btdf(tr)+body"] {
            assert!(Model::parse(spec, 1).is_err(), "{spec} parsed");
        }
    }
}
