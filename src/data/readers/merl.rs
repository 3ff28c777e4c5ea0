//! MERL BRDF tables (Matusik et al. 2003, "A Data-Driven Reflectance Model"): reader and
//! writer.
//!
//! # Layout (MERL's `BRDFRead.cpp`, re-implemented from its published definitions)
//!
//! - Header: three little-endian int32, the dimensions 90 (θh) × 90 (θd) × 180 (φd).
//! - Then 3 × 1,458,000 little-endian f64: the R block, the G block, the B block, each
//!   indexed `iφd + 180·(iθd + 90·iθh)`. A file is exactly 34,992,012 bytes.
//! - Stored values times R 1/1500, G 1.15/1500, B 1.66/1500 are the BRDF in sr⁻¹.
//!   Negative values mark cells that were not measured (below the horizon).
//! - Rusinkiewicz half/difference angles, from the **incident** direction: h =
//!   normalize(ωi + ωo), θh = acos hz, φh = atan2(hy, hx); d = Ry(−θh)·Rz(−φh)·ωi
//!   (right-handed rotations), θd = acos dz, φd = atan2(dy, dx). The table is isotropic
//!   (φh is dropped) and uses reciprocity, φd ≡ φd + π: a negative φd is shifted by π.
//! - Indices (truncation, clamped to the last cell): iθh = ⌊√(θh/(π/2)) · 90⌋ (non-linear,
//!   denser near the specular peak), iθd = ⌊θd/(π/2) · 90⌋, iφd = ⌊φd/π · 180⌋.
//!   [`lookup_index`] is this forward lookup.
//!
//! # Reading
//!
//! Each cell is read at its centre, as ALTA's MERL plugin does: θh = ((iθh + ½)/90)²·π/2,
//! θd = (iθd + ½)/90·π/2, φd = (iφd + ½)/180·π, with φh = 0; then ωi = Rz(φh)·Ry(θh)·d,
//! ωo = 2(ωi·h)h − ωi ([`cell_directions`]), rotated about the normal so that φi = 0.
//! Cells with a negative value in any channel, and cells whose centre has ωi or ωo below
//! the horizon, are dropped. The table holds up to 1.46 M cells; `--max-samples N`
//! ([`DEFAULT_MAX_SAMPLES`] by default, 0 for all) keeps a deterministic uniform random
//! subsample of the measured cells (a fixed-seed ChaCha8 stream, so the same file always
//! gives the same samples). Channels: R, G, B at the nominal wavelengths 650, 550,
//! 450 nm ([`NOMINAL_NM`]). MERL tables carry no uncertainties: reading them needs
//! `--assume-uncertainty` (see [`crate::data::readers`]).
//!
//! # Writing
//!
//! [`write`] / [`encode`] tabulate a function of the cell-centre angles (θh, θd, φd),
//! e.g. a fitted BRDF evaluated at [`cell_directions`], so the reader gives it back.

use super::{mark_assumed, require_assumption};
use crate::data::Notice;
use crate::data::{Builder, DataError, Dataset, Kind, RawRow, ReadOptions};
use crate::text::plural_with as count;
use glam::DVec3;
use rand::SeedableRng;
use std::collections::BTreeMap;
use std::f64::consts::{FRAC_PI_2, PI};
use std::io::Write;
use std::path::Path;

/// Table dimensions: θh, θd, φd.
pub const DIMS: [usize; 3] = [90, 90, 180];
/// Cells per colour block.
pub const CELLS: usize = DIMS[0] * DIMS[1] * DIMS[2];
/// Size of a MERL file in bytes.
pub const FILE_BYTES: usize = 12 + 3 * CELLS * 8;
/// Stored value × scale = BRDF (sr⁻¹), for R, G, B.
pub const SCALE: [f64; 3] = [1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0];
/// Nominal wavelengths (nm) of the R, G, B channels.
pub const NOMINAL_NM: [f64; 3] = [650.0, 550.0, 450.0];
/// Default `--max-samples`.
pub const DEFAULT_MAX_SAMPLES: usize = 20_000;
/// Seed of the subsample stream ("MERL").
const SUBSAMPLE_SEED: u64 = 0x4d45_524c;

const BLOCK: [&str; 3] = ["R", "G", "B"];

