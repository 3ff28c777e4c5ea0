//! The effect catalogue (docs/diagnose.md) as data: every effect a model may be missing, the
//! residual signature that points to it, and how an extension that adds it is made from
//! the current spec. [`super::extensions`] generates the candidates from [`EFFECTS`] and
//! from nothing else; the effect names are written here only.

use super::regions::Around;
use crate::data::Kind;

/// A physical effect a model may be missing (docs/diagnose.md; the names are a contract).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
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
}

/// How an extension is made from the current spec, whose core term M keeps its suffixes
/// (`+retro`, `+scale`, …) in the extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Make {
    /// Replace the diffuse base `from`, bare or as the argument of one of `inside`, by each
    /// of `to`: `lambert` → `on`, `fa(lambert)` → `fa(on)`.
    ReplaceBase {
        from: &'static str,
        to: &'static [&'static str],
        inside: &'static [&'static str],
    },
    /// Wrap a bare base in each combinator of `combinators` that accepts it (by the
    /// combinator's declared role): B → `fa(B)`.
    Wrap {
        combinators: &'static [&'static str],
    },
    /// Replace the bare term `from` by the spec `to` that contains it: `ggx` →
    /// `fa(lambert)` (a Lambertian base under the lobe).
    Replace {
        from: &'static str,
        to: &'static str,
    },
    /// Append the suffix `name` when the spec lacks it and the data has at least
    /// `min_planes` measurement planes: M → `M+retro`.
    Suffix {
        name: &'static str,
        min_planes: usize,
    },
    /// Swap the NDF family of `term(N)` for N in `from`: `btdf(beckmann)` → `btdf(tr)`.
    SwapNdf {
        term: &'static str,
        from: &'static [&'static str],
        to: &'static str,
    },
}

/// One way of making an extension for data of one kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rule {
    pub kind: Kind,
    pub make: Make,
    /// Whether the current model is the extension at some parameter values (the F test
    /// applies), or a swap that is not (BIC only).
    pub nested: bool,
}

/// One row of the catalogue.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EffectEntry {
    pub effect: Effect,
    /// The contract name (`specular_lobe`, …).
    pub name: &'static str,
    /// The residual signature docs/diagnose.md gives for the effect.
    pub signature: &'static str,
    /// How the extensions that add the effect are made; empty for an effect that is
    /// declared but not generated yet.
    pub rules: &'static [Rule],
    /// For an effect that adds a lobe: the direction its residual signature is centred
    /// on, whose flagged regions seed the new lobe's width (`diagnose`'s evidence starts).
    pub lobe_around: Option<Around>,
}

const fn rule(kind: Kind, make: Make, nested: bool) -> Rule {
    Rule { kind, make, nested }
}

