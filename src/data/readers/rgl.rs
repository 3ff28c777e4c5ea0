//! RGL measured-material files (`.bsdf`; Dupuy & Jakob 2018, the format of
//! [`crate::workflows::rgl`]) read as data: the material is a function, not a set of
//! samples, so it is evaluated at the directions of a named geometry
//! ([`ReadOptions::sample_geometry`], default [`DEFAULT_GEOMETRY`]) and at the
//! channels' wavelengths, the way a renderer evaluates it: the half vector in u space,
//! the inverse of the file's VNDF warp, the value table interpolated there (and between
//! incidence angles and wavelengths), divided by D/(4σ) when the file says so. The files
//! carry no uncertainties: `--assume-uncertainty` is required, as for MERL tables.
//! Isotropic materials only (an anisotropic file is refused with a message).

use super::{mark_assumed, require_assumption};
use crate::data::{Builder, DataError, Dataset, Kind, RawRow, ReadOptions};
use glam::DVec3;
use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::path::Path;

/// Where a `.bsdf` file is sampled without `--sample-geometry`: θi, θo = 0…80° and
/// φo = 0…180° by 10° (the isotropic grid of `bsdfit models`).
pub const DEFAULT_GEOMETRY: &str = "grid:10";
/// RGB files: the wavelengths R, G and B stand for (as for MERL tables).
pub const NOMINAL_NM: [f64; 3] = [650.0, 550.0, 450.0];

/// The tensor file's magic.
pub const MAGIC: &[u8; 12] = b"tensor_file\0";

pub fn looks_like(head: &[u8]) -> bool {
    head.starts_with(MAGIC)
}

/// One field: its shape and values (as f64).
struct Field {
    shape: Vec<usize>,
    values: Vec<f64>,
}

fn bad(file: &str, msg: impl Into<String>) -> DataError {
    DataError::File {
        file: file.into(),
        msg: msg.into(),
    }
}

/// The fields of a tensor file, by name (numbers as f64, bytes as 0–255).
fn fields(bytes: &[u8], file: &str) -> Result<BTreeMap<String, Field>, DataError> {
    let take = |at: usize, n: usize| -> Result<&[u8], DataError> {
        // Saturating: an offset or a size in a header may be anything up to 2⁶⁴ − 1.
        bytes.get(at..at.saturating_add(n)).ok_or_else(|| {
            bad(
                file,
                "RGL .bsdf file: truncated (a field runs past the end)",
            )
        })
    };
    if take(0, 12)? != MAGIC {
        return Err(bad(file, "not a tensor file (no 'tensor_file' header)"));
    }
    let version = take(12, 2)?;
    if version != [1, 0] {
        return Err(bad(
            file,
            format!(
                "tensor file version {}.{}, expected 1.0",
                version[0], version[1]
            ),
        ));
    }
    let n = u32::from_le_bytes(take(14, 4)?.try_into().expect("4 bytes"));
    let mut at = 18;
    let mut out = BTreeMap::new();
    for _ in 0..n {
        let len = u16::from_le_bytes(take(at, 2)?.try_into().expect("2 bytes")) as usize;
        let name = String::from_utf8_lossy(take(at + 2, len)?).into_owned();
        at += 2 + len;
        let ndim = u16::from_le_bytes(take(at, 2)?.try_into().expect("2 bytes")) as usize;
        let dtype = take(at + 2, 1)?[0];
        let offset = u64::from_le_bytes(take(at + 3, 8)?.try_into().expect("8 bytes")) as usize;
        at += 11;
        let mut shape = Vec::with_capacity(ndim);
        for _ in 0..ndim {
            shape.push(u64::from_le_bytes(take(at, 8)?.try_into().expect("8 bytes")) as usize);
            at += 8;
        }
        let count = shape
            .iter()
            .try_fold(1usize, |a, &s| a.checked_mul(s))
            .ok_or_else(|| bad(file, format!("field {name}: shape {shape:?} overflows")))?;
        let values: Vec<f64> = match dtype {
            1 => take(offset, count)?.iter().map(|&b| b as f64).collect(),
            10 => take(offset, count.saturating_mul(4))?
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")) as f64)
                .collect(),
            11 => take(offset, count.saturating_mul(8))?
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
                .collect(),
            t => {
                return Err(bad(
                    file,
                    format!(
                    "field {name}: element type {t} is not read (uint8, float32 and float64 are)"
                ),
                ))
            }
        };
        out.insert(name, Field { shape, values });
    }
    Ok(out)
}

