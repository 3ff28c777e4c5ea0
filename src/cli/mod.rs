//! The `bsdfit` command line: every command's options, and the handlers that turn them
//! into calls of the library. Option groups shared by several commands (data selection,
//! backend) are declared once here and flattened into each command, so every command
//! accepts the same spelling of the same option.

use crate::choice::{Choice, FieldError};
use crate::data::readers::alta::AltaValues;
use crate::data::readers::{self, merl};
use crate::data::{AssumeArg, Dataset, ReadOptions, ReadRequest};
use crate::engine::BackendChoice;
use anyhow::Result;
use clap::{Args, Parser, Subcommand};
use std::path::Path;

mod battery;
mod bench;
mod convert;
mod diagnose;
mod eval;
mod export;
mod fit;
pub mod models;
pub mod progress;
mod render;
mod sweep;
mod synth;

pub use crate::workflows::checks;
pub use crate::workflows::fit::DEFAULT_RESTARTS;

/// Value parser of `--seed`: a non-negative integer (clap would otherwise read `-1` as an
/// option and suggest `-- -1`).
pub fn parse_seed(s: &str) -> Result<u64, String> {
    s.trim().parse::<u64>().map_err(|_| {
        format!(
            "--seed takes a non-negative integer (0 to {}), got '{s}'",
            u64::MAX
        )
    })
}

/// Value parser of an option whose value is one of a library [`Choice`]'s words: the
/// words and their help come from the choice's table.
pub fn choice<T: Choice + Send + Sync>() -> impl clap::builder::TypedValueParser<Value = T> {
    use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
    let values = T::TABLE.iter().map(|(_, name, help)| {
        let value = PossibleValue::new(*name);
        if help.is_empty() {
            value
        } else {
            value.help(*help)
        }
    });
    PossibleValuesParser::new(values).try_map(|word| T::parse_choice(&word))
}

/// Value parser of `--restarts`: a positive integer.
pub fn parse_restarts(s: &str) -> Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(n) if n >= 1 => Ok(n),
        _ => Err(format!("--restarts takes a positive integer, got '{s}'")),
    }
}

#[derive(Parser)]
#[command(
    name = "bsdfit",
    version,
    about = "Fit BRDF/BTDF models to measured data with uncertainties (GPU batch fitter with a CPU reference)"
)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Fit one model to one dataset.
    Fit(fit::FitArgs),
    /// Write a synthetic dataset from a model with known parameters.
    Synth(synth::SynthArgs),
    /// List the model catalogue with its parameters, the losses and the geometries.
    Models,
    /// Measure CPU and GPU throughput (model-sample evaluations per second).
    Bench(bench::BenchArgs),
    /// Run the benchmark: every data set × model × loss × weighting (resumable, shardable),
    /// then results tables, angular plots, sphere renders and report.html.
    Sweep(sweep::SweepArgs),
    /// Combine the results of sweep shards (`sweep --shard I/N`) and write the report.
    Merge(sweep::MergeArgs),
    /// Render a sphere with a fitted BRDF, the tabulated measurement and their error image.
    Render(render::RenderArgs),
    /// Find where a model and the measurement disagree, name the missing effect, add it,
    /// and repeat while the improvement is significant.
    Diagnose(diagnose::DiagnoseArgs),
    /// The diagnosis's randomized battery: hide each effect of the effect table in random
    /// truths (geometry, channels, 200–20,000 samples, 1–5 % noise, parameters drawn from
    /// their ranges), add null cases, run `diagnose` on each, and print the detection and
    /// false-effect rates by signal-to-noise.
    Battery(battery::BatteryArgs),
    /// Convert a data file of any format read (bsdfit v1 CSV, ALTA text, MERL binary, RGL
    /// .bsdf, Zemax BSDF, ASTM E1392, Mueller-matrix BRDF CSV; recognised by content) to bsdfit v1 CSV, applying the
    /// data-selection options.
    Convert(convert::ConvertArgs),
    /// Evaluate a saved fit (`fit --json`) at the geometries of a data file or of a named
    /// geometry: a v1 CSV of model values with their standard uncertainties propagated
    /// from the fit's covariance.
    ///
    /// u² = gᵀ cov g, g = ∂f/∂θ by central differences, cov = diag(std)·corr·diag(std)
    /// from the report: the uncertainty of the model value due to the fitted parameters
    /// (not the scatter of new measurements). A parameter the fit could not determine
    /// (null std) counts with zero variance; a warning names it and counts the rows where
    /// the uncertainty is then a lower bound. Runs on the CPU; no GPU is needed.
    Eval(eval::EvalArgs),
    /// Write a saved fit (`fit --json`) for use elsewhere: a dense v1 table, a MERL binary
    /// BRDF table, or a Mitsuba 3 <bsdf> (for models with an exact counterpart).
    ///
    /// tabulated: the model and its propagated uncertainty (as `eval`) at θi, θo = 0…85°
    /// by 5° and φo = 0…345° by 15° with φi = 0 by default. merl and mitsuba take R, G, B
    /// from a one-channel fit (grey), a three-channel fit (longest wavelength → R) or
    /// --rgb. mitsuba writes only exact counterparts (lambert → diffuse; ggx →
    /// roughconductor with k = 0) and names them when it refuses a model.
    Export(export::ExportArgs),
}

