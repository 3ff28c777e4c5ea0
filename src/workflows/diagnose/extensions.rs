//! Candidate extensions of a spec (docs/diagnose.md's effect → extension table) and the
//! embedding of the current optimum in an extension's parameters.

use super::effects::{Extend, Rule};
use super::Effect;
pub use crate::bsdf::render_spec;
use crate::bsdf::{bases_of, registry, Ast, Model};
use crate::data::{Dataset, Kind};
use anyhow::Result;

/// One extension of the current model that would add an effect.
#[derive(Clone, Debug, PartialEq)]
pub struct Candidate {
    /// The extended spec (parses with [`Model::parse`]).
    pub spec: String,
    pub effect: Effect,
    /// Whether the current model is the extension at some parameter values (F test), or a
    /// swap that is not (BIC only).
    pub nested: bool,
}

/// Split a spec into its core term and its suffixes (left to right).
fn peel(ast: &Ast) -> (Ast, Vec<String>) {
    let mut suffixes = Vec::new();
    let mut cur = ast;
    while let Ast::Suffix { inner, name } = cur {
        suffixes.push(name.clone());
        cur = inner;
    }
    suffixes.reverse();
    (cur.clone(), suffixes)
}

fn with_suffixes(core: &str, suffixes: &[String]) -> String {
    let mut s = core.to_string();
    for x in suffixes {
        s.push('+');
        s.push_str(x);
    }
    s
}

/// Every applicable extension of `spec` for `data`: for each effect (in the order of
/// [`Effect::ALL`]), each model that declares it adds the effect ([`Effect::rules`], in
/// registry order), each checked to parse for the data's channels and planes. For a
/// core term M (its suffixes are kept), a declaration makes:
///
/// - [`Extend::Generalizes`] `base`: the leaf replaces `base`, bare or as a layer's base
///   (`lambert` → `on`, `fa(lambert)` → `fa(on)`);
/// - [`Extend::Wraps`]: a bare base B the layer accepts → `layer(B)`;
/// - [`Extend::Contains`] `leaf`, `base`: a bare `leaf` → `layer(base)`;
/// - [`Extend::Appended`]: M → `M+suffix`, where M lacks it and the data has the planes;
/// - [`Extend::Variant`] `from` → `to`: `term(F)` → `term(to)` for F in `from`.
///
/// docs/diagnose.md tabulates what the catalogue's models declare.
pub fn extensions(spec: &str, data: &Dataset) -> Result<Vec<Candidate>> {
    let clean: String = spec.chars().filter(|c| !c.is_whitespace()).collect();
    let ast = Ast::parse(&clean)?;
    let (core, suffixes) = peel(&ast);
    let planes = data.direction_planes();
    let mut out: Vec<Candidate> = Vec::new();
    for effect in Effect::all() {
        for rule in effect.rules() {
            if !rule.applies_to(data.kind) || planes < rule.adds.min_planes {
                continue;
            }
            for spec in make(&rule, &core, &suffixes) {
                out.push(Candidate {
                    spec,
                    effect,
                    nested: rule.adds.nested,
                });
            }
        }
    }
    // Every generated spec must parse for this data (channels, planes).
    out.retain(|c| Model::for_data(&c.spec, data).is_ok());
    Ok(out)
}

