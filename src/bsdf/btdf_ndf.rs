//! `btdf(tr)+ndf`: the transmission lobe of `btdf(tr)` with the data-driven NDF of
//! [`super::ndf`] (D = D_GGX(α) e^{s(θm)} / N on 32 knots, Smith masking from the same D),
//! which `+ndf` puts in place of the TR lobe. Walter's transmission (Eq. 1 of
//! [`super::btdf`]) is unchanged but for D and G1; the other distributions (Beckmann, GTR,
//! GG) are not GGX at zero deviation, so `+ndf` does not take them (they would not embed).
//!
//! Twin: `shaders/bsdf/btdf_ndf.wgsl` (with `btdf.wgsl` and `ndf.wgsl`).

use super::btdf::{walter_in, BTDF_WGSL};
use super::kernel::{lanes, Kernel, LaneChildren, LaneDir};
use super::microfacet::MICROFACET_WGSL;
use super::ndf::{knots, table, NAMES, NDF_WGSL};
use super::stretched::ANISO_WGSL;
use super::{Bsdf, Channels, Entry, ParamDecl, Role, WgslFn};
use crate::data::Kind;
use crate::math::lanes::Real;

const BTDF_NDF_WGSL: (&str, &str) = ("btdf_ndf", include_str!("../../shaders/bsdf/btdf_ndf.wgsl"));

/// `btdf(tr)` with the data-driven NDF: α, η, ndf1 … ndf31. Walter's transmission (Eq. 1
/// of [`super::btdf`]) with D from the table and the Smith G1(ω)/|μ| = 1/(|μ| + C(|μ|)) of
/// the same D, the masking of a direction below the surface taken at its |μ| (the
/// microsurface seen from the other side, as the analytic lobes take it). At s = 0 it is
/// `btdf(tr)` within the table's quadrature error, so `btdf(tr)` embeds in it.
#[derive(Debug, Clone, Copy)]
pub struct BtdfNdf;

const BTDF_ENTRY: Entry = Entry::term(
    "btdf",
    Kind::Btdf,
    Role::Transmission,
    "Walter 2007 microfacet transmission with a data-driven NDF",
    |_| Err("the data-driven form is made by +ndf".into()),
);

impl Kernel for BtdfNdf {
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], _: LaneChildren<R>, out: &mut [R]) {
        let eta = p.get(0, 1);
        let tab = table(p.get(0, 0), |k| p.get(0, 2 + k));
        for (_, (wi, wo), out) in lanes(dirs, p.len(), out) {
            let value = walter_in(
                wi,
                wo,
                eta,
                #[inline(always)]
                |m| tab.d_in(m),
                #[inline(always)]
                |w| tab.g1_over_mu(w),
            );
            out.fill(value);
        }
    }
}

impl Bsdf for BtdfNdf {
    fn ggx_lobe(&self) -> Option<(super::GgxPlace, super::Tabulated)> {
        Some((
            super::GgxPlace::Transmission,
            super::Tabulated {
                ndf: true,
                fresnel: false,
            },
        ))
    }
    fn entry(&self) -> &'static Entry {
        &BTDF_ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        [super::btdf::ALPHA, super::btdf::ETA]
            .into_iter()
            .chain(knots(&NAMES))
            .collect()
    }
    super::kernel::kernel_methods!();
    /// f(i, o) needs ωi above and ωo below, as `btdf(tr)`'s.
    fn reciprocal(&self) -> bool {
        false
    }
    fn wgsl(&self) -> WgslFn {
        WgslFn {
            sources: vec![
                MICROFACET_WGSL,
                ANISO_WGSL,
                BTDF_WGSL,
                NDF_WGSL,
                BTDF_NDF_WGSL,
            ],
            function: "btdf_ndf_eval".into(),
        }
    }
    fn wgsl_prepare(&self) -> Option<&'static str> {
        Some("btdf_ndf_prepare")
    }
}
