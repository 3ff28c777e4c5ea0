//! `bsdfit bench`.

use super::BackendArgs;
use crate::bsdf;
use crate::data::Kind;
use crate::engine::{self, BackendChoice};
use anyhow::{Context, Result};
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct BenchArgs {
    /// Models to measure (default: the whole catalogue, BRDF and BTDF).
    #[arg(long, value_delimiter = ';')]
    pub models: Option<Vec<String>>,
    /// Restarts per batch; a batch holds restarts × (2P + 1) candidates (one compass poll).
    #[arg(long, default_value_t = 256)]
    pub restarts: usize,
    /// Minimum measuring time per model and backend (seconds).
    #[arg(long, default_value_t = 1.0)]
    pub seconds: f64,
    /// Backends to compare: auto (CPU and, if present, GPU), cpu, gpu.
    #[command(flatten)]
    pub backend: BackendArgs,
    /// Write the rows as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

pub fn run(a: BenchArgs) -> Result<()> {
    use crate::workflows::bench::{measure, median_speedup};
    let specs: Vec<(Kind, String)> = match &a.models {
        Some(list) => list
            .iter()
            .map(|s| {
                Ok((
                    bsdf::spec_kind(s).context("--models")?,
                    s.trim().to_string(),
                ))
            })
            .collect::<Result<_>>()?,
        None => bsdf::catalogue(Kind::Brdf)
            .into_iter()
            .map(|s| (Kind::Brdf, s))
            .chain(
                bsdf::catalogue(Kind::Btdf)
                    .into_iter()
                    .map(|s| (Kind::Btdf, s)),
            )
            .collect(),
    };
    let mut backends: Vec<Box<dyn engine::Backend>> = Vec::new();
    if a.backend.backend != BackendChoice::Gpu {
        backends.push(Box::new(engine::cpu::CpuBackend::new()));
    }
    if a.backend.backend != BackendChoice::Cpu {
        match engine::gpu::GpuBackend::new() {
            Ok(g) => backends.push(Box::new(g)),
            Err(e) if a.backend.backend == BackendChoice::Auto => {
                eprintln!("no GPU ({e}); measuring the CPU only")
            }
            Err(e) => return Err(e.context("--backend gpu")),
        }
    }
    for b in &backends {
        eprintln!("backend: {}", b.name());
    }
    let bar = indicatif::ProgressBar::new((specs.len() * backends.len()) as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{msg:30} [{elapsed_precise}] {bar:30} {pos}/{len} (ETA {eta})",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let mut rows = Vec::new();
    for (kind, spec) in &specs {
        for b in &backends {
            bar.set_message(format!("{spec} on {}", b.id()));
            match measure(spec, *kind, b.as_ref(), a.restarts, a.seconds) {
                Ok(r) => rows.push(r),
                Err(e) => bar.println(format!("skipping {spec} on {}: {e:#}", b.id())),
            }
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    println!(
        "{:<24} {:>8} {:>8} {:>10} {:>14}",
        "model", "backend", "samples", "candidates", "evals/s"
    );
    for r in &rows {
        println!(
            "{:<24} {:>8} {:>8} {:>10} {:>14.3e}",
            r.model, r.backend, r.samples, r.candidates, r.evals_per_s
        );
    }
    if let Some(s) = median_speedup(&rows) {
        println!("median GPU/CPU speed-up over models: {s:.2}x");
    }
    if let Some(path) = &a.json {
        std::fs::write(path, serde_json::to_string_pretty(&rows)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}
