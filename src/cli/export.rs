//! `bsdfit export`.

use crate::data::readers::{self, zemax::Symmetry};
use crate::inference::saved::FitFile;
use crate::output::files::{write_atomic, write_result};
use crate::workflows::export::{self, Grid};
use crate::workflows::optical::{self, astm, zemax, zemax::ZemaxGrid};
use anyhow::Result;
use clap::{Args, ValueEnum};
use std::path::PathBuf;

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Format {
    /// A dense v1 CSV table of the model and its propagated uncertainty on a regular grid
    /// (--theta-step, --theta-max, --phi-step); BRDF and BTDF.
    Tabulated,
    /// A MERL binary table (90 × 90 × 180 half/difference cells, R, G, B); BRDF only.
    Merl,
    /// A Mitsuba 3 `<bsdf>` XML element, for the models with an exact counterpart
    /// (lambert → diffuse, ggx → roughconductor with k = 0).
    Mitsuba,
    /// An RGL measured-material `.bsdf` file (Dupuy & Jakob 2018), which Mitsuba 3's
    /// `measured` plugin and pbrt-v4's `measured` material render: any isotropic BRDF
    /// fit; RGB (R, G, B as for merl) or, with --spectral, every channel at its wavelength.
    Rgl,
    /// A Zemax tabular BSDF file (read by OpticStudio and other optical design programs):
    /// BRDF or BTDF, each table's TIS integrated from the model; plane-symmetrical, or
    /// asymmetrical for a per-plane fit (docs/data-formats.md).
    Zemax,
    /// ASTM E1392 text: one row per geometry, a column per channel, then the propagated
    /// standard uncertainties as u_ columns; BRDF or BTDF (docs/data-formats.md).
    Astm,
}

#[derive(Args)]
pub struct ExportArgs {
    /// A fit report written by `bsdfit fit --json`.
    pub fit: PathBuf,
    /// What to write: tabulated (v1 CSV on a grid), merl (MERL binary BRDF table),
    /// mitsuba (Mitsuba 3 XML, exact counterparts only), rgl, zemax or astm.
    #[arg(long, value_enum)]
    pub format: Format,
    /// Output file.
    #[arg(long)]
    pub out: PathBuf,
    /// For a report of `fit --per-axis` (one fit per plane): the plane φ (degrees) whose
    /// fit to export.
    #[arg(long, value_name = "PHI", allow_hyphen_values = true)]
    pub plane: Option<f64>,
    /// merl, mitsuba: the fit channels (nearest wavelengths, nm) that become R, G, B.
    /// Default: a one-channel fit gives the same value to R, G and B; a three-channel fit
    /// gives its longest wavelength to R and its shortest to B; other fits need this.
    #[arg(long, value_name = "R_NM,G_NM,B_NM", value_delimiter = ',')]
    pub rgb: Option<Vec<f64>>,
    /// rgl: write the spectral variant (a `spectra` table at the fit's wavelengths, for
    /// Mitsuba's spectral variants) instead of `rgb`.
    #[arg(long)]
    pub spectral: bool,
    /// tabulated: step of θi and θo (θt), degrees; θ = 0, step, 2·step, … ≤ --theta-max.
    #[arg(long, default_value_t = Grid::default().theta_step, value_name = "DEG")]
    pub theta_step: f64,
    /// tabulated: largest θi and θo (θt), degrees, below 90.
    #[arg(long, default_value_t = Grid::default().theta_max, value_name = "DEG")]
    pub theta_max: f64,
    /// tabulated: step of φo (φt) over [0, 360) degrees, with φi = 0 (a model with
    /// per-plane parameters is tabulated on its planes only).
    #[arg(long, default_value_t = Grid::default().phi_step, value_name = "DEG")]
    pub phi_step: f64,
    /// zemax, astm: where to tabulate. zemax: a Zemax file (its grid) or
    /// 'aoi=LIST;azimuth=LIST;radial=LIST[;rotation=LIST][;symmetry=S]' (LIST: numbers and
    /// from:step:to ranges); astm: a data file (its geometries) or a named geometry (see
    /// `bsdfit models`). Default: the fit's data file when it is of the same format, else
    /// the format's usual grid.
    #[arg(long, value_name = "SPEC")]
    pub geometry: Option<String>,
    /// zemax: the fit channel (nearest wavelength, nm) to write as the Monochrome table,
    /// for a fit with several channels.
    #[arg(long, value_name = "NM")]
    pub channel: Option<f64>,
}

