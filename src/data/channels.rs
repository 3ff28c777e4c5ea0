//! Channel selection: which wavelengths of a file become the data set's channels
//! (`--wavelengths`, optionally averaged over `--band`), once its rows are read.

use super::dataset::sample_key;
use super::Notice;
use super::{DataError, ReadOptions, Sample, MAX_WAVELENGTH_GAP_NM};
use crate::text::plural_with as count;
use std::collections::BTreeSet;

/// Wavelengths for messages: "450, 550, 650".
fn list(v: &[f64]) -> String {
    v.iter()
        .map(|w| w.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Choose the channels: every wavelength, or the ones nearest to `--wavelengths` (each
/// within [`MAX_WAVELENGTH_GAP_NM`]), optionally averaged over `--band`. Drops the other
/// samples and sets [`Sample::channel`].
pub(super) fn select_channels(
    samples: &mut Vec<Sample>,
    file: &str,
    opts: &ReadOptions,
    notices: &mut Vec<Notice>,
) -> Result<Vec<f64>, DataError> {
    let ferr = |msg: String| DataError::File {
        file: file.into(),
        msg,
    };
    let present = present_wavelengths(samples);
    let wanted = match &opts.wavelengths {
        Some(w)
            if opts.wavelengths_at_most && opts.band_nm.is_none() && w.len() >= present.len() =>
        {
            notices.push(Notice::from(format!(
                "--wavelengths names {} ({} nm); the file has {}: all kept",
                count(w.len(), "channel", "channels"),
                list(w),
                count(present.len(), "wavelength", "wavelengths"),
            )));
            None
        }
        w => w.as_ref(),
    };
    let Some(wanted) = wanted else {
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
    let chosen = nearest_present(wanted, &present, file, notices).map_err(ferr)?;
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
    let member_of = band_members(&chosen, &present, band).map_err(ferr)?;
    let (n_min, n_max) = average_bands(samples, &member_of, &chosen);
    for (ch, &c) in chosen.iter().enumerate() {
        let members: Vec<f64> = member_of
            .iter()
            .filter(|m| m.1 == ch)
            .map(|m| m.0)
            .collect();
        notices.push(Notice::from(format!(
            "{file}: --band ±{band} nm: channel {c} nm averages {} nm",
            list(&members)
        )));
    }
    if n_max > 0 {
        notices.push(Notice::from(format!(
            "{file}: --band: {} per geometry averaged (value = mean, u = sqrt(Σu²)/n)",
            if n_min == n_max {
                count(n_min, "sample", "samples")
            } else {
                format!("{n_min} to {n_max} samples")
            }
        )));
    }
    Ok(chosen)
}

/// The distinct wavelengths of the samples, ascending.
fn present_wavelengths(samples: &[Sample]) -> Vec<f64> {
    // Wavelengths are positive and finite, so their bit patterns sort as they do.
    samples
        .iter()
        .map(|s| s.wavelength_nm.to_bits())
        .collect::<BTreeSet<u64>>()
        .into_iter()
        .map(f64::from_bits)
        .collect()
}

/// The present wavelength nearest to each wanted one, in the order asked. An error when
/// none is within [`MAX_WAVELENGTH_GAP_NM`] or two would share one; a notice for each
/// substitution.
fn nearest_present(
    wanted: &[f64],
    present: &[f64],
    file: &str,
    notices: &mut Vec<Notice>,
) -> Result<Vec<f64>, String> {
    if wanted.is_empty() {
        return Err("--wavelengths selects no channel".into());
    }
    if wanted.len() > present.len() {
        return Err(format!(
            "--wavelengths asks for {} ({} nm) but the file has only {}: {} nm",
            count(wanted.len(), "channel", "channels"),
            list(wanted),
            count(present.len(), "wavelength", "wavelengths"),
            list(present)
        ));
    }
    let mut chosen: Vec<f64> = Vec::new();
    for &w in wanted {
        if !w.is_finite() || w <= 0.0 {
            return Err(format!(
                "--wavelengths: {w} nm is not a positive wavelength"
            ));
        }
        let nearest = present
            .iter()
            .copied()
            .min_by(|a, b| (a - w).abs().total_cmp(&(b - w).abs()))
            .unwrap_or(w);
        if (nearest - w).abs() > MAX_WAVELENGTH_GAP_NM {
            return Err(format!(
                "--wavelengths: no wavelength within {MAX_WAVELENGTH_GAP_NM} nm of {w} nm; the file has only: {} nm",
                list(present)
            ));
        }
        if let Some(c) = chosen.iter().position(|&c| c == nearest) {
            return Err(format!(
                "--wavelengths: {} nm and {w} nm would both use the {nearest} nm channel; the file has only these wavelengths: {} nm",
                wanted[c],
                list(present)
            ));
        }
        if nearest != w {
            notices.push(Notice::from(format!(
                "{file}: wavelength {w} nm → nearest present {nearest} nm"
            )));
        }
        chosen.push(nearest);
    }
    Ok(chosen)
}

/// Bands: every present wavelength within ±`band` of a chosen centre joins that channel,
/// as (wavelength, channel). An error when a wavelength would join two.
fn band_members(chosen: &[f64], present: &[f64], band: f64) -> Result<Vec<(f64, usize)>, String> {
    let mut member_of: Vec<(f64, usize)> = Vec::new();
    for (ch, &c) in chosen.iter().enumerate() {
        let members: Vec<f64> = present
            .iter()
            .copied()
            .filter(|w| (w - c).abs() <= band)
            .collect();
        for &w in &members {
            if let Some(&(_, other)) = member_of.iter().find(|m| m.0 == w) {
                return Err(format!(
                    "--band {band}: {w} nm lies in the bands of both {} nm and {c} nm; narrow the band or space the wavelengths",
                    chosen[other]
                ));
            }
            member_of.push((w, ch));
        }
    }
    Ok(member_of)
}

/// Replace the samples by one per (channel, geometry): the mean value, u = sqrt(Σu²)/n,
/// at the channel's wavelength, in the order of each group's first sample. Samples outside
/// every band are dropped. Returns the smallest and largest group size.
fn average_bands(
    samples: &mut Vec<Sample>,
    member_of: &[(f64, usize)],
    chosen: &[f64],
) -> (usize, usize) {
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
        // sqrt(Σu²)/n as a running hypot of u/n: Σu² overflowed to ∞ for u ≳ 1e154.
        let mut u = 0.0f64;
        for g in &groups[a..b] {
            let m = &samples[g.2];
            sum += m.value;
            u = u.hypot(m.uncertainty / n as f64);
        }
        s.value = sum / n as f64;
        s.uncertainty = u;
        s.channel = groups[a].0;
        s.wavelength_nm = chosen[groups[a].0];
        out.push((first, s));
        n_min = n_min.min(n);
        n_max = n_max.max(n);
        a = b;
    }
    out.sort_unstable_by_key(|(i, _)| *i);
    *samples = out.into_iter().map(|(_, s)| s).collect();
    (n_min, n_max)
}
