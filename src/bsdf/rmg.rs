//! `rmg(B)`: a layer of rough dielectric micrograins over a base BRDF B, after Lucas,
//! Ribardière, Pacanowski, Barla, "A Micrograin BSDF Model for the Rendering of Porous
//! Layers", ACM TOG 42(6), 2023 (the "plastic" grain of the authors' Shadertoy
//! shadertoy.com/view/cly3Dt, `micrograin_plastic_bsdf` in the shyHelios/mitsuba3 port):
//!
//! f = w·f_grain + (1 − w)·f_B,
//! f_grain = F(ωi·h)·D(h)·G1(μi)G1(μo)/(4 μi μo) + (1 − F(μi))(1 − F(μo))·ρ_g/π,
//!
//! with w the visibility weight (Eqs. 21–23), D the micrograin NDF (Eq. 17) and G1 the
//! Smith function of its Λ series (supplemental), all in [`super::micrograin`]. F is the
//! exact dielectric Fresnel of index η_g: at the half-vector angle for the specular term,
//! at μi and μo for the diffuse transmittances, as the reference shader does. Differences
//! from that shader: Λ is summed to 32 terms instead of 7 (they differ by > 1e-3 in G1
//! only for τ0 ≳ 0.95, by up to 0.08 at τ0 = 0.999), and μ is not clamped to
//! [1e-5, 0.99999] (nothing here divides by μ: G1/μ is computed directly).
//!
//! Parameters: τ0 [1e-3, 0.999] (log), β [1e-2, 1] (log: it is the GGX roughness of the NDF
//! as τ0 → 0, and the width of the specular lobe, like `ggx`'s α), ρ_g rgb [0, 1],
//! η_g [1, 5]; then B's as `base.*`. B ∈ `lambert on eon vmf ggx`.
//! Twins: `shaders/bsdf/micrograin.wgsl` + `shaders/bsdf/rmg.wgsl` (with `microfacet.wgsl`).

use super::kernel::{lanes, Kernel, LaneChildren, LaneDir};
use super::micrograin::{
    layer, layer_wgsl, rough_grain, weight, weight_in, Grains, RoughGrain, RoughGrainMemo, BETA_LO, ETA_G,
    MICROGRAIN_BASES, RHO_G, TAU0,
};
use super::effect::{Adds, Effect};
use super::{Bsdf, Channels, Entry, Node, ParamDecl, WgslFn};
use crate::data::Kind;
use crate::math::lanes::Real;
use glam::DVec3;

/// β of rmg: log scale (see the module doc).
pub const BETA: ParamDecl = ParamDecl::shared("beta", BETA_LO, 1.0, 0.5, "grain height / radius")
    .log()
    .neutral_at_lo();

#[derive(Debug, Clone, Copy)]
pub struct RoughMicrograin;

/// The rmg layer over a base value `f_base`.
pub fn rmg_layer(
    tau0: f64,
    beta: f64,
    rho_g: f64,
    eta_g: f64,
    wi: DVec3,
    wo: DVec3,
    f_base: f64,
) -> f64 {
    if wi.z <= 0.0 || wo.z <= 0.0 {
        return 0.0;
    }
    layer(
        weight(tau0, beta, wi.z, wo.z),
        rough_grain(tau0, beta, eta_g, rho_g, wi, wo),
        f_base,
    )
}

