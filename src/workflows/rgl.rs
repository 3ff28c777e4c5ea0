//! The RGL measured-material format (`.bsdf`; Dupuy & Jakob, "An Adaptive
//! Parameterization for Efficient Material Acquisition and Rendering", SIGGRAPH Asia
//! 2018), as Mitsuba 3's `measured` plugin and pbrt-v4's `measured` material read it
//! (docs/export.md). Written from the published description of the format and of the
//! readers' evaluation, not from their code.
//!
//! A file is a *tensor file*: the 12 bytes `tensor_file\0`, version 1.0, a field count,
//! then per field its name, rank, type, byte offset and shape, then the data. The fields
//! of a material (isotropic, RGB):
//!
//! | field | shape | meaning |
//! |---|---|---|
//! | `theta_i`, `phi_i` | [Nθ], [Nφ] | incidence nodes (radians; Nφ ≤ 2 means isotropic; an anisotropic file's φi nodes span 2π/R for a symmetry of order R) |
//! | `rgb` (or `spectra` + `wavelengths`) | [Nφ, Nθ, C, H, W] | the value tables |
//! | `vndf`, `luminance` | [Nφ, Nθ, H, W] | sample warps (VNDF, then luminance) |
//! | `ndf` | [h, w] | the NDF over u_m, `sigma` [h, w] its projected area over u_i |
//! | `jacobian` | [1] u8 | 1: values are divided by D/(4σ); 0: values are f·cos θo |
//! | `description` | [n] u8 | text |
//!
//! A reader maps a direction pair to the half vector m in "u space",
//! u_m = (√(2θm/π), (φm − φi + π)/2π) (φm alone, for an anisotropic file, after turning
//! both directions into the span of the φi nodes), inverts the VNDF warp to a point of the value
//! table's square, and interpolates the table there (bilinearly, and linearly between
//! incidence nodes). What bsdfit writes: a uniform VNDF, so the warp is the identity and
//! the value table is simply f·cos θo on a grid of u_m (dense near the half vector's
//! pole, where highlights live); `jacobian` = 0, so `ndf` and `sigma` are not used by
//! the evaluation, and they hold the fit's own microfacet distribution where it has an
//! isotropic GGX lobe ([`distribution`]: the tabulated D of `+ndf`, or GGX's, and its
//! projected area), uniform tables otherwise; and a `luminance` map proportional to
//! f·cos θo times the solid angle of each cell, which is what the readers sample
//! directions from: importance sampling by the tabulated BRDF itself.

use crate::bsdf::ndf::NdfTable;
use crate::bsdf::{GgxPlace, LobePart};
use crate::data::Kind;
use crate::inference::saved::SavedFit;
use anyhow::Result;
use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::PI;

/// Nodes of the value table along u_θm (0 … π/2 by √) and along φm − φi (−π … π); the
/// readers require a square table.
pub const THETA_M_NODES: usize = 128;
pub const PHI_M_NODES: usize = THETA_M_NODES;

/// Incidence nodes (degrees): every 1° to 88°, then 89.5° (a reader clamps beyond).
/// Between nodes a reader blends two tables at the same half vector, which smears a
/// highlight that moves with θi: 2° nodes left a median error of 1.2 % near a GGX peak
/// of α = 0.05, 1° nodes 0.36 % (docs/export.md).
pub fn theta_i_nodes() -> Vec<f64> {
    let mut v: Vec<f64> = (0..=88).map(|k| k as f64).collect();
    v.push(89.5);
    v
}

pub use crate::data::readers::rgl::{u_to_phi, u_to_theta};

/// The outgoing direction whose half vector with `wi` is the u-space point (ux, uy)
/// (φm relative to φi), or None below the horizon.
fn outgoing(wi: DVec3, phi_i: f64, ux: f64, uy: f64) -> Option<(DVec3, f64)> {
    let (theta_m, phi_m) = (u_to_theta(ux), u_to_phi(uy) + phi_i);
    let m = DVec3::new(
        theta_m.sin() * phi_m.cos(),
        theta_m.sin() * phi_m.sin(),
        theta_m.cos(),
    );
    let d = wi.dot(m);
    let wo = 2.0 * d * m - wi;
    (d > 0.0 && wo.z > 1e-9).then_some((wo, d))
}

