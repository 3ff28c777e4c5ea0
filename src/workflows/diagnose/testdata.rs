//! Test datasets for the diagnose unit tests.

use super::{Effect, FitResult, Step};
use crate::bsdf::Model;
use crate::data::{Dataset, Kind, RawRow};

/// A dataset with the given (θi, φi, θo, φo) rows and `channels` channels, every value
/// 0.1 ± 0.01.
pub(super) fn dataset(kind: Kind, rows: &[[f64; 4]], channels: usize) -> Dataset {
    let wl = [450.0, 550.0, 650.0];
    let mut raw = Vec::new();
    for (i, r) in rows.iter().enumerate() {
        for (c, &w) in wl.iter().take(channels).enumerate() {
            raw.push((
                i * channels + c + 1,
                RawRow {
                    theta_i: r[0],
                    phi_i: r[1],
                    theta_o: r[2],
                    phi_o: r[3],
                    wavelength_nm: w,
                    value: 0.1,
                    uncertainty: 0.01,
                },
            ));
        }
    }
    Dataset::from_rows(kind, "t", &raw, "<t>", &crate::data::ReadOptions::default()).unwrap()
}

/// In-plane rows (φ = 0, θo signed from −80° to 80° in 10° steps) at each of `theta_i`,
/// but for the θo equal to θi (the retro direction a detector would hide) when `skip_retro`.
pub(super) fn in_plane_rows(theta_i: &[f64], skip_retro: bool) -> Vec<[f64; 4]> {
    let mut rows = Vec::new();
    for &ti in theta_i {
        for k in 0..=16 {
            let to = -80.0 + 10.0 * k as f64;
            if !(skip_retro && (to - ti).abs() < 0.5) {
                rows.push([ti, 0.0, to, 0.0]);
            }
        }
    }
    rows
}

/// Data synthesised from `spec` at its `assignments` (the rest at their defaults) on
/// `rows` at 550 nm, with relative and absolute noise `(rel, abs)`.
pub(super) fn synthesized(
    spec: &str,
    assignments: &str,
    rows: &[[f64; 4]],
    (rel, abs): (f64, f64),
    seed: u64,
) -> Dataset {
    let model = Model::parse(spec, 1).unwrap();
    let truth = model.params_from_assignments(assignments).unwrap();
    let noise = crate::workflows::synth::Noise { rel, abs };
    crate::workflows::synth::synthesize(&model, &truth, rows, &[550.0], noise, seed, spec).unwrap()
}

/// A path step of `model` after `effect` (None: the start), its fit `fit`: what the path
/// logic reads of a step, laid out by hand.
pub(super) fn step(model: &str, effect: Option<Effect>, fit: &FitResult) -> Step {
    Step {
        model: model.into(),
        effect,
        chi2_red: fit.chi2_red,
        loss: fit.loss,
        evidence: String::new(),
        fit: fit.clone(),
        candidates: vec![],
        round_seconds: None,
        removed: vec![],
    }
}