impl Kernel for RoughMicrograin {
    /// Eight lanes: with G1(μ)/μ from one-entry memos, sixteen lanes ran `rmg(eon)` 0.8×
    /// as fast as eight; with it from per-block μ tables ([`super::kernel::SlotMemo`])
    /// sixteen are no faster overall (medians of four alternated pairs, sixteen against
    /// eight: `rmg(lambert)` 0.98× and `rmg(eon)` 0.87× on `bench`'s built-in set,
    /// `rmg(lambert)` 0.98× and `rmg(lambert)+mrm82+coat` 1.19× on a 5,130-sample
    /// off-plane file).
    const NARROW_LANES: bool = true;
    /// The weight and the grain's specular term and transmittances once per direction.
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], base: LaneChildren<R>, out: &mut [R]) {
        let (grains, eta_g) = (Grains::new(p.get(0, 0), p.get(0, 1)), p.get(0, 3));
        let mut memo = RoughGrainMemo::default();
        let zero = R::zero();
        for (d, (wi, wo), out) in lanes(dirs, p.len(), out) {
            let above = zero.lt(wi.z) & zero.lt(wo.z);
            if !R::any(above) {
                out.fill(zero);
                continue;
            }
            let w = weight_in(&grains, wi.z, wo.z);
            let grain = RoughGrain::at_memo(&mut memo, &grains, eta_g, &dirs[d]);
            for (i, (o, &b)) in out.iter_mut().zip(base.at(0, d)).enumerate() {
                *o = R::select(above, layer(w, grain.value(R::splat(p.get(i, 2))), b), zero);
            }
        }
    }
}

impl Bsdf for RoughMicrograin {
    fn entry(&self) -> &'static Entry {
        &ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![TAU0, BETA, RHO_G, ETA_G]
    }
    fn child_roles(&self) -> &'static [&'static str] {
        &["base"]
    }
    super::kernel::kernel_methods!();
    fn wgsl(&self) -> WgslFn {
        layer_wgsl("rmg", include_str!("../../shaders/bsdf/rmg.wgsl"))
    }
    fn wgsl_prepare(&self) -> Option<&'static str> {
        // G1(μ)/μ at every polar cosine of the problem, once per candidate.
        Some("rmg_prepare")
    }
}

/// Registry entry (one line in [`super::registry::REGISTRY`]).
pub const ENTRY: Entry = Entry::layer(
    "rmg",
    Kind::Brdf,
    MICROGRAIN_BASES,
    "rough micrograin layer over a base B (Lucas et al. 2023): rmg(B)",
    |base| Node::with(RoughMicrograin, vec![base]),
)
// At the thinnest layer the base shows through unchanged: the grains darken it at grazing
// angles (Lucas et al. 2023).
.adding(&[Adds::wrapping(Effect::GrazingDecay)]);

#[cfg(test)]
mod tests {
    use super::super::micrograin::testutil::*;
    use super::super::micrograin::{g1, lambda0, ndf};
    use super::super::Model;
    use super::*;
    use crate::math::fresnel_dielectric;
    use std::f64::consts::PI;

    fn base_assign(base: &str, v: f64) -> String {
        format!("{}={v}", if base == "ggx" { "base.ks" } else { "base.rho" })
    }

