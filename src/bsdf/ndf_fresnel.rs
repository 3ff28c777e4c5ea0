//! A GGX lobe with both its microfacet distribution and its Fresnel curve data-driven:
//! the form `M+ndf+fresnel` (or `M+fresnel+ndf`) puts in place of each GGX highlight.
//! In channel c the lobe is
//!
//!   k_s,c · F(θd; η) · exp(s_c(θd)) · D(h) G1(ωi) G1(ωo) / (4 μi μo),
//!
//! D = D_GGX(α) exp(t(θm)) / N the tabulated NDF of [`super::ndf`] with the Smith masking
//! of that same D, and exp(s_c) the per-channel Fresnel curve of [`super::fresnel`]. The
//! two factors depend on different angles (θm of the half vector against the normal, θd
//! between ωi and the half vector), so neither can take the other's shape; with the body
//! profile (`+body`) the three factors of a tabulated microfacet model are all free. At
//! t = 0 it is `M+fresnel`, at s = 0 `M+ndf`: each embeds (diagnose's F test). The
//! parameters are `+ndf`'s, then `+fresnel`'s knots, with k_s bounded as `+fresnel`'s.
//!
//! Not registered: `+fresnel` puts these forms in place of `+ndf`'s lobes and `+ndf` in
//! place of `+fresnel`'s ([`super::registry::ggx_form`]).
//!
//! Twin: `shaders/bsdf/ndf_fresnel.wgsl`.

use super::coat::blend_block_with;
use super::fa::aggregate_block_with;
use super::fresnel::{coat_curve, curved, KS_SCALE};
use super::ggx::{lobe_block_with, GgxLobe, ALPHA, ETA};
use super::kernel::{Kernel, LaneChildren, LaneDir};
use super::microfacet::MICROFACET_WGSL;
use super::{fresnel, ndf, Bsdf, Channels, Entry, InCatalogue, Node, ParamDecl, Role, WgslFn};
use crate::data::Kind;
use crate::math::lanes::Real;

/// Free knots of the NDF: the Fresnel knots follow them.
const NDF_FREE: usize = ndf::KNOTS - 1;

const NDF_FRESNEL_WGSL: (&str, &str) = (
    "ndf_fresnel",
    include_str!("../../shaders/bsdf/ndf_fresnel.wgsl"),
);

/// `ggx` with a data-driven NDF and Fresnel curve: ks, alpha, eta, ndf1 … 15, fresnel1 … 8.
#[derive(Debug, Clone, Copy)]
pub struct GgxNdfFresnel;

const GGX_ENTRY: Entry = Entry::leaf(
    "ggx",
    Kind::Brdf,
    Role::SpecularLobe,
    "GGX reflection with a data-driven NDF and Fresnel curve",
    || Node::leaf(GgxNdfFresnel),
);

impl Kernel for GgxNdfFresnel {
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], _: LaneChildren<R>, out: &mut [R]) {
        let eta = p.get(0, 2);
        let tab = ndf::table(p.get(0, 1), |k| p.get(0, 3 + k));
        lobe_block_with(
            p,
            dirs,
            out,
            #[inline(always)]
            |wi, wo| GgxLobe::at_with(eta, wi, wo, |m| tab.reflection(wi, wo, m)),
            #[inline(always)]
            |lobe, i| curved(lobe, p, i, 0, 3 + NDF_FREE),
        );
    }
}

impl Bsdf for GgxNdfFresnel {
    fn ggx_lobe(&self) -> Option<(super::GgxPlace, super::Tabulated)> {
        Some((
            super::GgxPlace::Ggx,
            super::Tabulated {
                ndf: true,
                fresnel: true,
            },
        ))
    }
    fn bounded_albedo(&self) -> bool {
        false // k_s F e^s has no bound of 1 (see fresnel.rs)
    }
    fn entry(&self) -> &'static Entry {
        &GGX_ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        [KS_SCALE, ALPHA, ETA]
            .into_iter()
            .chain(ndf::knots(&ndf::NAMES))
            .chain(fresnel::knots(&fresnel::NAMES))
            .collect()
    }
    super::kernel::kernel_methods!();
    fn wgsl(&self) -> WgslFn {
        wgsl("ggx_ndf_fresnel_eval")
    }
    fn wgsl_prepare(&self) -> Option<&'static str> {
        Some("ggx_ndf_fresnel_prepare")
    }
}