/// The specs that `rule` makes from the core term `core` with `suffixes` (none where the
/// rule does not apply).
fn make(rule: &Rule, core: &Ast, suffixes: &[String]) -> Vec<String> {
    let Ast::Term { name, arg } = core else {
        unreachable!("peel returns a term")
    };
    let name = name.as_str();
    let bare = arg.is_none();
    // The argument when it is a bare term: `lambert` in `fa(lambert)`.
    let arg_name = match arg.as_deref() {
        Some(Ast::Term { name, arg: None }) => Some(name.as_str()),
        _ => None,
    };
    let keep = |c: String| with_suffixes(&c, suffixes);
    let by = rule.by;
    let is_layer = |n: &str| registry::entry(n, false).is_some_and(|e| !bases_of(e).is_empty());
    match rule.adds.how {
        Extend::Generalizes { base } => {
            if bare && name == base {
                vec![keep(by.name.to_string())]
            } else if is_layer(name) && arg_name == Some(base) {
                vec![keep(format!("{name}({})", by.name))]
            } else {
                vec![]
            }
        }
        Extend::Wraps if bare && bases_of(by).contains(&name) => {
            vec![keep(format!("{}({name})", by.name))]
        }
        Extend::Contains { leaf, base } if bare && name == leaf => {
            vec![keep(format!("{}({base})", by.name))]
        }
        Extend::Appended if !suffixes.iter().any(|s| s == by.name) => {
            let mut more = suffixes.to_vec();
            more.push(by.name.to_string());
            vec![with_suffixes(&render_spec(core), &more)]
        }
        Extend::Variant { from, to }
            if name == by.name && arg_name.is_some_and(|a| from.contains(&a)) =>
        {
            vec![keep(format!("{}({to})", by.name))]
        }
        _ => vec![],
    }
}