/// A 2D table over [0, 1]², one slice per combination of parameter nodes, interpolated
/// bilinearly inside a slice and linearly between parameter nodes; with `sampling`, the
/// continuous (bilinear) sample warp of the table normalised per slice, and its inverse.
/// The construction follows the published description of the RGL readers' warps.
struct Table {
    w: usize,
    h: usize,
    /// Nodes of each parameter (first = outermost in memory).
    params: Vec<Vec<f64>>,
    data: Vec<f64>,
    /// Per slice: the CDF along x of every row (h × (w − 1)), and the marginal CDF over
    /// rows (h − 1).
    cond: Vec<f64>,
    marg: Vec<f64>,
}

impl Table {
    fn new(data: Vec<f64>, w: usize, h: usize, params: Vec<Vec<f64>>, sampling: bool) -> Table {
        let slices: usize = params.iter().map(Vec::len).product();
        let mut t = Table {
            w,
            h,
            params,
            data,
            cond: Vec::new(),
            marg: Vec::new(),
        };
        if sampling {
            let (sx, sy) = (0.5 / (w - 1) as f64, 0.5 / (h - 1) as f64);
            t.cond = vec![0.0; slices * h * (w - 1)];
            t.marg = vec![0.0; slices * (h - 1)];
            for s in 0..slices {
                let d = &mut t.data[s * w * h..(s + 1) * w * h];
                let cond = &mut t.cond[s * h * (w - 1)..(s + 1) * h * (w - 1)];
                let mut row_sum = vec![0.0; h];
                for y in 0..h {
                    let mut acc = 0.0;
                    for x in 0..w - 1 {
                        acc += sx * (d[y * w + x] + d[y * w + x + 1]);
                        cond[y * (w - 1) + x] = acc;
                    }
                    row_sum[y] = acc;
                }
                let marg = &mut t.marg[s * (h - 1)..(s + 1) * (h - 1)];
                let mut acc = 0.0;
                for y in 0..h - 1 {
                    acc += sy * (row_sum[y] + row_sum[y + 1]);
                    marg[y] = acc;
                }
                let norm = if acc > 0.0 { 1.0 / acc } else { 1.0 };
                cond.iter_mut().for_each(|v| *v *= norm);
                marg.iter_mut().for_each(|v| *v *= norm);
                d.iter_mut().for_each(|v| *v *= norm);
            }
        }
        t
    }

    /// The slices to blend for these parameter values, with their weights.
    fn slices(&self, p: &[f64]) -> Vec<(usize, f64)> {
        let mut out = vec![(0usize, 1.0)];
        for (dim, nodes) in self.params.iter().enumerate() {
            let stride: usize = self.params[dim + 1..].iter().map(Vec::len).product();
            if nodes.len() == 1 {
                continue;
            }
            // The last interval whose left node is below p (clamped), and the weight of
            // its right node.
            let i = nodes[..nodes.len() - 1]
                .iter()
                .rposition(|&v| v < p[dim])
                .unwrap_or(0);
            let w1 = ((p[dim] - nodes[i]) / (nodes[i + 1] - nodes[i])).clamp(0.0, 1.0);
            out = out
                .into_iter()
                .flat_map(|(s, w)| {
                    [
                        (s + i * stride, w * (1.0 - w1)),
                        (s + (i + 1) * stride, w * w1),
                    ]
                })
                .collect();
        }
        out
    }

    fn lookup(table: &[f64], per_slice: usize, slices: &[(usize, f64)], i: usize) -> f64 {
        slices
            .iter()
            .map(|&(s, w)| {
                if w == 0.0 {
                    0.0
                } else {
                    w * table[s * per_slice + i]
                }
            })
            .sum()
    }

    /// The cell of a position in [0, 1]² and the position within it.
    fn cell(&self, u: f64, v: f64) -> (usize, usize, f64, f64) {
        let (x, y) = (
            u.clamp(0.0, 1.0) * (self.w - 1) as f64,
            v.clamp(0.0, 1.0) * (self.h - 1) as f64,
        );
        let (cx, cy) = ((x as usize).min(self.w - 2), (y as usize).min(self.h - 2));
        (cx, cy, x - cx as f64, y - cy as f64)
    }

    /// Bilinear value at (u, v).
    fn eval(&self, u: f64, v: f64, p: &[f64]) -> f64 {
        let s = self.slices(p);
        let (cx, cy, fx, fy) = self.cell(u, v);
        let n = self.w * self.h;
        let at =
            |dx: usize, dy: usize| Self::lookup(&self.data, n, &s, (cy + dy) * self.w + cx + dx);
        let (v00, v10, v01, v11) = (at(0, 0), at(1, 0), at(0, 1), at(1, 1));
        lerp(lerp(v00, v10, fx), lerp(v01, v11, fx), fy)
    }

