//! `M+aniso`: the microfacet lobes of M made anisotropic. Each lobe's roughness α becomes
//! two, α_u along the surface's tangent u and α_v along its bitangent v, and the tangent
//! frame is turned by φ0 (degrees) against the data's φ = 0: `ggx+aniso`,
//! `fa(B)+aniso` (the highlight), `M+coat+aniso` (the coat), `btdf(tr|beckmann|gg)+aniso`
//! (transmission with β_u, β_v for the generalized Gaussian). At α_u = α_v every form is
//! its isotropic model for any φ0, so M embeds in `M+aniso` (diagnose's F test).
//! Twin: `shaders/bsdf/aniso.wgsl`.
//!
//! The distributions are the stretched forms of Heitz 2014 ("Understanding the
//! Masking-Shadowing Function", §5.3): with the slopes of m scaled by 1/α_u and 1/α_v the
//! distribution is the α = 1 one, so, in the tangent frame (x along u, y along v),
//!
//! - GGX (Heitz 2014, Eq. 85 and 86; Burley 2012, Eq. 13):
//!   D(m) = 1 / (π α_u α_v ((m_x/α_u)² + (m_y/α_v)² + m_z²)²),
//!   Λ(ω) = ½ (√(1 + (α_u² ω_x² + α_v² ω_y²)/ω_z²) − 1);
//! - Beckmann: D(m) = exp(−((m_x/α_u)² + (m_y/α_v)²)/m_z²) / (π α_u α_v m_z⁴), masked by
//!   the GGX Λ above (as the isotropic `btdf(beckmann)`, after the benchmark paper);
//! - generalized Gaussian (Holzschuch & Pacanowski 2017): D(m) = p / (π β_u β_v Γ(1/p))
//!   exp(−(((m_x/β_u)² + (m_y/β_v)²)/m_z²)^p) / m_z⁴, its Λ the isotropic table at the
//!   projected width √(β_u² ω_x² + β_v² ω_y²) in place of β sinθ.
//!
//! Every form takes the directions turned into the tangent frame ([`Frame::local`]);
//! Fresnel factors, half vectors and the refraction geometry do not depend on the
//! azimuth, so the rest of each model is its isotropic code. Like the isotropic forms,
//! none computes 1 − cos²θ.
//!
//! The parametrisation has a symmetry: (α_u, α_v, φ0) and (α_v, α_u, φ0 ± 90°) are the
//! same surface, so φ0 ranges over [−90°, 90°] and every surface is found with
//! |φ0| ≤ 45°, away from the bounds; fits report that form ([`Bsdf::frame_params`]).

use super::btdf::{walter_transmission, Ndf};
use super::effect::{Adds, Effect};
use super::ggx::{ETA, KS};
use super::microfacet::{gg_lambda_table, Distribution, Gg, Masking, C2_MIN, MICROFACET_WGSL};
use super::{
    each_direction, Bsdf, Channels, Children, Dir, Entry, InCatalogue, Node, ParamDecl, Role,
    WgslFn,
};
use crate::data::Kind;
use crate::math::{fresnel_dielectric, fresnel_transmittance};
use glam::DVec3;
use std::f64::consts::PI;
use std::sync::Arc;

const ANISO_WGSL: (&str, &str) = ("aniso", include_str!("../../shaders/bsdf/aniso.wgsl"));

/// Registry entry: a suffix of either kind.
pub const ENTRY: Entry = Entry::suffix(
    "aniso",
    None,
    // For data on several planes, beside `+peraxis`: the scaled BTDFs as one anisotropic
    // surface.
    InCatalogue::MultiPlaneAfter("scale"),
    "anisotropic microfacet lobes: alpha_u, alpha_v and the tangent azimuth phi0 (ggx, fa, +coat, btdf tr/beckmann/gg)",
    build,
)
// α_u = α_v is M for any φ0. Only data on two or more planes (or off-plane) can tell
// α_u from α_v: one plane sees one combination of them.
.adding(&[Adds::appended(Effect::Anisotropy).on_planes(2)]);

