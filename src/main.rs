//! The `bsdfit` command line (DESIGN §8).

use anyhow::{Context, Result};
use bsdfit::backend::{self, BackendChoice};
use bsdfit::dataset::{Dataset, Kind, ReadOptions};
use bsdfit::fit::{fit, FitOptions, Optimizer};
use bsdfit::loss::{Loss, Metric, Weights};
use bsdfit::model::{self, Model};
use bsdfit::synth;
use clap::{Args, Parser, Subcommand};
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "bsdfit",
    version,
    about = "Fit BRDF/BTDF models to measured data with uncertainties (GPU batch fitter with a CPU reference)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Fit one model to one dataset.
    Fit(FitArgs),
    /// Write a synthetic dataset from a model with known parameters.
    Synth(SynthArgs),
    /// List the model catalogue with its parameters, the losses and the geometries.
    Models,
    /// Measure CPU and GPU throughput (model-sample evaluations per second).
    Bench(BenchArgs),
    /// Run the benchmark: every data set × model × loss × weighting (resumable, shardable),
    /// then results tables, angular plots, sphere renders and report.html.
    Sweep(bsdfit::sweep::SweepArgs),
    /// Combine the results of sweep shards (`sweep --shard I/N`) and write the report.
    Merge(bsdfit::sweep::MergeArgs),
    /// Render a sphere with a fitted BRDF, the tabulated measurement and their error image.
    Render(bsdfit::render::RenderArgs),
    /// Find where a model and the measurement disagree, name the missing effect, add it,
    /// and repeat while the improvement is significant (DESIGN §7).
    Diagnose(bsdfit::diagnose::DiagnoseArgs),
    /// Convert a data file of any supported format (v1 CSV, ALTA text, MERL binary) to
    /// bsdfit v1 CSV, applying the data-selection options.
    Convert(ConvertArgs),
}

#[derive(Args)]
struct ConvertArgs {
    /// Input file (format recognised by content).
    input: PathBuf,
    /// Output v1 CSV file.
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    data_args: DataArgs,
}

#[derive(Args)]
struct BenchArgs {
    /// Models to measure (default: the whole catalogue, BRDF and BTDF).
    #[arg(long, value_delimiter = ';')]
    models: Option<Vec<String>>,
    /// Restarts per batch; a batch holds restarts × (2P + 1) candidates (one compass poll).
    #[arg(long, default_value_t = 256)]
    restarts: usize,
    /// Minimum measuring time per model and backend (seconds).
    #[arg(long, default_value_t = 1.0)]
    seconds: f64,
    /// Backends to compare: auto (CPU and, if present, GPU), cpu, gpu.
    #[arg(long, value_enum, default_value = "auto")]
    backend: BackendChoice,
    /// Write the rows as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
}

#[derive(Args, Clone)]
struct DataArgs {
    /// Keep the channels nearest these wavelengths (nm), e.g. 450,550,650.
    #[arg(long, value_delimiter = ',')]
    wavelengths: Option<Vec<f64>>,
    /// Replace zero uncertainties by a floor (max(1%·|value|, 1e-6)) instead of rejecting them.
    #[arg(long)]
    allow_zero_uncertainty: bool,
    #[command(flatten)]
    selection: bsdfit::readers::DataSelection,
}

impl DataArgs {
    fn options(&self) -> Result<ReadOptions> {
        let mut opts = ReadOptions {
            allow_zero_uncertainty: self.allow_zero_uncertainty,
            wavelengths: self.wavelengths.clone(),
            ..Default::default()
        };
        self.selection
            .apply(&mut opts)
            .map_err(|e| anyhow::anyhow!(e))?;
        Ok(opts)
    }

    fn read(&self, path: &std::path::Path) -> Result<Dataset> {
        let ds = bsdfit::readers::load_reporting(path, &self.options()?)?;
        for n in &ds.notices {
            eprintln!("note: {n}");
        }
        Ok(ds)
    }
}

#[derive(Args)]
struct FitArgs {
    /// Dataset file (bsdfit CSV v1).
    data: PathBuf,
    /// Model spec, e.g. lambert, on, fa(eon), rmg(ggx), btdf(tr)+scale.
    #[arg(long)]
    model: String,
    /// Loss: smape rmse ngan low (BRDF), f cosf logf logcosf (BTDF), chi2 (any).
    #[arg(long, default_value = "rmse")]
    loss: String,
    /// Weights: uniform, relunc (BRDF, paper §2.2), invunc (BTDF, paper §2.3.2).
    #[arg(long, default_value = "uniform")]
    weights: String,
    #[arg(long, value_enum, default_value = "compass")]
    optimizer: Optimizer,
    /// Number of random restarts (stepped in lockstep).
    #[arg(long, default_value_t = 32)]
    restarts: usize,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    #[arg(long, value_enum, default_value = "auto")]
    backend: BackendChoice,
    /// Write the fit report (DESIGN §8) as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Fit each measured φ plane separately (anisotropic samples, paper §2.3.2); the JSON
    /// is then {"per_axis": [{"phi": …, "fit": report}, …]}.
    #[arg(long)]
    per_axis: bool,
    #[command(flatten)]
    data_args: DataArgs,
}