/// The help of a data-file argument: every format the readers recognise by content
/// (`data::readers::Format`'s names; `tests/cli.rs` checks each command's help names
/// them all).
pub const DATA_FILE_HELP: &str = "Data file, in any format read (recognised by content): bsdfit v1 CSV, ALTA text, MERL binary, RGL .bsdf, Zemax BSDF, ASTM E1392, Mueller-matrix BRDF CSV";

/// Data selection and validation, shared by every command that reads measurements.
#[derive(Args, Clone, Debug)]
pub struct DataArgs {
    /// Keep the channels nearest these wavelengths (nm), e.g. 450,550,650.
    #[arg(long, value_delimiter = ',')]
    pub wavelengths: Option<Vec<f64>>,
    /// Replace zero uncertainties by a floor (max(1%·|value|, 1e-6)) instead of rejecting them.
    #[arg(long)]
    pub allow_zero_uncertainty: bool,
    /// For files without uncertainties (ALTA without #VS, MERL): assume
    /// u = sqrt((REL·|value|)² + ABS²) sr⁻¹, e.g. 0.05,0.001. Every output then says the
    /// uncertainties were assumed. Without it such files are refused.
    #[arg(long, value_name = "REL,ABS")]
    pub assume_uncertainty: Option<String>,
    /// With --wavelengths: each channel averages every wavelength within ±NM nm of it,
    /// per geometry (value = mean, u = sqrt(Σu²)/n).
    #[arg(long, value_name = "NM")]
    pub band: Option<f64>,
    /// MERL tables: keep at most N measured cells, a deterministic subsample (a full table
    /// has about 1.5 million; 0 keeps all).
    #[arg(long, value_name = "N", default_value_t = merl::DEFAULT_MAX_SAMPLES)]
    pub max_samples: usize,
    /// ALTA files without a #PARAM_OUT line: what their values are (such files are
    /// refused without it). A file whose #PARAM_OUT disagrees is refused; other formats
    /// ignore the option.
    #[arg(long, value_parser = choice::<AltaValues>(), value_name = "KIND")]
    pub alta_values: Option<AltaValues>,
    /// RGL .bsdf materials (which hold a function, not samples): sample them at this named
    /// geometry (`bsdfit models` lists them; e.g. hemi, grid:5). Default: grid:10. Other
    /// formats ignore the option.
    #[arg(long, value_name = "NAME")]
    pub sample_geometry: Option<String>,
}

impl DataArgs {
    /// The reader options these flags ask for.
    pub fn read_options(&self) -> Result<ReadOptions> {
        ReadOptions::from_request(ReadRequest {
            allow_zero_uncertainty: self.allow_zero_uncertainty,
            wavelengths: self.wavelengths.clone(),
            band_nm: self.band,
            assume_uncertainty: self.assume_uncertainty.clone().map(AssumeArg::Text),
            max_samples: Some(self.max_samples),
            alta_values: self.alta_values,
            sample_geometry: self.sample_geometry.clone(),
        })
    }

    /// Read a dataset (any format, by content) with these options and print its notices.
    pub fn read(&self, path: &Path) -> Result<Dataset> {
        let ds = readers::load_reporting(path, &self.read_options()?)?;
        for n in &ds.notices {
            eprintln!("note: {n}");
        }
        Ok(ds)
    }
}

