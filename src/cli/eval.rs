//! `bsdfit eval`.

use super::DataArgs;
use crate::data::readers;
use crate::data::NoticeKind;
use crate::inference::saved::FitFile;
use crate::output::files::write_result;
use crate::workflows::{export, synth};
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
#[command(group = clap::ArgGroup::new("where").required(true).args(["at", "geometry"]))]
pub struct EvalArgs {
    /// A fit report written by `bsdfit fit --json` (with `fit --per-axis`, each sample is
    /// evaluated with the fit of its own plane).
    pub fit: PathBuf,
    /// Evaluate at every sample (geometry and wavelength) of this data file, in any format
    /// read (bsdfit v1 CSV, ALTA text, MERL binary, RGL .bsdf, Zemax BSDF, ASTM E1392, Mueller-matrix BRDF CSV;
    /// recognised by content). Only its geometries are used: files without uncertainties
    /// need no --assume-uncertainty here.
    #[arg(long, value_name = "DATA")]
    pub at: Option<PathBuf>,
    /// Evaluate on a named geometry (see `bsdfit models`), or names joined by `+`, at every
    /// channel of the fit.
    #[arg(long, value_name = "NAME")]
    pub geometry: Option<String>,
    /// Output v1 CSV: one row per sample with the model value in `value` and its standard
    /// uncertainty (k = 1) propagated from the fit's covariance in `uncertainty`.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub data_args: DataArgs,
}

pub fn run(a: &EvalArgs) -> Result<()> {
    crate::output::check_writable_file(&a.out, "--out")?;
    let fit_path = a.fit.display().to_string();
    let file = FitFile::read(&a.fit)?;
    let (at, what) = match (&a.at, &a.geometry) {
        (Some(path), _) => {
            let mut opts = a.data_args.read_options()?;
            // Only the geometries are used: a file without uncertainties (or with zero
            // ones) is read with placeholders, and the notices about them are not shown.
            let placeholder = opts.assume_uncertainty.is_none();
            if placeholder {
                opts.assume_uncertainty = Some((0.0, 1.0));
            }
            let floor = !opts.allow_zero_uncertainty;
            opts.allow_zero_uncertainty = true;
            let ds = readers::load_reporting(path, &opts)?;
            for n in &ds.notices {
                let hidden = match n.kind {
                    NoticeKind::AssumedUncertainty | NoticeKind::AssumptionIgnored => placeholder,
                    NoticeKind::UncertaintyFloor => floor,
                    NoticeKind::Reading => false,
                };
                if !hidden {
                    eprintln!("note: {n}");
                }
            }
            (ds, path.display().to_string())
        }
        (None, Some(expr)) => {
            let (kind, rows) =
                synth::geometry_expr(expr).map_err(|e| anyhow::anyhow!("--geometry: {e}"))?;
            let label = format!("geometry {expr}");
            let ds = export::geometry_dataset(kind, &rows, &export::fit_channels(&file), &label)?;
            (ds, label)
        }
        (None, None) => anyhow::bail!("give --at DATA or --geometry NAME"),
    };
    let p = export::predict(&file, &fit_path, &at, &what)?;
    for w in &p.warnings {
        eprintln!("warning: {w}");
    }
    write_result(&a.out, &p.data.to_csv(), false)?;
    eprintln!(
        "wrote {} ({}, {} channel(s): {:?} nm)",
        a.out.display(),
        crate::text::plural_with(p.data.len(), "sample", "samples"),
        p.data.channel_count(),
        p.data.channels
    );
    Ok(())
}
