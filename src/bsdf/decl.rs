//! What a model declares once: its parameters ([`ParamDecl`]) and its registry [`Entry`]
//! (name, kind, role, documentation, builder). The catalogue, the base allow-lists,
//! `bsdfit models`, the per-plane variants, the kind of a spec and diagnose's extensions
//! and embeddings are all derived from these declarations (see [`super::registry`]).

use super::effect::Adds;
use super::spec::Ast;
use super::Node;
use crate::data::Kind;

/// The nodes that hold an isotropic GGX (Trowbridge–Reitz) lobe: `ggx`, the highlight of
/// `fa(B)`, the lobe of `+coat`, and the transmission lobe of `btdf(tr)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GgxPlace {
    Ggx,
    Aggregate,
    Coat,
    Transmission,
}

/// Which factors of a GGX lobe are tabulated: its NDF (`+ndf`), its Fresnel curve
/// (`+fresnel`), both or neither. A lobe's node declares it ([`super::Bsdf::ggx_lobe`]) and
/// the suffixes swap it for the node of the same place with one factor more
/// ([`super::registry::ggx_form`]), so no model file names another's forms.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Tabulated {
    pub ndf: bool,
    pub fresnel: bool,
}

/// How a parameter is mapped to the optimizers' unit box.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scale {
    Linear,
    /// Logarithmic, for parameters spanning decades (roughness); needs lo > 0.
    Log,
    /// Quadratic: value = lo + (hi − lo)·u², for a parameter that a model depends on
    /// through its square root near `lo` (VMF's roughness r: slope m ≈ √r), whose
    /// derivative is then finite at the bound.
    Quadratic,
    /// Quadratic towards `hi`: value = hi − (hi − lo)·(1 − u)², for a parameter that a
    /// model depends on through √(hi − value) (VMF's albedo: its order ≥ 4 residual
    /// uses √(1 − ρ)), whose derivative is then finite at the bound.
    QuadraticHi,
    /// Logit: ln(v/(1 − v)) linear in u, for a fraction in (0, 1) whose both ends span
    /// decades (micrograin's filling factor τ0: the model scales with τ0 near 0 and
    /// with ln(1 − τ0) near 1); needs 0 < lo < hi < 1.
    Logit,
}

/// What a parameter is to a lobe of its model: its angular width, its amplitude, or
/// neither. `diagnose` seeds a new lobe's width and amplitude from the residuals it is
/// meant to explain (a misfit within 5° of the retro direction seeds a lobe about that
/// wide), besides the random restarts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LobePart {
    Other,
    /// A GGX-like roughness α: the lobe's angular half-width at half maximum is about
    /// 1.3 α radians (measured from its axis to the direction it scatters to).
    Width,
    /// A scale the lobe is proportional to.
    Amplitude,
}

/// One parameter, declared once by the model that owns it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamDecl {
    /// Stable ASCII name (docs/models.md), without the role prefix of nested models.
    pub name: &'static str,
    pub lo: f64,
    pub hi: f64,
    pub default: f64,
    /// One value per channel ("rgb") or shared across channels.
    pub rgb: bool,
    pub scale: Scale,
    pub doc: &'static str,
    /// The value at which the parameter makes its model add nothing to what it wraps or
    /// extends (k_s = 0, σ = 0, S = 1, γ = 2 …): a fitted model embeds into its extension
    /// at this value (diagnose), and a test checks the claim. `None`: no such value.
    pub neutral: Option<f64>,
    /// A roughness that gets one value per measured φ plane under `+peraxis`.
    pub per_axis: bool,
    /// What the parameter is to a lobe ([`LobePart`]).
    pub lobe: LobePart,
    /// Determined only by data on two or more planes through the normal (or off-plane):
    /// an anisotropic lobe's two roughnesses and its frame, of which one plane sees a
    /// single combination.
    pub needs_planes: bool,
    /// One knot of a tabulated function (`+ndf`'s log-factor): the knots a node declares
    /// in a row form a chain anchored at 0 before its first knot, whose second
    /// differences the fit's smoothness prior penalises ([`crate::inference::constraints`]).
    pub knot: bool,
}