pub const ALPHA_U: ParamDecl =
    ParamDecl::shared("alpha_u", 1e-3, 1.0, 0.2, "GGX roughness along the tangent u")
        .log()
        .lobe_width()
        .needs_planes();
pub const ALPHA_V: ParamDecl =
    ParamDecl::shared("alpha_v", 1e-3, 1.0, 0.2, "GGX roughness along the bitangent v")
        .log()
        .lobe_width()
        .needs_planes();
pub const PHI0: ParamDecl = ParamDecl::shared(
    "phi0",
    -90.0,
    90.0,
    0.0,
    "azimuth of the tangent u against the data's phi = 0 (degrees)",
)
.needs_planes();
pub const BETA_U: ParamDecl = ParamDecl::shared(
    "beta_u",
    3e-3,
    1.0,
    0.2,
    "generalized Gaussian width along the tangent u",
)
.log()
.needs_planes();
pub const BETA_V: ParamDecl = ParamDecl::shared(
    "beta_v",
    3e-3,
    1.0,
    0.2,
    "generalized Gaussian width along the bitangent v",
)
.log()
.needs_planes();

/// The surface's tangent frame, turned by φ0 about the normal.
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    cos: f64,
    sin: f64,
}

impl Frame {
    /// The frame whose tangent u lies at azimuth `phi0_deg` (degrees).
    pub fn new(phi0_deg: f64) -> Frame {
        let (sin, cos) = phi0_deg.to_radians().sin_cos();
        Frame { cos, sin }
    }
    /// `w` in the tangent frame: (w·u, w·v, w·n).
    #[inline]
    pub fn local(&self, w: DVec3) -> DVec3 {
        DVec3::new(
            w.x * self.cos + w.y * self.sin,
            w.y * self.cos - w.x * self.sin,
            w.z,
        )
    }
}

/// (α_u ω_x)² + (α_v ω_y)²: α² sin²θ of the isotropic forms.
#[inline]
fn projected2(au: f64, av: f64, w: DVec3) -> f64 {
    let (x, y) = (au * w.x, av * w.y);
    x * x + y * y
}

/// (m_x/α_u)² + (m_y/α_v)²: sin²θ/α² of the isotropic forms.
#[inline]
fn stretched2(au: f64, av: f64, m: DVec3) -> f64 {
    let (x, y) = (m.x / au, m.y / av);
    x * x + y * y
}

/// Anisotropic GGX (Trowbridge–Reitz) in the tangent frame.
#[derive(Clone, Copy, Debug)]
pub struct AnisoGgx {
    pub au: f64,
    pub av: f64,
}

impl Distribution for AnisoGgx {
    fn d(&self, m: DVec3) -> f64 {
        if m.z <= 0.0 {
            return 0.0;
        }
        let t = stretched2(self.au, self.av, m) + m.z * m.z;
        1.0 / (PI * self.au * self.av * t * t)
    }
}

impl Masking for AnisoGgx {
    fn lambda(&self, w: DVec3) -> f64 {
        let mu = w.z.abs();
        let as2 = projected2(self.au, self.av, w);
        as2 / (2.0 * mu * (mu + (mu * mu + as2).sqrt()))
    }
    fn g1_over_mu(&self, w: DVec3) -> f64 {
        let mu = w.z.abs();
        2.0 / (mu + (mu * mu + projected2(self.au, self.av, w)).sqrt())
    }
}

