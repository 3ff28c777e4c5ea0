//! Channel selection: which wavelengths of a file become the data set's channels
//! (`--wavelengths`, optionally averaged over `--band`), once its rows are read.

use super::dataset::sample_key;
use super::{count, DataError, ReadOptions, Sample, MAX_WAVELENGTH_GAP_NM};
use std::collections::BTreeSet;

/// Choose the channels: every wavelength, or the ones nearest to `--wavelengths` (each
/// within [`MAX_WAVELENGTH_GAP_NM`]), optionally averaged over `--band`. Drops the other
/// samples and sets [`Sample::channel`].
pub(super) fn select_channels(
    samples: &mut Vec<Sample>,
    file: &str,
    opts: &ReadOptions,
    notices: &mut Vec<String>,
) -> Result<Vec<f64>, DataError> {
    let ferr = |msg: String| DataError::File {
        file: file.into(),
        msg,
    };
    // Wavelengths are positive and finite, so their bit patterns sort as they do.
    let present: Vec<f64> = samples
        .iter()
        .map(|s| s.wavelength_nm.to_bits())
        .collect::<BTreeSet<u64>>()
        .into_iter()
        .map(f64::from_bits)
        .collect();
    let list = |v: &[f64]| {
        v.iter()
            .map(|w| w.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let Some(wanted) = &opts.wavelengths else {
        if opts.band_nm.is_some() {
            return Err(ferr(
                "--band needs --wavelengths: the centres of the bands to average".into(),
            ));
        }
        for s in samples.iter_mut() {
            s.channel = present
                .binary_search_by(|p| p.total_cmp(&s.wavelength_nm))
                .unwrap_or(0);
        }
        return Ok(present);
    };
    if wanted.is_empty() {
        return Err(ferr("--wavelengths selects no channel".into()));
    }
    if wanted.len() > present.len() {
        return Err(ferr(format!(
            "--wavelengths asks for {} ({} nm) but the file has only {}: {} nm",
            count(wanted.len(), "channel", "channels"),
            list(wanted),
            count(present.len(), "wavelength", "wavelengths"),
            list(&present)
        )));
    }
    let mut chosen: Vec<f64> = Vec::new();
    for &w in wanted {
        if !w.is_finite() || w <= 0.0 {
            return Err(ferr(format!(
                "--wavelengths: {w} nm is not a positive wavelength"
            )));
        }
        let nearest = present
            .iter()
            .copied()
            .min_by(|a, b| (a - w).abs().total_cmp(&(b - w).abs()))
            .unwrap_or(w);
        if (nearest - w).abs() > MAX_WAVELENGTH_GAP_NM {
            return Err(ferr(format!(
                "--wavelengths: no wavelength within {MAX_WAVELENGTH_GAP_NM} nm of {w} nm; the file has only: {} nm",
                list(&present)
            )));
        }
        if let Some(c) = chosen.iter().position(|&c| c == nearest) {
            return Err(ferr(format!(
                "--wavelengths: {} nm and {w} nm would both use the {nearest} nm channel; the file has only these wavelengths: {} nm",
                wanted[c],
                list(&present)
            )));
        }
        if nearest != w {
            notices.push(format!(
                "{file}: wavelength {w} nm → nearest present {nearest} nm"
            ));
        }
        chosen.push(nearest);
    }
    let band = match opts.band_nm {
        None => 0.0,
        Some(b) if b.is_finite() && b >= 0.0 => b,
        Some(b) => return Err(ferr(format!("--band {b}: expected a width ≥ 0 nm"))),
    };
    if band == 0.0 {
        samples.retain(|s| chosen.contains(&s.wavelength_nm));
        for s in samples.iter_mut() {
            s.channel = chosen
                .iter()
                .position(|&c| c == s.wavelength_nm)
                .unwrap_or(0);
        }
        return Ok(chosen);
    }
    // Bands: every present wavelength within ±band of a chosen centre joins its channel.
    let mut member_of: Vec<(f64, usize)> = Vec::new();
    for (ch, &c) in chosen.iter().enumerate() {
        let members: Vec<f64> = present
            .iter()
            .copied()
            .filter(|w| (w - c).abs() <= band)
            .collect();
        for &w in &members {
            if let Some(&(_, other)) = member_of.iter().find(|m| m.0 == w) {
                return Err(ferr(format!(
                    "--band {band}: {w} nm lies in the bands of both {} nm and {c} nm; narrow the band or space the wavelengths",
                    chosen[other]
                )));
            }
            member_of.push((w, ch));
        }
    }
    // Group by (channel, geometry) and average.
    let mut groups: Vec<(usize, [i64; 4], usize)> = samples
        .iter()
        .enumerate()
        .filter_map(|(i, s)| {
            let ch = member_of.iter().find(|m| m.0 == s.wavelength_nm)?.1;
            let k = sample_key(s);
            Some((ch, [k[0], k[1], k[2], k[3]], i))
        })
        .collect();
    groups.sort_unstable();
    let mut out: Vec<(usize, Sample)> = Vec::new();
    let (mut n_min, mut n_max) = (usize::MAX, 0usize);
    let mut a = 0;
    while a < groups.len() {
        let mut b = a + 1;
        while b < groups.len() && groups[b].0 == groups[a].0 && groups[b].1 == groups[a].1 {
            b += 1;
        }
        let n = b - a;
        let first = groups[a].2; // smallest index of the group (sorted last)
        let mut s = samples[first].clone();
        let mut sum = 0.0;
        let mut var = 0.0;
        for g in &groups[a..b] {
            let m = &samples[g.2];
            sum += m.value;
            var += m.uncertainty * m.uncertainty;
        }
        s.value = sum / n as f64;
        s.uncertainty = var.sqrt() / n as f64;
        s.channel = groups[a].0;
        s.wavelength_nm = chosen[groups[a].0];
        out.push((first, s));
        n_min = n_min.min(n);
        n_max = n_max.max(n);
        a = b;
    }
    out.sort_unstable_by_key(|(i, _)| *i);
    *samples = out.into_iter().map(|(_, s)| s).collect();
    for (ch, &c) in chosen.iter().enumerate() {
        let members: Vec<f64> = member_of
            .iter()
            .filter(|m| m.1 == ch)
            .map(|m| m.0)
            .collect();
        notices.push(format!(
            "{file}: --band ±{band} nm: channel {c} nm averages {} nm",
            list(&members)
        ));
    }
    if n_max > 0 {
        notices.push(format!(
            "{file}: --band: {} per geometry averaged (value = mean, u = sqrt(Σu²)/n)",
            if n_min == n_max {
                count(n_min, "sample", "samples")
            } else {
                format!("{n_min} to {n_max} samples")
            }
        ));
    }
    Ok(chosen)
}