#[derive(Args)]
struct SynthArgs {
    #[arg(long)]
    model: String,
    /// Parameter values, e.g. rho=0.5,sigma=0.7 or rho=0.4:0.5:0.6 (one per channel).
    #[arg(long, default_value = "")]
    params: String,
    /// Geometry name (see `bsdfit models`), or names joined by `+` for their union.
    #[arg(long)]
    geometry: Option<String>,
    /// Angular standard uncertainty (degrees) of θi and θo, propagated through the model's
    /// slope into each sample's uncertainty (larger on the flanks of peaks).
    #[arg(long, default_value_t = 0.0)]
    angular_unc: f64,
    /// Noise as REL,ABS: u = sqrt((REL·f)² + ABS²).
    #[arg(long, default_value = "0.015,0.0001")]
    noise: String,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Wavelengths (nm), one per channel; default 450,550,650 (BRDF) or 633 (BTDF).
    #[arg(long, value_delimiter = ',')]
    wavelengths: Option<Vec<f64>>,
    /// Material name written in the file.
    #[arg(long)]
    material: Option<String>,
    #[arg(long)]
    out: PathBuf,
}

fn main() {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Fit(a) => cmd_fit(a),
        Command::Synth(a) => cmd_synth(a),
        Command::Models => cmd_models(),
        Command::Bench(a) => cmd_bench(a),
        Command::Sweep(a) => bsdfit::sweep::run_sweep(&a),
        Command::Merge(a) => bsdfit::sweep::run_merge(&a),
        Command::Render(a) => bsdfit::render::run_render(&a),
        Command::Diagnose(a) => bsdfit::diagnose::run_diagnose(&a),
        Command::Convert(a) => cmd_convert(a),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn parse_loss(loss: &str, weights: &str, kind: Kind) -> Result<Loss> {
    let metric: Metric = loss
        .parse()
        .map_err(|e: String| anyhow::anyhow!("--loss: {e}"))?;
    let weights: Weights = weights
        .parse()
        .map_err(|e: String| anyhow::anyhow!("--weights: {e}"))?;
    anyhow::ensure!(
        metric.applies_to(kind),
        "--loss {metric} is not defined for {kind} data (use one of {:?} or chi2)",
        Metric::for_kind(kind)
            .iter()
            .map(|m| m.to_string())
            .collect::<Vec<_>>()
    );
    Ok(Loss::new(metric, weights))
}

fn cmd_fit(a: FitArgs) -> Result<()> {
    let data = a.data_args.read(&a.data)?;
    let loss = parse_loss(&a.loss, &a.weights, data.kind)?;
    let backend = backend::select(a.backend, &mut |m| eprintln!("{m}"))?;
    let opts = FitOptions {
        optimizer: a.optimizer,
        restarts: a.restarts,
        seed: a.seed,
        ..Default::default()
    };
    let run = |data: &Dataset| -> Result<bsdfit::fit::FitReport> {
        let model = Model::for_data(&a.model, data).context("--model")?;
        let bar = indicatif::ProgressBar::new(a.restarts as u64);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{spinner} {msg} [{elapsed_precise}] {bar:30} {pos}/{len} restarts converged",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar.set_message(format!("fitting {}", model.spec));
        let report = fit(&model, data, loss, backend.as_ref(), &opts, &mut |active| {
            bar.set_position((a.restarts - active) as u64)
        })?;
        bar.finish_and_clear();
        print!("{}", report.summary());
        Ok(report)
    };
    let json = if a.per_axis {
        // The paper's approach for anisotropic samples (§2.3.2): one fit per φ plane.
        anyhow::ensure!(
            data.axes.len() > 1,
            "--per-axis: {} is measured on a single plane (φ = {}°)",
            a.data.display(),
            data.axes[0]
        );
        let mut fits = Vec::new();
        for (i, phi) in data.axes.iter().enumerate() {
            println!("== plane φ = {phi}° ==");
            let report = run(&data.axis_subset(i))?;
            fits.push(serde_json::json!({ "phi": phi, "fit": report }));
        }
        serde_json::json!({ "per_axis": fits })
    } else {
        serde_json::to_value(run(&data)?)?
    };
    if let Some(path) = &a.json {
        let text = serde_json::to_string_pretty(&json)?;
        std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

fn cmd_synth(a: SynthArgs) -> Result<()> {
    let ast_kind = if a.model.trim_start().starts_with("btdf") {
        Kind::Btdf
    } else {
        Kind::Brdf
    };
    let wavelengths = a.wavelengths.clone().unwrap_or_else(|| match ast_kind {
        Kind::Brdf => vec![450.0, 550.0, 650.0],
        Kind::Btdf => vec![633.0],
    });
    let geometry = a.geometry.clone().unwrap_or_else(|| match ast_kind {
        Kind::Brdf => "inplane10".into(),
        Kind::Btdf => "oblique".into(),
    });
    let (gkind, rows) =
        synth::geometry_expr(&geometry).map_err(|e| anyhow::anyhow!("--geometry: {e}"))?;
    let planes = bsdfit::dataset::measurement_planes(
        rows.iter()
            .map(|r| bsdfit::dataset::normalise_angles(r[2], r[3])),
    );
    let model = Model::parse_for(&a.model, wavelengths.len(), &planes).context("--model")?;
    anyhow::ensure!(
        gkind == model.kind,
        "--geometry {geometry} is a {gkind} geometry but {} is a {} model",
        model.spec,
        model.kind
    );
    let flat = model.params_from_assignments(&a.params)?;
    let (rel, abs) = a
        .noise
        .split_once(',')
        .and_then(|(r, s)| Some((r.trim().parse::<f64>().ok()?, s.trim().parse::<f64>().ok()?)))
        .ok_or_else(|| {
            anyhow::anyhow!(
                "--noise: expected REL,ABS such as 0.015,0.0001, got '{}'",
                a.noise
            )
        })?;
    let material = a
        .material
        .clone()
        .unwrap_or_else(|| format!("synthetic {}", model.spec));
    let mut ds = synth::synthesize_angular(
        &model,
        &flat,
        &rows,
        &wavelengths,
        synth::Noise { rel, abs },
        a.angular_unc,
        a.seed,
        &material,
    )
    .map_err(|e| anyhow::anyhow!(e))?;
    ds.meta.insert("synth_geometry".into(), geometry.clone());
    ds.write(&a.out)?;
    eprintln!(
        "wrote {} ({}, {} channel(s), geometry {geometry})",
        a.out.display(),
        bsdfit::dataset::count(ds.len(), "sample", "samples"),
        ds.channel_count()
    );
    Ok(())
}

fn cmd_convert(a: ConvertArgs) -> Result<()> {
    let ds = bsdfit::readers::convert(&a.input, &a.out, &a.data_args.options()?)?;
    for n in &ds.notices {
        eprintln!("note: {n}");
    }
    eprintln!(
        "wrote {} ({}, {} channel(s): {:?} nm)",
        a.out.display(),
        bsdfit::dataset::count(ds.len(), "sample", "samples"),
        ds.channel_count(),
        ds.channels
    );
    Ok(())
}

fn cmd_models() -> Result<()> {
    println!("Models (spec strings; nested parameters are prefixed by role, rgb = one value per channel):");
    let mut examples: Vec<String> = model::catalogue(Kind::Brdf);
    examples.push("lambert+retro".into());
    examples.extend(model::catalogue(Kind::Btdf));
    for (name, _, doc) in model::TERMS {
        println!("  {name:<8} {doc}");
    }
    for (name, _, doc) in model::SUFFIXES {
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

fn cmd_bench(a: BenchArgs) -> Result<()> {
    use bsdfit::bench::{measure, median_speedup};
    let specs: Vec<(Kind, String)> = match &a.models {
        Some(list) => list
            .iter()
            .map(|s| {
                let kind = if s.trim_start().starts_with("btdf") {
                    Kind::Btdf
                } else {
                    Kind::Brdf
                };
                (kind, s.trim().to_string())
            })
            .collect(),
        None => model::catalogue(Kind::Brdf)
            .into_iter()
            .map(|s| (Kind::Brdf, s))
            .chain(
                model::catalogue(Kind::Btdf)
                    .into_iter()
                    .map(|s| (Kind::Btdf, s)),
            )
            .collect(),
    };
    let mut backends: Vec<Box<dyn backend::Backend>> = Vec::new();
    if a.backend != BackendChoice::Gpu {
        backends.push(Box::new(backend::cpu::CpuBackend::new()));
    }
    if a.backend != BackendChoice::Cpu {
        match backend::gpu::GpuBackend::new() {
            Ok(g) => backends.push(Box::new(g)),
            Err(e) if a.backend == BackendChoice::Auto => {
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