impl AnisoGgx {
    /// D(h) G1(ωi, h) G1(ωo, h) / (4 μi μo) at `m`, any positive multiple of the half
    /// vector: with G1(ω) = 2μ/(μ + r), r = √(μ² + α_u² ω_x² + α_v² ω_y²), the μi μo
    /// cancel, and D(m/|m|) = |m|⁴ / (π α_u α_v t²), t = (m_x/α_u)² + (m_y/α_v)² + m_z²,
    /// so the kernel is |m|⁴ / (π α_u α_v t² (μi + ri)(μo + ro)) (the isotropic
    /// [`super::microfacet::Ggx::reflection`] at α_u = α_v). ωi and ωo above.
    #[inline]
    pub fn reflection(&self, wi: DVec3, wo: DVec3, m: DVec3) -> f64 {
        if m.z <= 0.0 || wi.dot(m) * wi.z <= 0.0 || wo.dot(m) * wo.z <= 0.0 {
            return 0.0;
        }
        let t = stretched2(self.au, self.av, m) + m.z * m.z;
        let m2 = m.length_squared();
        let r = |w: DVec3| {
            let mu = w.z.abs();
            mu + (mu * mu + projected2(self.au, self.av, w)).sqrt()
        };
        m2 * m2 / (PI * self.au * self.av * t * t * r(wi) * r(wo))
    }
}

/// Anisotropic Beckmann in the tangent frame.
#[derive(Clone, Copy, Debug)]
pub struct AnisoBeckmann {
    pub au: f64,
    pub av: f64,
}

impl Distribution for AnisoBeckmann {
    fn d(&self, m: DVec3) -> f64 {
        let c2 = m.z * m.z;
        if m.z <= 0.0 || c2 < C2_MIN {
            return 0.0;
        }
        (-stretched2(self.au, self.av, m) / c2 - 2.0 * c2.ln()).exp() / (PI * self.au * self.av)
    }
}

/// Anisotropic generalized Gaussian in the tangent frame: the isotropic form's shape
/// constants (they depend on p alone) with its own normalisation and widths.
#[derive(Clone, Copy, Debug)]
pub struct AnisoGg {
    pub bu: f64,
    pub bv: f64,
    shape: Gg,
    /// ln(p / (π β_u β_v Γ(1/p))).
    ln_norm: f64,
}

impl AnisoGg {
    pub fn new(bu: f64, bv: f64, p: f64) -> AnisoGg {
        let shape = Gg::new(1.0, p);
        AnisoGg {
            bu,
            bv,
            ln_norm: shape.ln_norm - (bu * bv).ln(),
            shape,
        }
    }
    /// (μ, μΛ) as the isotropic form, with β sinθ → √(β_u² ω_x² + β_v² ω_y²).
    fn mu_lambda(&self, w: DVec3) -> (f64, f64) {
        let bs = projected2(self.bu, self.bv, w).sqrt();
        self.shape.mu_lambda_at(w.z.abs(), bs)
    }
}

impl Distribution for AnisoGg {
    fn d(&self, m: DVec3) -> f64 {
        let c2 = m.z * m.z;
        if m.z <= 0.0 || c2 < C2_MIN {
            return 0.0;
        }
        self.shape
            .d_at(self.ln_norm, stretched2(self.bu, self.bv, m) / c2, c2)
    }
}

impl Masking for AnisoGg {
    fn lambda(&self, w: DVec3) -> f64 {
        let (mu, mu_lambda) = self.mu_lambda(w);
        mu_lambda / mu
    }
    fn g1_over_mu(&self, w: DVec3) -> f64 {
        let (mu, mu_lambda) = self.mu_lambda(w);
        1.0 / (mu + mu_lambda)
    }
}

/// The anisotropic GGX reflection lobe k_s F(ωi·h; η) D G1 G1 / (4 μi μo), directions in
/// the data's frame.
pub fn ggx_aniso_reflect(
    ks: f64,
    au: f64,
    av: f64,
    frame: Frame,
    eta: f64,
    wi: DVec3,
    wo: DVec3,
) -> f64 {
    ks * lobe_kernel(au, av, frame, eta, wi, wo)
}