    #[test]
    fn parameters_are_named_and_laid_out() {
        let m = Model::parse("rmg(ggx)", 3).unwrap();
        let names: Vec<&str> = m.params.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "tau0",
                "beta",
                "rho_g",
                "eta_g",
                "base.ks",
                "base.alpha",
                "base.eta"
            ]
        );
        assert_eq!(m.dim, 1 + 1 + 3 + 1 + 3 + 1 + 1);
    }

    /// τ0 at its lower bound 1e-3: for θi, θo ≤ 60° (E ≤ 2), w ≤ 2e-3, so
    /// |f − f_B| ≤ 2e-3·max(f_grain, f_B). Checked on every base, off the specular peak.
    #[test]
    fn tau0_lower_bound_reproduces_the_base() {
        for base in super::super::registry::bases_of(&ENTRY) {
            let m = Model::parse(&format!("rmg({base})"), 1).unwrap();
            let p = m
                .params_from_assignments(&format!("tau0=0.001,beta=0.3,{}", base_assign(base, 0.5)))
                .unwrap();
            let mb = Model::parse(base, 1).unwrap();
            let pb = p[4..].to_vec();
            for &mi in &[0.5, 0.7, 1.0] {
                for &mo in &[0.5, 0.8, 1.0] {
                    for &phi in &[0.0, 1.0, PI] {
                        let (wi, wo) = (dir_mu(mi, 0.0), dir_mu(mo, phi));
                        let (f, fb) = (m.eval(&p, 0, wi, wo), mb.eval(&pb, 0, wi, wo));
                        let fg = rough_grain(0.001, 0.3, 1.5, 0.5, wi, wo);
                        let tol = 2e-3 * fb.max(fg) + 1e-15;
                        assert!((f - fb).abs() <= tol, "{base}: {f} vs {fb} (grain {fg})");
                    }
                }
            }
        }
    }

    #[test]
    fn reciprocal_finite_and_non_negative_on_edge_grid() {
        for base in super::super::registry::bases_of(&ENTRY) {
            let m = Model::parse(&format!("rmg({base})"), 1).unwrap();
            let base_reciprocal = m.root.children[0].bsdf.reciprocal();
            for &tau0 in &[1e-3, 0.3, 0.999] {
                for &beta in &[BETA_LO, 0.4, 1.0] {
                    for &eta in &[1.0, 1.5, 5.0] {
                        let assign = format!(
                            "tau0={tau0},beta={beta},rho_g=0.7,eta_g={eta},{}",
                            base_assign(base, 0.4)
                        );
                        let p = m.params_from_assignments(&assign).unwrap();
                        for wi in edge_directions() {
                            for wo in edge_directions() {
                                let f = m.eval(&p, 0, wi, wo);
                                assert!(
                                    f.is_finite() && f >= 0.0,
                                    "{base} {assign} {wi} {wo}: {f}"
                                );
                                if base_reciprocal {
                                    let r = m.eval(&p, 0, wo, wi);
                                    assert!(
                                        (f - r).abs() <= 1e-9 * f.abs().max(1e-12),
                                        "{base} {assign}: {f} vs {r}"
                                    );
                                }
                            }
                        }
                    }
                }
            }
        }
    }

    /// Directional albedo of rmg(lambert), ρ = ρ_g = 1, at incidence cosine μi:
    /// the diffuse parts (functions of μo only) by a 1-D rule in μo; the specular part in
    /// the NDF's own variable: with ωo = reflect(ωi, h), μo dωo = 4 (ωi·h) μo/… so
    /// ∫ w F D G1i G1o/(4μiμo) μo dωo = ∫ w F G1i G1o (ωi·h)/(μi cos θh) · D cos θh dωh and
    /// D cos θh dωh = (Λ0/τ0) e^{−Λ0 u} du dφ/2π, tan²θh = β² u/(1−u).
    fn albedo(tau0: f64, beta: f64, eta: f64, mu_i: f64) -> f64 {
        let wi = dir_mu(mu_i, 0.0);
        let ti = 1.0 - fresnel_dielectric(mu_i, eta);
        let mut diffuse = 0.0;
        for (mo, wt) in composite(50, 20, 0.0, 1.0) {
            let w = weight(tau0, beta, mu_i, mo);
            let fg = ti * (1.0 - fresnel_dielectric(mo, eta)) / PI;
            diffuse += wt * (w * fg + (1.0 - w) / PI) * mo * 2.0 * PI;
        }
        let l0 = lambda0(tau0);
        let g1i = g1(tau0, beta, mu_i);
        let nphi = 256;
        let mut spec = 0.0;
        for (u, wt) in composite(400, 8, 0.0, 1.0) {
            let tan_h = beta * (u / (1.0 - u)).sqrt();
            let ch = 1.0 / (1.0 + tan_h * tan_h).sqrt();
            let sh = tan_h * ch;
            let mut acc = 0.0;
            for k in 0..nphi {
                // φ ∈ [0, π], doubled by symmetry
                let phi = PI * (k as f64 + 0.5) / nphi as f64;
                let h = DVec3::new(sh * phi.cos(), sh * phi.sin(), ch);
                let ih = wi.dot(h);
                if ih <= 0.0 {
                    continue;
                }
                let wo = 2.0 * ih * h - wi;
                if wo.z <= 0.0 {
                    continue;
                }
                let w = weight(tau0, beta, mu_i, wo.z);
                acc +=
                    w * fresnel_dielectric(ih, eta) * g1i * g1(tau0, beta, wo.z) * ih / (mu_i * ch);
            }
            spec += wt * (l0 / tau0) * (-l0 * u).exp() * acc / nphi as f64;
        }
        diffuse + spec
    }

    #[test]
    fn albedo_quadrature_is_the_full_model() {
        // The albedo's integrand pieces are the model's: spot-check f = w f_grain + (1−w) ρ/π
        // and the D cos θh change of variables (D at one h).
        let m = Model::parse("rmg(lambert)", 1).unwrap();
        let p = m
            .params_from_assignments("tau0=0.5,beta=0.3,rho_g=1,eta_g=1.5,base.rho=1")
            .unwrap();
        let (wi, wo) = (dir_mu(0.5, 0.0), dir_mu(0.6, 2.5));
        let w = weight(0.5, 0.3, 0.5, 0.6);
        let expect = w * rough_grain(0.5, 0.3, 1.5, 1.0, wi, wo) + (1.0 - w) / PI;
        assert!((m.eval(&p, 0, wi, wo) - expect).abs() < 1e-14);
        let u: f64 = 0.37;
        let tan2 = 0.09 * u / (1.0 - u);
        let ch = 1.0 / (1.0 + tan2).sqrt();
        let h = DVec3::new((1.0 - ch * ch).sqrt(), 0.0, ch);
        let l0 = lambda0(0.5);
        // dω = 2π d(cos) ... D cos θh · |d cos θh / du| · 2π = (Λ0/τ0) e^{−Λ0 u}
        let dc_du = 0.5 * 0.09 * ch * ch * ch / ((1.0 - u) * (1.0 - u));
        let lhs = ndf(0.5, 0.3, h) * ch * dc_du * 2.0 * PI;
        let rhs = (l0 / 0.5) * (-l0 * u).exp();
        assert!((lhs - rhs).abs() < 1e-12 * rhs, "{lhs} {rhs}");
    }

    /// Albedo with a white Lambert base and white grains: ≤ 1 + 2e-4 (the quadrature's
    /// error, cross-checked against two 4e6-sample Monte-Carlo values of the research:
    /// 0.9396 ± 3e-4 at (τ0, β, η, θi) = (0.5, 0.3, 1.5, 60°) and 0.7003 ± 5e-4 at
    /// (0.999, 1, 5, 80°)); η_g = 1 makes F = 0, f ≡ 1/π and the albedo exactly 1.
    #[test]
    fn albedo_is_at_most_one() {
        let a = albedo(0.5, 0.3, 1.5, 60f64.to_radians().cos());
        assert!((a - 0.9396).abs() < 1e-3, "{a}");
        let a = albedo(0.999, 1.0, 5.0, 80f64.to_radians().cos());
        assert!((a - 0.7003).abs() < 2e-3, "{a}");
        for &tau0 in &[1e-3, 0.5, 0.999] {
            for &beta in &[0.05, 0.3, 1.0] {
                for &eta in &[1.0, 1.5, 5.0] {
                    for &ti in &[0.0f64, 30.0, 60.0, 85.0] {
                        let a = albedo(tau0, beta, eta, ti.to_radians().cos());
                        assert!(
                            a.is_finite() && a <= 1.0 + 2e-4,
                            "tau0 {tau0} beta {beta} eta {eta} theta_i {ti}: {a}"
                        );
                        if eta == 1.0 {
                            assert!((a - 1.0).abs() < 1e-9, "{a}");
                        }
                    }
                }
            }
        }
    }
}
