//! RGL measured-material files (`.bsdf`; Dupuy & Jakob 2018, the format of
//! [`crate::workflows::rgl`]) read as data: the material is a function, not a set of
//! samples, so it is evaluated at the directions of a named geometry
//! ([`ReadOptions::sample_geometry`], default [`DEFAULT_GEOMETRY`]) and at the
//! channels' wavelengths, the way a renderer evaluates it: the half vector in u space,
//! the inverse of the file's VNDF warp, the value table interpolated there (and between
//! incidence angles and wavelengths), divided by D/(4σ) when the file says so. The files
//! carry no uncertainties: `--assume-uncertainty` is required, as for MERL tables.
//! Anisotropic materials (three or more incidence azimuths) are interpolated between
//! their azimuths too, and sampled by default on [`DEFAULT_ANISOTROPIC_GEOMETRY`], whose
//! incidence azimuths vary.

use super::tensor::TensorFile;
use super::{mark_assumed, require_assumption};
use crate::data::Notice;
use crate::data::{Builder, DataError, Dataset, Kind, RawRow, ReadOptions};
use glam::DVec3;
use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::path::Path;

/// Where a `.bsdf` file is sampled without `--sample-geometry`: θi, θo = 0…80° and
/// φo = 0…180° by 10° (the isotropic grid of `bsdfit models`).
pub const DEFAULT_GEOMETRY: &str = "grid:10";
/// Where an anisotropic `.bsdf` file is sampled without `--sample-geometry`: incidence
/// azimuths as well as outgoing ones vary.
pub const DEFAULT_ANISOTROPIC_GEOMETRY: &str = "azimuths";
/// RGB files: the wavelengths R, G and B stand for (as for MERL tables).
pub const NOMINAL_NM: [f64; 3] = [650.0, 550.0, 450.0];

pub use super::tensor::MAGIC;

pub fn looks_like(head: &[u8]) -> bool {
    head.starts_with(MAGIC)
}

fn bad(file: &str, msg: impl Into<String>) -> DataError {
    DataError::File {
        file: file.into(),
        msg: msg.into(),
    }
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
    /// An anisotropic material: the order R of its symmetry (its φi nodes span 2π/R);
    /// None for an isotropic one.
    reduction: Option<u32>,
    ndf: Table,
    sigma: Table,
    vndf: Table,
    values: Table,
    /// Wavelengths of the value table's channels (RGB files: 0, 1, 2 for R, G, B).
    wavelengths: Vec<f64>,
    jacobian: bool,
    /// The file's `description`, its first line, if any.
    description: Option<String>,
}

