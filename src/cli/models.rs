//! `bsdfit models`.

use crate::bsdf::{self, Model};
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
    let examples = bsdf::registry::listed_specs();
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

fn role_word(r: bsdf::Role) -> &'static str {
    match r {
        bsdf::Role::DiffuseBase => "diffuse base",
        bsdf::Role::SpecularLobe => "specular lobe",
        bsdf::Role::Layer { .. } => "layer over B",
        bsdf::Role::Transmission => "transmission",
        bsdf::Role::Suffix => "suffix",
    }
}
