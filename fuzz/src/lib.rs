//! What every fuzz target checks: the readers' contract (the same as
//! `tests/fuzz_readers.rs`), and the option sets each input is read with.

use bsdfit::data::readers::alta::AltaValues;
use bsdfit::data::{DataError, Dataset, ReadOptions};

/// The name every input is read under (the `any` target also uses other extensions).
pub const FILE: &str = "fuzz-input.dat";

/// The option sets each input is read with: strict (nothing assumed, every sample kept),
/// assumed uncertainties (ALTA without `#VS`, MERL, RGL), and lenient (zero
/// uncertainties floored, a channel selection with bands, `--alta-values`, a small
/// MERL subsample). RGL materials are sampled on small geometries to keep inputs fast.
pub fn option_sets() -> [ReadOptions; 4] {
    [
        ReadOptions {
            max_samples: Some(0),
            sample_geometry: Some("grid:30".into()),
            ..Default::default()
        },
        ReadOptions {
            assume_uncertainty: Some((0.05, 0.001)),
            max_samples: Some(0),
            alta_values: Some(AltaValues::BrdfCos),
            sample_geometry: Some("grid:30".into()),
            ..Default::default()
        },
        ReadOptions {
            allow_zero_uncertainty: true,
            wavelengths: Some(vec![550.0, 650.0]),
            band_nm: Some(30.0),
            assume_uncertainty: Some((0.02, 0.0)),
            max_samples: Some(5),
            alta_values: Some(AltaValues::Brdf),
            sample_geometry: Some("csic".into()),
            wavelengths_at_most: false,
        },
        // A collection's selection: three channels where a file has more, all of its own
        // where it has no more.
        ReadOptions {
            wavelengths: Some(vec![450.0, 550.0, 650.0]),
            wavelengths_at_most: true,
            assume_uncertainty: Some((0.05, 0.001)),
            ..Default::default()
        },
    ]
}

/// The contract, as a message when broken: an error names `file`; a dataset is well
/// formed (samples, finite values, positive finite uncertainties, indices in range, unit
/// directions).
pub fn contract(result: Result<Dataset, DataError>, file: &str) -> Result<(), String> {
    match result {
        Err(e) => {
            let msg = e.to_string();
            if !msg.contains(file) {
                return Err(format!("error without the file name: {msg}"));
            }
        }
        Ok(d) => {
            if d.samples.is_empty() {
                return Err("a dataset without samples".into());
            }
            for s in &d.samples {
                if !(s.value.is_finite() && s.uncertainty.is_finite() && s.uncertainty > 0.0) {
                    return Err(format!("sample {s:?}: value or uncertainty"));
                }
                if !(s.channel < d.channels.len() && s.axis < d.axes.len()) {
                    return Err(format!("sample {s:?}: channel or axis out of range"));
                }
                if !((s.wi().length() - 1.0).abs() < 1e-9 && (s.wo().length() - 1.0).abs() < 1e-9) {
                    return Err(format!("sample {s:?}: directions not unit"));
                }
            }
        }
    }
    Ok(())
}

/// Whether every place an error message names is `file:line:column:` — the contract of
/// the Zemax and ASTM readers (one error, or "N bad rows in file:" and one per line).
pub fn located(msg: &str, file: &str) -> bool {
    let place = |l: &str| {
        let Some(rest) = l.strip_prefix(file).and_then(|r| r.strip_prefix(':')) else {
            return false;
        };
        let mut parts = rest.splitn(3, ':');
        let num = |x: Option<&str>| {
            x.is_some_and(|x| !x.is_empty() && x.bytes().all(|b| b.is_ascii_digit()))
        };
        num(parts.next()) && num(parts.next()) && parts.next().is_some()
    };
    let mut lines = msg.lines();
    let first = lines.next().unwrap_or("");
    if first.ends_with(&format!("bad rows in {file}:")) {
        lines.all(|l| l.starts_with("… and ") || place(l))
    } else {
        place(first)
    }
}

/// [`contract`] as the fuzz targets need it: a violation panics, which libFuzzer reports
/// as a crash.
pub fn check(result: Result<Dataset, DataError>, file: &str) {
    if let Err(why) = contract(result, file) {
        panic!("{why}");
    }
}

/// [`check`] for the readers whose every error names `file:line:column` (Zemax BSDF, ASTM
/// E1392): one located error, or "N bad rows in file:" and one located error per line.
pub fn check_located(result: Result<Dataset, DataError>, file: &str) {
    if let Err(e) = &result {
        let msg = e.to_string();
        assert!(located(&msg, file), "error without file:line:column: {msg}");
    }
    check(result, file);
}