/// What the format cannot hold, as an error naming the alternative.
fn check_representable(fit: &SavedFit) -> Result<()> {
    let m = &fit.model;
    anyhow::ensure!(
        m.kind == Kind::Brdf,
        "{} is a BTDF model: the RGL .bsdf format holds reflection only (isotropic BRDFs); use --format tabulated for a table of the BTDF",
        m.spec
    );
    anyhow::ensure!(
        m.axes.len() <= 1,
        "{} has parameters per measurement plane (anisotropic, planes {:?}°): the RGL .bsdf files bsdfit writes are isotropic; export one plane's fit (fit --per-axis, then --plane PHI), or use --format tabulated",
        m.spec,
        m.axes
    );
    Ok(())
}

/// The fit's microfacet distribution, for the file's `ndf` and `sigma` fields: that of its
/// highlight (`ggx`, `fa`'s lobe) or else of its coat's lobe; the tabulated D where the
/// lobe has one (`+ndf`), GGX's otherwise (the table at zero deviation, which is GGX
/// within its quadrature's 3e-4). None for a model without an isotropic GGX lobe.
pub fn distribution(fit: &SavedFit) -> Option<NdfTable> {
    let view = fit.model.scalars(&fit.flat, 0);
    let node = fit
        .model
        .nodes()
        .into_iter()
        .filter_map(|n| n.bsdf.ggx_lobe().map(|(place, _)| (n, place)))
        .min_by_key(|&(_, place)| place == GgxPlace::Coat)?
        .0;
    let params = node.bsdf.params();
    let alpha = params.iter().position(|p| p.lobe == LobePart::Width)?;
    // The NDF's knots (`ndf1`, `lobe.ndf1`, `ndf_c1` …), shared by the channels.
    let first = params.iter().position(|p| {
        p.knot
            && p.name
                .rsplit('.')
                .next()
                .is_some_and(|n| n.starts_with("ndf"))
    });
    let s = std::array::from_fn(|k| match first {
        Some(f) if k > 0 => view[node.offset + f + k - 1],
        _ => 0.0,
    });
    Some(NdfTable::new(view[node.offset + alpha], s))
}

/// The `ndf` field (D over u_m = (√(2θm/π), φm / 2π), `n` × `n`) and the `sigma` field
/// (the projected area σ(ωi) = ∫ (ωi·m)⁺ D dω_m = μi + C(μi) over u_i) of `table`; 2 × 2
/// tables of ones without one.
fn distribution_fields(table: Option<&NdfTable>, n: usize) -> [Field; 2] {
    let (ndf, sigma) = match table {
        Some(t) => {
            let theta = |x: usize| u_to_theta(x as f64 / (n - 1) as f64);
            let d: Vec<f32> = (0..n)
                .map(|x| t.d(DVec3::new(theta(x).sin(), 0.0, theta(x).cos())) as f32)
                .collect();
            let a: Vec<f32> = (0..n)
                .map(|x| {
                    let mu = theta(x).cos().max(0.0);
                    (mu + t.facing_away(mu)) as f32
                })
                .collect();
            // Isotropic: the same row at every azimuth (rows are u_φ, columns u_θ).
            let rows = |v: Vec<f32>| (vec![n as u64, n as u64], v.repeat(n));
            (rows(d), rows(a))
        }
        None => ((vec![2, 2], vec![1.0; 4]), (vec![2, 2], vec![1.0; 4])),
    };
    [
        Field {
            name: "ndf",
            shape: ndf.0,
            data: FieldData::F32(ndf.1),
        },
        Field {
            name: "sigma",
            shape: sigma.0,
            data: FieldData::F32(sigma.1),
        },
    ]
}

/// A tensor file's field.
struct Field {
    name: &'static str,
    shape: Vec<u64>,
    data: FieldData,
}

enum FieldData {
    F32(Vec<f32>),
    U8(Vec<u8>),
}