/// What the channels of one direction share: F(ωi·h; η) · D G1 G1 / (4 μi μo), 0 below
/// the surface (k_s is the lobe's only rgb parameter).
#[inline]
fn lobe_kernel(au: f64, av: f64, frame: Frame, eta: f64, wi: DVec3, wo: DVec3) -> f64 {
    if wi.z <= 0.0 || wo.z <= 0.0 {
        return 0.0;
    }
    let (li, lo) = (frame.local(wi), frame.local(wo));
    let sum = li + lo;
    let len = sum.length();
    let (m, cos_h) = if len < 1e-12 {
        (DVec3::Z, li.z)
    } else {
        (sum, 0.5 * len)
    };
    fresnel_dielectric(cos_h, eta) * AnisoGgx { au, av }.reflection(li, lo, m)
}

// ---------------------------------------------------------------------------------------
// Nodes: the anisotropic form of each lobe. Their entries are not registered (the spec
// names them as `M+aniso`); each carries its isotropic model's name, kind and role.

/// `ggx` made anisotropic: k_s, α_u, α_v, φ0, η.
#[derive(Debug, Clone, Copy)]
pub struct GgxAniso;

const GGX_ENTRY: Entry = Entry::leaf(
    "ggx",
    Kind::Brdf,
    Role::SpecularLobe,
    "GGX microfacet reflection, anisotropic",
    || Node::leaf(GgxAniso),
);

impl Bsdf for GgxAniso {
    fn entry(&self) -> &'static Entry {
        &GGX_ENTRY
    }
    fn frame_params(&self) -> Option<[usize; 3]> {
        Some([1, 2, 3])
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![KS, ALPHA_U, ALPHA_V, PHI0, ETA]
    }
    fn eval(&self, p: &[f64], wi: DVec3, wo: DVec3, _children: &[f64]) -> f64 {
        ggx_aniso_reflect(p[0], p[1], p[2], Frame::new(p[3]), p[4], wi, wo)
    }
    fn eval_channels(&self, p: Channels, dirs: &[Dir], _: Children, out: &mut [f64]) {
        let (au, av, frame, eta) = (p.get(0, 1), p.get(0, 2), Frame::new(p.get(0, 3)), p.get(0, 4));
        each_direction(dirs, p.len(), out, |_, wi, wo, out| {
            let lobe = lobe_kernel(au, av, frame, eta, wi, wo);
            for (i, o) in out.iter_mut().enumerate() {
                *o = p.get(i, 0) * lobe;
            }
        });
    }
    fn wgsl(&self) -> WgslFn {
        aniso_wgsl("ggx_aniso_eval")
    }
}

/// `fa(B)` with an anisotropic highlight: lobe.α_u, lobe.α_v, lobe.φ0, lobe.η, lobe.k_s.
#[derive(Debug, Clone, Copy)]
pub struct FaAniso;

const FA_ENTRY: Entry = Entry::layer(
    "fa",
    Kind::Brdf,
    &[Role::DiffuseBase],
    "Fresnel aggregate with an anisotropic GGX lobe",
    |base| Node::with(FaAniso, vec![base]),
);

impl Bsdf for FaAniso {
    fn entry(&self) -> &'static Entry {
        &FA_ENTRY
    }
    fn frame_params(&self) -> Option<[usize; 3]> {
        Some([0, 1, 2])
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![
            ALPHA_U.renamed("lobe.alpha_u"),
            ALPHA_V.renamed("lobe.alpha_v"),
            PHI0.renamed("lobe.phi0"),
            ETA.renamed("lobe.eta"),
            KS.renamed("lobe.ks"),
        ]
    }
    fn child_roles(&self) -> &'static [&'static str] {
        &["base"]
    }
    fn eval(&self, p: &[f64], wi: DVec3, wo: DVec3, children: &[f64]) -> f64 {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return 0.0;
        }
        let eta = p[3];
        let transmit = fresnel_transmittance(wi.z, eta) * fresnel_transmittance(wo.z, eta);
        ggx_aniso_reflect(p[4], p[0], p[1], Frame::new(p[2]), eta, wi, wo) + transmit * children[0]
    }
    fn eval_channels(&self, p: Channels, dirs: &[Dir], base: Children, out: &mut [f64]) {
        let (au, av, frame, eta) = (p.get(0, 0), p.get(0, 1), Frame::new(p.get(0, 2)), p.get(0, 3));
        each_direction(dirs, p.len(), out, |d, wi, wo, out| {
            if wi.z <= 0.0 || wo.z <= 0.0 {
                out.fill(0.0);
                return;
            }
            let transmit = fresnel_transmittance(wi.z, eta) * fresnel_transmittance(wo.z, eta);
            let lobe = lobe_kernel(au, av, frame, eta, wi, wo);
            for (i, (o, &b)) in out.iter_mut().zip(base.at(0, d)).enumerate() {
                *o = p.get(i, 4) * lobe + transmit * b;
            }
        });
    }
    fn wgsl(&self) -> WgslFn {
        aniso_wgsl("fa_aniso_eval")
    }
}