/// Whether `head` (the first bytes of a file of `len` bytes) looks like a MERL table: the
/// MERL dimensions, or positive dimensions whose three blocks of doubles fill the file.
pub fn looks_like(head: &[u8], len: u64) -> bool {
    let Some(d) = dims(head) else { return false };
    if d == DIMS.map(|x| x as i32) {
        return true;
    }
    d.iter().all(|&x| x > 0)
        && (d[0] as u128 * d[1] as u128 * d[2] as u128) * 24 + 12 == len as u128
}

fn dims(head: &[u8]) -> Option<[i32; 3]> {
    let h = head.get(..12)?;
    Some(
        [0, 1, 2].map(|k| i32::from_le_bytes([h[4 * k], h[4 * k + 1], h[4 * k + 2], h[4 * k + 3]])),
    )
}

/// The flat index of a cell.
pub fn cell_index(i_theta_h: usize, i_theta_d: usize, i_phi_d: usize) -> usize {
    i_phi_d + DIMS[2] * (i_theta_d + DIMS[1] * i_theta_h)
}

/// The centre angles (θh, θd, φd), radians, of the cell with flat index `index`.
pub fn cell_angles(index: usize) -> (f64, f64, f64) {
    let i_phi_d = index % DIMS[2];
    let i_theta_d = (index / DIMS[2]) % DIMS[1];
    let i_theta_h = index / (DIMS[2] * DIMS[1]);
    let th = (i_theta_h as f64 + 0.5) / DIMS[0] as f64;
    (
        th * th * FRAC_PI_2,
        (i_theta_d as f64 + 0.5) / DIMS[1] as f64 * FRAC_PI_2,
        (i_phi_d as f64 + 0.5) / DIMS[2] as f64 * PI,
    )
}

/// (ωi, ωo) of half/difference angles (φh = 0), rotated about the normal so that φi = 0;
/// `None` when either lies below the horizon.
pub fn cell_directions(theta_h: f64, theta_d: f64, phi_d: f64) -> Option<(DVec3, DVec3)> {
    let h = DVec3::new(theta_h.sin(), 0.0, theta_h.cos());
    let d = DVec3::new(
        theta_d.sin() * phi_d.cos(),
        theta_d.sin() * phi_d.sin(),
        theta_d.cos(),
    );
    let wi = super::alta::rot_y(d, theta_h);
    let wo = 2.0 * wi.dot(h) * h - wi;
    if wi.z <= 1e-12 || wo.z <= 1e-12 {
        return None;
    }
    let (wi, wo) = super::alta::to_phi_i_zero(wi.normalize(), wo.normalize());
    Some((wi, wo))
}

/// MERL's lookup: the flat cell index holding the BRDF value of (ωi, ωo).
pub fn lookup_index(wi: DVec3, wo: DVec3) -> usize {
    let h = (wi + wo).normalize();
    let theta_h = h.z.clamp(-1.0, 1.0).acos();
    let phi_h = h.y.atan2(h.x);
    let d = super::alta::rot_y(super::alta::rot_z(wi, -phi_h), -theta_h);
    let theta_d = d.z.clamp(-1.0, 1.0).acos();
    let mut phi_d = d.y.atan2(d.x);
    let n = |v: f64, k: usize| (v as isize).clamp(0, k as isize - 1) as usize;
    let i_theta_h = if theta_h <= 0.0 {
        0
    } else {
        n(
            (theta_h / FRAC_PI_2 * DIMS[0] as f64 * DIMS[0] as f64).sqrt(),
            DIMS[0],
        )
    };
    let i_theta_d = n(theta_d / FRAC_PI_2 * DIMS[1] as f64, DIMS[1]);
    if phi_d < 0.0 {
        phi_d += PI;
    }
    let i_phi_d = n(phi_d / PI * DIMS[2] as f64, DIMS[2]);
    cell_index(i_theta_h, i_theta_d, i_phi_d)
}

fn f64_at(bytes: &[u8], offset: usize) -> f64 {
    let mut b = [0u8; 8];
    b.copy_from_slice(&bytes[offset..offset + 8]);
    f64::from_le_bytes(b)
}