impl ParamDecl {
    pub const fn shared(
        name: &'static str,
        lo: f64,
        hi: f64,
        default: f64,
        doc: &'static str,
    ) -> Self {
        ParamDecl {
            name,
            lo,
            hi,
            default,
            rgb: false,
            scale: Scale::Linear,
            doc,
            neutral: None,
            per_axis: false,
            lobe: LobePart::Other,
            needs_planes: false,
            knot: false,
        }
    }
    /// One value per channel.
    pub const fn rgb(
        name: &'static str,
        lo: f64,
        hi: f64,
        default: f64,
        doc: &'static str,
    ) -> Self {
        ParamDecl {
            rgb: true,
            ..ParamDecl::shared(name, lo, hi, default, doc)
        }
    }
    pub const fn log(self) -> Self {
        ParamDecl {
            scale: Scale::Log,
            ..self
        }
    }
    /// Map to the unit box quadratically (see [`Scale::Quadratic`]).
    pub const fn quadratic(self) -> Self {
        ParamDecl {
            scale: Scale::Quadratic,
            ..self
        }
    }
    /// Map to the unit box quadratically towards `hi` (see [`Scale::QuadraticHi`]).
    pub const fn quadratic_hi(self) -> Self {
        ParamDecl {
            scale: Scale::QuadraticHi,
            ..self
        }
    }
    /// Map to the unit box by the logit (see [`Scale::Logit`]).
    pub const fn logit(self) -> Self {
        ParamDecl {
            scale: Scale::Logit,
            ..self
        }
    }
    /// Declare the value at which the parameter adds nothing (see [`ParamDecl::neutral`]).
    pub const fn neutral_at(self, v: f64) -> Self {
        ParamDecl {
            neutral: Some(v),
            ..self
        }
    }
    /// Neutral at its lower bound (the thinnest layer, the flattest grains).
    pub const fn neutral_at_lo(self) -> Self {
        ParamDecl {
            neutral: Some(self.lo),
            ..self
        }
    }
    /// One value per measured φ plane under `+peraxis`.
    pub const fn per_axis(self) -> Self {
        ParamDecl {
            per_axis: true,
            ..self
        }
    }
    /// Determined only across planes ([`ParamDecl::needs_planes`]).
    pub const fn needs_planes(self) -> Self {
        ParamDecl {
            needs_planes: true,
            ..self
        }
    }
    /// A knot of a tabulated function ([`ParamDecl::knot`]).
    pub const fn knot(self) -> Self {
        ParamDecl { knot: true, ..self }
    }
    /// A lobe's width ([`LobePart::Width`]).
    pub const fn lobe_width(self) -> Self {
        ParamDecl {
            lobe: LobePart::Width,
            ..self
        }
    }
    /// A lobe's amplitude ([`LobePart::Amplitude`]).
    pub const fn lobe_amplitude(self) -> Self {
        ParamDecl {
            lobe: LobePart::Amplitude,
            ..self
        }
    }
    /// The same declaration under another name (a lobe's `lobe.alpha`).
    pub const fn renamed(self, name: &'static str) -> Self {
        ParamDecl { name, ..self }
    }

    /// The name without its knot number (`body3` → `body`, `lobe.ndf12` → `lobe.ndf`): one
    /// tabulated function's knots share it, so consecutive knots of one stem are one run
    /// (two functions side by side, `fa(B)+fresnel+body`, are two runs).
    pub fn knot_stem(&self) -> &'static str {
        self.name.trim_end_matches(|c: char| c.is_ascii_digit())
    }

    /// Unit-box coordinate → physical value.
    pub fn from_unit(&self, u: f64) -> f64 {
        let u = u.clamp(0.0, 1.0);
        match self.scale {
            Scale::Linear => self.lo + u * (self.hi - self.lo),
            Scale::Log => (self.lo.ln() + u * (self.hi.ln() - self.lo.ln())).exp(),
            Scale::Quadratic => self.lo + u * u * (self.hi - self.lo),
            Scale::QuadraticHi => self.hi - (1.0 - u) * (1.0 - u) * (self.hi - self.lo),
            Scale::Logit => {
                let l = logit(self.lo) + u * (logit(self.hi) - logit(self.lo));
                1.0 / (1.0 + (-l).exp())
            }
        }
        .clamp(self.lo, self.hi)
    }

    /// Physical value → unit-box coordinate (clamped to the box).
    pub fn to_unit(&self, v: f64) -> f64 {
        let v = v.clamp(self.lo, self.hi);
        match self.scale {
            Scale::Linear => (v - self.lo) / (self.hi - self.lo),
            Scale::Log => (v.ln() - self.lo.ln()) / (self.hi.ln() - self.lo.ln()),
            Scale::Quadratic => ((v - self.lo) / (self.hi - self.lo)).sqrt(),
            Scale::QuadraticHi => 1.0 - ((self.hi - v) / (self.hi - self.lo)).sqrt(),
            Scale::Logit => (logit(v) - logit(self.lo)) / (logit(self.hi) - logit(self.lo)),
        }
    }
}