pub fn run(a: &ExportArgs) -> Result<()> {
    crate::output::check_writable_file(&a.out, "--out")?;
    let fit_path = a.fit.display().to_string();
    let file = FitFile::read(&a.fit)?;
    check_format_options(a)?;
    match a.format {
        Format::Rgl => write_rgl(a, file, &fit_path),
        Format::Tabulated => write_tabulated(a, file, &fit_path),
        Format::Merl => write_merl(a, file, &fit_path),
        Format::Mitsuba => write_mitsuba(a, file, &fit_path),
        Format::Zemax => write_zemax(a, file, &fit_path),
        Format::Astm => write_astm(a, file, &fit_path),
    }
}

/// Refuse the options that the chosen format would silently ignore (the grid options
/// outside tabulated, --spectral outside rgl): a user who gave them expected an effect.
fn check_format_options(a: &ExportArgs) -> Result<()> {
    if a.format != Format::Tabulated {
        for (name, v) in [
            ("--theta-step", a.theta_step != Grid::default().theta_step),
            ("--theta-max", a.theta_max != Grid::default().theta_max),
            ("--phi-step", a.phi_step != Grid::default().phi_step),
        ] {
            anyhow::ensure!(!v, "{name} applies to --format tabulated only");
        }
    }
    anyhow::ensure!(
        !a.spectral || a.format == Format::Rgl,
        "--spectral applies to --format rgl only"
    );
    anyhow::ensure!(
        a.geometry.is_none() || matches!(a.format, Format::Zemax | Format::Astm),
        "--geometry applies to --format zemax and astm"
    );
    anyhow::ensure!(
        a.channel.is_none() || a.format == Format::Zemax,
        "--channel applies to --format zemax only"
    );
    anyhow::ensure!(
        a.rgb.is_none() || !matches!(a.format, Format::Zemax | Format::Astm),
        "--rgb applies to --format merl, mitsuba and rgl"
    );
    Ok(())
}

/// A fit file, narrowed to one fit when --plane is given.
fn narrowed(a: &ExportArgs, file: FitFile, fit_path: &str) -> Result<FitFile> {
    Ok(match a.plane {
        Some(p) => FitFile::Single(Box::new(file.select(Some(p), fit_path)?)),
        None => file,
    })
}

/// The fit's data file, when it exists and is of `format`.
fn fit_data_of(file: &FitFile, format: readers::Format) -> Option<PathBuf> {
    let data = match file {
        FitFile::Single(f) => f.data.clone(),
        FitFile::PerAxis(v) => v[0].1.data.clone(),
    };
    let path = PathBuf::from(data);
    (path.is_file() && readers::detect(&path).ok() == Some(format)).then_some(path)
}

/// `--format zemax`: the Zemax tabular BSDF of the fit.
fn write_zemax(a: &ExportArgs, file: FitFile, fit_path: &str) -> Result<()> {
    let file = narrowed(a, file, fit_path)?;
    let planes = optical::Planes::new(&file);
    let symmetry = if planes.per_plane() {
        Symmetry::Asymmetrical
    } else {
        Symmetry::PlaneSymmetrical
    };
    let (mut grid, mut from) = match (&a.geometry, fit_data_of(&file, readers::Format::ZemaxBsdf)) {
        (Some(spec), _) => (
            ZemaxGrid::parse(spec, symmetry)?,
            format!("--geometry {spec}"),
        ),
        (None, Some(path)) => (
            ZemaxGrid::parse(&path.display().to_string(), symmetry)?,
            format!("the grid of the fit's data {}", path.display()),
        ),
        (None, None) => (ZemaxGrid::usual(symmetry), "the usual grid".into()),
    };
    // A per-plane fit on a plane-symmetric file's grid: the grid mirrored to the whole
    // circle (an explicit symmetry=PlaneSymmetrical is refused by zemax_file).
    let from_file = a
        .geometry
        .as_deref()
        .is_none_or(|g| std::path::Path::new(g).is_file());
    if planes.per_plane() && grid.symmetry == Symmetry::PlaneSymmetrical && from_file {
        grid = grid.asymmetrical();
        from += ", its azimuths mirrored to the whole circle for a per-plane fit";
    }
    let spectrum = zemax::spectrum(&planes.channels, a.channel)?;
    let w = zemax::zemax_file(&file, fit_path, &grid, spectrum)?;
    write_result(&a.out, &w.text, true)?;
    eprintln!(
        "wrote {} (Zemax {} {}, {} tables, {} cells, on {from}; TIS integrated from the model)",
        a.out.display(),
        w.symmetry.name(),
        if planes.kind == crate::data::Kind::Btdf {
            "BTDF"
        } else {
            "BRDF"
        },
        w.tables,
        w.cells
    );
    note_fit_warnings(&planes.first().warnings);
    Ok(())
}