/// Read a MERL table held in memory (see the module documentation).
pub fn parse(bytes: &[u8], file: &str, opts: &ReadOptions) -> Result<Dataset, DataError> {
    check_layout(bytes, file)?;
    let (rel, abs) = require_assumption(file, opts, "a MERL table")?;
    let Cells {
        valid,
        unmeasured,
        below,
    } = measured_cells(bytes, file)?;
    let keep = match opts.max_samples.unwrap_or(DEFAULT_MAX_SAMPLES) {
        0 => valid.len(),
        n => n.min(valid.len()),
    };
    let chosen = subsample(&valid, keep);
    let mut b = Builder::new(Kind::Brdf, file, opts);
    b.notices.push(Notice::from(format!(
        "{file}: MERL table: {} of {CELLS} ({unmeasured} unmeasured, {below} below the horizon at the cell centre); {} kept{}",
        count(valid.len(), "measured cell", "measured cells"),
        keep,
        if keep < valid.len() {
            " (deterministic subsample, --max-samples)"
        } else {
            ""
        }
    )));
    b.notices.push(Notice::from(format!(
        "{file}: MERL channels R, G, B at nominal wavelengths {} nm, {} nm, {} nm; cells read at their centres",
        NOMINAL_NM[0], NOMINAL_NM[1], NOMINAL_NM[2]
    )));
    for &idx in &chosen {
        push_cell(&mut b, bytes, idx as usize, rel, abs);
    }
    let mut meta = BTreeMap::new();
    meta.insert(
        "source_format".into(),
        "MERL binary (90 × 90 × 180 half/difference table; 'line' numbers are cell indices + 1)"
            .to_string(),
    );
    let material = Path::new(file)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut ds = b.finish(&material, meta)?;
    mark_assumed(&mut ds, rel, abs);
    Ok(ds)
}

/// Check the header's dimensions and the file's size, saying where a wrong-sized file
/// stops or what trails it.
fn check_layout(bytes: &[u8], file: &str) -> Result<(), DataError> {
    let ferr = |msg: String| DataError::File {
        file: file.into(),
        msg,
    };
    let Some(d) = dims(bytes) else {
        return Err(ferr(format!(
            "{}: too short for a MERL table, which starts with a 12-byte header (three little-endian int32 dimensions)",
            count(bytes.len(), "byte", "bytes")
        )));
    };
    if d != DIMS.map(|x| x as i32) {
        return Err(ferr(format!(
            "MERL header (bytes 0–11) gives dimensions {} × {} × {}; expected {} × {} × {} (θh × θd × φd)",
            d[0], d[1], d[2], DIMS[0], DIMS[1], DIMS[2]
        )));
    }
    if bytes.len() != FILE_BYTES {
        let msg = if bytes.len() < FILE_BYTES {
            let k = (bytes.len() - 12) / 8;
            format!(
                "truncated MERL table: {} bytes, expected {FILE_BYTES} (12-byte header + 3 × {CELLS} doubles); the data stop at byte offset {} in the {} block (cell {})",
                bytes.len(),
                bytes.len(),
                BLOCK[(k / CELLS).min(2)],
                k % CELLS
            )
        } else {
            format!(
                "{} bytes: {} more than a MERL table of {FILE_BYTES} bytes (trailing data from byte offset {FILE_BYTES})",
                bytes.len(),
                bytes.len() - FILE_BYTES
            )
        };
        return Err(ferr(msg));
    }
    Ok(())
}

/// The measured cells of a table, and how many of the others were not measured or lie
/// below the horizon.
struct Cells {
    /// Flat indices of the cells with all three channels ≥ 0 and both directions above the
    /// horizon, ascending.
    valid: Vec<u32>,
    unmeasured: usize,
    below: usize,
}

