//! The effect catalogue (DESIGN §7): the physical effects a model may be missing.

/// A physical effect a model may be missing (DESIGN §7; the names are a contract).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Effect {
    SpecularLobe,
    Backscatter,
    RetroLobe,
    GrazingDecay,
    Scale,
    Absorption,
    LongTail,
    Anisotropy,
    DiffuseFloor,
}

impl Effect {
    pub const ALL: [Effect; 9] = [
        Effect::SpecularLobe,
        Effect::Backscatter,
        Effect::RetroLobe,
        Effect::GrazingDecay,
        Effect::Scale,
        Effect::Absorption,
        Effect::LongTail,
        Effect::Anisotropy,
        Effect::DiffuseFloor,
    ];

    /// The contract name (`specular_lobe`, …).
    pub fn name(self) -> &'static str {
        match self {
            Effect::SpecularLobe => "specular_lobe",
            Effect::Backscatter => "backscatter",
            Effect::RetroLobe => "retro_lobe",
            Effect::GrazingDecay => "grazing_decay",
            Effect::Scale => "scale",
            Effect::Absorption => "absorption",
            Effect::LongTail => "long_tail",
            Effect::Anisotropy => "anisotropy",
            Effect::DiffuseFloor => "diffuse_floor",
        }
    }

    /// The residual signature DESIGN §7 gives for the effect.
    pub fn signature(self) -> &'static str {
        match self {
            Effect::SpecularLobe => "excess around the mirror direction",
            Effect::Backscatter => "excess toward the retro direction, growing with θi",
            Effect::RetroLobe => "a sharp excess within a few degrees of ωo = ωi",
            Effect::GrazingDecay => "model too bright at large θo",
            Effect::Scale => "one-signed residual everywhere",
            Effect::Absorption => "deficit growing with θt",
            Effect::LongTail => "excess in the tails far from the peak",
            Effect::Anisotropy => "different widths on the two φ axes",
            Effect::DiffuseFloor => "a flat excess far from every lobe",
        }
    }

    pub fn from_name(name: &str) -> Option<Effect> {
        Effect::ALL.into_iter().find(|e| e.name() == name)
    }
}

impl std::fmt::Display for Effect {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}