impl Material {
    fn from_file(tf: &TensorFile, file: &str) -> Result<Material, DataError> {
        let info = |name: &str| {
            tf.field(name).ok_or_else(|| {
                bad(
                    file,
                    format!("RGL .bsdf file without the field '{name}' (not a measured material?)"),
                )
            })
        };
        let values = |name: &str| info(name).map(|_| tf.values(name).expect("the field exists"));
        if let Some(d) = tf.field("description").filter(|d| !d.element.is_byte()) {
            return Err(bad(
                file,
                format!(
                    "field description: element type {} cannot hold text (uint8 or int8 can)",
                    d.element.name()
                ),
            ));
        }
        let theta_i = increasing(values("theta_i")?, "theta_i", file)?;
        let phi_i = increasing(values("phi_i")?, "phi_i", file)?;
        // Three or more incidence azimuths: an anisotropic material, whose nodes span
        // 2π/R for a symmetry of order R (the readers fold ωi into that span).
        let reduction = if phi_i.len() > 2 {
            let span = phi_i[phi_i.len() - 1] - phi_i[0];
            let r = (2.0 * PI / span).round();
            if !(r >= 1.0 && (r * span - 2.0 * PI).abs() < 1e-3 * 2.0 * PI) {
                return Err(bad(
                    file,
                    format!(
                        "field phi_i: an anisotropic material's incidence azimuths must span 2π/R for a whole R (360°, 180°, 90°…); these span {:.2}°",
                        span.to_degrees()
                    ),
                ));
            }
            Some(r as u32)
        } else {
            None
        };
        let spectral = tf.field("spectra").is_some() && tf.field("wavelengths").is_some();
        let (table_name, wavelengths) = if spectral {
            (
                "spectra",
                increasing(values("wavelengths")?, "wavelengths", file)?,
            )
        } else if tf.field("rgb").is_some() {
            ("rgb", vec![0.0, 1.0, 2.0])
        } else {
            return Err(bad(
                file,
                "RGL .bsdf file without an 'rgb' or 'spectra' table",
            ));
        };
        let (table, ndf, sigma, vndf) = (
            info(table_name)?,
            info("ndf")?,
            info("sigma")?,
            info("vndf")?,
        );
        let (np, nt) = (phi_i.len(), theta_i.len());
        let grid = |shape: &[usize], rank: usize| {
            shape.len() == rank && shape[rank - 2..].iter().all(|&s| s >= 2)
        };
        let per_incidence = |shape: &[usize]| shape[0] == np && shape[1] == nt;
        if !(grid(&table.shape, 5)
            && per_incidence(&table.shape)
            && table.shape[2] == wavelengths.len()
            && grid(&ndf.shape, 2)
            && grid(&sigma.shape, 2)
            && grid(&vndf.shape, 4)
            && per_incidence(&vndf.shape))
        {
            return Err(bad(
                file,
                format!(
                    "RGL .bsdf file with tables of inconsistent shapes ({table_name} {:?}, vndf {:?}, ndf {:?}, sigma {:?} for {np} incidence azimuth(s), {nt} incidence angle(s){})",
                    table.shape,
                    vndf.shape,
                    ndf.shape,
                    sigma.shape,
                    if spectral { format!(", {} wavelengths", wavelengths.len()) } else { String::new() }
                ),
            ));
        }
        let (table_shape, vndf_shape) = (table.shape.clone(), vndf.shape.clone());
        let table = values(table_name)?;
        let vndf = values("vndf")?;
        // An isotropic file has one incidence azimuth, or two holding the same tables;
        // the first is read. Two that differ describe an anisotropic material too coarsely
        // to interpolate (three or more are needed).
        if np == 2 {
            same_azimuth_slices(&phi_i, &[(table_name, &table), ("vndf", &vndf)], file)?;
        }
        // An isotropic file keeps its first azimuth's tables, an anisotropic one all.
        let kept = if reduction.is_some() { np } else { 1 };
        let first = |v: Vec<f64>| v[..v.len() / np * kept].to_vec();
        let phi_i = phi_i[..kept].to_vec();
        let jacobian = tf
            .values("jacobian")
            .is_some_and(|j| j.first().is_some_and(|&v| v != 0.0));
        Ok(Material {
            ndf: Table::new(values("ndf")?, ndf.shape[1], ndf.shape[0], vec![], false),
            sigma: Table::new(
                values("sigma")?,
                sigma.shape[1],
                sigma.shape[0],
                vec![],
                false,
            ),
            vndf: Table::new(
                first(vndf),
                vndf_shape[3],
                vndf_shape[2],
                vec![phi_i.clone(), theta_i.clone()],
                true,
            ),
            values: Table::new(
                first(table),
                table_shape[4],
                table_shape[3],
                vec![phi_i, theta_i.clone(), wavelengths.clone()],
                false,
            ),
            theta_i,
            reduction,
            wavelengths,
            jacobian,
            description: tf
                .text("description")
                .and_then(|d| {
                    d.lines()
                        .next()
                        .map(|l| l.trim().chars().take(80).collect())
                })
                .filter(|d: &String| !d.is_empty()),
        })
    }