/// Find the measured cells (all three channels ≥ 0, both directions above the horizon at
/// the cell centre); a value that is not a number is an error naming its byte offset.
fn measured_cells(bytes: &[u8], file: &str) -> Result<Cells, DataError> {
    let (mut unmeasured, mut below) = (0usize, 0usize);
    let mut valid: Vec<u32> = Vec::new();
    for idx in 0..CELLS {
        let mut any_negative = false;
        for (c, block) in BLOCK.iter().enumerate() {
            let off = 12 + 8 * (c * CELLS + idx);
            let v = f64_at(bytes, off);
            if !v.is_finite() {
                return Err(DataError::File {
                    file: file.into(),
                    msg: format!(
                        "byte offset {off}: cell {idx} of the {block} block holds {v}, not a number"
                    ),
                });
            }
            any_negative |= v < 0.0;
        }
        if any_negative {
            unmeasured += 1;
            continue;
        }
        let (th, td, pd) = cell_angles(idx);
        if cell_directions(th, td, pd).is_none() {
            below += 1;
            continue;
        }
        valid.push(idx as u32);
    }
    Ok(Cells {
        valid,
        unmeasured,
        below,
    })
}

/// `keep` of the `valid` cells, ascending: all of them, or a uniform random subsample from
/// a fixed-seed stream (the same file always gives the same cells).
fn subsample(valid: &[u32], keep: usize) -> Vec<u32> {
    if keep == valid.len() {
        return valid.to_vec();
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(SUBSAMPLE_SEED);
    let mut picked: Vec<u32> = rand::seq::index::sample(&mut rng, valid.len(), keep)
        .into_iter()
        .map(|i| valid[i])
        .collect();
    picked.sort_unstable();
    picked
}

/// Push the R, G, B samples of cell `idx`, read at its centre, with the assumed
/// uncertainties; the row number is the cell index + 1.
fn push_cell(b: &mut Builder, bytes: &[u8], idx: usize, rel: f64, abs: f64) {
    let (th, td, pd) = cell_angles(idx);
    let Some((wi, wo)) = cell_directions(th, td, pd) else {
        return;
    };
    let (ti, pi) = super::alta::angles_deg(wi);
    let (to, po) = super::alta::angles_deg(wo);
    for c in 0..3 {
        let value = f64_at(bytes, 12 + 8 * (c * CELLS + idx)) * SCALE[c];
        b.push(
            idx + 1,
            RawRow {
                theta_i: ti,
                phi_i: pi,
                theta_o: to,
                phi_o: po,
                wavelength_nm: NOMINAL_NM[c],
                value,
                uncertainty: super::assumed_uncertainty(value, rel, abs),
            },
            None,
        );
    }
}

/// A MERL table of `f(θh, θd, φd) → [R, G, B]` (BRDF values, sr⁻¹) at every cell centre
/// whose directions are above the horizon; the other cells hold −1 (unmeasured). Values
/// are stored divided by [`SCALE`].
pub fn encode(mut f: impl FnMut(f64, f64, f64) -> [f64; 3]) -> Vec<u8> {
    let cells: Vec<Option<[f64; 3]>> = (0..CELLS)
        .map(|idx| {
            let (th, td, pd) = cell_angles(idx);
            cell_directions(th, td, pd).map(|_| f(th, td, pd))
        })
        .collect();
    serialise(&cells)
}

/// [`encode`] with `f` evaluated on every core (rayon): a full table is 1.46 M cells, and
/// a fitted model costs about a microsecond per cell and channel.
pub fn encode_par(f: impl Fn(f64, f64, f64) -> [f64; 3] + Sync) -> Vec<u8> {
    use rayon::prelude::*;
    let cells: Vec<Option<[f64; 3]>> = (0..CELLS)
        .into_par_iter()
        .map(|idx| {
            let (th, td, pd) = cell_angles(idx);
            cell_directions(th, td, pd).map(|_| f(th, td, pd))
        })
        .collect();
    serialise(&cells)
}

/// The file bytes of a table given per cell (`None`: unmeasured, stored as −1).
pub fn serialise(cells: &[Option<[f64; 3]>]) -> Vec<u8> {
    let mut out = Vec::with_capacity(FILE_BYTES);
    for d in DIMS {
        out.extend_from_slice(&(d as i32).to_le_bytes());
    }
    for c in 0..3 {
        for cell in cells {
            let v = cell.map_or(-1.0, |rgb| rgb[c] / SCALE[c]);
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out
}

/// Write [`encode`]`(f)` to `path`.
pub fn write(path: &Path, f: impl FnMut(f64, f64, f64) -> [f64; 3]) -> std::io::Result<()> {
    let mut w = std::io::BufWriter::new(std::fs::File::create(path)?);
    w.write_all(&encode(f))?;
    w.flush()
}
