//! `bsdfit bench`.

use super::checks::batch_memory;
use super::progress::Progress;
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
    #[arg(long, default_value_t = 256, value_parser = super::parse_restarts, allow_hyphen_values = true)]
    pub restarts: usize,
    /// Minimum measuring time per model and backend (seconds).
    #[arg(long, default_value_t = 1.0)]
    pub seconds: f64,
    /// Backends to compare: auto (CPU and, if present, GPU), cpu, gpu.
    #[command(flatten)]
    pub backend: BackendArgs,
    /// Write the rows as JSON here (checked before measuring; if the write fails
    /// afterwards, the JSON is printed to stdout instead).
    #[arg(long)]
    pub json: Option<PathBuf>,
}

pub fn run(a: BenchArgs) -> Result<()> {
    use crate::workflows::bench::{bench_dataset, measure, median_speedup};
    if let Some(path) = &a.json {
        crate::output::check_writable_file(path, "--json")?;
    }
    anyhow::ensure!(
        a.seconds.is_finite() && a.seconds > 0.0 && a.seconds <= 3600.0,
        "--seconds must be in (0, 3600], got {}",
        a.seconds
    );
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
    // Every batch must fit in memory: checked for all models before measuring any.
    for (kind, spec) in &specs {
        if let Ok(data) = bench_dataset(spec, *kind) {
            if let Ok(m) = bsdf::Model::parse(spec, data.channel_count()) {
                let cands = a.restarts as u64 * (2 * m.dim as u64 + 1);
                batch_memory(
                    "--restarts",
                    a.restarts,
                    cands,
                    m.dim,
                    data.len(),
                    spec,
                    &mut |w| eprintln!("{w}"),
                )?;
            }
        }
    }
    for b in &backends {
        eprintln!("backend: {}", b.name());
    }
    let mut progress = Progress::new(
        "bench",
        (specs.len() * backends.len()) as u64,
        "measurements",
    );
    let mut rows = Vec::new();
    for (kind, spec) in &specs {
        for b in &backends {
            progress.set_message(format!("{spec} on {}", b.id()));
            match measure(spec, *kind, b.as_ref(), a.restarts, a.seconds) {
                Ok(r) => rows.push(r),
                Err(e) => progress.println(format!("skipping {spec} on {}: {e:#}", b.id())),
            }
            progress.inc(1);
        }
    }
    progress.finish();
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
        let text = serde_json::to_string_pretty(&rows)? + "\n";
        crate::output::files::write_result(path, &text, true)?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}