/// `fa(B)` whose highlight has a data-driven NDF and Fresnel curve: lobe.alpha, lobe.eta,
/// lobe.ks, lobe.ndf1 … 15, lobe.fresnel1 … 8; the base's transmittance stays dielectric.
#[derive(Debug, Clone, Copy)]
pub struct FaNdfFresnel;

const FA_ENTRY: Entry = Entry::layer(
    "fa",
    Kind::Brdf,
    &[Role::DiffuseBase],
    "Fresnel aggregate whose highlight has a data-driven NDF and Fresnel curve",
    |base| Node::with(FaNdfFresnel, vec![base]),
);

impl Kernel for FaNdfFresnel {
    #[inline(always)]
    fn block<R: Real>(
        &self,
        p: Channels,
        dirs: &[LaneDir<R>],
        base: LaneChildren<R>,
        out: &mut [R],
    ) {
        let eta = p.get(0, 1);
        let tab = ndf::table(p.get(0, 0), |k| p.get(0, 3 + k));
        aggregate_block_with(
            p,
            p.get(0, 1),
            dirs,
            base,
            out,
            #[inline(always)]
            |wi, wo| GgxLobe::at_with(eta, wi, wo, |m| tab.reflection(wi, wo, m)),
            #[inline(always)]
            |lobe, i| curved(lobe, p, i, 2, 3 + NDF_FREE),
        );
    }
}

impl Bsdf for FaNdfFresnel {
    fn ggx_lobe(&self) -> Option<(super::GgxPlace, super::Tabulated)> {
        Some((
            super::GgxPlace::Aggregate,
            super::Tabulated {
                ndf: true,
                fresnel: true,
            },
        ))
    }
    fn bounded_albedo(&self) -> bool {
        false // k_s F e^s has no bound of 1 (see fresnel.rs)
    }
    fn entry(&self) -> &'static Entry {
        &FA_ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        [
            ALPHA.renamed("lobe.alpha"),
            ETA.renamed("lobe.eta"),
            KS_SCALE.renamed("lobe.ks"),
        ]
        .into_iter()
        .chain(ndf::knots(&ndf::LOBE_NAMES))
        .chain(fresnel::knots(&fresnel::LOBE_NAMES))
        .collect()
    }
    fn child_roles(&self) -> &'static [&'static str] {
        &["base"]
    }
    super::kernel::kernel_methods!();
    fn wgsl(&self) -> WgslFn {
        wgsl("fa_ndf_fresnel_eval")
    }
    fn wgsl_prepare(&self) -> Option<&'static str> {
        Some("fa_ndf_fresnel_prepare")
    }
}

/// `M+coat` whose coat lobe has a data-driven NDF and angular reflectance: kc, alpha_c,
/// ndf_c1 … 15, fresnel_c1 … 8 (the coat has no Fresnel factor: k_c e^{s(θd)}).
#[derive(Debug, Clone, Copy)]
pub struct CoatNdfFresnel;

const COAT_ENTRY: Entry = Entry::suffix(
    "coat",
    Some(Kind::Brdf),
    InCatalogue::No,
    "a second GGX lobe with a data-driven NDF and angular reflectance",
    |inner| Ok(Node::with(CoatNdfFresnel, vec![inner])),
);

impl Kernel for CoatNdfFresnel {
    #[inline(always)]
    fn block<R: Real>(
        &self,
        p: Channels,
        dirs: &[LaneDir<R>],
        inner: LaneChildren<R>,
        out: &mut [R],
    ) {
        let tab = ndf::table(p.get(0, 1), |k| p.get(0, 2 + k));
        blend_block_with(
            p,
            dirs,
            inner,
            out,
            #[inline(always)]
            |wi, wo| tab.reflection(wi, wo, wi + wo),
            #[inline(always)]
            |i, wi, wo| coat_curve(p, i, 2 + NDF_FREE, wi, wo),
        );
    }
}