/// The bytes of a tensor file (little endian; data aligned to 8 bytes).
fn tensor_file(fields: &[Field]) -> Vec<u8> {
    let mut head = Vec::new();
    head.extend_from_slice(crate::data::readers::rgl::MAGIC);
    head.extend_from_slice(&[1, 0]);
    head.extend_from_slice(&(fields.len() as u32).to_le_bytes());
    let header_len: usize = head.len()
        + fields
            .iter()
            .map(|f| 2 + f.name.len() + 2 + 1 + 8 + 8 * f.shape.len())
            .sum::<usize>();
    let align = |x: usize| x.div_ceil(8) * 8;
    let mut offset = align(header_len);
    let mut body_offsets = Vec::new();
    for f in fields {
        head.extend_from_slice(&(f.name.len() as u16).to_le_bytes());
        head.extend_from_slice(f.name.as_bytes());
        head.extend_from_slice(&(f.shape.len() as u16).to_le_bytes());
        let (dtype, bytes) = match &f.data {
            FieldData::U8(v) => (1u8, v.len()),
            FieldData::F32(v) => (10u8, 4 * v.len()),
        };
        head.push(dtype);
        head.extend_from_slice(&(offset as u64).to_le_bytes());
        for s in &f.shape {
            head.extend_from_slice(&s.to_le_bytes());
        }
        body_offsets.push(offset);
        offset = align(offset + bytes);
    }
    let mut out = head;
    for (f, &at) in fields.iter().zip(&body_offsets) {
        out.resize(at, 0);
        match &f.data {
            FieldData::U8(v) => out.extend_from_slice(v),
            FieldData::F32(v) => v
                .iter()
                .for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
        }
    }
    out
}

/// Which channels of the fit become the file's channels: R, G, B (rgb), or every channel
/// at its wavelength (spectral).
pub enum Channels {
    Rgb([usize; 3]),
    Spectral,
}

/// An anisotropic material (`+aniso`): incidence azimuths φi from −180° to 0° by this
/// many degrees. Every anisotropic form of the catalogue is unchanged when both directions
/// turn by 180° about the normal (its D and Λ depend on the squares of the tangent-frame
/// components), so half the azimuths hold the material: the readers fold ωi into
/// y ≤ 0 (the format's reduction by 2, from the nodes' range of 180°).
pub const ANISO_PHI_I_STEP_DEG: f64 = 15.0;
/// An anisotropic material's value tables: 64 × 64 nodes, and incidence angles every 3°
/// (the file holds 13 azimuths × 31 angles of them: ~20 MB in RGB).
pub const ANISO_TABLE_NODES: usize = 64;
pub fn aniso_theta_i_nodes() -> Vec<f64> {
    let mut v: Vec<f64> = (0..=29).map(|k| 3.0 * k as f64).collect();
    v.push(89.5);
    v
}

/// The incidence nodes and table size of a fit's file.
pub struct Layout {
    /// Incidence azimuths (degrees): φi = 0 alone for an isotropic fit, −180° … 0° for an
    /// anisotropic one (`+aniso`).
    pub phis: Vec<f64>,
    /// Incidence angles (degrees).
    pub thetas: Vec<f64>,
    /// Nodes along each side of the value tables.
    pub nodes: usize,
}

pub fn layout(fit: &SavedFit) -> Layout {
    if fit.model.params.iter().any(|p| p.decl.needs_planes) {
        let steps = (180.0 / ANISO_PHI_I_STEP_DEG).round() as usize;
        Layout {
            phis: (0..=steps)
                .map(|k| -180.0 + k as f64 * ANISO_PHI_I_STEP_DEG)
                .collect(),
            thetas: aniso_theta_i_nodes(),
            nodes: ANISO_TABLE_NODES,
        }
    } else {
        Layout {
            phis: vec![0.0],
            thetas: theta_i_nodes(),
            nodes: THETA_M_NODES,
        }
    }
}