/// `--format astm`: the ASTM E1392 text of the fit, with its propagated uncertainties.
fn write_astm(a: &ExportArgs, file: FitFile, fit_path: &str) -> Result<()> {
    let file = narrowed(a, file, fit_path)?;
    let planes = export::fit_planes(&file);
    let (rows, what) = match (&a.geometry, fit_data_of(&file, readers::Format::AstmE1392)) {
        (Some(spec), _) if std::path::Path::new(spec).is_file() => {
            (astm::file_rows(std::path::Path::new(spec))?.1, spec.clone())
        }
        (Some(spec), _) => (
            crate::workflows::synth::geometry_expr(spec)
                .map_err(|e| anyhow::anyhow!("--geometry: {e}"))?
                .1,
            format!("geometry {spec}"),
        ),
        (None, Some(path)) => (astm::file_rows(&path)?.1, path.display().to_string()),
        (None, None) => (
            astm::usual_rows(planes.as_deref()),
            "the usual ASTM grid".into(),
        ),
    };
    let (text, warnings) = astm::astm_file(&file, fit_path, &rows, &what)?;
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    write_result(&a.out, &text, true)?;
    eprintln!(
        "wrote {} (ASTM E1392, {} rows at {what}, values and u_ columns)",
        a.out.display(),
        rows.len()
    );
    Ok(())
}

/// `--format rgl`: the RGL `.bsdf` file of one fit, RGB or (--spectral) every channel.
fn write_rgl(a: &ExportArgs, file: FitFile, fit_path: &str) -> Result<()> {
    let fit = file.select(a.plane, fit_path)?;
    let channels = if a.spectral {
        anyhow::ensure!(a.rgb.is_none(), "--rgb and --spectral exclude each other");
        crate::workflows::rgl::Channels::Spectral
    } else {
        crate::workflows::rgl::Channels::Rgb(export::rgb_channels(&fit, a.rgb.as_deref())?)
    };
    let description = format!(
        "bsdfit fit of {} to {}: {}",
        fit.model.spec,
        fit.material,
        fit.params_text()
    );
    let bytes = crate::workflows::rgl::rgl_file(&fit, channels, &description)?;
    write_atomic(&a.out, &bytes)?;
    let layout = crate::workflows::rgl::layout(&fit);
    let azimuths = match layout.phis.len() {
        1 => String::new(),
        n => format!("{n} incidence azimuths × "),
    };
    eprintln!(
        "wrote {} (RGL .bsdf of {}, {azimuths}{} incidence angles × {} × {} half-vector cells, {})",
        a.out.display(),
        fit.model.spec,
        layout.thetas.len(),
        layout.nodes,
        layout.nodes,
        if a.spectral {
            format!("spectral at {:?} nm", fit.channels)
        } else {
            "RGB".into()
        }
    );
    note_fit_warnings(&fit.warnings);
    Ok(())
}