impl Bsdf for CoatNdfFresnel {
    fn ggx_lobe(&self) -> Option<(super::GgxPlace, super::Tabulated)> {
        Some((
            super::GgxPlace::Coat,
            super::Tabulated {
                ndf: true,
                fresnel: true,
            },
        ))
    }
    fn bounded_albedo(&self) -> bool {
        false // k_c e^s has no bound of 1 (see fresnel.rs)
    }
    fn entry(&self) -> &'static Entry {
        &COAT_ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        [super::coat::KC, super::coat::ALPHA_C]
            .into_iter()
            .chain(ndf::knots(&ndf::COAT_NAMES))
            .chain(fresnel::knots(&fresnel::COAT_NAMES))
            .collect()
    }
    fn child_roles(&self) -> &'static [&'static str] {
        &[""]
    }
    super::kernel::kernel_methods!();
    fn wgsl(&self) -> WgslFn {
        wgsl("coat_ndf_fresnel_eval")
    }
    fn wgsl_prepare(&self) -> Option<&'static str> {
        Some("coat_ndf_fresnel_prepare")
    }
}

fn wgsl(function: &str) -> WgslFn {
    WgslFn {
        sources: vec![
            MICROFACET_WGSL,
            fresnel::KNOTS_WGSL,
            ndf::NDF_WGSL,
            NDF_FRESNEL_WGSL,
        ],
        function: function.into(),
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{assert_suffix_embeds, dir};
    use super::super::Model;
    use rand::{Rng, SeedableRng};

    /// The table the suffixes swap lobes through and what each node declares agree: the
    /// form handed out for a place and a set of tabulated factors declares that place
    /// and those factors (a node declaring another would be swapped for the wrong form).
    #[test]
    fn every_lobe_form_declares_what_the_table_hands_it_out_for() {
        use super::super::{registry::ggx_form, GgxPlace, Tabulated};
        use GgxPlace::{Aggregate, Coat, Ggx, Transmission};
        for place in [Ggx, Aggregate, Coat, Transmission] {
            for (ndf, fresnel) in [(false, false), (true, false), (false, true), (true, true)] {
                let tabulated = Tabulated { ndf, fresnel };
                let Some(form) = ggx_form(place, tabulated) else {
                    // A transmission lobe's Fresnel factor is not tabulated.
                    assert!(place == Transmission && fresnel, "{place:?} {tabulated:?}");
                    continue;
                };
                assert_eq!(
                    form.ggx_lobe(),
                    Some((place, tabulated)),
                    "{place:?} {tabulated:?}: {form:?}"
                );
            }
        }
    }

    /// At s = 0 the form is `M+ndf` value for value (`M+ndf+fresnel` embeds `M+ndf`, and so
    /// M within `+ndf`'s own table error), and `M+fresnel+ndf` is the same model as
    /// `M+ndf+fresnel`, on each of the three lobes.
    #[test]
    fn the_fresnel_curve_at_zero_is_the_ndf_form_and_the_order_does_not_matter() {
        for (seed, core) in ["ggx", "fa(lambert)", "lambert+coat", "fa(on)+coat"]
            .iter()
            .enumerate()
        {
            let both = assert_suffix_embeds(&format!("{core}+ndf"), "fresnel", seed as u64);
            let lobes = core.matches("fa").count()
                + core.matches("ggx").count()
                + core.matches("coat").count();
            let forms = both
                .nodes()
                .into_iter()
                .filter(|n| n.bsdf.wgsl().function.contains("ndf_fresnel"))
                .count();
            assert_eq!(forms, lobes, "{core}");
            let swapped = Model::parse(&format!("{core}+fresnel+ndf"), 3).unwrap();
            let names = both.flat_names();
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed as u64);
            for _ in 0..10 {
                let unit: Vec<f64> = (0..both.dim)
                    .map(|_| rng.random_range(0.05..0.95))
                    .collect();
                let p = both.from_unit(&unit);
                let q: Vec<f64> = swapped
                    .flat_names()
                    .iter()
                    .map(|n| p[names.iter().position(|m| m == n).unwrap()])
                    .collect();
                for c in 0..3 {
                    let (wi, wo) = (
                        dir(rng.random_range(0.0..1.5), 0.0),
                        dir(rng.random_range(0.0..1.5), rng.random_range(0.0..6.3)),
                    );
                    let (a, b) = (both.eval(&p, c, wi, wo), swapped.eval(&q, c, wi, wo));
                    assert!(a.is_finite() && a == b, "{core}: {a} {b}");
                }
            }
        }
    }
}