fn logit(v: f64) -> f64 {
    (v / (1.0 - v)).ln()
}

/// What a model is for. Layers name the roles they accept as a base, so allow-lists are
/// derived, never listed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// A diffuse base (`lambert on eon vmf`): a complete BRDF that may sit under a layer.
    DiffuseBase,
    /// A specular lobe that is a complete BRDF on its own (`ggx`).
    SpecularLobe,
    /// A layer or aggregate over one base, `name(B)`, B of one of these roles.
    Layer { over: &'static [Role] },
    /// A transmission family, `btdf(ndf)`; its variants are declared by the model.
    Transmission,
    /// A suffix `M+name` wrapping a model of its kind (any kind when [`Entry::kind`] is None).
    Suffix,
}

/// Where a model appears in the default catalogue (what `sweep` fits by default).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InCatalogue {
    No,
    /// Yes: as itself (leaves, layers over every accepted base, each transmission
    /// variant) or, for a suffix, appended to each catalogue model of its kind.
    Yes,
    /// For data measured on several φ planes: appended to every catalogue model whose
    /// spec ends with this suffix (the scaled BTDFs get per-plane roughness).
    MultiPlaneAfter(&'static str),
}

/// Builds a node from a term's optional argument.
pub type TermBuilder = fn(arg: Option<&Ast>) -> Result<Node, String>;
/// Wraps a node in a suffix combinator.
pub type SuffixBuilder = fn(inner: Node) -> Result<Node, String>;

/// Makes a leaf node (a term without argument).
pub type LeafBuilder = fn() -> Node;

/// Wraps the base of `layer(B)` (checked against the layer's role first).
pub type LayerBuilder = fn(base: Node) -> Node;

#[derive(Clone, Copy, Debug)]
pub enum Builder {
    Leaf(LeafBuilder),
    Layer(LayerBuilder),
    Term(TermBuilder),
    Suffix(SuffixBuilder),
}

impl Entry {
    /// A term `name` or `name(arg)`, in the default catalogue.
    pub const fn term(
        name: &'static str,
        kind: Kind,
        role: Role,
        doc: &'static str,
        build: TermBuilder,
    ) -> Entry {
        Entry {
            name,
            kind: Some(kind),
            role,
            catalogue: InCatalogue::Yes,
            doc,
            build: Builder::Term(build),
            variants: &[],
            adds: &[],
            mitsuba: None,
            covered_on: &[],
        }
    }
    /// A term without argument (`lambert`), in the default catalogue.
    pub const fn leaf(
        name: &'static str,
        kind: Kind,
        role: Role,
        doc: &'static str,
        build: LeafBuilder,
    ) -> Entry {
        Entry {
            build: Builder::Leaf(build),
            ..Entry::term(name, kind, role, doc, |_| Err(String::new()))
        }
    }
    /// A layer `name(B)` over a base of one of `over`'s roles, in the default catalogue
    /// over each accepted base.
    pub const fn layer(
        name: &'static str,
        kind: Kind,
        over: &'static [Role],
        doc: &'static str,
        build: LayerBuilder,
    ) -> Entry {
        Entry {
            build: Builder::Layer(build),
            ..Entry::term(
                name,
                kind,
                Role::Layer { over },
                doc,
                |_| Err(String::new()),
            )
        }
    }
    /// A suffix `M+name` for models of `kind` (None: either kind).
    pub const fn suffix(
        name: &'static str,
        kind: Option<Kind>,
        catalogue: InCatalogue,
        doc: &'static str,
        build: SuffixBuilder,
    ) -> Entry {
        Entry {
            name,
            kind,
            role: Role::Suffix,
            catalogue,
            doc,
            build: Builder::Suffix(build),
            variants: &[],
            adds: &[],
            mitsuba: None,
            covered_on: &[],
        }
    }
    /// The term's argument names (`btdf(tr)`), each a catalogue model.
    pub const fn with_variants(self, variants: &'static [&'static str]) -> Entry {
        Entry { variants, ..self }
    }
    /// The model's exact Mitsuba 3 counterpart (`export --format mitsuba`).
    pub const fn with_mitsuba(self, mitsuba: &'static MitsubaBsdf) -> Entry {
        Entry {
            mitsuba: Some(mitsuba),
            ..self
        }
    }
    /// The effects the model adds to others, and how (`diagnose`'s extensions).
    pub const fn adding(self, adds: &'static [Adds]) -> Entry {
        Entry { adds, ..self }
    }
    /// [`Entry::covered_on`].
    pub const fn covered_on(self, covered_on: &'static [&'static str]) -> Entry {
        Entry { covered_on, ..self }
    }
}