/// A `.bsdf` file of the fitted BRDF (see the module's documentation).
pub fn rgl_file(fit: &SavedFit, channels: Channels, description: &str) -> Result<Vec<u8>> {
    check_representable(fit)?;
    let m = &fit.model;
    let (groups, wavelengths) = channel_groups(fit, channels);
    let views: Vec<Vec<f64>> = groups.iter().map(|&g| m.scalars(&fit.flat, g)).collect();
    let Layout {
        phis,
        thetas,
        nodes: n,
    } = layout(fit);
    // One incidence node per task (azimuth-major): its value slice (C × H × W) and
    // luminance (H × W).
    let nodes: Vec<(f64, f64)> = phis
        .iter()
        .flat_map(|&p| thetas.iter().map(move |&t| (p, t)))
        .collect();
    let slices: Vec<(Vec<f32>, Vec<f32>)> = nodes
        .par_iter()
        .map(|&(phi, deg)| incidence_slice(fit, &views, phi, deg, n))
        .collect();
    let (w, h, nc) = (n, n, groups.len());
    let mut values = Vec::with_capacity(slices.len() * nc * h * w);
    let mut luminance = Vec::with_capacity(slices.len() * h * w);
    for (v, l) in &slices {
        values.extend_from_slice(v);
        luminance.extend_from_slice(l);
    }
    anyhow::ensure!(
        values.iter().any(|&v| v > 0.0),
        "{}: the fitted BRDF is zero everywhere; nothing to export",
        m.spec
    );
    let tables = Tables {
        phis: &phis,
        thetas: &thetas,
        nodes: n,
        channels: nc,
        values,
        luminance,
        wavelengths,
        distribution: distribution(fit),
    };
    Ok(tensor_file(&material_fields(description, tables)))
}

/// The fit's channels (scalar-view groups) that become the file's, and for a spectral
/// file their wavelengths (ascending).
fn channel_groups(fit: &SavedFit, channels: Channels) -> (Vec<usize>, Option<Vec<f64>>) {
    match channels {
        Channels::Rgb(rgb) => (rgb.to_vec(), None),
        Channels::Spectral => {
            let mut order: Vec<usize> = (0..fit.channels.len()).collect();
            order.sort_by(|&a, &b| fit.channels[a].total_cmp(&fit.channels[b]));
            let wl = order.iter().map(|&g| fit.channels[g]).collect();
            (order, Some(wl))
        }
    }
}

/// The value table (C × H × W, f·cos θo per channel of `views`, on `n` × `n` nodes) and
/// the luminance map (H × W) of the incidence node at azimuth `phi` and polar angle `deg`
/// (degrees). The half vector's azimuth in u space is absolute (an anisotropic file) or
/// relative to φi (an isotropic one, whose only node has φi = 0: the same).
fn incidence_slice(
    fit: &SavedFit,
    views: &[Vec<f64>],
    phi: f64,
    deg: f64,
    n: usize,
) -> (Vec<f32>, Vec<f32>) {
    let m = &fit.model;
    let (w, h, nc) = (n, n, views.len());
    let (ti, pi) = (deg.to_radians(), phi.to_radians());
    let wi = DVec3::new(ti.sin() * pi.cos(), ti.sin() * pi.sin(), ti.cos());
    let mut values = vec![0f32; nc * h * w];
    let mut lum = vec![0f32; h * w];
    for y in 0..h {
        for x in 0..w {
            let (ux, uy) = (x as f64 / (w - 1) as f64, y as f64 / (h - 1) as f64);
            let Some((wo, wi_m)) = outgoing(wi, 0.0, ux, uy) else {
                continue;
            };
            let mut l = 0.0;
            for c in 0..nc {
                let f = m.root.eval(&views[c], wi, wo) * wo.z;
                let f = if f.is_finite() { f.max(0.0) } else { 0.0 };
                values[(c * h + y) * w + x] = f as f32;
                l += f / nc as f64;
            }
            // Solid angle of ωo per unit u-area: 2π² u sin θm · 4 (ωi·m).
            let jac = 2.0 * PI * PI * ux * u_to_theta(ux).sin() * 4.0 * wi_m;
            lum[y * w + x] = (l * jac) as f32;
        }
    }
    // A positive floor: the luminance warp must reach every cell with a value.
    let peak = lum.iter().cloned().fold(0f32, f32::max);
    let floor = if peak > 0.0 { peak * 1e-4 } else { 1.0 };
    lum.iter_mut().for_each(|v| *v = v.max(floor));
    (values, lum)
}

