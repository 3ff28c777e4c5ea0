//! `bsdfit bench`.

use super::checks::batch_memory;
use super::progress::{ConsoleObserver, Progress};
use super::BackendArgs;
use crate::bsdf;
use crate::data::Kind;
use crate::engine::{self, BackendChoice};
use anyhow::{Context, Result};
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct BenchArgs {
    /// Models to measure, comma-separated as in `sweep` (default: the whole catalogue,
    /// BRDF and BTDF; with --data, the catalogue of the data's kind).
    #[arg(long, value_delimiter = ',')]
    pub models: Option<Vec<String>>,
    /// Measure on this data file instead of the built-in synthetic sets (816 BRDF samples
    /// in 3 channels, 195 BTDF samples): any format read (bsdfit v1 CSV, ALTA text, MERL
    /// binary, RGL .bsdf, Zemax BSDF, ASTM E1392, Mueller-matrix BRDF CSV; recognised by content).
    #[arg(long, value_name = "FILE")]
    pub data: Option<PathBuf>,
    /// Reading options of --data.
    #[command(flatten)]
    pub data_args: super::DataArgs,
    /// Restarts per batch; a batch holds restarts × (2P + 1) candidates (one compass poll).
    #[arg(long, default_value_t = 256, value_parser = super::parse_restarts, allow_hyphen_values = true)]
    pub restarts: usize,
    /// Minimum measuring time per model and backend (seconds).
    #[arg(long, default_value_t = 1.0)]
    pub seconds: f64,
    /// Backends to compare: auto (the CPU reference, the SIMD engine and, if an adapter
    /// exists, the GPU engine), or one of cpu, simd, gpu.
    #[command(flatten)]
    pub backend: BackendArgs,
    /// Write the rows as JSON here (checked before measuring; if the write fails
    /// afterwards, the JSON is printed to stdout instead).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Also time a whole sweep (`bsdfit sweep` with its defaults, no pictures) once per
    /// backend, each into its own temporary folder, and compare the GPU's and the SIMD
    /// engine's each with the CPU reference's: wall time, fits, evaluations, evals/s, the
    /// GPU's device submissions (how many; candidates, evaluations and milliseconds each),
    /// the GPU/CPU and SIMD/CPU time ratios, whether the rankings (per data set ×
    /// loss × weighting, models by best loss) are identical, and if not whether they agree
    /// up to ties (losses within the 1e-3 tolerance) or which pairs of models the two
    /// order oppositely, the fits at different local optima (losses more than 1e-3
    /// apart), and the largest parameter differences at one optimum against the stated
    /// f32 tolerance (1e-2 of the parameter's box, or 0.05 of its standard uncertainty
    /// where that is looser). `--models` applies to it.
    #[arg(long)]
    pub sweep: bool,
    /// Data of `--sweep`: files or directories of *.csv (default: the bundled data/, as
    /// `sweep`).
    #[arg(long, num_args = 1.., requires = "sweep")]
    pub sweep_data: Vec<PathBuf>,
    /// Restarts per fit of `--sweep` (default: the sweep's).
    #[arg(long, default_value_t = super::DEFAULT_RESTARTS, value_parser = super::parse_restarts, allow_hyphen_values = true)]
    pub sweep_restarts: usize,
    /// With `--sweep`: also run the CPU reference's sweep with this seed (the sweeps use
    /// seed 1) and compare the two CPU sweeps as the GPU's is compared: how much
    /// multi-start variance alone moves the losses and reorders the rankings, the scale
    /// against which the GPU's differences should be read. Costs one more CPU sweep.
    #[arg(long, requires = "sweep", value_parser = super::parse_seed)]
    pub sweep_reference_seed: Option<u64>,
    /// Measure how cost grows with the data instead: for random isotropic data sets of
    /// each size of --scale-sizes, the throughput of a fit's two batches (LM's normal
    /// equations of 16 restarts, the costs of 128 screened points) and the process's peak
    /// resident memory, for the models of --models (default: lambert, fa(eon),
    /// btdf(gg)), on each backend in one run, with each engine's ratio to the CPU
    /// reference.
    #[arg(long, conflicts_with_all = ["data", "sweep"])]
    pub scale: bool,
    /// With --scale: the data sizes (samples), comma-separated; 1e6 and 1_000_000 both
    /// read.
    #[arg(long, value_delimiter = ',', requires = "scale", value_parser = parse_size)]
    pub scale_sizes: Option<Vec<usize>>,
}