    /// The inverse of the sample warp: the point of [0, 1]² that the warp sends to (u, v).
    fn invert(&self, u: f64, v: f64, p: &[f64]) -> (f64, f64) {
        let s = self.slices(p);
        let (w, h) = (self.w, self.h);
        let (cx, cy, mut x, y) = self.cell(u, v);
        let n = w * h;
        let at = |dx: usize, dy: usize| Self::lookup(&self.data, n, &s, (cy + dy) * w + cx + dx);
        let (v00, v10, v01, v11) = (at(0, 0), at(1, 0), at(0, 1), at(1, 1));
        let (c0, c1) = (lerp(v00, v01, y), lerp(v10, v11, y));
        let (pw, ph) = (1.0 / (w - 1) as f64, 1.0 / (h - 1) as f64);
        // Along x: the integral of the bilinear density over the part of the cell.
        x = x * lerp(c0, c1, 0.5 * x) * pw;
        let nc = h * (w - 1);
        let cond = |row: usize, col: usize| Self::lookup(&self.cond, nc, &s, row * (w - 1) + col);
        if cx > 0 {
            x += lerp(cond(cy, cx - 1), cond(cy + 1, cx - 1), y);
        }
        let (r0, r1) = (cond(cy, w - 2), cond(cy + 1, w - 2));
        let row_total = lerp(r0, r1, y);
        if row_total > 0.0 {
            x /= row_total;
        }
        let mut yy = y * lerp(r0, r1, 0.5 * y) * ph;
        if cy > 0 {
            yy += Self::lookup(&self.marg, h - 1, &s, cy - 1);
        }
        (x, yy)
    }
}

fn lerp(a: f64, b: f64, t: f64) -> f64 {
    a + (b - a) * t
}

/// The format's unit square: θ (radians, 0…π/2) ↔ u = √(2θ/π), dense near the pole
/// where highlights are; φ (radians, −π…π) ↔ u = (φ + π)/2π. Writer and reader share them.
pub fn theta_to_u(theta: f64) -> f64 {
    (theta * (2.0 / PI)).max(0.0).sqrt()
}
pub fn phi_to_u(phi: f64) -> f64 {
    (phi + PI) / (2.0 * PI)
}
pub fn u_to_theta(u: f64) -> f64 {
    u * u * (PI / 2.0)
}
pub fn u_to_phi(u: f64) -> f64 {
    (2.0 * u - 1.0) * PI
}

/// A measured material, ready to evaluate.
struct Material {
    theta_i: Vec<f64>,
    ndf: Table,
    sigma: Table,
    vndf: Table,
    values: Table,
    /// Wavelengths of the value table's channels (RGB files: 0, 1, 2 for R, G, B).
    wavelengths: Vec<f64>,
    jacobian: bool,
}

