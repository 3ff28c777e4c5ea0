//! What `diagnose` knows of each effect besides the models that add it: the residual
//! signature that points to it and, for a lobe, the direction it is centred on. Which
//! extensions add an effect, and how they are made, is declared by the models themselves
//! ([`crate::bsdf::effect::Adds`] in each registry entry); [`Effect::rules`] collects them.

use super::regions::Around;
pub use crate::bsdf::effect::{Adds, Effect, Extend};
use crate::bsdf::{registry, Entry};
use crate::data::Kind;

/// One row of the catalogue.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EffectEntry {
    pub effect: Effect,
    /// The residual signature docs/diagnose.md gives for the effect.
    pub signature: &'static str,
    /// For an effect that adds a lobe: the direction its residual signature is centred
    /// on, whose flagged regions seed the new lobe's width (`diagnose`'s evidence starts).
    pub lobe_around: Option<Around>,
    /// For an effect whose signature is a sharp lobe: the widest half width at half
    /// maximum (degrees, about 1.3 α rad for a GGX lobe of roughness α) at which a fitted
    /// lobe still is that effect. A wider one reshapes the whole hemisphere instead.
    pub max_half_width_deg: Option<f64>,
}

/// The signatures, in the order of [`Effect::ALL`].
pub const EFFECTS: &[EffectEntry] = &[
    EffectEntry {
        effect: Effect::Backscatter,
        signature: "excess toward the retro direction, growing with θi",
        lobe_around: None,
        max_half_width_deg: None,
    },
    EffectEntry {
        effect: Effect::SpecularLobe,
        signature: "excess around the mirror direction",
        lobe_around: Some(Around::Mirror),
        max_half_width_deg: None,
    },
    EffectEntry {
        effect: Effect::LongTail,
        signature: "excess in the tails far from the peak",
        lobe_around: None,
        max_half_width_deg: None,
    },
    EffectEntry {
        effect: Effect::Scale,
        signature: "one-signed residual everywhere",
        lobe_around: None,
        max_half_width_deg: None,
    },
    EffectEntry {
        effect: Effect::Absorption,
        signature: "deficit growing with θt",
        lobe_around: None,
        max_half_width_deg: None,
    },
    EffectEntry {
        effect: Effect::DiffuseFloor,
        signature: "a flat excess far from every lobe",
        lobe_around: None,
        max_half_width_deg: None,
    },
    EffectEntry {
        effect: Effect::GrazingDecay,
        signature: "model too bright at large θo",
        lobe_around: None,
        max_half_width_deg: None,
    },
    EffectEntry {
        effect: Effect::RetroLobe,
        signature: "a sharp excess within a few degrees of ωo = ωi",
        lobe_around: Some(Around::Retro),
        // Retroreflective sheets and tapes have lobes a few degrees wide; the battery's
        // retro truths reach α_r = 0.5 (37°). Fitted to isotropic truths without any
        // backscatter, `+retro` ends at α_r ≈ 0.9–1 (70°): a broad glow that reshapes
        // the body, not a retro lobe.
        max_half_width_deg: Some(40.0),
    },
    EffectEntry {
        effect: Effect::RetroFalloff,
        signature: "the retro peak too bright at large θi and too dark at small θi",
        lobe_around: None,
        max_half_width_deg: None,
    },
    EffectEntry {
        effect: Effect::Anisotropy,
        signature: "different widths on the two φ axes",
        lobe_around: None,
        max_half_width_deg: None,
    },
    EffectEntry {
        effect: Effect::HighlightShape,
        signature: "misfit across the highlight (or the transmitted peak) that no analytic lobe width removes: a peak or tail of another shape",
        lobe_around: None,
        max_half_width_deg: None,
    },
    EffectEntry {
        effect: Effect::HighlightFresnel,
        signature: "the highlight's strength changes with the angle to the half vector (θd) unlike a dielectric's Fresnel curve, or differently per channel: a conductor's or a coating's reflectance",
        lobe_around: None,
        max_half_width_deg: None,
    },
    EffectEntry {
        effect: Effect::BodyProfile,
        signature: "misfit that follows θi and θo over the whole hemisphere, not one lobe: the body brighter or darker toward grazing than its base's analytic shape (a particulate body's limb darkening, a sheen's grazing brightening)",
        lobe_around: None,
        max_half_width_deg: None,
    },
];

/// One way of making an extension that adds an effect: a model's declaration.
#[derive(Clone, Copy, Debug)]
pub struct Rule {
    /// The model that adds the effect.
    pub by: &'static Entry,
    pub adds: Adds,
}

impl Rule {
    /// Whether the rule applies to data of `kind`.
    pub fn applies_to(&self, kind: Kind) -> bool {
        self.adds.kind.or(self.by.kind).is_none_or(|k| k == kind)
    }
}

impl Effect {
    /// The effect's row of [`EFFECTS`].
    pub fn entry(self) -> &'static EffectEntry {
        EFFECTS
            .iter()
            .find(|e| e.effect == self)
            .expect("every effect has a row in EFFECTS")
    }

    /// The residual signature docs/diagnose.md gives for the effect.
    pub fn signature(self) -> &'static str {
        self.entry().signature
    }

    /// Every model declaration that adds the effect, in registry order (the order of the
    /// candidate table).
    pub fn rules(self) -> Vec<Rule> {
        registry::all()
            .iter()
            .flat_map(|&by| by.adds.iter().map(move |&adds| Rule { by, adds }))
            .filter(|r| r.adds.effect == self)
            .collect()
    }

    /// The kinds of data some model adds the effect on.
    pub fn kinds(self) -> Vec<Kind> {
        let rules = self.rules();
        [Kind::Brdf, Kind::Btdf]
            .into_iter()
            .filter(|&k| rules.iter().any(|r| r.applies_to(k)))
            .collect()
    }

    /// The fewest measurement planes on which some model adds the effect to data of
    /// `kind` (1 when none does).
    pub fn min_planes(self, kind: Kind) -> usize {
        self.rules()
            .iter()
            .filter(|r| r.applies_to(kind))
            .map(|r| r.adds.min_planes)
            .min()
            .unwrap_or(1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One row per effect in the order of `Effect::ALL`, one effect per name, the
    /// contract's names, and at least one model that adds each effect.
    #[test]
    fn the_catalogue_has_one_row_per_effect() {
        assert_eq!(EFFECTS.len(), Effect::ALL.len());
        for (e, &effect) in EFFECTS.iter().zip(&Effect::ALL) {
            assert_eq!(e.effect, effect);
            assert_eq!(Effect::from_name(effect.name()), Some(effect));
            assert_eq!(effect.entry(), e);
            assert!(!effect.rules().is_empty(), "no model adds {effect}");
        }
        let mut names: Vec<&str> = Effect::all().map(Effect::name).collect();
        names.sort();
        assert_eq!(
            names,
            [
                "absorption",
                "anisotropy",
                "backscatter",
                "body_profile",
                "diffuse_floor",
                "grazing_decay",
                "highlight_fresnel",
                "highlight_shape",
                "long_tail",
                "retro_falloff",
                "retro_lobe",
                "scale",
                "specular_lobe"
            ]
        );
    }
}