/// A model's registry entry: declared once, next to its code, and listed by one line of
/// [`super::registry::REGISTRY`].
#[derive(Clone, Copy, Debug)]
pub struct Entry {
    /// The spec name (`lambert`, `dmg`, `retro`, …).
    pub name: &'static str,
    /// BRDF or BTDF; None for suffixes that apply to either (`+peraxis`).
    pub kind: Option<Kind>,
    pub role: Role,
    pub catalogue: InCatalogue,
    /// One line for `bsdfit models`.
    pub doc: &'static str,
    pub build: Builder,
    /// The argument names a term accepts (`btdf(tr)`): its variants. Empty otherwise.
    pub variants: &'static [&'static str],
    /// The physical effects this model adds to another model, and how the extension is
    /// made ([`Adds`]); `diagnose` tries them where the data shows the effect missing.
    pub adds: &'static [Adds],
    /// A Mitsuba 3 BSDF that evaluates exactly as this model (a leaf), if there is one.
    pub mitsuba: Option<&'static MitsubaBsdf>,
    /// For a suffix whose node is the same whatever the model under it: the core models
    /// [`super::every_spec`] puts it on (one per place it can sit), instead of every core
    /// it builds on. Empty: every core.
    pub covered_on: &'static [&'static str],
}

/// A Mitsuba 3 `<bsdf>` equal to a leaf model: its plugin and its fields, each a fitted
/// parameter or a constant (`export --format mitsuba` writes it).
#[derive(Clone, Copy, Debug)]
pub struct MitsubaBsdf {
    /// The plugin (`type` attribute).
    pub plugin: &'static str,
    /// What it becomes, in a few words (listed by the export's messages).
    pub summary: &'static str,
    /// Why it is exact: the lines of the XML comment.
    pub why: &'static [&'static str],
    pub fields: &'static [MitsubaField],
}

/// One field of a [`MitsubaBsdf`].
#[derive(Clone, Copy, Debug)]
pub enum MitsubaField {
    /// `<string name=… value=…/>`.
    Text {
        name: &'static str,
        value: &'static str,
    },
    /// `<float name=…/>` from the model's shared parameter `param`.
    Param {
        name: &'static str,
        param: &'static str,
    },
    /// `<float name=… value=…/>`, a constant.
    Constant { name: &'static str, value: f64 },
    /// `<rgb name=…/>` from the model's per-channel parameter `param` at the R, G, B
    /// channels.
    Rgb {
        name: &'static str,
        param: &'static str,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every scale maps the box's ends to the bounds, increases strictly, and inverts:
    /// the optimizers' box and the reported values must describe the same point.
    #[test]
    fn every_scale_maps_the_box_onto_the_bounds_and_back() {
        let base = ParamDecl::shared("x", 2e-3, 0.995, 0.5, "test");
        for d in [
            base,
            base.log(),
            base.quadratic(),
            base.quadratic_hi(),
            base.logit(),
        ] {
            assert!((d.from_unit(0.0) - d.lo).abs() < 1e-12, "{:?}", d.scale);
            assert!((d.from_unit(1.0) - d.hi).abs() < 1e-12, "{:?}", d.scale);
            let mut last = f64::NEG_INFINITY;
            for i in 0..=200 {
                let u = i as f64 / 200.0;
                let v = d.from_unit(u);
                assert!(v > last, "{:?} not increasing at u = {u}", d.scale);
                last = v;
                let back = d.to_unit(v);
                assert!(
                    (back - u).abs() < 1e-9,
                    "{:?}: u {u} → {v} → {back}",
                    d.scale
                );
            }
        }
    }

    /// The reason for the quadratic maps: √(v − lo) (resp. √(hi − v)) is linear in u, so
    /// its derivative in the box stays finite at the bound.
    #[test]
    fn quadratic_maps_make_a_square_root_linear_at_their_bound() {
        let d = ParamDecl::shared("x", 0.0, 1.0, 0.5, "test");
        for u in [0.0, 1e-6, 0.3, 0.999] {
            let v = d.quadratic().from_unit(u);
            assert!((v.sqrt() - u).abs() < 1e-12, "u {u}");
            // 1 − v rounds to ≈ 1e-16 absolute: √ of it to ≈ 1e-10 at u = 1e-6.
            let v = d.quadratic_hi().from_unit(1.0 - u);
            assert!(((1.0 - v).sqrt() - u).abs() < 1e-9, "u {u}");
        }
    }
}