impl Material {
    fn from_fields(f: BTreeMap<String, Field>, file: &str) -> Result<Material, DataError> {
        let get = |name: &str| {
            f.get(name).ok_or_else(|| {
                bad(
                    file,
                    format!("RGL .bsdf file without the field '{name}' (not a measured material?)"),
                )
            })
        };
        let theta_i = get("theta_i")?.values.clone();
        let phi_i = get("phi_i")?.values.clone();
        if phi_i.len() > 2 {
            return Err(bad(
                file,
                format!(
                    "an anisotropic RGL material ({} incidence azimuths): bsdfit reads isotropic ones only",
                    phi_i.len()
                ),
            ));
        }
        let phi_i = vec![phi_i.first().copied().unwrap_or(0.0)];
        let (table, wavelengths) = match (f.get("rgb"), f.get("spectra"), f.get("wavelengths")) {
            (_, Some(s), Some(w)) => (s, w.values.clone()),
            (Some(r), _, _) => (r, vec![0.0, 1.0, 2.0]),
            _ => {
                return Err(bad(
                    file,
                    "RGL .bsdf file without an 'rgb' or 'spectra' table",
                ))
            }
        };
        let shape_ok =
            |fd: &Field, rank: usize| fd.shape.len() == rank && fd.shape.iter().all(|&s| s >= 1);
        let (ndf, sigma, vndf) = (get("ndf")?, get("sigma")?, get("vndf")?);
        let nt = theta_i.len();
        let sliced = |fd: &Field| fd.shape[1] == nt && fd.shape[2] >= 2 && fd.shape[3] >= 2;
        if !(shape_ok(table, 5)
            && table.shape[1] == nt
            && table.shape[2] == wavelengths.len()
            && table.shape[3] >= 2
            && table.shape[4] >= 2
            && shape_ok(ndf, 2)
            && shape_ok(sigma, 2)
            && shape_ok(vndf, 4)
            && sliced(vndf)
            && ndf.shape.iter().all(|&s| s >= 2)
            && sigma.shape.iter().all(|&s| s >= 2))
        {
            return Err(bad(
                file,
                "RGL .bsdf file with tables of inconsistent shapes",
            ));
        }
        // Keep the first azimuth's slices only (an isotropic file has one or two equal).
        let first = |fd: &Field, per: usize| fd.values[..per].to_vec();
        let per_values = nt * table.shape[2] * table.shape[3] * table.shape[4];
        let per_vndf = nt * vndf.shape[2] * vndf.shape[3];
        let jacobian = f
            .get("jacobian")
            .is_some_and(|j| j.values.first() == Some(&1.0));
        Ok(Material {
            ndf: Table::new(
                ndf.values.clone(),
                ndf.shape[1],
                ndf.shape[0],
                vec![],
                false,
            ),
            sigma: Table::new(
                sigma.values.clone(),
                sigma.shape[1],
                sigma.shape[0],
                vec![],
                false,
            ),
            vndf: Table::new(
                first(vndf, per_vndf),
                vndf.shape[3],
                vndf.shape[2],
                vec![phi_i.clone(), theta_i.clone()],
                true,
            ),
            values: Table::new(
                first(table, per_values),
                table.shape[4],
                table.shape[3],
                vec![phi_i.clone(), theta_i.clone(), wavelengths.clone()],
                false,
            ),
            theta_i,
            wavelengths,
            jacobian,
        })
    }

    /// f (sr⁻¹) for (ωi, ωo) at channel parameter `lambda` (a wavelength, or 0/1/2).
    fn brdf(&self, wi: DVec3, wo: DVec3, lambda: f64) -> f64 {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return 0.0;
        }
        let m = (wi + wo).normalize();
        let (theta_i, phi_i) = (wi.z.clamp(-1.0, 1.0).acos(), wi.y.atan2(wi.x));
        let (theta_m, phi_m) = (m.z.clamp(-1.0, 1.0).acos(), m.y.atan2(m.x));
        let mut um = (theta_to_u(theta_m), phi_to_u(phi_m - phi_i));
        um.1 -= um.1.floor();
        let params = [phi_i, theta_i];
        let (sx, sy) = self.vndf.invert(um.0, um.1, &params);
        let mut v = self.values.eval(sx, sy, &[phi_i, theta_i, lambda]);
        if self.jacobian {
            let ui = (theta_to_u(theta_i), phi_to_u(phi_i));
            let sigma = self.sigma.eval(ui.0, ui.1, &[]);
            if sigma <= 0.0 {
                return 0.0;
            }
            v *= self.ndf.eval(um.0, um.1, &[]) / (4.0 * sigma);
        }
        // The table holds f·cos θo.
        v / wo.z
    }
}

/// Read an RGL `.bsdf` file as a dataset: the material evaluated at the directions of
/// the sample geometry and at the channels (RGB: R, G, B at [`NOMINAL_NM`]; spectral:
/// `--wavelengths`, default 450, 550, 650 nm), with the assumed uncertainties.
pub fn parse(bytes: &[u8], file: &str, opts: &ReadOptions) -> Result<Dataset, DataError> {
    let (rel, abs) = require_assumption(file, opts, "an RGL .bsdf material")?;
    let material = Material::from_fields(fields(bytes, file)?, file)?;
    let spectral = material.wavelengths.len() != 3 || material.wavelengths != [0.0, 1.0, 2.0];
    let (expr, rows) = sample_geometry(file, opts)?;
    let channels = channels(&material, spectral, file, opts)?;
    let mut b = Builder::new(Kind::Brdf, file, opts);
    b.notices.push(format!(
        "{file}: RGL measured material ({} incidence angles), sampled on geometry {expr} ({} directions){}",
        material.theta_i.len(),
        rows.len(),
        if spectral {
            format!(
                " at {} nm (interpolated in the file's {} wavelengths)",
                channels
                    .iter()
                    .map(|c| c.0.to_string())
                    .collect::<Vec<_>>()
                    .join(", "),
                material.wavelengths.len()
            )
        } else {
            format!(
                "; channels R, G, B at nominal wavelengths {} nm, {} nm, {} nm",
                NOMINAL_NM[0], NOMINAL_NM[1], NOMINAL_NM[2]
            )
        }
    ));
    // Rows first (validated and normalised as any file's), then each sample's value from
    // its own stored directions: normalisation may re-express an azimuth (at θ = 0).
    for (k, r) in rows.iter().enumerate() {
        for &(nm, _) in &channels {
            b.push(
                k + 1,
                RawRow {
                    theta_i: r[0],
                    phi_i: r[1],
                    theta_o: r[2],
                    phi_o: r[3],
                    wavelength_nm: nm,
                    value: 1.0,
                    uncertainty: 1.0,
                },
                None,
            );
        }
    }
    let mut meta = BTreeMap::new();
    meta.insert(
        "source_format".into(),
        format!("RGL .bsdf measured material sampled on geometry {expr} ('line' numbers are direction indices + 1)"),
    );
    let name = Path::new(file)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut ds = b.finish(&name, meta)?;
    evaluate(&mut ds, &material, &channels, file, (rel, abs))?;
    mark_assumed(&mut ds, rel, abs);
    Ok(ds)
}

