//! Where the model and the measurement disagree: statistics of the normalized residuals
//! over angular regions, and the sentences that say which regions are off.

use crate::data::{Dataset, Kind, Sample};
use glam::DVec3;

/// The direction a cone-shaped region is centred on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Around {
    Mirror,
    Retro,
    /// A BTDF curve's brightest sample.
    Peak,
}

/// A region of the directions within `radius_deg` of a direction (`around`): what seeds
/// the width of a new lobe meant to explain a misfit there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cone {
    pub around: Around,
    pub radius_deg: f64,
}

/// Mean and RMS of z over one angular region (optionally restricted in θi).
#[derive(Clone, Debug)]
pub struct RegionStat {
    /// The region in words, e.g. "within 15° of the mirror direction for θi ≥ 30°".
    pub words: String,
    /// The cone it is, where it is one.
    pub cone: Option<Cone>,
    pub n: usize,
    pub mean: f64,
    pub rms: f64,
    /// Fraction of the region's residuals with the sign of the mean.
    pub same_sign: f64,
    mask: Vec<bool>,
}

impl RegionStat {
    /// mean·√n: the mean's significance if the z were independent N(0, 1).
    pub fn t(&self) -> f64 {
        self.mean * (self.n as f64).sqrt()
    }
}

fn angle_deg(a: DVec3, b: DVec3) -> f64 {
    a.normalize()
        .dot(b.normalize())
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

fn stat(words: String, cone: Option<Cone>, mask: Vec<bool>, z: &[f64]) -> Option<RegionStat> {
    let zs: Vec<f64> = z
        .iter()
        .zip(&mask)
        .filter(|(_, &m)| m)
        .map(|(&v, _)| v)
        .collect();
    if zs.is_empty() {
        return None;
    }
    let n = zs.len();
    let mean = zs.iter().sum::<f64>() / n as f64;
    let rms = (zs.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
    let same_sign = zs.iter().filter(|v| v.signum() == mean.signum()).count() as f64 / n as f64;
    Some(RegionStat {
        words,
        cone,
        n,
        mean,
        rms,
        same_sign,
        mask,
    })
}

/// The statistics of z over every angular region of docs/diagnose.md that the data covers:
/// BRDF — near the mirror and the retro direction (5° and 15°), the source (backscatter)
/// side, the forward side away from the mirror, grazing θo ≥ 60°, the tails more than 30°
/// from the mirror; BTDF — near the transmission peak (the brightest sample of each
/// incidence and plane), its flanks (5–50 % of the peak) and tails (< 5 %), large θt;
/// both — everywhere and each φ plane; each also for θi ≥ 30° and θi ≥ 60°.
pub fn region_stats(data: &Dataset, z: &[f64]) -> Vec<RegionStat> {
    let mut regions = match data.kind {
        Kind::Brdf => brdf_regions(data),
        Kind::Btdf => btdf_regions(data),
    };
    regions.push(("everywhere".into(), None, vec![true; data.len()]));
    regions.extend(plane_regions(data));
    stats_by_incidence(data, regions, z)
}

/// A region before its statistics: its words, the cone it is (where it is one), and which
/// samples it holds.
type Region = (String, Option<Cone>, Vec<bool>);

/// Which samples of `data` satisfy `f`.
fn mask(data: &Dataset, f: impl Fn(&Sample) -> bool) -> Vec<bool> {
    data.samples.iter().map(f).collect()
}

/// The BRDF regions: the cones about the mirror and the retro direction (each sample in
/// the nearer one's), the source and forward sides, grazing θo, the tails.
fn brdf_regions(data: &Dataset) -> Vec<Region> {
    let mut regions: Vec<Region> = Vec::new();
    let cone = |around, radius_deg| Some(Cone { around, radius_deg });
    let mirror = |s: &Sample| angle_deg(s.wo(), DVec3::new(-s.wi().x, -s.wi().y, s.wi().z));
    let retro = |s: &Sample| angle_deg(s.wo(), s.wi());
    for r in [5.0, 15.0] {
        regions.push((
            format!("within {r}° of the mirror direction"),
            cone(Around::Mirror, r),
            mask(data, |s| mirror(s) <= r + 0.5 && mirror(s) < retro(s)),
        ));
    }
    for r in [5.0, 15.0] {
        regions.push((
            format!("within {r}° of the retro direction"),
            cone(Around::Retro, r),
            mask(data, |s| retro(s) <= r + 0.5 && retro(s) < mirror(s)),
        ));
    }
    let side = |s: &Sample| s.wo().x * s.wi().x + s.wo().y * s.wi().y;
    regions.push((
        "on the source (backscatter) side".into(),
        None,
        mask(data, |s| side(s) > 1e-9),
    ));
    regions.push((
        "on the forward side away from the mirror direction".into(),
        None,
        mask(data, |s| side(s) < -1e-9 && mirror(s) > 15.5),
    ));
    regions.push((
        "at grazing θo ≥ 60° away from the mirror direction".into(),
        None,
        mask(data, |s| s.theta_o.to_degrees() >= 59.5 && mirror(s) > 15.5),
    ));
    regions.push((
        "in the tails more than 30° from the mirror direction".into(),
        None,
        mask(data, |s| mirror(s) > 30.5),
    ));
    regions
}

/// The BTDF regions, relative to the peak of each (incidence, plane, channel) curve (its
/// brightest sample): the cones about it, its flanks and tails by value, large θt.
fn btdf_regions(data: &Dataset) -> Vec<Region> {
    let mut regions: Vec<Region> = Vec::new();
    let key = |s: &Sample| {
        (
            (s.theta_i.to_degrees() * 10.0).round() as i64,
            (s.phi_i.to_degrees() * 10.0).round() as i64,
            s.axis,
            s.channel,
        )
    };
    let mut peaks: std::collections::HashMap<_, usize> = Default::default();
    for (j, s) in data.samples.iter().enumerate() {
        let e = peaks.entry(key(s)).or_insert(j);
        if s.value > data.samples[*e].value {
            *e = j;
        }
    }
    let peak = |s: &Sample| &data.samples[peaks[&key(s)]];
    let ratio = |s: &Sample| s.value / peak(s).value.max(1e-300);
    for r in [5.0, 15.0] {
        regions.push((
            format!("within {r}° of the transmission peak"),
            Some(Cone {
                around: Around::Peak,
                radius_deg: r,
            }),
            mask(data, |s| angle_deg(s.wo(), peak(s).wo()) <= r + 0.5),
        ));
    }
    regions.push((
        "on the flanks of the peak (5–50 % of its value)".into(),
        None,
        mask(data, |s| (0.05..0.5).contains(&ratio(s))),
    ));
    regions.push((
        "in the tails (below 5 % of the peak value)".into(),
        None,
        mask(data, |s| ratio(s) < 0.05),
    ));
    regions.push((
        "at large θt ≥ 50°".into(),
        None,
        mask(data, |s| s.theta_o.to_degrees() >= 49.5),
    ));
    regions.push((
        "at θt ≥ 70°".into(),
        None,
        mask(data, |s| s.theta_o.to_degrees() >= 69.5),
    ));
    regions
}

/// Each φ plane of data measured on more than one (its normal-exit sample left out, which
/// every plane shares).
fn plane_regions(data: &Dataset) -> Vec<Region> {
    if data.axes.len() <= 1 {
        return vec![];
    }
    data.axes
        .iter()
        .enumerate()
        .map(|(a, phi)| {
            (
                format!("on the φ = {phi}° plane"),
                None,
                mask(data, |s| s.axis == a && s.theta_o > 1e-9),
            )
        })
        .collect()
}

/// The statistics of each region, each followed by those of its part at θi ≥ 30° and at
/// θi ≥ 60° where that part is neither empty nor the whole region: a misfit that grows
/// with incidence shows there.
fn stats_by_incidence(data: &Dataset, regions: Vec<Region>, z: &[f64]) -> Vec<RegionStat> {
    let mut out = Vec::new();
    let ti = |s: &Sample| s.theta_i.to_degrees();
    for (words, cone, mask) in regions {
        if let Some(st) = stat(words.clone(), cone, mask.clone(), z) {
            out.push(st);
        }
        for lim in [30.0, 60.0] {
            let sub: Vec<bool> = mask
                .iter()
                .zip(&data.samples)
                .map(|(&m, s)| m && ti(s) >= lim - 0.5)
                .collect();
            let n_sub = sub.iter().filter(|&&m| m).count();
            let n_all = mask.iter().filter(|&&m| m).count();
            if n_sub > 0 && n_sub < n_all {
                if let Some(st) = stat(format!("{words} for θi ≥ {lim}°"), cone, sub, z) {
                    out.push(st);
                }
            }
        }
    }
    out
}

fn sentence(r: &RegionStat) -> String {
    let dir = if r.mean < 0.0 { "dark" } else { "bright" };
    let sign = if r.words == "everywhere" {
        format!(", {:.0} % of residuals one-signed", 100.0 * r.same_sign)
    } else {
        String::new()
    };
    format!(
        "model {:.1}σ too {dir} {} (n = {}, RMS z = {:.1}{sign})",
        r.mean.abs(),
        r.words,
        r.n,
        r.rms
    )
}

/// Where the residuals say the model misses: up to three regions whose mean z exceeds 1σ
/// in size and 3 in significance (mean·√n), each localized to its most concentrated
/// sub-region, overlapping regions reported once. Most significant first.
pub fn flagged_regions(data: &Dataset, z: &[f64]) -> Vec<RegionStat> {
    let stats = region_stats(data, z);
    let passes = |r: &RegionStat| r.n >= 3 && r.mean.abs() >= 1.0 && r.t().abs() >= 3.0;
    let mut order: Vec<&RegionStat> = stats.iter().filter(|r| passes(r)).collect();
    order.sort_by(|a, b| b.t().abs().total_cmp(&a.t().abs()));
    let mut covered = vec![false; z.len()];
    let mut flagged: Vec<RegionStat> = Vec::new();
    for r in order {
        if flagged.len() == 3 {
            break;
        }
        // At most half of a region may repeat what was said already.
        let mostly_said = |s: &RegionStat| {
            let overlap = s
                .mask
                .iter()
                .zip(&covered)
                .filter(|(&m, &c)| m && c)
                .count();
            overlap * 2 > s.n
        };
        if mostly_said(r) {
            continue;
        }
        // Localize: a sub-region of the same sign with a much larger mean says it better.
        let mut best = r;
        loop {
            let inner = stats
                .iter()
                .filter(|s| passes(s) && s.n < best.n && s.mean.signum() == best.mean.signum())
                .filter(|s| s.mask.iter().zip(&best.mask).all(|(&a, &b)| !a || b))
                .filter(|s| s.mean.abs() >= 1.5 * best.mean.abs())
                .max_by(|a, b| a.mean.abs().total_cmp(&b.mean.abs()));
            match inner {
                Some(s) => best = s,
                None => break,
            }
        }
        if mostly_said(best) {
            continue;
        }
        for (c, &m) in covered.iter_mut().zip(&r.mask) {
            *c |= m;
        }
        flagged.push(best.clone());
    }
    flagged
}

impl RegionStat {
    /// Σ z² over the region's samples.
    pub fn chi2(&self, z: &[f64]) -> f64 {
        z.iter()
            .zip(&self.mask)
            .filter(|(_, &m)| m)
            .map(|(v, _)| v * v)
            .sum()
    }

    /// Whether sample `k` lies in the region.
    pub fn contains(&self, k: usize) -> bool {
        self.mask[k]
    }
}

/// Where the residuals say the model misses, in words ([`flagged_regions`]).
pub fn describe_regions(data: &Dataset, z: &[f64]) -> String {
    let said: Vec<String> = flagged_regions(data, z).iter().map(sentence).collect();
    if said.is_empty() {
        let (j, zmax) = z.iter().enumerate().fold((0, 0.0f64), |acc, (j, &v)| {
            if v.abs() > acc.1.abs() {
                (j, v)
            } else {
                acc
            }
        });
        let rms = (z.iter().map(|v| v * v).sum::<f64>() / z.len().max(1) as f64).sqrt();
        let s = &data.samples[j];
        format!(
            "no angular region is off by more than 1σ on average (RMS z = {rms:.2}; largest z = {zmax:+.1} at θi = {:.0}°, θo = {:.0}°, φo = {:.0}°)",
            s.theta_i.to_degrees(),
            s.theta_o.to_degrees(),
            s.phi_o.to_degrees()
        )
    } else {
        said.join("; ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::workflows::diagnose::testdata::dataset;

    #[test]
    fn evidence_names_the_regions() {
        let rows = crate::workflows::synth::geometry("inplane10").unwrap().1;
        let data = dataset(Kind::Brdf, &rows, 1);
        // Model too dark near the mirror for θi ≥ 30°, fine elsewhere.
        let z: Vec<f64> = data
            .samples
            .iter()
            .map(|s| {
                let m = angle_deg(s.wo(), DVec3::new(-s.wi().x, -s.wi().y, s.wi().z));
                if m <= 15.5 && s.theta_i.to_degrees() >= 29.5 && m < angle_deg(s.wo(), s.wi()) {
                    -4.0
                } else {
                    0.1
                }
            })
            .collect();
        let e = describe_regions(&data, &z);
        assert!(e.starts_with("model 4.0σ too dark within"), "{e}");
        assert!(e.contains("of the mirror direction for θi ≥ 30°"), "{e}");
        // One sign everywhere.
        let z = vec![2.0; data.len()];
        let e = describe_regions(&data, &z);
        assert!(
            e.contains("model 2.0σ too bright everywhere")
                && e.contains("100 % of residuals one-signed"),
            "{e}"
        );
        // Nothing coherent.
        let z: Vec<f64> = (0..data.len())
            .map(|i| if i % 2 == 0 { 0.5 } else { -0.5 })
            .collect();
        assert!(describe_regions(&data, &z).starts_with("no angular region"));
    }
}
