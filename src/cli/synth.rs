//! `bsdfit synth`.

use crate::bsdf::{self, Model};
use crate::data::Kind;
use crate::workflows::synth;
use anyhow::{Context, Result};
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct SynthArgs {
    /// Model spec whose values are written (see `bsdfit models`).
    #[arg(long)]
    pub model: String,
    /// Parameter values, e.g. rho=0.5,sigma=0.7 or rho=0.4:0.5:0.6 (one per channel).
    #[arg(long, default_value = "")]
    pub params: String,
    /// Geometry name (see `bsdfit models`), or names joined by `+` for their union.
    #[arg(long)]
    pub geometry: Option<String>,
    /// Angular standard uncertainty (degrees) of θi and θo, propagated through the model's
    /// slope into each sample's uncertainty (larger on the flanks of peaks).
    #[arg(long, default_value_t = 0.0)]
    pub angular_unc: f64,
    /// Noise as REL,ABS: u = sqrt((REL·f)² + ABS²).
    #[arg(long, default_value = "0.015,0.0001")]
    pub noise: String,
    /// Seed of the noise (a non-negative integer).
    #[arg(long, default_value_t = 1, value_parser = super::parse_seed, allow_hyphen_values = true)]
    pub seed: u64,
    /// Wavelengths (nm), one per channel; default 450,550,650 (BRDF) or 633 (BTDF).
    #[arg(long, value_delimiter = ',')]
    pub wavelengths: Option<Vec<f64>>,
    /// Material name written in the file.
    #[arg(long)]
    pub material: Option<String>,
    /// Output file: a bsdfit CSV v1, or, where it ends in `.binary`, a MERL table
    /// (three channels, read as R, G, B = the longest to the shortest wavelength; values
    /// below 0 written as 0; the table holds no uncertainties: read it back with
    /// --assume-uncertainty REL,ABS and --max-samples 0 for every cell).
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(a: SynthArgs) -> Result<()> {
    let ast_kind = bsdf::spec_kind(&a.model).context("--model")?;
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
    let planes = crate::data::measurement_planes(
        rows.iter()
            .map(|r| crate::data::normalise_angles(r[2], r[3])),
    );
    let model = Model::parse_for(&a.model, wavelengths.len(), &planes).context("--model")?;
    anyhow::ensure!(
        gkind == model.kind,
        "--geometry {geometry} is a {gkind} geometry but {} is a {} model: give a {} geometry (`bsdfit models` lists each geometry with its kind)",
        model.spec,
        model.kind,
        model.kind
    );
    let flat = model
        .params_from_assignments(&a.params)
        .context("--params")?;
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
    if a.out.extension().is_some_and(|e| e == "binary") {
        return write_merl(&ds, &a.out, &geometry);
    }
    ds.write(&a.out)?;
    eprintln!(
        "wrote {} ({}, {}, geometry {geometry})",
        a.out.display(),
        crate::text::plural(ds.len(), "sample"),
        crate::text::plural(ds.channel_count(), "channel")
    );
    Ok(())
}

/// `ds` as a MERL table: each sample in the cell of its directions (the last one where
/// several fall in one cell), channels from the longest wavelength (R) to the shortest.
fn write_merl(ds: &crate::data::Dataset, out: &std::path::Path, geometry: &str) -> Result<()> {
    use crate::data::readers::merl;
    let next = if ds.kind != Kind::Brdf {
        "write it as a bsdfit CSV (an --out that does not end in .binary)"
    } else {
        "give three wavelengths, e.g. --wavelengths 450,550,650"
    };
    anyhow::ensure!(
        ds.kind == Kind::Brdf && ds.channel_count() == 3,
        "--out {}: a MERL table holds three BRDF channels (R, G, B); this is {} data in {}: {next}",
        out.display(),
        ds.kind,
        crate::text::plural(ds.channel_count(), "channel")
    );
    let mut cells: Vec<Option<[f64; 3]>> = vec![None; merl::CELLS];
    for s in &ds.samples {
        let cell = cells[merl::lookup_index(s.wi(), s.wo())].get_or_insert([0.0; 3]);
        // Channels ascend in wavelength; MERL's R, G, B descend.
        cell[2 - s.channel] = s.value.max(0.0);
    }
    let filled = cells.iter().filter(|c| c.is_some()).count();
    std::fs::write(out, merl::serialise(&cells))
        .with_context(|| format!("cannot write {}", out.display()))?;
    eprintln!(
        "wrote {} (MERL table: {filled} of {} cells from {}, geometry {geometry}; no uncertainties: read it with --assume-uncertainty)",
        out.display(),
        merl::CELLS,
        crate::text::plural(ds.len(), "sample")
    );
    Ok(())
}