/// A sample count: an integer, or a power of ten written 1e6.
fn parse_size(s: &str) -> Result<usize, String> {
    let t = s.trim().replace('_', "");
    let v: f64 = t
        .parse()
        .map_err(|_| format!("'{s}' is not a sample count"))?;
    if !((1.0..=1e9).contains(&v) && v.fract() == 0.0) {
        return Err(format!("'{s}': a sample count from 1 to 1e9"));
    }
    Ok(v as usize)
}

/// The seed of `bench --sweep`'s sweeps (`sweep`'s default).
const SWEEP_SEED: u64 = crate::workflows::sweep::run::DEFAULT_SEED;

/// The models `bench` measures: `--models`, or the catalogue of the data's kind (of both
/// kinds without `--data`); a model of the other kind than `--data`'s is an error.
fn selected_specs(
    a: &BenchArgs,
    file: Option<&crate::data::Dataset>,
) -> Result<Vec<(Kind, String)>> {
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
        None => [Kind::Brdf, Kind::Btdf]
            .into_iter()
            .filter(|&k| file.is_none_or(|d| d.kind == k))
            .flat_map(|k| bsdf::catalogue(k).into_iter().map(move |s| (k, s)))
            .collect(),
    };
    if let Some(d) = file {
        if let Some((kind, spec)) = specs.iter().find(|(k, _)| *k != d.kind) {
            anyhow::bail!(
                "--models: {spec} is a {kind} model but --data {} holds {} data",
                d.source.display(),
                d.kind
            );
        }
    }
    Ok(specs)
}

/// The throughput table on stdout.
fn print_table(rows: &[crate::workflows::bench::BenchRow], file: Option<&crate::data::Dataset>) {
    if let Some(d) = file {
        println!("data: {} ({} samples)", d.source.display(), d.len());
    }
    println!(
        "{:<24} {:>8} {:>8} {:>10} {:>12} {:>12} {:>12}",
        "model", "backend", "samples", "candidates", "evals/s", "per thread", "per CPU-s"
    );
    let sci = |v: Option<f64>| v.map_or_else(|| "-".to_string(), |v| format!("{v:.3e}"));
    for r in rows {
        println!(
            "{:<24} {:>8} {:>8} {:>10} {:>12.3e} {:>12} {:>12}",
            r.model,
            r.backend,
            r.samples,
            r.candidates,
            r.evals_per_s,
            sci(r.threads.map(|t| r.evals_per_s / t.max(1) as f64)),
            sci(r.evals_per_cpu_s)
        );
    }
}