/// `M+coat` with an anisotropic coat: k_c, α_c,u, α_c,v, φ0_c.
#[derive(Debug, Clone, Copy)]
pub struct CoatAniso;

const COAT_ENTRY: Entry = Entry::suffix(
    "coat",
    Some(Kind::Brdf),
    InCatalogue::No,
    "a second GGX lobe, anisotropic",
    |inner| Ok(Node::with(CoatAniso, vec![inner])),
);

impl Bsdf for CoatAniso {
    fn entry(&self) -> &'static Entry {
        &COAT_ENTRY
    }
    fn frame_params(&self) -> Option<[usize; 3]> {
        Some([1, 2, 3])
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![
            super::coat::KC,
            ALPHA_U.renamed("alpha_c_u"),
            ALPHA_V.renamed("alpha_c_v"),
            PHI0.renamed("phi0_c"),
        ]
    }
    fn child_roles(&self) -> &'static [&'static str] {
        &[""]
    }
    fn eval(&self, p: &[f64], wi: DVec3, wo: DVec3, children: &[f64]) -> f64 {
        let kernel = if wi.z <= 0.0 || wo.z <= 0.0 {
            0.0
        } else {
            let frame = Frame::new(p[3]);
            let (li, lo) = (frame.local(wi), frame.local(wo));
            AnisoGgx { au: p[1], av: p[2] }.reflection(li, lo, li + lo)
        };
        (1.0 - p[0]) * children[0] + p[0] * kernel
    }
    fn wgsl(&self) -> WgslFn {
        aniso_wgsl("coat_aniso_eval")
    }
}

/// `btdf(ndf)` with an anisotropic distribution: α_u, α_v, φ0, η (tr, beckmann) or
/// β_u, β_v, φ0, p, η (gg).
#[derive(Debug, Clone, Copy)]
pub struct BtdfAniso {
    pub ndf: Ndf,
}

const BTDF_ENTRY: Entry = Entry::term(
    "btdf",
    Kind::Btdf,
    Role::Transmission,
    "Walter 2007 microfacet transmission, anisotropic",
    |_| Err("the anisotropic forms are made by +aniso".into()),
);

impl BtdfAniso {
    /// The NDFs with an anisotropic form (GTR is not shape-invariant: stretching its
    /// slopes does not give a GTR).
    pub fn of(ndf: Ndf) -> Option<BtdfAniso> {
        matches!(ndf, Ndf::Tr | Ndf::Beckmann | Ndf::Gg).then_some(BtdfAniso { ndf })
    }
}

