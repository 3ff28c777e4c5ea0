//! `bsdfit models`.

use crate::bsdf::{self, Model};
use crate::data::Kind;
use crate::workflows::synth;
use anyhow::Result;

pub fn run() -> Result<()> {
    println!("Models (spec strings; nested parameters are prefixed by role, rgb = one value per channel):");
    for e in bsdf::registry::all() {
        let name = match e.role {
            bsdf::Role::Suffix => format!("+{}", e.name),
            _ => e.name.to_string(),
        };
        let kind = e
            .kind
            .map(|k| k.to_string())
            .unwrap_or_else(|| "any".into());
        println!("  {name:<8} {kind:<4} {:<13} {}", role_word(e.role), e.doc);
    }
    let examples = listed_specs();
    println!("\nCatalogue:");
    for spec in examples {
        match Model::parse(&spec, 3) {
            Ok(m) => {
                let ps: Vec<String> = m
                    .params
                    .iter()
                    .map(|p| {
                        format!(
                            "{}{} [{}, {}]",
                            p.name,
                            if p.decl.rgb { " rgb" } else { "" },
                            p.decl.lo,
                            p.decl.hi
                        )
                    })
                    .collect();
                println!("  {spec:<22} {}", ps.join("; "));
            }
            Err(e) => println!("  {spec:<22} unavailable: {e}"),
        }
    }
    println!("\nLosses: smape rmse ngan low (BRDF); f cosf logf logcosf (BTDF); chi2 (any)");
    println!("Weights: uniform relunc invunc");
    println!("\nSynthetic geometries:");
    for g in synth::GEOMETRIES {
        println!("  {:<10} {:<5} {}", g.name, g.kind.to_string(), g.doc);
    }
    Ok(())
}

/// The specs `bsdfit models` lists: the default catalogue of each kind, then one example
/// of each model outside it (a suffix with the first spec the registry derives with it).
pub fn listed_specs() -> Vec<String> {
    let mut examples: Vec<String> = bsdf::catalogue(Kind::Brdf);
    examples.extend(bsdf::catalogue_for(Kind::Btdf, 2));
    for e in bsdf::registry::all() {
        if e.catalogue == bsdf::InCatalogue::No {
            match e.role {
                // The first spec the registry derives with it (`lambert+retro`, or
                // `lambert+retro+falloff` for a suffix that follows another).
                bsdf::Role::Suffix => {
                    let tail = format!("+{}", e.name);
                    let kind = e.kind.unwrap_or(Kind::Brdf);
                    examples.push(
                        bsdf::every_spec(kind)
                            .into_iter()
                            .find(|s| s.ends_with(&tail))
                            .unwrap_or_else(|| format!("{}{tail}", bsdf::catalogue(kind)[0])),
                    )
                }
                _ => examples.push(e.name.to_string()),
            }
        }
    }
    examples
}

fn role_word(r: bsdf::Role) -> &'static str {
    match r {
        bsdf::Role::DiffuseBase => "diffuse base",
        bsdf::Role::SpecularLobe => "specular lobe",
        bsdf::Role::Layer { .. } => "layer over B",
        bsdf::Role::Transmission => "transmission",
        bsdf::Role::Suffix => "suffix",
    }
}