/// The sample geometry (`--sample-geometry`, else [`DEFAULT_GEOMETRY`]): its expression
/// and its (θi, φi, θo, φo) rows in degrees. It must be a BRDF geometry.
fn sample_geometry(file: &str, opts: &ReadOptions) -> Result<(String, Vec<[f64; 4]>), DataError> {
    let expr = opts
        .sample_geometry
        .clone()
        .unwrap_or_else(|| DEFAULT_GEOMETRY.to_string());
    let (kind, rows) = crate::workflows::synth::geometry_expr(&expr)
        .map_err(|e| bad(file, format!("--sample-geometry: {e}")))?;
    if kind != Kind::Brdf {
        return Err(bad(
            file,
            format!("--sample-geometry {expr} is a {kind} geometry; an RGL material is a BRDF"),
        ));
    }
    Ok((expr, rows))
}

/// The channels as (wavelength written, channel parameter of the value table): R, G, B
/// at [`NOMINAL_NM`] for an RGB file; for a spectral one the `--wavelengths` (default
/// 450, 550, 650 nm), each within the file's range.
fn channels(
    material: &Material,
    spectral: bool,
    file: &str,
    opts: &ReadOptions,
) -> Result<Vec<(f64, f64)>, DataError> {
    if !spectral {
        return Ok(NOMINAL_NM
            .iter()
            .enumerate()
            .map(|(c, &w)| (w, c as f64))
            .collect());
    }
    let lo = material
        .wavelengths
        .iter()
        .cloned()
        .fold(f64::INFINITY, f64::min);
    let hi = material
        .wavelengths
        .iter()
        .cloned()
        .fold(f64::NEG_INFINITY, f64::max);
    let wanted = opts
        .wavelengths
        .clone()
        .unwrap_or(vec![450.0, 550.0, 650.0]);
    for &w in &wanted {
        if !(lo - 1e-9..=hi + 1e-9).contains(&w) {
            return Err(bad(
                file,
                format!("--wavelengths: {w} nm is outside the material's {lo}–{hi} nm"),
            ));
        }
    }
    Ok(wanted.iter().map(|&w| (w, w)).collect())
}

/// Give each sample the material's value at its own (stored) directions and channel, and
/// the assumed uncertainty `(rel, abs)`; a value that is not a finite BRDF is an error
/// naming the direction.
fn evaluate(
    ds: &mut Dataset,
    material: &Material,
    channels: &[(f64, f64)],
    file: &str,
    (rel, abs): (f64, f64),
) -> Result<(), DataError> {
    for s in &mut ds.samples {
        let lambda = channels
            .iter()
            .find(|c| c.0 == s.wavelength_nm)
            .map_or(s.wavelength_nm, |c| c.1);
        let value = material.brdf(s.wi(), s.wo(), lambda);
        if !value.is_finite() || value < 0.0 {
            return Err(DataError::Line {
                file: file.into(),
                line: s.line as usize,
                msg: format!(
                    "the material gives {value} at θi = {:.2}°, θo = {:.2}°, φo − φi = {:.2}° (a damaged file?)",
                    s.theta_i.to_degrees(),
                    s.theta_o.to_degrees(),
                    (s.phi_o - s.phi_i).to_degrees()
                ),
            });
        }
        s.value = value;
        s.uncertainty = super::assumed_uncertainty(value, rel, abs);
    }
    Ok(())
}