    /// f (sr⁻¹) for (ωi, ωo) at channel parameter `lambda` (a wavelength, or 0/1/2).
    fn brdf(&self, wi: DVec3, wo: DVec3, lambda: f64) -> f64 {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return 0.0;
        }
        let (wi, wo) = match self.reduction {
            Some(r) if r >= 2 => fold(wi, wo, r),
            _ => (wi, wo),
        };
        let m = (wi + wo).normalize();
        let (theta_i, phi_i) = (wi.z.clamp(-1.0, 1.0).acos(), wi.y.atan2(wi.x));
        let (theta_m, phi_m) = (m.z.clamp(-1.0, 1.0).acos(), m.y.atan2(m.x));
        // An isotropic table is over the half vector's azimuth relative to ωi's, an
        // anisotropic one over its azimuth in the surface's frame.
        let relative = if self.reduction.is_some() { 0.0 } else { phi_i };
        let mut um = (theta_to_u(theta_m), phi_to_u(phi_m - relative));
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

/// Both directions turned by the material's symmetry (order 2: a half turn, order 4: a
/// quarter turn as well) so that ωi lies in the span of the φi nodes: y ≤ 0 (order 2),
/// x ≤ 0 and y ≤ 0 (order 4), as the renderers fold them.
fn fold(wi: DVec3, wo: DVec3, r: u32) -> (DVec3, DVec3) {
    // −sign(s) with sign(0) = +1.
    let flip = |s: f64| if s >= 0.0 { -1.0 } else { 1.0 };
    let sy = flip(wi.y);
    let sx = if r == 4 { flip(wi.x) } else { sy };
    let turn = |w: DVec3| DVec3::new(w.x * sx, w.y * sy, w.z);
    (turn(wi), turn(wo))
}

/// The nodes of a parameter (`theta_i`, `phi_i`, `wavelengths`): finite and strictly
/// increasing, as interpolation between them needs.
fn increasing(v: Vec<f64>, name: &str, file: &str) -> Result<Vec<f64>, DataError> {
    if v.is_empty() || v.iter().any(|x| !x.is_finite()) || v.windows(2).any(|w| w[1] <= w[0]) {
        return Err(bad(
            file,
            format!("field {name}: its values must be finite and increase ({v:?})"),
        ));
    }
    Ok(v)
}

/// With two incidence azimuths, each table's two halves (one per azimuth) must agree to
/// float32 rounding: otherwise the material depends on φi and is anisotropic.
fn same_azimuth_slices(
    phi_i: &[f64],
    tables: &[(&str, &[f64])],
    file: &str,
) -> Result<(), DataError> {
    for (name, t) in tables {
        let (a, b) = t.split_at(t.len() / 2);
        let scale = t.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let worst = a
            .iter()
            .zip(b)
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
        if worst > 1e-6 * scale {
            return Err(bad(
                file,
                format!(
                    "an anisotropic RGL material: its two incidence azimuths (φi = {:.1}° and {:.1}°) hold different {name} tables (largest difference {:.2e} of the table's maximum); bsdfit reads isotropic materials only",
                    phi_i[0].to_degrees(),
                    phi_i[1].to_degrees(),
                    worst / scale
                ),
            ));
        }
    }
    Ok(())
}

/// Read an RGL `.bsdf` file as a dataset: the material evaluated at the directions of
/// the sample geometry and at the channels (RGB: R, G, B at [`NOMINAL_NM`]; spectral:
/// `--wavelengths`, default 450, 550, 650 nm), with the assumed uncertainties.
pub fn parse(bytes: &[u8], file: &str, opts: &ReadOptions) -> Result<Dataset, DataError> {
    let (rel, abs) = require_assumption(file, opts, "an RGL .bsdf material")?;
    let tf = TensorFile::parse(bytes).map_err(|e| bad(file, format!("RGL .bsdf file: {e}")))?;
    let material = Material::from_file(&tf, file)?;
    let spectral = material.wavelengths.len() != 3 || material.wavelengths != [0.0, 1.0, 2.0];
    let (expr, rows) = sample_geometry(file, opts, material.reduction.is_some())?;
    let channels = channels(&material, spectral, file, opts)?;
    let mut b = Builder::new(Kind::Brdf, file, opts);
    b.notices.push(Notice::from(format!(
        "{file}: RGL measured material{} ({} incidence angles{}), sampled on geometry {expr} ({} directions){}",
        material
            .description
            .as_ref()
            .map_or(String::new(), |d| format!(" '{d}'")),
        material.theta_i.len(),
        material.reduction.map_or(String::new(), |r| format!(
            "; anisotropic: {} incidence azimuths, symmetric under turns of {}°",
            material.values.params[0].len(),
            360 / r
        )),
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
    )));
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
fn sample_geometry(
    file: &str,
    opts: &ReadOptions,
    anisotropic: bool,
) -> Result<(String, Vec<[f64; 4]>), DataError> {
    let default = if anisotropic {
        DEFAULT_ANISOTROPIC_GEOMETRY
    } else {
        DEFAULT_GEOMETRY
    };
    let expr = opts
        .sample_geometry
        .clone()
        .unwrap_or_else(|| default.to_string());
    let (kind, rows) = crate::data::geometries::geometry_expr(&expr)
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
    let mut clamped = 0usize;
    for s in &mut ds.samples {
        let lambda = channels
            .iter()
            .find(|c| c.0 == s.wavelength_nm)
            .map_or(s.wavelength_nm, |c| c.1);
        let mut value = material.brdf(s.wi(), s.wo(), lambda);
        if value < 0.0 && value.is_finite() {
            // RGB tables hold negative values where the measured spectrum lies outside the
            // colour gamut; the database's own RGB reader clamps them to zero, and so does
            // bsdfit (counted in a notice).
            value = 0.0;
            clamped += 1;
        }
        if !value.is_finite() {
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
    if clamped > 0 {
        ds.notices.push(Notice::from(format!(
            "{file}: {clamped} of {} sampled values were negative in the material's table (colours outside the gamut of an RGB file) and are read as 0",
            ds.samples.len()
        )));
    }
    Ok(())
}