/// `--format tabulated`: the model and its propagated uncertainty on the grid, as a v1
/// CSV (a per-plane report whole, or the fit of --plane).
fn write_tabulated(a: &ExportArgs, file: FitFile, fit_path: &str) -> Result<()> {
    anyhow::ensure!(
        a.rgb.is_none(),
        "--rgb applies to --format merl and mitsuba"
    );
    let file = match a.plane {
        Some(p) => FitFile::Single(Box::new(file.select(Some(p), fit_path)?)),
        None => file,
    };
    let grid = Grid {
        theta_step: a.theta_step,
        theta_max: a.theta_max,
        phi_step: a.phi_step,
    };
    let channels = export::fit_channels(&file);
    let planes = export::fit_planes(&file);
    let rows = grid.rows(planes.as_deref(), channels.len())?;
    let kind = match &file {
        FitFile::Single(f) => f.model.kind,
        FitFile::PerAxis(v) => v[0].1.model.kind,
    };
    let grid_text = grid_words(a, kind, planes.as_deref());
    let what = format!("a grid ({grid_text})");
    let ds = export::geometry_dataset(kind, &rows, &channels, "grid")?;
    let mut p = export::predict(&file, fit_path, &ds, &what)?;
    p.data.meta.insert("grid".into(), grid_text);
    for w in &p.warnings {
        eprintln!("warning: {w}");
    }
    write_result(&a.out, &p.data.to_csv(), false)?;
    eprintln!(
        "wrote {} ({} on {what})",
        a.out.display(),
        crate::text::plural_with(p.data.len(), "sample", "samples"),
    );
    Ok(())
}

/// The tabulated grid in words, for the file's `grid` header and the closing message:
/// "θi, θo = 0…85° by 5°, φo = 0…360° by 15°, φi = 0" (θt for a BTDF; the fit's planes
/// instead of the φo sweep for a per-plane model).
fn grid_words(a: &ExportArgs, kind: crate::data::Kind, planes: Option<&[f64]>) -> String {
    format!(
        "θi, θ{} = 0…{}° by {}°, {}",
        if kind == crate::data::Kind::Btdf {
            "t"
        } else {
            "o"
        },
        a.theta_max,
        a.theta_step,
        match planes {
            Some(p) => format!(
                "on the fit's planes φ = {}° (and + 180°)",
                p.iter()
                    .map(|x| x.to_string())
                    .collect::<Vec<_>>()
                    .join("°, ")
            ),
            None => format!("φo = 0…360° by {}°, φi = 0", a.phi_step),
        }
    )
}

/// `--format merl`: the MERL binary table of one BRDF fit, R, G, B from its channels.
fn write_merl(a: &ExportArgs, file: FitFile, fit_path: &str) -> Result<()> {
    let fit = file.select(a.plane, fit_path)?;
    let rgb = export::rgb_channels(&fit, a.rgb.as_deref())?;
    let bytes = export::merl_table(&fit, rgb)?;
    write_atomic(&a.out, &bytes)?;
    eprintln!(
        "wrote {} (MERL table of {}: R, G, B = fit channels {} nm)",
        a.out.display(),
        fit.model.spec,
        rgb.map(|g| fit.channels[g].to_string()).join(", ")
    );
    note_fit_warnings(&fit.warnings);
    Ok(())
}

/// `--format mitsuba`: the Mitsuba 3 `<bsdf>` of one fit whose model has an exact
/// counterpart ([`export::mitsuba_exact`]).
fn write_mitsuba(a: &ExportArgs, file: FitFile, fit_path: &str) -> Result<()> {
    let fit = file.select(a.plane, fit_path)?;
    let rgb = export::rgb_channels(&fit, a.rgb.as_deref())?;
    let xml = export::mitsuba_xml(&fit, rgb, fit_path)?;
    write_result(&a.out, &xml, true)?;
    eprintln!(
        "wrote {} (Mitsuba 3 <bsdf> of {}: {})",
        a.out.display(),
        fit.model.spec,
        export::mitsuba_exact()
            .into_iter()
            .find(|(n, _)| *n == fit.model.root.bsdf.name())
            .map_or("", |(_, to)| to)
    );
    note_fit_warnings(&fit.warnings);
    Ok(())
}

/// A table or XML carries no uncertainty: repeat what the fit could not establish.
fn note_fit_warnings(warnings: &[String]) {
    for w in warnings {
        eprintln!("note: the fit says: {w}");
    }
}