/// The extension's parameters at which it reproduces the current model (or a good start
/// for a swap): shared names are copied (a wrapped base's `base.x` from `x`, a lobe's
/// `lobe.x` from `x`, an anisotropic lobe's `x_u` and `x_v` from `x`), per-plane copies
/// replicate a shared value, and the new parameters
/// take their neutral values (σ = r = 0, k_s = 0 and η = 1, k_r = 0, S = 1, τ = 0,
/// k_d = 0, γ = 2, τ0 at its lower bound with Lambertian-like grains (η_g = 1) as bright
/// as the base).
pub fn embed(old: &Model, old_flat: &[f64], new: &Model) -> Vec<f64> {
    let ch = new.channels;
    let mut flat = new.defaults();
    let find = |name: &str| old.params.iter().find(|q| q.name == name);
    let alias = |name: &str| -> Option<&'static str> {
        match (new.kind, name) {
            (Kind::Btdf, "alpha") => Some("beta"),
            (Kind::Btdf, "beta") => Some("alpha"),
            _ => None,
        }
    };
    // An anisotropic lobe's two roughnesses both start from the isotropic one (α_u = α_v
    // is the isotropic lobe for any φ0).
    let isotropic = |name: &str| -> Option<String> {
        let base = name
            .strip_suffix("_u")
            .or_else(|| name.strip_suffix("_v"))?;
        Some(base.to_string())
    };
    let lookup = |name: &str| {
        find(name)
            .or_else(|| name.strip_prefix("base.").and_then(find))
            .or_else(|| name.strip_prefix("lobe.").and_then(find))
            .or_else(|| alias(name).and_then(find))
    };
    for p in &new.params {
        let w = p.width(ch);
        let mut source = lookup(&p.name).or_else(|| {
            let iso = isotropic(&p.name)?;
            lookup(&iso).or_else(|| {
                let leaf = iso.rsplit('.').next().unwrap_or(&iso);
                alias(leaf).and_then(find)
            })
        });
        if p.name == "rho_g" && source.is_none() {
            // Grains as bright as the base: dmg(lambert) is then lambert for any τ0.
            source = find("rho").or_else(|| find("base.rho"));
        }
        let slot = &mut flat[p.index..p.index + w];
        match source {
            Some(q) => {
                let src = &old_flat[q.index..q.index + q.width(old.channels)];
                for (k, v) in slot.iter_mut().enumerate() {
                    *v = src[k % src.len()].clamp(p.decl.lo, p.decl.hi);
                }
            }
            None => {
                // The value each model declares for "adds nothing" (ParamDecl::neutral).
                if let Some(v) = p.decl.neutral {
                    slot.fill(v.clamp(p.decl.lo, p.decl.hi));
                }
            }
        }
    }
    flat
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::workflows::diagnose::testdata::dataset;

    fn specs(c: &[Candidate]) -> Vec<(String, Effect)> {
        c.iter().map(|c| (c.spec.clone(), c.effect)).collect()
    }

    #[test]
    fn extensions_follow_the_effect_table() {
        use Effect::*;
        let geometry = |name: &str| crate::workflows::synth::geometry(name).unwrap().1;
        let brdf = dataset(Kind::Brdf, &geometry("inplane10"), 3);
        let btdf = dataset(Kind::Btdf, &geometry("oblique"), 1);
        let two = dataset(Kind::Btdf, &geometry("ptb1"), 1);
        let hemi = dataset(Kind::Brdf, &geometry("hemi"), 3);
        // The candidates in the order of the catalogue (the order of candidates.json).
        type Want = &'static [(&'static str, Effect)];
        let cases: [(&str, &Dataset, Want); 8] = [
            (
                "lambert",
                &brdf,
                &[
                    ("on", Backscatter),
                    ("eon", Backscatter),
                    ("vmf", Backscatter),
                    ("fa(lambert)", SpecularLobe),
                    ("lambert+coat", SpecularLobe),
                    ("dmg(lambert)", GrazingDecay),
                    ("rmg(lambert)", GrazingDecay),
                    ("lambert+retro", RetroLobe),
                    ("lambert+mrm82", RetroLobe),
                ],
            ),
            (
                "fa(lambert)+retro",
                &brdf,
                &[
                    ("fa(on)+retro", Backscatter),
                    ("fa(eon)+retro", Backscatter),
                    ("fa(vmf)+retro", Backscatter),
                    ("fa(lambert)+retro+coat", SpecularLobe),
                    ("fa(lambert)+retro+falloff", RetroFalloff),
                ],
            ),
            (
                "eon+mrm82",
                &brdf,
                &[
                    ("fa(eon)+mrm82", SpecularLobe),
                    ("eon+mrm82+coat", SpecularLobe),
                    ("dmg(eon)+mrm82", GrazingDecay),
                    ("rmg(eon)+mrm82", GrazingDecay),
                    ("eon+mrm82+falloff", RetroFalloff),
                ],
            ),
            (
                "ggx",
                &brdf,
                &[
                    ("ggx+coat", SpecularLobe),
                    ("fa(lambert)", DiffuseFloor),
                    ("dmg(ggx)", GrazingDecay),
                    ("rmg(ggx)", GrazingDecay),
                    ("ggx+retro", RetroLobe),
                    ("ggx+mrm82", RetroLobe),
                ],
            ),
            (
                "btdf(beckmann)+scale",
                &btdf,
                &[
                    ("btdf(tr)+scale", LongTail),
                    ("btdf(beckmann)+scale+absorb", Absorption),
                    ("btdf(beckmann)+scale+diffuse", DiffuseFloor),
                ],
            ),
            // One plane: no +peraxis.
            (
                "btdf(tr)",
                &btdf,
                &[
                    ("btdf(gtr)", LongTail),
                    ("btdf(tr)+scale", Scale),
                    ("btdf(tr)+absorb", Absorption),
                    ("btdf(tr)+diffuse", DiffuseFloor),
                ],
            ),
            (
                "btdf(tr)+scale",
                &two,
                &[
                    ("btdf(gtr)+scale", LongTail),
                    ("btdf(tr)+scale+absorb", Absorption),
                    ("btdf(tr)+scale+diffuse", DiffuseFloor),
                    ("btdf(tr)+scale+aniso", Anisotropy),
                ],
            ),
            // Off-plane: the lobe may be anisotropic.
            (
                "ggx",
                &hemi,
                &[
                    ("ggx+coat", SpecularLobe),
                    ("fa(lambert)", DiffuseFloor),
                    ("dmg(ggx)", GrazingDecay),
                    ("rmg(ggx)", GrazingDecay),
                    ("ggx+retro", RetroLobe),
                    ("ggx+mrm82", RetroLobe),
                    ("ggx+aniso", Anisotropy),
                ],
            ),
        ];
        for (spec, data, want) in cases {
            let want: Vec<(String, Effect)> =
                want.iter().map(|&(s, e)| (s.to_string(), e)).collect();
            let (driven, analytic): (Vec<Candidate>, Vec<Candidate>) = extensions(spec, data)
                .unwrap()
                .into_iter()
                .partition(|c| c.effect.is_data_driven());
            assert_eq!(specs(&analytic), want, "{spec}");
            // The data-driven NDF, for a model with a GGX lobe (btdf(tr)'s too), and the
            // Fresnel curve, for one with a GGX highlight (after the analytic ones).
            let nodes = Model::for_data(spec, data).unwrap();
            let has = |form: &dyn Fn(&dyn crate::bsdf::Bsdf) -> bool| {
                nodes.nodes().iter().any(|n| form(n.bsdf.as_ref()))
            };
            let mut want_driven = vec![];
            if has(&|b| b.ggx_lobe().is_some()) {
                want_driven.push((format!("{spec}+ndf"), HighlightShape));
            }
            if has(&|b| {
                b.ggx_lobe()
                    .is_some_and(|(p, _)| p != crate::bsdf::GgxPlace::Transmission)
            }) {
                want_driven.push((format!("{spec}+fresnel"), HighlightFresnel));
            }
            // The body's profile, for one with a diffuse base.
            if has(&|b| b.entry().role == crate::bsdf::Role::DiffuseBase) {
                want_driven.push((format!("{spec}+body"), BodyProfile));
            }
            assert_eq!(specs(&driven), want_driven, "{spec}");
        }
        for c in extensions("btdf(gg)+absorb", &two)
            .unwrap()
            .iter()
            .chain(&extensions("dmg(lambert)", &brdf).unwrap())
        {
            let data = match Model::parse(&c.spec, 1).unwrap().kind {
                Kind::Btdf => &two,
                Kind::Brdf => &brdf,
            };
            Model::for_data(&c.spec, data).unwrap();
        }
    }

    /// Every extension marked nested reproduces the current model at the embedded
    /// parameters (the micrograin layers of grazing_decay only in the limit τ0 → 0:
    /// within 1 %).
    #[test]
    fn nested_extensions_embed_the_current_model() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let brdf = dataset(
            Kind::Brdf,
            &crate::workflows::synth::geometry("hemi").unwrap().1,
            3,
        );
        let btdf = dataset(
            Kind::Btdf,
            &crate::workflows::synth::geometry("ptb1").unwrap().1,
            1,
        );
        for (start, data) in [
            ("lambert", &brdf),
            ("on", &brdf),
            ("eon", &brdf),
            ("vmf", &brdf),
            ("ggx", &brdf),
            ("fa(lambert)", &brdf),
            ("fa(lambert)+mrm82", &brdf),
            ("lambert+retro", &brdf),
            ("dmg(lambert)", &brdf),
            ("btdf(tr)", &btdf),
            ("btdf(beckmann)+scale", &btdf),
            ("btdf(gg)", &btdf),
        ] {
            let old = Model::for_data(start, data).unwrap();
            for trial in 0..3 {
                let unit: Vec<f64> = (0..old.dim).map(|_| rng.random_range(0.2..0.8)).collect();
                let flat = old.from_unit(&unit);
                for c in extensions(start, data).unwrap() {
                    let new = Model::for_data(&c.spec, data).unwrap();
                    let nf = embed(&old, &flat, &new);
                    if !c.nested {
                        continue;
                    }
                    // The micrograin layer's weight is τ0 at its bound; a data-driven NDF
                    // at s = 0 is GGX through its tabulated masking (3e-4 at θ ≤ 86°).
                    let tol = match c.effect {
                        Effect::GrazingDecay => 1e-2,
                        Effect::HighlightShape => 1e-3,
                        _ => 1e-6,
                    };
                    for s in &data.samples {
                        let a = old.eval(&flat, old.group_of(s), s.wi(), s.wo());
                        let b = new.eval(&nf, new.group_of(s), s.wi(), s.wo());
                        assert!(
                            (a - b).abs() <= tol * a.abs().max(1e-3),
                            "{start} → {} (trial {trial}): {a} vs {b}",
                            c.spec
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn spec_rendering_round_trips() {
        for s in [
            "lambert",
            "fa(eon)+retro",
            "btdf(gtr)+scale+diffuse",
            "dmg(on)",
            "btdf(tr)+peraxis+absorb",
        ] {
            assert_eq!(render_spec(&Ast::parse(s).unwrap()), s);
        }
    }
}
