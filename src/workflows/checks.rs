//! Checks made around fits (by the command line, the sweep and the Python module): whether
//! a request fits in memory before it starts, and, when a fit ends with a non-finite
//! χ²_red or loss, which samples caused it.

use crate::bsdf::Model;
use crate::data::Dataset;
use crate::engine::loss::{normalised_residuals, Loss};
use crate::engine::{Backend, Problem};
use anyhow::Result;

/// A batch needing more memory than this is refused.
pub const BATCH_MEMORY_LIMIT: u64 = 4 << 30;
/// A batch needing more memory than this is allowed with a warning.
pub const BATCH_MEMORY_WARN: u64 = 1 << 30;

/// Random draws screened per restart (see `FitOptions::screen`): the first batch of a fit
/// holds restarts × this many candidates.
const SCREEN: u64 = 8;

/// Candidates in a fit's largest batch: the screening draws (restarts × 8) or one compass
/// poll (restarts × (2P + 1)), whichever is larger.
pub fn batch_candidates(restarts: usize, params: usize) -> u64 {
    // Saturating: a request of near 2⁶⁴ restarts must read as huge, not wrap to a few.
    (restarts as u64).saturating_mul(SCREEN.max(2 * params as u64 + 1))
}

/// Bytes of one batch: candidates × (P parameters + the P(P + 1)/2 + P + 1 sums of
/// their normal equations + the values of one window of samples) × 8 bytes (f64). The
/// engine streams the samples window by window ([`crate::engine::reduce`]), so a window
/// (at most [`crate::engine::cpu::WINDOW_ROWS`] samples) is all a batch holds of them.
pub fn batch_bytes(candidates: u64, params: usize, samples: usize) -> u64 {
    let window = samples.min(crate::engine::cpu::WINDOW_ROWS) as u64;
    let sums = crate::engine::reduce::gram_entries(params) as u64;
    candidates
        .saturating_mul(params as u64 + sums + window)
        .saturating_mul(8)
}

fn gib(b: u64) -> String {
    format!("{:.1} GiB", b as f64 / (1u64 << 30) as f64)
}

/// Refuse (above [`BATCH_MEMORY_LIMIT`]) or warn about (above [`BATCH_MEMORY_WARN`]) a
/// request of `restarts` restarts of a P-parameter model on K samples (values at every
/// sample and channel). `what` says which fit, e.g. "on on on.csv".
pub fn check_batch_memory(
    restarts: usize,
    params: usize,
    samples: usize,
    what: &str,
    warn: &mut dyn FnMut(String),
) -> Result<()> {
    batch_memory(
        "--restarts",
        restarts,
        batch_candidates(restarts, params),
        params,
        samples,
        what,
        warn,
    )
}

/// As [`check_batch_memory`] for a batch of `candidates` given outright (e.g. `bench`:
/// restarts × (2P + 1)); `option`/`value` name the option that sets its size.
pub fn batch_memory(
    option: &str,
    value: usize,
    candidates: u64,
    params: usize,
    samples: usize,
    what: &str,
    warn: &mut dyn FnMut(String),
) -> Result<()> {
    let bytes = batch_bytes(candidates, params, samples);
    let per_unit = batch_bytes(candidates.div_ceil(value.max(1) as u64), params, samples).max(1);
    let max_value = BATCH_MEMORY_LIMIT / per_unit;
    let desc = format!(
        "{option} {value}: a batch of {candidates} candidate parameter vectors × ({params} parameters + {} normal-equation sums + {} values of a window of samples) × 8 bytes needs about {} for {what}",
        crate::engine::reduce::gram_entries(params),
        samples.min(crate::engine::cpu::WINDOW_ROWS),
        gib(bytes)
    );
    if bytes > BATCH_MEMORY_LIMIT {
        anyhow::bail!(
            "{desc}, over the limit of {}; use fewer (at most about {max_value} here)",
            gib(BATCH_MEMORY_LIMIT)
        );
    }
    if bytes > BATCH_MEMORY_WARN {
        warn(format!(
            "warning: {desc} (limit {}); fewer would be faster",
            gib(BATCH_MEMORY_LIMIT)
        ));
    }
    Ok(())
}

