//! `dmg(B)`: a layer of diffuse (Lambertian) micrograins over a base BRDF B, after Lucas,
//! Ribardière, Pacanowski, Barla, "A Micrograin BSDF Model for the Rendering of Porous
//! Layers", ACM TOG 42(6), 2023:
//! f = w·ρ_g/π + (1 − w)·f_B, with the grains' visibility weight
//! w = 1 − (1 − τ0)^{½(γβ(θi)/μi + γβ(θo)/μo)}, γβ(θ) = √(β² sin²θ + cos²θ) (Eqs. 21–23,
//! see [`super::micrograin`]). The Lambertian grain f_grain = ρ_g/π is the docs/models.md
//! simplification: the authors' renderer integrates a Lambertian microfacet over the
//! micrograin NDF stochastically, which has no closed form.
//!
//! Parameters: τ0 [1e-3, 0.999] (log scale, see [`super::micrograin::TAU0`]), β [1e-2, 1]
//! (linear: in dmg β only enters w through β² tan²θ, which matters for β ≳ 0.1, so a log box
//! would spend half its length where dmg hardly changes), ρ_g rgb [0, 1]; then B's as `base.*`.
//! B ∈ `lambert on eon vmf ggx`. Twins: `shaders/bsdf/micrograin.wgsl` +
//! `shaders/bsdf/dmg.wgsl` (with `microfacet.wgsl`).

use super::kernel::{lanes, Kernel, LaneChildren, LaneDir};
use super::micrograin::{
    layer, layer_wgsl, weight, weight_in, Grains, BETA_LO, MICROGRAIN_BASES, RHO_G, TAU0,
};
use super::effect::{Adds, Effect};
use super::{Bsdf, Channels, Entry, Node, ParamDecl, WgslFn};
use crate::data::Kind;
use crate::math::lanes::Real;
use glam::DVec3;
use std::f64::consts::FRAC_1_PI;

/// β of dmg: linear scale (see the module doc).
pub const BETA: ParamDecl =
    ParamDecl::shared("beta", BETA_LO, 1.0, 0.5, "grain height / radius").neutral_at_lo();

#[derive(Debug, Clone, Copy)]
pub struct DiffuseMicrograin;

/// The dmg layer over a base value `f_base`.
pub fn dmg_layer(tau0: f64, beta: f64, rho_g: f64, wi: DVec3, wo: DVec3, f_base: f64) -> f64 {
    if wi.z <= 0.0 || wo.z <= 0.0 {
        return 0.0;
    }
    layer(weight(tau0, beta, wi.z, wo.z), rho_g * FRAC_1_PI, f_base)
}

impl Kernel for DiffuseMicrograin {
    /// The visibility weight once per direction (τ0 and β are shared).
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], base: LaneChildren<R>, out: &mut [R]) {
        let grains = Grains::new(p.get(0, 0), p.get(0, 1));
        let zero = R::zero();
        for (d, (wi, wo), out) in lanes(dirs, p.len(), out) {
            let below = wi.z.le(zero) | wo.z.le(zero);
            let w = weight_in(&grains, wi.z, wo.z);
            for (i, (o, &b)) in out.iter_mut().zip(base.at(0, d)).enumerate() {
                let v = layer(w, R::splat(p.get(i, 2)) * R::splat(FRAC_1_PI), b);
                *o = R::select(below, zero, v);
            }
        }
    }
}

impl Bsdf for DiffuseMicrograin {
    fn entry(&self) -> &'static Entry {
        &ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![TAU0, BETA, RHO_G]
    }
    fn child_roles(&self) -> &'static [&'static str] {
        &["base"]
    }
    super::kernel::kernel_methods!();
    fn wgsl(&self) -> WgslFn {
        layer_wgsl("dmg", include_str!("../../shaders/bsdf/dmg.wgsl"))
    }
}

/// Registry entry (one line in [`super::registry::REGISTRY`]).
pub const ENTRY: Entry = Entry::layer(
    "dmg",
    Kind::Brdf,
    MICROGRAIN_BASES,
    "diffuse micrograin layer over a base B (Lucas et al. 2023): dmg(B)",
    |base| Node::with(DiffuseMicrograin, vec![base]),
)
// At the thinnest layer the base shows through unchanged: the grains darken it at grazing
// angles (Lucas et al. 2023).
.adding(&[Adds::wrapping(Effect::GrazingDecay)]);

#[cfg(test)]
mod tests {
    use super::super::micrograin::testutil::*;
    use super::super::Model;
    use super::*;
    use std::f64::consts::PI;