/// The effect catalogue. A round's candidates are generated in the order of this table
/// (and of each entry's rules), which is the order of the candidate table in the log and
/// of `candidates.json`.
pub const EFFECTS: &[EffectEntry] = &[
    EffectEntry {
        effect: Effect::Backscatter,
        name: "backscatter",
        signature: "excess toward the retro direction, growing with θi",
        rules: &[rule(
            Kind::Brdf,
            Make::ReplaceBase {
                from: "lambert",
                to: &["on", "eon", "vmf"],
                inside: &["fa", "dmg", "rmg"],
            },
            true,
        )],
        lobe_around: None,
    },
    EffectEntry {
        effect: Effect::SpecularLobe,
        name: "specular_lobe",
        signature: "excess around the mirror direction",
        // A bare diffuse base gets the Fresnel aggregate's lobe; any model, one with a lobe
        // of its own too, gets a second (coat) lobe: real coated materials show a sharp
        // reflection off a smooth top film over a broad one.
        rules: &[
            rule(
                Kind::Brdf,
                Make::Wrap {
                    combinators: &["fa"],
                },
                true,
            ),
            rule(
                Kind::Brdf,
                Make::Suffix {
                    name: "coat",
                    min_planes: 1,
                },
                true,
            ),
        ],
        lobe_around: Some(Around::Mirror),
    },
    EffectEntry {
        effect: Effect::LongTail,
        name: "long_tail",
        signature: "excess in the tails far from the peak",
        rules: &[
            rule(
                Kind::Btdf,
                Make::SwapNdf {
                    term: "btdf",
                    from: &["beckmann", "gg"],
                    to: "tr",
                },
                false,
            ),
            // γ = 2 is TR.
            rule(
                Kind::Btdf,
                Make::SwapNdf {
                    term: "btdf",
                    from: &["tr"],
                    to: "gtr",
                },
                true,
            ),
        ],
        lobe_around: None,
    },
    EffectEntry {
        effect: Effect::Scale,
        name: "scale",
        signature: "one-signed residual everywhere",
        rules: &[rule(
            Kind::Btdf,
            Make::Suffix {
                name: "scale",
                min_planes: 1,
            },
            true,
        )],
        lobe_around: None,
    },
    EffectEntry {
        effect: Effect::Absorption,
        name: "absorption",
        signature: "deficit growing with θt",
        rules: &[rule(
            Kind::Btdf,
            Make::Suffix {
                name: "absorb",
                min_planes: 1,
            },
            true,
        )],
        lobe_around: None,
    },
    EffectEntry {
        effect: Effect::DiffuseFloor,
        name: "diffuse_floor",
        signature: "a flat excess far from every lobe",
        rules: &[
            rule(
                Kind::Brdf,
                Make::Replace {
                    from: "ggx",
                    to: "fa(lambert)",
                },
                true,
            ),
            rule(
                Kind::Btdf,
                Make::Suffix {
                    name: "diffuse",
                    min_planes: 1,
                },
                true,
            ),
        ],
        lobe_around: None,
    },
    EffectEntry {
        effect: Effect::GrazingDecay,
        name: "grazing_decay",
        signature: "model too bright at large θo",
        rules: &[rule(
            Kind::Brdf,
            Make::Wrap {
                combinators: &["dmg", "rmg"],
            },
            true,
        )],
        lobe_around: None,
    },
    // The MRM lobe with the F82-tint Fresnel (docs/models.md): k_r = 0 (the declared
    // neutral) is the current model, and F0 = F82 = 1 gives the Fresnel-free back-vector
    // lobe of `+retro` up to the height-correlated G2.
    EffectEntry {
        effect: Effect::RetroLobe,
        name: "retro_lobe",
        signature: "a sharp excess within a few degrees of ωo = ωi",
        // Both lobes are offered: on real tapes `+mrm82`'s k_r and F0 trade off and k_r can
        // end on its bound 1, and such a step is not adopted; `+retro` (k_r up to 10, no
        // Fresnel) then carries the effect, and the residuals choose between them.
        rules: &[
            rule(
                Kind::Brdf,
                Make::Suffix {
                    name: "retro",
                    min_planes: 1,
                },
                true,
            ),
            rule(
                Kind::Brdf,
                Make::Suffix {
                    name: "mrm82",
                    min_planes: 1,
                },
                true,
            ),
        ],
        lobe_around: Some(Around::Retro),
    },
    // The entrance-angle efficiency (μi μo)^q of the retro lobe already in the model (q = 0
    // is the current model). Only a spec with a retro lobe (`+retro`, `+mrm`, `+mrm82`)
    // accepts `+falloff`; for any other the candidate does not parse and is not generated.
    EffectEntry {
        effect: Effect::RetroFalloff,
        name: "retro_falloff",
        signature: "the retro peak too bright at large θi and too dark at small θi",
        rules: &[rule(
            Kind::Brdf,
            Make::Suffix {
                name: "falloff",
                min_planes: 1,
            },
            true,
        )],
        lobe_around: None,
    },
    EffectEntry {
        effect: Effect::Anisotropy,
        name: "anisotropy",
        signature: "different widths on the two φ axes",
        rules: &[rule(
            Kind::Btdf,
            Make::Suffix {
                name: "peraxis",
                min_planes: 2,
            },
            true,
        )],
        lobe_around: None,
    },
];

impl Effect {
    /// Every effect, in the order of [`EFFECTS`].
    pub fn all() -> impl Iterator<Item = Effect> {
        EFFECTS.iter().map(|e| e.effect)
    }

    /// The effect's row of [`EFFECTS`].
    pub fn entry(self) -> &'static EffectEntry {
        EFFECTS
            .iter()
            .find(|e| e.effect == self)
            .expect("every effect has a row in EFFECTS")
    }

    /// The contract name (`specular_lobe`, …).
    pub fn name(self) -> &'static str {
        self.entry().name
    }

    /// The residual signature docs/diagnose.md gives for the effect.
    pub fn signature(self) -> &'static str {
        self.entry().signature
    }

    pub fn from_name(name: &str) -> Option<Effect> {
        EFFECTS.iter().find(|e| e.name == name).map(|e| e.effect)
    }
}

impl std::fmt::Display for Effect {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One row per effect, one effect per name, and the contract's names.
    #[test]
    fn the_catalogue_has_one_row_per_effect() {
        for e in EFFECTS {
            assert_eq!(
                EFFECTS.iter().filter(|x| x.effect == e.effect).count(),
                1,
                "{e:?}"
            );
            assert_eq!(Effect::from_name(e.name), Some(e.effect));
            assert_eq!(e.effect.entry(), e);
        }
        let mut names: Vec<&str> = EFFECTS.iter().map(|e| e.name).collect();
        names.sort();
        assert_eq!(
            names,
            [
                "absorption",
                "anisotropy",
                "backscatter",
                "diffuse_floor",
                "grazing_decay",
                "long_tail",
                "retro_falloff",
                "retro_lobe",
                "scale",
                "specular_lobe"
            ]
        );
    }
}