pub fn run(a: BenchArgs) -> Result<()> {
    use crate::workflows::bench::{bench_dataset, measure, median_ratio, median_speedup};
    if let Some(path) = &a.json {
        crate::output::check_writable_file(path, "--json")?;
    }
    anyhow::ensure!(
        a.sweep_reference_seed != Some(SWEEP_SEED),
        "--sweep-reference-seed {SWEEP_SEED} is the sweeps' own seed: give another"
    );
    anyhow::ensure!(
        a.seconds.is_finite() && a.seconds > 0.0 && a.seconds <= 3600.0,
        "--seconds must be in (0, 3600], got {}",
        a.seconds
    );
    if a.scale {
        return scale_bench(&a);
    }
    let file = match &a.data {
        Some(path) => Some(a.data_args.read(path).context("--data")?),
        None => None,
    };
    let specs = selected_specs(&a, file.as_ref())?;
    // The data of each model: the file, or the built-in synthetic set of its kind.
    let data_for = |spec: &str, kind: Kind| -> Result<std::borrow::Cow<crate::data::Dataset>> {
        Ok(match &file {
            Some(d) => std::borrow::Cow::Borrowed(d),
            None => std::borrow::Cow::Owned(bench_dataset(spec, kind)?),
        })
    };
    let backends = backends_for(a.backend.backend)?;
    // Every batch must fit in memory: checked for all models before measuring any.
    for (kind, spec) in &specs {
        if let Ok(data) = data_for(spec, *kind) {
            if let Ok(m) = bsdf::Model::for_data(spec, &data) {
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
            let row = data_for(spec, *kind)
                .and_then(|data| measure(spec, &data, b.as_ref(), a.restarts, a.seconds));
            match row {
                Ok(r) => rows.push(r),
                Err(e) => progress.println(format!(
                    "skipping {spec} on {}: {}",
                    b.id(),
                    super::error_text(&e)
                )),
            }
            progress.inc(1);
        }
    }
    progress.finish();
    print_table(&rows, file.as_ref());
    let median = median_speedup(&rows);
    if let Some(s) = median {
        println!("median GPU/CPU speed-up over models: {s:.2}x");
    }
    let median_simd = median_ratio(&rows, "simd", "cpu");
    if let Some(s) = median_simd {
        println!("median SIMD/CPU speed-up over models: {s:.2}x");
    }
    if let Some(s) = median_ratio(&rows, "simd", "gpu") {
        println!("median SIMD/GPU speed ratio over models: {s:.2}x");
    }
    let sweep = if a.sweep {
        Some(sweep_bench(&a, &backends)?)
    } else {
        None
    };
    if let Some(path) = &a.json {
        let value = match &sweep {
            None => serde_json::to_value(&rows)?,
            Some(s) => serde_json::json!({
                "rows": rows,
                "median_speedup": median,
                "median_simd_speedup": median_simd,
                "sweep": s,
            }),
        };
        let text = serde_json::to_string_pretty(&value)? + "\n";
        crate::output::files::write_result(path, &text, true)?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

/// `--sweep`: the sweep once per measured backend (CPU first), then printed.
fn sweep_bench(
    a: &BenchArgs,
    backends: &[Box<dyn engine::Backend>],
) -> Result<crate::workflows::bench::SweepBench> {
    use crate::workflows::sweep::{Selection, SweepConfig};
    let defaults = SweepConfig::default();
    let base = SweepConfig {
        data: a.sweep_data.clone(),
        selection: Selection {
            models: a.models.clone(),
            ..defaults.selection.clone()
        },
        restarts: a.sweep_restarts,
        seed: SWEEP_SEED,
        pictures: false,
        ..defaults
    };
    // The measured backends, by the choice that selects each.
    let choices = backends
        .iter()
        .map(|b| {
            BackendChoice::from_name(b.id())
                .with_context(|| format!("no --backend selects the backend '{}'", b.id()))
        })
        .collect::<Result<Vec<_>>>()?;
    let bench = crate::workflows::bench::sweep_bench(
        &base,
        &choices,
        a.sweep_reference_seed,
        &mut ConsoleObserver::new("sweep"),
    )?;
    print_sweep_bench(&bench);
    Ok(bench)
}

/// The `--sweep` tables and comparisons on stdout.
fn print_sweep_bench(bench: &crate::workflows::bench::SweepBench) {
    let timings = &bench.backends;
    println!();
    println!(
        "{:<8} {:>10} {:>6} {:>14} {:>12}",
        "sweep", "wall (s)", "fits", "evaluations", "evals/s"
    );
    for t in timings {
        println!(
            "{:<8} {:>10.2} {:>6} {:>14} {:>12.3e}",
            t.backend, t.wall_seconds, t.fits, t.evaluations, t.evals_per_s
        );
    }
    for t in timings {
        let p = &t.phases;
        println!(
            "{} phases (s, summed over the sweep's worker threads): set-up {:.2}, screening \
             {:.2}, search {:.2}, f64 polish {:.2}, conclusions {:.2}",
            t.backend, p.setup, p.screening, p.search, p.polish, p.conclusions
        );
    }
    for t in timings {
        if let Some(s) = &t.submissions {
            println!(
                "{} submissions: {}; candidates each: median {:.0}, p90 {:.0}, max {:.0}; \
                 evaluations each: median {:.3e}, p90 {:.3e}, max {:.3e}; time each: median \
                 {:.2} ms, mean {:.2} ms ({:.1} s in all, summed over the sweep's threads)",
                t.backend,
                s.submissions,
                s.candidates.median,
                s.candidates.p90,
                s.candidates.max,
                s.evaluations.median,
                s.evaluations.p90,
                s.evaluations.max,
                s.seconds.median * 1e3,
                s.seconds.mean * 1e3,
                s.seconds_total
            );
        }
    }
    if let Some(r) = bench.gpu_cpu_time_ratio {
        println!("GPU/CPU sweep time ratio: {r:.3}");
    }
    if let Some(r) = bench.simd_cpu_time_ratio {
        println!("SIMD/CPU sweep time ratio: {r:.3}");
    }
    if let Some(c) = &bench.comparison {
        print_comparison(
            c,
            timings.first().map_or(0, |t| t.fits),
            ["cpu", "gpu"],
            "the f32 tolerance",
        );
    }
    if let Some(c) = &bench.simd_comparison {
        print_comparison(
            c,
            timings.first().map_or(0, |t| t.fits),
            ["cpu", "simd"],
            "the f32 tolerance",
        );
    }
    if let Some(r) = &bench.reference_seed {
        println!();
        println!(
            "CPU reference, seed {SWEEP_SEED} against seed {} ({:.2} s): the spread of \
             multi-start search alone",
            r.seed, r.wall_seconds
        );
        print_comparison(
            &r.comparison,
            timings
                .iter()
                .find(|t| t.backend == "cpu")
                .map_or(0, |t| t.fits),
            [format!("seed {SWEEP_SEED}"), format!("seed {}", r.seed)],
            "the tolerance",
        );
    }
}

/// Print a comparison of two sweeps, `labels` naming the first and the second (the
/// comparison's `cpu` and `gpu` sides).
fn print_comparison(
    c: &crate::workflows::bench::SweepComparison,
    fits: usize,
    labels: [impl std::fmt::Display; 2],
    tolerance: &str,
) {
    let [first, second] = &labels;
    println!(
        "rankings (data set × loss × weighting, models by best loss): {}",
        if c.rankings_identical {
            "identical".to_string()
        } else if c.rankings_agree_up_to_ties {
            format!(
                "the same up to ties within {:.0e} ({} group(s) order tied models differently)",
                c.loss_tolerance, c.groups_reordered
            )
        } else {
            format!(
                "{} group(s) order models oppositely beyond {:.0e} ({} reordered in all)",
                c.ranking_differences.len(),
                c.loss_tolerance,
                c.groups_reordered
            )
        }
    );
    for d in &c.ranking_differences {
        println!("  {} {}/{}:", d.data, d.loss, d.weights);
        for p in &d.inverted {
            println!(
                "    {first} {} {:.6e} < {} {:.6e}; {second} {:.6e} > {:.6e}",
                p.better_on_cpu,
                p.cpu_losses[0],
                p.better_on_gpu,
                p.cpu_losses[1],
                p.gpu_losses[0],
                p.gpu_losses[1]
            );
        }
        if d.inverted.is_empty() {
            println!(
                "    {first} {} | {second} {}",
                d.cpu.join(" < "),
                d.gpu.join(" < ")
            );
        }
    }
    println!(
        "largest relative best-loss difference: {:.2e} ({}); {} fit(s) differ by more than \
         {:.0e}, at different local optima ({first} lower in {}, {second} in {}): where \
         restarts land is multi-start's chance, not f32's",
        c.max_rel_loss_diff.value,
        c.max_rel_loss_diff.at,
        c.fits_at_different_optima,
        c.loss_tolerance,
        c.fits_at_different_optima - c.different_optima_lower_on_gpu,
        c.different_optima_lower_on_gpu
    );
    println!(
        "largest parameter difference (unit box), over the fits at one optimum and the \
         parameters both determined ({} undetermined value(s) left out): {:.2e} ({})",
        c.params_undetermined, c.max_param_diff_unit_box.value, c.max_param_diff_unit_box.at
    );
    println!(
        "largest parameter difference in standard uncertainties (same fits and parameters): \
         {:.2e} σ ({})",
        c.max_param_diff_sigma.value, c.max_param_diff_sigma.at
    );
    println!(
        "largest parameter difference over its tolerance ({:.0e} of the box, or {} σ where \
         that is looser): {:.2} ({})",
        c.param_tolerance,
        c.param_tolerance_sigma,
        c.max_param_diff_over_tolerance.value,
        c.max_param_diff_over_tolerance.at
    );
    println!(
        "{} of {fits} fits compared; at one optimum, {}",
        c.fits_compared,
        if c.within_tolerance {
            format!("within {tolerance}")
        } else {
            format!("NOT within {tolerance}")
        }
    );
}

/// `--scale`: every model at every size on every backend.
fn scale_bench(a: &BenchArgs) -> Result<()> {
    use crate::workflows::scale::{
        measure_scale, scale_dataset, table, DEFAULT_MODELS, DEFAULT_SIZES,
    };
    let specs: Vec<(Kind, String)> = match &a.models {
        Some(list) => list.iter().map(|s| s.trim().to_string()).collect(),
        None => DEFAULT_MODELS
            .iter()
            .map(|s| s.to_string())
            .collect::<Vec<_>>(),
    }
    .into_iter()
    .map(|s| Ok((bsdf::spec_kind(&s).context("--models")?, s)))
    .collect::<Result<_>>()?;
    let sizes = a.scale_sizes.clone().unwrap_or(DEFAULT_SIZES.to_vec());
    let backends = backends_for(a.backend.backend)?;
    for b in &backends {
        eprintln!("backend: {}", b.name());
    }
    let mut progress = Progress::new(
        "bench --scale",
        (specs.len() * sizes.len() * backends.len()) as u64,
        "measurements",
    );
    let mut rows = Vec::new();
    for &size in &sizes {
        for (kind, spec) in &specs {
            progress.set_message(format!("{spec}, {size} samples: data"));
            let data = scale_dataset(spec, *kind, size, 1)?;
            for b in &backends {
                progress.set_message(format!("{spec}, {size} samples, {}", b.id()));
                match measure_scale(spec, &data, b.as_ref(), a.seconds) {
                    Ok(r) => rows.push(r),
                    Err(e) => progress.println(format!(
                        "skipping {spec} at {size} on {}: {}",
                        b.id(),
                        super::error_text(&e)
                    )),
                }
                progress.inc(1);
            }
        }
    }
    progress.finish();
    print!("{}", table(&rows));
    if let Some(path) = &a.json {
        let text = serde_json::to_string_pretty(&rows)? + "\n";
        crate::output::files::write_result(path, &text, true)?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

/// The backends `--backend` asks to measure: one of them, or (auto) the CPU reference,
/// the SIMD engine and the GPU engine where an adapter exists, in one run.
fn backends_for(choice: BackendChoice) -> Result<Vec<Box<dyn engine::Backend>>> {
    let mut backends: Vec<Box<dyn engine::Backend>> = Vec::new();
    if matches!(choice, BackendChoice::Auto | BackendChoice::Cpu) {
        backends.push(Box::new(engine::cpu::CpuBackend::new()));
    }
    if matches!(choice, BackendChoice::Auto | BackendChoice::Simd) {
        backends.push(Box::new(engine::simd::SimdBackend::new()));
    }
    if matches!(choice, BackendChoice::Auto | BackendChoice::Gpu) {
        match engine::gpu::GpuBackend::new() {
            Ok(g) => backends.push(Box::new(g)),
            Err(e) if choice == BackendChoice::Auto => {
                eprintln!("no GPU ({e}); measuring the CPU engines only")
            }
            Err(e) => return Err(e.context("--backend gpu")),
        }
    }
    Ok(backends)
}