/// What a user imposes on the fitted parameters, shared by fit, sweep and diagnose.
/// NAME is a parameter's full name (`lobe.alpha`), a flat entry (`rho[1]`, `alpha@phi90`)
/// or its last component when that is unambiguous (`alpha`); `bsdfit models` lists them.
#[derive(Args, Clone, Debug, Default)]
pub struct ConstraintArgs {
    /// Hold a parameter at a value: not fitted, not counted among the parameters of χ²_red,
    /// standard uncertainty 0. Repeatable; `rho=0.4:0.5:0.6` gives one value per channel.
    #[arg(long, value_name = "NAME=VALUE")]
    pub fix: Vec<String>,
    /// Narrow a parameter's search range to [LO, HI] (inside its declared range). A fit
    /// that ends on a bound says so. Repeatable.
    #[arg(long, value_name = "NAME=LO:HI")]
    pub bounds: Vec<String>,
    /// Gaussian prior: adds ((θ − MEAN)/SD)² to χ² as one more residual (reported in the
    /// JSON; χ²_red counts it as an observation). Needs the chi2 loss. Repeatable.
    #[arg(long, value_name = "NAME=MEAN:SD")]
    pub prior: Vec<String>,
}

impl ConstraintArgs {
    /// The options as a spec; `lenient` for runs over several models (a model that lacks
    /// a parameter ignores its options). A text that is not of its option's form fails.
    pub fn spec(&self, lenient: bool) -> Result<crate::inference::constraints::ConstraintSpec> {
        crate::inference::constraints::ConstraintSpec::parse(
            &self.fix,
            &self.bounds,
            &self.prior,
            lenient,
        )
    }
}

/// Where the models are evaluated, shared by every command that fits or measures.
#[derive(Args, Clone, Copy, Debug)]
pub struct BackendArgs {
    /// Which engine evaluates the models (`bench` measures all three where it is auto).
    /// The f32 engines' fits are polished and concluded on the f64 reference.
    #[arg(long, value_parser = choice::<BackendChoice>(), default_value = "auto")]
    pub backend: BackendChoice,
}

/// Parse the command line and run the command; the process exit code.
pub fn main() -> i32 {
    main_with_args(std::env::args_os())
}

/// Run the command line `args` (the program's name first), as the `bsdfit` binary does:
/// the exit code. The Python package's `bsdfit` command runs it through the native module.
pub fn main_with_args<I, T>(args: I) -> i32
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let cli = match Cli::try_parse_from(args) {
        Ok(cli) => cli,
        Err(e) => {
            // Help and version are printed on stdout with status 0, mistakes on stderr.
            let _ = e.print();
            return e.exit_code();
        }
    };
    match dispatch(cli.command) {
        Ok(()) => 0,
        Err(e) => {
            eprintln!("error: {}", error_text(&e));
            1
        }
    }
}

/// An option as the command line spells it: `--mc-scale`, `--loss chi2`.
fn flag(name: &str, value: Option<&str>) -> String {
    let flag = format!("--{}", name.replace('_', "-"));
    match value {
        Some(v) => format!("{flag} {v}"),
        None => flag,
    }
}

/// An error as the command line prints it: its causes joined by ": ", with the library's
/// option names ([`FieldError`]) written as flags.
pub fn error_text(e: &anyhow::Error) -> String {
    e.chain()
        .map(|cause| match cause.downcast_ref::<FieldError>() {
            Some(field) => field.render(&flag),
            None => cause.to_string(),
        })
        .collect::<Vec<_>>()
        .join(": ")
}

fn dispatch(command: Command) -> Result<()> {
    match command {
        Command::Fit(a) => fit::run(a),
        Command::Synth(a) => synth::run(a),
        Command::Models => models::run(),
        Command::Bench(a) => bench::run(a),
        Command::Sweep(a) => sweep::run_sweep(&a).map(|_| ()),
        Command::Merge(a) => sweep::run_merge(&a),
        Command::Render(a) => render::run(&a),
        Command::Diagnose(a) => diagnose::run(&a),
        Command::Battery(a) => battery::run(&a),
        Command::Convert(a) => convert::run(&a),
        Command::Eval(a) => eval::run(&a),
        Command::Export(a) => export::run(&a),
    }
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    /// Every option and argument of every command says what it is (`--help` shows no
    /// bare flag), and every command has an about line.
    #[test]
    fn every_option_has_help() {
        let root = super::Cli::command();
        let mut bare = Vec::new();
        for cmd in root.get_subcommands() {
            if cmd.get_about().is_none() {
                bare.push(format!("{} (the command)", cmd.get_name()));
            }
            for arg in cmd.get_arguments() {
                let id = arg.get_id().as_str();
                if id == "help" || id == "version" {
                    continue;
                }
                if arg.get_help().is_none() && arg.get_long_help().is_none() {
                    bare.push(format!("{} --{}", cmd.get_name(), id.replace('_', "-")));
                }
            }
        }
        assert!(bare.is_empty(), "options without help: {bare:?}");
    }
}