/// Why a fit's χ²_red or loss is not finite: the samples whose normalised residual
/// (y′ − y)/u or loss term is not finite (or, if every one is finite and only their sum
/// overflowed, the largest), up to 5, each with its file line, geometry, value,
/// uncertainty and model value. `flat` is the fit's best parameter vector.
pub fn nonfinite_cause(
    model: &Model,
    data: &Dataset,
    loss: Loss,
    flat: &[f64],
    backend: &dyn Backend,
) -> String {
    let cpu = crate::engine::cpu::CpuBackend::new();
    let problem = Problem { model, data, loss };
    let values = backend
        .prepare(problem)
        .and_then(|mut e| e.values(flat))
        .or_else(|_| cpu.prepare(problem).and_then(|mut e| e.values(flat)));
    let values = match values {
        Ok(v) if v.len() == data.len() => v,
        Ok(_) | Err(_) => {
            return "the model could not be evaluated at the best parameters".into();
        }
    };
    if flat.iter().any(|x| !x.is_finite()) {
        return format!(
            "the best parameters are not finite ({})",
            model
                .flat_names()
                .iter()
                .zip(flat)
                .filter(|(_, x)| !x.is_finite())
                .map(|(n, x)| format!("{n} = {x}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let z = normalised_residuals(data, &values);
    let terms = loss.terms(data);
    let bad: Vec<usize> = (0..data.len())
        .filter(|&k| !z[k].is_finite() || !terms.term_at(k, values[k]).is_finite())
        .collect();
    let overflow = bad.is_empty();
    let (head, picked) = if overflow {
        let mut order: Vec<usize> = (0..data.len()).collect();
        order.sort_by(|&a, &b| z[b].abs().total_cmp(&z[a].abs()));
        (
            "every sample's (y′ − y)/u is finite but their squares overflow the sum; the largest"
                .to_string(),
            order,
        )
    } else {
        (
            format!(
                "{} with a non-finite (y′ − y)/u or {} loss term",
                crate::text::plural(bad.len(), "sample"),
                loss.metric
            ),
            bad,
        )
    };
    let n = picked.len();
    let mut s = format!("{head}:");
    for &k in picked.iter().take(5) {
        let smp = &data.samples[k];
        let at = if smp.line > 0 {
            format!("{}:{}", data.source.display(), smp.line)
        } else {
            format!("sample {}", k + 1)
        };
        s += &format!(
            "\n  {at}: θi = {:.4}°, φi = {:.4}°, θo = {:.4}°, φo = {:.4}°, {} nm: value {:e} ± {:e}, model {:e}, (y′ − y)/u = {:e}",
            smp.theta_i.to_degrees(),
            smp.phi_i.to_degrees(),
            smp.theta_o.to_degrees(),
            smp.phi_o.to_degrees(),
            smp.wavelength_nm,
            smp.value,
            smp.uncertainty,
            values[k],
            z[k]
        );
    }
    if n > 5 && !overflow {
        s += &format!("\n  … and {} more", n - 5);
    }
    s
}

/// The error of a fit whose χ²_red or loss is not finite, naming the samples that cause it.
#[allow(clippy::too_many_arguments)]
pub fn nonfinite_message(
    model: &Model,
    data: &Dataset,
    loss: Loss,
    flat: &[f64],
    chi2_red: f64,
    best_loss: f64,
    backend: &dyn Backend,
) -> String {
    format!(
        "the fit of {} to {} ended with χ²_red = {chi2_red} and {loss} loss = {best_loss}; {}",
        model.spec,
        data.source.display(),
        nonfinite_cause(model, data, loss, flat, backend)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn memory_limits() {
        // 1e6 restarts of a 4-parameter model on 384 samples: refused, naming the option.
        let e = check_batch_memory(1_000_000, 4, 384, "on", &mut |_| {}).unwrap_err();
        let m = e.to_string();
        assert!(
            m.contains("--restarts 1000000") && m.contains("fewer"),
            "{m}"
        );
        let mut warned = Vec::new();
        check_batch_memory(16, 4, 384, "on", &mut |w| warned.push(w)).unwrap();
        assert!(warned.is_empty());
        check_batch_memory(60_000, 4, 384, "on", &mut |w| warned.push(w)).unwrap();
        assert_eq!(warned.len(), 1, "{warned:?}");
        // The largest requests are refused too: restarts × (2P + 1) or × 8 once wrapped
        // around to 2 and to 0 candidates for the last two.
        for (restarts, params) in [(usize::MAX, 4), (usize::MAX / 9 + 1, 4), (1 << 63, 2)] {
            let e = check_batch_memory(restarts, params, 384, "on", &mut |_| {});
            assert!(e.is_err(), "{restarts} restarts of {params} parameters");
        }
    }
}
