//! The physical effects a model may be missing, and how a model declares that it adds
//! one to another ([`Adds`], in its registry [`Entry`](super::Entry)). `diagnose` makes
//! its candidate extensions of a fitted model from these declarations alone, so a new
//! model that declares what it adds is tried without any change to `diagnose`.

use crate::data::Kind;

/// A physical effect a model may be missing (the names are a contract: `diagnose`'s JSON
/// and `battery --effects`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Effect {
    SpecularLobe,
    Backscatter,
    RetroLobe,
    RetroFalloff,
    GrazingDecay,
    Scale,
    Absorption,
    LongTail,
    Anisotropy,
    DiffuseFloor,
    /// The highlight's (or the transmission lobe's) microfacet distribution is not of an
    /// analytic family: a data-driven NDF (`+ndf`).
    HighlightShape,
    /// The highlight's Fresnel curve is not the dielectric one: a data-driven factor per
    /// channel in θd (`+fresnel`).
    HighlightFresnel,
    /// The diffuse body's angular profile is not its base's: a data-driven factor
    /// ρ(θi) ρ(θo) (`+body`).
    BodyProfile,
}

impl Effect {
    /// Every effect, in the order `diagnose` tries them (the order of its candidate table
    /// and of `candidates.json`).
    pub const ALL: [Effect; 13] = [
        Effect::Backscatter,
        Effect::SpecularLobe,
        Effect::LongTail,
        Effect::Scale,
        Effect::Absorption,
        Effect::DiffuseFloor,
        Effect::GrazingDecay,
        Effect::RetroLobe,
        Effect::RetroFalloff,
        Effect::Anisotropy,
        Effect::HighlightShape,
        Effect::HighlightFresnel,
        Effect::BodyProfile,
    ];

    /// Every effect, in the order of [`Effect::ALL`].
    pub fn all() -> impl Iterator<Item = Effect> {
        Effect::ALL.into_iter()
    }

    /// The contract name (`specular_lobe`, …).
    pub fn name(self) -> &'static str {
        match self {
            Effect::SpecularLobe => "specular_lobe",
            Effect::Backscatter => "backscatter",
            Effect::RetroLobe => "retro_lobe",
            Effect::RetroFalloff => "retro_falloff",
            Effect::GrazingDecay => "grazing_decay",
            Effect::Scale => "scale",
            Effect::Absorption => "absorption",
            Effect::LongTail => "long_tail",
            Effect::Anisotropy => "anisotropy",
            Effect::DiffuseFloor => "diffuse_floor",
            Effect::HighlightShape => "highlight_shape",
            Effect::HighlightFresnel => "highlight_fresnel",
            Effect::BodyProfile => "body_profile",
        }
    }

    /// Whether the effect is a data-driven factor (a tabulated function in place of an
    /// analytic family's): `diagnose` offers it only once no analytic effect is
    /// significant, and the battery, whose truths come from the catalogue, does not draw
    /// it.
    pub fn is_data_driven(self) -> bool {
        matches!(
            self,
            Effect::HighlightShape | Effect::HighlightFresnel | Effect::BodyProfile
        )
    }

    pub fn from_name(name: &str) -> Option<Effect> {
        Effect::all().find(|e| e.name() == name)
    }
}

impl std::fmt::Display for Effect {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// How the declaring model extends a model M (its core term keeps M's suffixes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Extend {
    /// The declaring leaf generalizes the leaf `base` (which it equals at its neutral
    /// parameters) and replaces it, bare or as the base of a layer: `lambert` → `on`,
    /// `fa(lambert)` → `fa(on)`.
    Generalizes { base: &'static str },
    /// The declaring layer wraps a bare base it accepts: B → `fa(B)`.
    Wraps,
    /// The declaring layer over `base` contains the bare leaf `leaf` (it is `leaf` when
    /// `base` adds nothing) and replaces it: `ggx` → `fa(lambert)`.
    Contains {
        leaf: &'static str,
        base: &'static str,
    },
    /// The declaring suffix is appended when M lacks it: M → `M+retro`.
    Appended,
    /// The declaring term's variant `to` replaces each variant of `from`:
    /// `btdf(beckmann)` → `btdf(tr)`.
    Variant {
        from: &'static [&'static str],
        to: &'static str,
    },
}

/// One effect a model adds to another, declared by the model that adds it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Adds {
    pub effect: Effect,
    pub how: Extend,
    /// Whether the extended model is the extension at some parameter values (an F test
    /// applies), or a swap that is not (BIC only).
    pub nested: bool,
    /// The kind of data the extension is tried on; `None`: the declaring entry's kind
    /// (or either kind, for a suffix of either kind).
    pub kind: Option<Kind>,
    /// The fewest measurement φ planes the data must have.
    pub min_planes: usize,
}

impl Adds {
    const fn new(effect: Effect, how: Extend) -> Adds {
        Adds {
            effect,
            how,
            nested: true,
            kind: None,
            min_planes: 1,
        }
    }
    /// The declaring leaf generalizes `base` ([`Extend::Generalizes`]).
    pub const fn generalizing(effect: Effect, base: &'static str) -> Adds {
        Adds::new(effect, Extend::Generalizes { base })
    }
    /// The declaring layer wraps a bare base ([`Extend::Wraps`]).
    pub const fn wrapping(effect: Effect) -> Adds {
        Adds::new(effect, Extend::Wraps)
    }
    /// The declaring layer over `base` replaces `leaf` ([`Extend::Contains`]).
    pub const fn containing(effect: Effect, leaf: &'static str, base: &'static str) -> Adds {
        Adds::new(effect, Extend::Contains { leaf, base })
    }
    /// The declaring suffix is appended ([`Extend::Appended`]).
    pub const fn appended(effect: Effect) -> Adds {
        Adds::new(effect, Extend::Appended)
    }
    /// The declaring term's variant `to` replaces those of `from` ([`Extend::Variant`]).
    pub const fn variant(effect: Effect, from: &'static [&'static str], to: &'static str) -> Adds {
        Adds::new(effect, Extend::Variant { from, to })
    }
    /// Only on data measured on at least `min_planes` φ planes.
    pub const fn on_planes(self, min_planes: usize) -> Adds {
        Adds { min_planes, ..self }
    }
    /// A swap: the extended model is not the extension at any parameter values.
    pub const fn not_nested(self) -> Adds {
        Adds {
            nested: false,
            ..self
        }
    }
    /// Only on data of `kind`.
    pub const fn for_kind(self, kind: Kind) -> Adds {
        Adds {
            kind: Some(kind),
            ..self
        }
    }
}
