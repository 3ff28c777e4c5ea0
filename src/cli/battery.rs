//! `bsdfit battery`.

use super::progress::Progress;
use super::BackendArgs;
use crate::engine;
use crate::workflows::diagnose::battery::{
    effects_named, rates_table, run_battery, BatteryOptions,
};
use crate::workflows::diagnose::{DiagnoseOptions, Effect};
use anyhow::{Context, Result};
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct BatteryArgs {
    /// Cases per hidden effect.
    #[arg(long, default_value_t = BatteryOptions::default().cases)]
    pub cases: usize,
    /// Cases with no hidden effect (the truth is the start model).
    #[arg(long, default_value_t = BatteryOptions::default().nulls)]
    pub nulls: usize,
    /// Misspecified null cases: isotropic truths whose highlight lies outside the
    /// catalogue (Beckmann, GTR with γ ≠ 2 and two-scale NDFs, V-cavity shadowing, Schlick
    /// Fresnel), at one incidence azimuth and at several, diagnosed from fa(lambert); the
    /// table says which effects were named on them.
    #[arg(long, default_value_t = BatteryOptions::default().misspecified)]
    pub misspecified: usize,
    /// Misspecified transmission cases: rough dielectrics whose NDF is outside the BTDF
    /// catalogue (a two-scale Beckmann mixture, a Student-t NDF), at one incidence
    /// azimuth and at several, diagnosed from btdf(tr); drawn after the reflection ones.
    #[arg(long, default_value_t = BatteryOptions::default().misspecified_btdf)]
    pub misspecified_btdf: usize,
    /// Seed of the cases (a non-negative integer): the same seed draws the same battery.
    #[arg(long, default_value_t = BatteryOptions::default().seed, value_parser = super::parse_seed, allow_hyphen_values = true)]
    pub seed: u64,
    /// The effects to hide, comma-separated (default: every effect of the table; `bsdfit
    /// diagnose --help` and docs/diagnose.md list them).
    #[arg(long, value_delimiter = ',')]
    pub effects: Option<Vec<String>>,
    /// The range the hidden effect's size is drawn from, log-uniform: the RMS of
    /// (truth − start)/u over the samples before any fit.
    #[arg(long, value_name = "LO,HI", default_value_t = pair_text(BatteryOptions::default().signal))]
    pub signal: String,
    /// The range of sample counts, log-uniform.
    #[arg(long, value_name = "LO,HI", default_value_t = pair_text(BatteryOptions::default().samples))]
    pub samples: String,
    /// Random restarts per fit of each diagnosis.
    #[arg(long, default_value_t = BatteryOptions::default().diagnose.restarts, value_parser = super::parse_restarts, allow_hyphen_values = true)]
    pub restarts: usize,
    #[command(flatten)]
    pub backend: BackendArgs,
    /// Write every case and its outcome as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write the rates table (markdown) here.
    #[arg(long)]
    pub markdown: Option<PathBuf>,
    /// Run only case ID of this battery (the same options draw the same cases), printing
    /// its truth and its diagnosis's log.
    #[arg(long, value_name = "ID")]
    pub case: Option<usize>,
    /// Offer the data-driven factors (highlight_shape, highlight_fresnel, body_profile)
    /// in each diagnosis's last round, as `diagnose` does by default. Off by default:
    /// the catalogue's truths need none, and on a misspecified case the round can cost
    /// minutes (its factors' bootstrap). A data-driven factor is never a false effect.
    #[arg(long)]
    pub data_driven: bool,
}

/// `LO,HI` as the option writes it.
fn pair_text<T: std::fmt::Display>((lo, hi): (T, T)) -> String {
    format!("{lo},{hi}")
}

fn pair<T: std::str::FromStr>(text: &str, option: &str) -> Result<(T, T)> {
    let (a, b) = text
        .split_once(',')
        .ok_or_else(|| anyhow::anyhow!("{option}: expected LO,HI, got '{text}'"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<T>()
            .map_err(|_| anyhow::anyhow!("{option}: '{v}' is not a number"))
    };
    Ok((parse(a)?, parse(b)?))
}

pub fn run(a: &BatteryArgs) -> Result<()> {
    for p in [&a.json, &a.markdown].into_iter().flatten() {
        crate::output::check_writable_file(p, "--json/--markdown")?;
    }
    let effects: Vec<Effect> = match &a.effects {
        None => Effect::all().filter(|e| !e.is_data_driven()).collect(),
        Some(names) => effects_named(names)?,
    };
    let opts = BatteryOptions {
        cases: a.cases,
        nulls: a.nulls,
        misspecified: a.misspecified,
        misspecified_btdf: a.misspecified_btdf,
        seed: a.seed,
        effects,
        signal: pair(&a.signal, "--signal")?,
        samples: pair(&a.samples, "--samples")?,
        diagnose: DiagnoseOptions {
            restarts: a.restarts,
            seed: a.seed,
            data_driven: a.data_driven,
            ..BatteryOptions::default().diagnose
        },
        only: a.case,
    };
    opts.check()?;
    let backend = engine::select(a.backend.backend, &mut |m| eprintln!("{m}"))?;
    let total = opts.total();
    let progress = Progress::new("battery", total as u64, "cases");
    let outcomes = run_battery(&opts, backend.as_ref(), &mut |o| {
        if opts.only.is_some() {
            progress.println(format!(
                "case {}: truth {} {:?} on {} ({} samples, {} channel(s), noise {:.1} %), signal {:.2}",
                o.case.id,
                o.case.truth,
                o.case.truth_params,
                o.case.geometry,
                o.case.samples,
                o.case.channels,
                100.0 * o.case.noise_rel,
                o.case.signal
            ));
            for l in &o.log {
                progress.println(l);
            }
        }
        progress.println(format!(
            "case {:>4} {:<18} {:<28} → {:<34} SNR {:>5.1}  χ²_red {:>9.3} → {:>7.3}  named [{}]{}{}{}",
            o.case.id,
            // A misspecified case hides nothing: its truth's family says what it is.
            o.case
                .hidden
                .as_deref()
                .or(o.case.misspecified.as_deref())
                .unwrap_or("none"),
            o.case.start,
            o.final_model,
            o.snr,
            o.chi2_red_start,
            o.chi2_red_final,
            o.named.join(", "),
            if o.detected { "  detected" } else { "" },
            if o.false_effect { "  FALSE EFFECT" } else { "" },
            o.error.as_ref().map(|e| format!("  error: {e}")).unwrap_or_default()
        ));
        progress.inc(1);
    });
    drop(progress);
    let table = rates_table(&outcomes);
    println!("{table}");
    if let Some(p) = &a.markdown {
        std::fs::write(p, &table).with_context(|| format!("cannot write {}", p.display()))?;
    }
    if let Some(p) = &a.json {
        let text = serde_json::to_string_pretty(&outcomes)? + "\n";
        crate::output::files::write_result(p, &text, true)?;
        eprintln!("wrote {}", p.display());
    }
    Ok(())
}
