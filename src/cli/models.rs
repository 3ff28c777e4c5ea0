//! `bsdfit models`.

use crate::bsdf::{self, Model};
use crate::data::Kind;
use crate::workflows::synth;
use anyhow::Result;

pub fn run() -> Result<()> {
    println!("Models (spec strings; nested parameters are prefixed by role, rgb = one value per channel):");
    let mut examples: Vec<String> = bsdf::catalogue(Kind::Brdf);
    examples.push("lambert+retro".into());
    examples.extend(bsdf::catalogue(Kind::Btdf));
    for (name, _, doc) in bsdf::TERMS {
        println!("  {name:<8} {doc}");
    }
    for (name, _, doc) in bsdf::SUFFIXES {
        println!("  +{name:<7} {doc}");
    }
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