    fn model(base: &str, assign: &str) -> (Model, Vec<f64>) {
        let m = Model::parse(&format!("dmg({base})"), 1).unwrap();
        let p = m.params_from_assignments(assign).unwrap();
        (m, p)
    }

    #[test]
    fn parameters_are_named_and_laid_out() {
        let (m, _) = model("eon", "");
        let names: Vec<&str> = m.params.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(names, ["tau0", "beta", "rho_g", "base.rho", "base.r"]);
        assert!(Model::parse("dmg", 3).is_err());
        assert!(Model::parse("dmg(dmg(lambert))", 3).is_err());
    }

    /// τ0 at its lower bound 1e-3: for θi, θo ≤ 60° (E ≤ 2), w ≤ 2e-3, so
    /// |f − f_B| ≤ 2e-3·max(ρ_g/π, f_B). Checked on every base.
    #[test]
    fn tau0_lower_bound_reproduces_the_base() {
        for base in super::super::registry::bases_of(&ENTRY) {
            let (m, p) = model(base, "tau0=0.001,rho_g=0.9");
            let mb = Model::parse(base, 1).unwrap();
            let pb = p[3..].to_vec();
            for &mi in &[0.5, 0.7, 1.0] {
                for &mo in &[0.5, 0.8, 1.0] {
                    for &phi in &[0.0, 1.0, PI] {
                        let (wi, wo) = (dir_mu(mi, 0.0), dir_mu(mo, phi));
                        let (f, fb) = (m.eval(&p, 0, wi, wo), mb.eval(&pb, 0, wi, wo));
                        let tol = 2e-3 * fb.max(0.9 / PI) + 1e-15;
                        assert!((f - fb).abs() <= tol, "{base}: {f} vs {fb}");
                    }
                }
            }
        }
    }

    #[test]
    fn reciprocal_finite_and_non_negative_on_edge_grid() {
        for base in super::super::registry::bases_of(&ENTRY) {
            let m = Model::parse(&format!("dmg({base})"), 1).unwrap();
            let base_reciprocal = m.root.children[0].bsdf.reciprocal();
            for &tau0 in &[1e-3, 0.3, 0.999] {
                for &beta in &[BETA_LO, 0.4, 1.0] {
                    let b = if base == "ggx" { "base.ks" } else { "base.rho" };
                    let assign = format!("tau0={tau0},beta={beta},rho_g=0.7,{b}=0.4");
                    let p = m.params_from_assignments(&assign).unwrap();
                    for wi in edge_directions() {
                        for wo in edge_directions() {
                            let f = m.eval(&p, 0, wi, wo);
                            assert!(f.is_finite() && f >= 0.0, "{base} {assign} {wi} {wo}: {f}");
                            if base_reciprocal {
                                let r = m.eval(&p, 0, wo, wi);
                                assert!(
                                    (f - r).abs() <= 1e-9 * f.abs().max(1e-12),
                                    "{base}: {f} vs {r}"
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    /// With a white Lambert base and white grains the layer is white: albedo = 1 to 1e-10
    /// (w and ρ/π only depend on μo, so a 1-D Gauss–Legendre rule in μo suffices); and
    /// ≤ 1 whatever ρ_g, ρ ≤ 1.
    #[test]
    fn albedo_of_white_layer_is_one() {
        let (m, _) = model("lambert", "");
        for &tau0 in &[1e-3, 0.2, 0.7, 0.999] {
            for &beta in &[BETA_LO, 0.3, 1.0] {
                for &(rg, rb) in &[(1.0, 1.0), (0.3, 1.0), (1.0, 0.2)] {
                    let p = m
                        .params_from_assignments(&format!(
                            "tau0={tau0},beta={beta},rho_g={rg},base.rho={rb}"
                        ))
                        .unwrap();
                    for &ti in &[0.0f64, 30.0, 60.0, 80.0, 89.0] {
                        let wi = dir_mu(ti.to_radians().cos(), 0.0);
                        let mut a = 0.0;
                        for (mo, wt) in composite(50, 20, 0.0, 1.0) {
                            a += wt * m.eval(&p, 0, wi, dir_mu(mo, 0.5)) * mo * 2.0 * PI;
                        }
                        assert!(a <= 1.0 + 1e-10, "{tau0} {beta} {ti}: {a}");
                        if rg == 1.0 && rb == 1.0 {
                            assert!((a - 1.0).abs() < 1e-10, "{tau0} {beta} {ti}: {a}");
                        }
                    }
                }
            }
        }
    }
}