impl Bsdf for BtdfAniso {
    fn entry(&self) -> &'static Entry {
        &BTDF_ENTRY
    }
    fn frame_params(&self) -> Option<[usize; 3]> {
        Some([0, 1, 2])
    }
    fn params(&self) -> Vec<ParamDecl> {
        match self.ndf {
            Ndf::Gg => vec![BETA_U, BETA_V, PHI0, super::btdf::P_SHAPE, super::btdf::ETA],
            _ => vec![ALPHA_U, ALPHA_V, PHI0, super::btdf::ETA],
        }
    }
    fn eval(&self, p: &[f64], wi: DVec3, wo: DVec3, _children: &[f64]) -> f64 {
        let frame = Frame::new(p[2]);
        let (li, lo) = (frame.local(wi), frame.local(wo));
        let tr = AnisoGgx { au: p[0], av: p[1] };
        match self.ndf {
            Ndf::Tr => walter_transmission(li, lo, p[3], &tr, &tr),
            Ndf::Beckmann => {
                walter_transmission(li, lo, p[3], &AnisoBeckmann { au: p[0], av: p[1] }, &tr)
            }
            _ => {
                let gg = AnisoGg::new(p[0], p[1], p[3]);
                walter_transmission(li, lo, p[4], &gg, &gg)
            }
        }
    }
    fn reciprocal(&self) -> bool {
        false
    }
    fn wgsl(&self) -> WgslFn {
        aniso_wgsl(match self.ndf {
            Ndf::Tr => "btdf_aniso_tr_eval",
            Ndf::Beckmann => "btdf_aniso_beckmann_eval",
            _ => "btdf_aniso_gg_eval",
        })
    }
    fn lut(&self) -> Option<Vec<f32>> {
        (self.ndf == Ndf::Gg).then(|| gg_lambda_table().to_f32())
    }
}

fn aniso_wgsl(function: &str) -> WgslFn {
    WgslFn {
        sources: vec![MICROFACET_WGSL, super::btdf::BTDF_WGSL, ANISO_WGSL],
        function: function.into(),
    }
}

/// The `+aniso` node: passes its inner model's value through (the anisotropy lives in
/// the lobes [`build`] put in place of the isotropic ones).
#[derive(Debug, Clone, Copy)]
pub struct Aniso {
    kind: Kind,
}

impl super::kernel::PassThrough for Aniso {}

impl Bsdf for Aniso {
    fn entry(&self) -> &'static Entry {
        &ENTRY
    }
    fn kind(&self) -> Kind {
        self.kind
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![]
    }
    fn child_roles(&self) -> &'static [&'static str] {
        &[""]
    }
    super::kernel::kernel_methods!();
    fn reciprocal(&self) -> bool {
        // ggx and fa stay reciprocal (the frame turns both directions); btdf never was.
        self.kind == Kind::Brdf
    }
    fn wgsl(&self) -> WgslFn {
        aniso_wgsl("aniso_eval")
    }
}

/// Replace every lobe of `inner` that has an anisotropic form ([`Bsdf::anisotropic`]) by
/// it, and wrap the result in the pass-through `+aniso` node.
pub fn build(inner: Node) -> Result<Node, String> {
    let kind = inner.bsdf.kind();
    let (swapped, count, names) = inner.with_forms(&|b| b.anisotropic());
    if names.contains(&ENTRY.name) || names.contains(&super::peraxis::ENTRY.name) {
        return Err(
            "+aniso given twice, or with +peraxis (one surface, or one roughness per plane: not both)"
                .into(),
        );
    }
    if count == 0 {
        return Err(
            "+aniso needs a microfacet lobe with an anisotropic form: ggx, fa(B), +coat, or btdf(tr|beckmann|gg)"
                .into(),
        );
    }
    Ok(Node::with(Aniso { kind }, vec![swapped]))
}

/// The anisotropic forms, as [`Bsdf::anisotropic`] hands them out.
pub fn ggx() -> Arc<dyn Bsdf> {
    Arc::new(GgxAniso)
}
pub fn fa() -> Arc<dyn Bsdf> {
    Arc::new(FaAniso)
}
pub fn coat() -> Arc<dyn Bsdf> {
    Arc::new(CoatAniso)
}
pub fn btdf(ndf: Ndf) -> Option<Arc<dyn Bsdf>> {
    BtdfAniso::of(ndf).map(|b| Arc::new(b) as Arc<dyn Bsdf>)
}