/// The tables of a material file, every incidence node's one after the other
/// (azimuth-major).
struct Tables<'a> {
    /// Incidence azimuths (degrees): one (φi = 0) for an isotropic material.
    phis: &'a [f64],
    /// Incidence nodes (degrees).
    thetas: &'a [f64],
    /// Nodes along each side of the value tables.
    nodes: usize,
    /// C, the value table's channels.
    channels: usize,
    values: Vec<f32>,
    luminance: Vec<f32>,
    /// The channels' wavelengths for a spectral file; None for RGB.
    wavelengths: Option<Vec<f64>>,
    /// The fit's microfacet distribution ([`distribution`]).
    distribution: Option<NdfTable>,
}

/// The fields of an isotropic material file (see the module's documentation).
fn material_fields(description: &str, t: Tables) -> Vec<Field> {
    let n = t.thetas.len() as u64;
    let np = t.phis.len() as u64;
    let (hw, wu) = (t.nodes as u64, t.nodes as u64);
    // Not used by the evaluation when `jacobian` is 0: the fit's distribution, for readers
    // and tools that take the NDF from the file.
    let [ndf, sigma] = distribution_fields(t.distribution.as_ref(), t.nodes);
    let mut fields = vec![
        Field {
            name: "description",
            shape: vec![description.len() as u64],
            data: FieldData::U8(description.as_bytes().to_vec()),
        },
        Field {
            name: "jacobian",
            shape: vec![1],
            data: FieldData::U8(vec![0]),
        },
        Field {
            name: "theta_i",
            shape: vec![n],
            data: FieldData::F32(t.thetas.iter().map(|d| d.to_radians() as f32).collect()),
        },
        Field {
            name: "phi_i",
            shape: vec![np],
            data: FieldData::F32(t.phis.iter().map(|d| d.to_radians() as f32).collect()),
        },
        ndf,
        sigma,
        // Uniform: the warp from the value table's square to u_m is the identity (a
        // 2 × 2 table is enough; readers do not require the value table's size).
        Field {
            name: "vndf",
            shape: vec![np, n, 2, 2],
            data: FieldData::F32(vec![1.0; t.phis.len() * t.thetas.len() * 4]),
        },
        Field {
            name: "luminance",
            shape: vec![np, n, hw, wu],
            data: FieldData::F32(t.luminance),
        },
    ];
    let table_shape = vec![np, n, t.channels as u64, hw, wu];
    match t.wavelengths {
        None => fields.push(Field {
            name: "rgb",
            shape: table_shape,
            data: FieldData::F32(t.values),
        }),
        Some(wl) => {
            fields.push(Field {
                name: "wavelengths",
                shape: vec![wl.len() as u64],
                data: FieldData::F32(wl.iter().map(|&x| x as f32).collect()),
            });
            fields.push(Field {
                name: "spectra",
                shape: table_shape,
                data: FieldData::F32(t.values),
            });
        }
    }
    fields
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::Model;

    fn saved(spec: &str, set: &[(&str, f64)]) -> SavedFit {
        let model = Model::parse(spec, 1).unwrap();
        let mut flat = model.defaults();
        for (name, v) in set {
            flat[model.params.iter().find(|p| p.name == *name).unwrap().index] = *v;
        }
        SavedFit {
            std: vec![None; model.dim],
            correlation: vec![],
            channels: vec![550.0],
            material: String::new(),
            data: String::new(),
            warnings: vec![],
            model,
            flat,
        }
    }

    fn row(field: &Field, n: usize) -> Vec<f64> {
        let FieldData::F32(v) = &field.data else {
            panic!("{} is not f32", field.name)
        };
        assert_eq!(field.shape, vec![n as u64, n as u64], "{}", field.name);
        // Isotropic: every row (u_φ) the same.
        assert!(v.chunks(n).all(|r| r == &v[..n]), "{}", field.name);
        v[..n].iter().map(|&x| x as f64).collect()
    }

    /// The `ndf` and `sigma` fields hold the fit's distribution: GGX's D and projected
    /// area μ (1 + Λ(μ)) for an analytic lobe (formulas written here; within the table's
    /// 3e-4 and f32), a `+ndf` lobe's knots as ratios to GGX, ∫ D cos θm dω = 1 in both,
    /// the highlight's rather than a coat's, and 2 × 2 ones without a GGX lobe.
    #[test]
    fn the_distribution_fields_hold_the_fits_ndf() {
        let n = THETA_M_NODES;
        let theta = |x: usize| u_to_theta(x as f64 / (n - 1) as f64);
        let alpha = 0.3;
        let ggx = |t: f64| {
            let (c2, t2) = (t.cos().powi(2), t.tan().powi(2));
            alpha * alpha / (PI * c2 * c2 * (alpha * alpha + t2).powi(2))
        };
        // ∫ D cos θ dω = 2π ∫ D(θ) cos θ sin θ dθ, trapezoids on the field's nodes.
        let norm = |d: &[f64]| {
            (1..n)
                .map(|x| {
                    let g = |x: usize| d[x] * theta(x).cos() * theta(x).sin();
                    0.5 * (g(x) + g(x - 1)) * (theta(x) - theta(x - 1))
                })
                .sum::<f64>()
                * 2.0
                * PI
        };
        let fit = saved(
            "fa(lambert)+coat",
            &[("lobe.alpha", alpha), ("alpha_c", 0.05)],
        );
        let [ndf, sigma] = distribution_fields(distribution(&fit).as_ref(), n);
        let (d, a) = (row(&ndf, n), row(&sigma, n));
        for x in (0..n - 1).step_by(9) {
            let t = theta(x);
            let lambda = 0.5 * ((1.0 + (alpha * t.tan()).powi(2)).sqrt() - 1.0);
            let (want_d, want_a) = (ggx(t), t.cos() * (1.0 + lambda));
            assert!(
                (d[x] / want_d - 1.0).abs() < 4e-4,
                "D at {t}: {} vs {want_d}",
                d[x]
            );
            assert!(
                (a[x] / want_a - 1.0).abs() < 4e-4,
                "σ at {t}: {} vs {want_a}",
                a[x]
            );
        }
        assert!((norm(&d) - 1.0).abs() < 2e-3, "∫ D cos = {}", norm(&d));

        let knots = [("lobe.ndf5", 1.0), ("lobe.ndf9", -0.7), ("lobe.ndf12", 0.4)];
        let fit = saved(
            "fa(lambert)+ndf",
            &[&[("lobe.alpha", alpha)][..], &knots].concat(),
        );
        let [ndf, _] = distribution_fields(distribution(&fit).as_ref(), n);
        let d = row(&ndf, n);
        // At a knot's angle ln(D / D_GGX) is the knot's value plus one constant (−ln N):
        // compare two knots through the node nearest each (the field is on its own grid).
        let at = |k: usize| {
            let (c, _) = crate::bsdf::ndf::knot_angle(k);
            let t = c.acos();
            let x = (0..n)
                .min_by(|&a, &b| (theta(a) - t).abs().total_cmp(&(theta(b) - t).abs()))
                .unwrap();
            (d[x] / ggx(theta(x))).ln()
        };
        let (k5, k9) = (at(5), at(9));
        assert!(
            ((k5 - k9) - (1.0 - -0.7)).abs() < 0.05,
            "ln D/D_GGX at knots 5 and 9: {k5} {k9}"
        );
        assert!((norm(&d) - 1.0).abs() < 2e-3, "∫ D cos = {}", norm(&d));

        let fit = saved("lambert", &[]);
        assert!(distribution(&fit).is_none());
        let [ndf, sigma] = distribution_fields(None, n);
        for f in [ndf, sigma] {
            assert_eq!(f.shape, vec![2, 2]);
        }
    }
}
