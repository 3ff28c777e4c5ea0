//! RGL `.bsdf` materials read from files written here, from the format's definition, never
//! by bsdfit's writer: a tensor file (`tensor_file\0`, version 1.0, then per field its name,
//! rank, element type, offset and shape; data little-endian, row-major) holding the fields
//! the RGL database's materials hold. The expected values are closed forms of the tables
//! written, computed here from the definition of the renderers' evaluation:
//!
//! f(ωi, ωo)·cos θo = T(W⁻¹(u_m), θi, λ) · [D(u_m) / (4 σ(u_i)) when `jacobian` ≠ 0],
//! with u = (√(2θ/π), (φ + π)/2π), the half vector's φ taken relative to φi, W the bilinear
//! sample warp of the `vndf` table and T the value table (`rgb`: R, G, B; or `spectra`).
//!
//! Tables linear along the first u coordinate make every step exact: the bilinear
//! interpolant of a linear function is that function, and the warp of a density a + b·x
//! is its CDF, (a·x + b·x²/2) / (a + b/2).

use bsdfit::data::readers::tensor::{ElementType, TensorFile};
use bsdfit::data::readers::{self};
use bsdfit::data::{Dataset, ReadOptions};
use std::f64::consts::PI;
use std::path::Path;

/// One field to write: its element type, shape and values (converted to the type).
struct Field {
    name: &'static str,
    element: ElementType,
    shape: Vec<usize>,
    values: Vec<f64>,
}

fn field(name: &'static str, element: ElementType, shape: &[usize], values: Vec<f64>) -> Field {
    assert_eq!(shape.iter().product::<usize>(), values.len(), "{name}");
    Field {
        name,
        element,
        shape: shape.to_vec(),
        values,
    }
}

/// IEEE 754 half precision of a value that it represents exactly (the tests use small
/// integers and simple fractions): sign, 5-bit exponent biased by 15, 10-bit fraction.
fn f16_bits(v: f64) -> u16 {
    if v == 0.0 {
        return 0;
    }
    let sign = if v < 0.0 { 0x8000 } else { 0 };
    let a = v.abs();
    let e = a.log2().floor() as i32;
    let frac = ((a / 2f64.powi(e) - 1.0) * 1024.0).round() as u16;
    assert!((-14..=15).contains(&e), "{v} is not a normal half");
    assert_eq!(
        (1.0 + frac as f64 / 1024.0) * 2f64.powi(e),
        a,
        "{v} is not exact in half precision"
    );
    sign | (((e + 15) as u16) << 10) | frac
}

/// The little-endian bytes of one element.
fn element_bytes(t: ElementType, v: f64) -> Vec<u8> {
    match t {
        ElementType::U8 => vec![v as u8],
        ElementType::I8 => (v as i8).to_le_bytes().to_vec(),
        ElementType::U16 => (v as u16).to_le_bytes().to_vec(),
        ElementType::I16 => (v as i16).to_le_bytes().to_vec(),
        ElementType::U32 => (v as u32).to_le_bytes().to_vec(),
        ElementType::I32 => (v as i32).to_le_bytes().to_vec(),
        ElementType::U64 => (v as u64).to_le_bytes().to_vec(),
        ElementType::I64 => (v as i64).to_le_bytes().to_vec(),
        ElementType::F16 => f16_bits(v).to_le_bytes().to_vec(),
        ElementType::F32 => (v as f32).to_le_bytes().to_vec(),
        ElementType::F64 => v.to_le_bytes().to_vec(),
    }
}

/// Type codes as the format numbers them (uint8 = 1 … float64 = 11), written out here
/// rather than taken from the library.
fn code(t: ElementType) -> u8 {
    match t {
        ElementType::U8 => 1,
        ElementType::I8 => 2,
        ElementType::U16 => 3,
        ElementType::I16 => 4,
        ElementType::U32 => 5,
        ElementType::I32 => 6,
        ElementType::U64 => 7,
        ElementType::I64 => 8,
        ElementType::F16 => 9,
        ElementType::F32 => 10,
        ElementType::F64 => 11,
    }
}

/// A tensor file of `fields`, in the order given, each field's data aligned to 8 bytes
/// after the header (as Mitsuba's and the RGL tools' writers align them).
fn tensor_file(fields: &[Field]) -> Vec<u8> {
    let mut header = b"tensor_file\0".to_vec();
    header.extend_from_slice(&[1, 0]);
    header.extend_from_slice(&(fields.len() as u32).to_le_bytes());
    let header_len = header.len()
        + fields
            .iter()
            .map(|f| 2 + f.name.len() + 2 + 1 + 8 + 8 * f.shape.len())
            .sum::<usize>();
    let mut offset = header_len.div_ceil(8) * 8;
    let mut body = Vec::new();
    for f in fields {
        header.extend_from_slice(&(f.name.len() as u16).to_le_bytes());
        header.extend_from_slice(f.name.as_bytes());
        header.extend_from_slice(&(f.shape.len() as u16).to_le_bytes());
        header.push(code(f.element));
        header.extend_from_slice(&(offset as u64).to_le_bytes());
        for &s in &f.shape {
            header.extend_from_slice(&(s as u64).to_le_bytes());
        }
        let data: Vec<u8> = f
            .values
            .iter()
            .flat_map(|&v| element_bytes(f.element, v))
            .collect();
        body.push((offset, data));
        offset = (offset + body.last().unwrap().1.len()).div_ceil(8) * 8;
    }
    let mut bytes = header;
    for (at, data) in body {
        bytes.resize(at, 0);
        bytes.extend_from_slice(&data);
    }
    bytes
}

fn read(path: &Path, geometry: &str) -> Result<Dataset, bsdfit::data::DataError> {
    readers::load(
        path,
        &ReadOptions {
            assume_uncertainty: Some((0.01, 1e-6)),
            sample_geometry: Some(geometry.into()),
            ..Default::default()
        },
    )
}

/// Unit direction of polar angle θ and azimuth φ (radians).
fn dir(theta: f64, phi: f64) -> [f64; 3] {
    [
        theta.sin() * phi.cos(),
        theta.sin() * phi.sin(),
        theta.cos(),
    ]
}

/// u_θ of the format: √(2θ/π).
fn u_theta(theta: f64) -> f64 {
    (2.0 * theta / PI).sqrt()
}

/// (θi, u_θ of ωi, u_θ of the half vector, cos θo) of a sample.
fn sample_angles(s: &bsdfit::data::Sample) -> (f64, f64, f64, f64) {
    let (wi, wo) = (dir(s.theta_i, s.phi_i), dir(s.theta_o, s.phi_o));
    let h: Vec<f64> = (0..3).map(|k| wi[k] + wo[k]).collect();
    let len = (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt();
    let theta_m = (h[2] / len).clamp(-1.0, 1.0).acos();
    let theta_i = wi[2].clamp(-1.0, 1.0).acos();
    (theta_i, u_theta(theta_i), u_theta(theta_m), wo[2])
}

/// The sample's value is `want` to `tol` relative, or the failure names the sample.
fn assert_read_as(s: &bsdfit::data::Sample, want: f64, tol: f64) {
    assert!(
        (s.value - want).abs() <= tol * want.abs(),
        "{} nm, θi {:.1}° φi {:.1}° θo {:.1}° φo {:.1}°: {} vs {want}",
        s.wavelength_nm,
        s.theta_i.to_degrees(),
        s.phi_i.to_degrees(),
        s.theta_o.to_degrees(),
        s.phi_o.to_degrees(),
        s.value
    );
}

/// R, G, B: the nominal wavelengths bsdfit gives an RGB file's channels, and the
/// coefficients of each channel's table (distinct, so that a swap shows).
const RGB_NM: [f64; 3] = [650.0, 550.0, 450.0];

#[test]
fn every_element_type_reads_to_the_same_material() {
    // Constant tables: with a uniform VNDF the value is c_k · D/(4σ) / cos θo at every
    // direction. Every numeric field is stored in the type under test; the constants
    // fit all of them (int8 included).
    let dir = tempfile::tempdir().unwrap();
    let c = [3.0, 5.0, 7.0];
    let (n, nt) = (5, 2);
    for t in ElementType::ALL {
        let fields = vec![
            field(
                "description",
                ElementType::U8,
                &[4],
                b"test".map(f64::from).to_vec(),
            ),
            field("jacobian", t, &[1], vec![1.0]),
            field("theta_i", t, &[nt], vec![0.0, 1.0]),
            field("phi_i", t, &[1], vec![0.0]),
            field("ndf", t, &[n, n], vec![6.0; n * n]),
            field("sigma", t, &[n, n], vec![3.0; n * n]),
            field("vndf", t, &[1, nt, n, n], vec![2.0; nt * n * n]),
            field("luminance", t, &[1, nt, n, n], vec![1.0; nt * n * n]),
            field(
                "rgb",
                t,
                &[1, nt, 3, n, n],
                (0..nt * 3 * n * n).map(|i| c[(i / (n * n)) % 3]).collect(),
            ),
        ];
        let path = dir.path().join(format!("{}.bsdf", t.name()));
        std::fs::write(&path, tensor_file(&fields)).unwrap();
        let data = read(&path, "grid:10").unwrap_or_else(|e| panic!("{}: {e}", t.name()));
        assert_eq!(data.channels, vec![450.0, 550.0, 650.0]);
        for s in &data.samples {
            let k = RGB_NM.iter().position(|&w| w == s.wavelength_nm).unwrap();
            let (_, _, _, cos_o) = sample_angles(s);
            let want = c[k] * 6.0 / (4.0 * 3.0) / cos_o;
            assert!(
                (s.value - want).abs() <= 1e-12 * want,
                "{}: {} nm at θo = {:.1}°: {} vs {want}",
                t.name(),
                s.wavelength_nm,
                s.theta_o.to_degrees(),
                s.value
            );
        }
    }
}

#[test]
fn tensor_elements_decode_by_type_signed_fractional_and_wide() {
    let cases: [(ElementType, Vec<f64>); 11] = [
        (ElementType::U8, vec![0.0, 1.0, 255.0]),
        (ElementType::I8, vec![-128.0, -1.0, 127.0]),
        (ElementType::U16, vec![0.0, 300.0, 65535.0]),
        (ElementType::I16, vec![-32768.0, -2.0, 32767.0]),
        (ElementType::U32, vec![0.0, 70_000.0, 4_294_967_295.0]),
        (
            ElementType::I32,
            vec![-2_147_483_648.0, -3.0, 2_147_483_647.0],
        ),
        (ElementType::U64, vec![0.0, 2f64.powi(40), 2f64.powi(53)]),
        (
            ElementType::I64,
            vec![-(2f64.powi(53)), -4.0, 2f64.powi(45)],
        ),
        (ElementType::F16, vec![-1.5, 0.0999755859375, 65504.0]),
        (
            ElementType::F32,
            vec![-1.5, 0.1f32 as f64, 3.0e38f32 as f64],
        ),
        (ElementType::F64, vec![-1.5, 0.1, 1e300]),
    ];
    let fields: Vec<Field> = cases
        .iter()
        .enumerate()
        .map(|(k, (t, v))| {
            field(
                ["a", "b", "c", "d", "e", "f", "g", "h", "i", "j", "k"][k],
                *t,
                &[3],
                v.clone(),
            )
        })
        .collect();
    let bytes = tensor_file(&fields);
    let tf = TensorFile::parse(&bytes).unwrap();
    for f in &fields {
        assert_eq!(tf.field(f.name).unwrap().element, f.element);
        assert_eq!(tf.values(f.name).unwrap(), f.values, "{}", f.element.name());
    }
}

/// The fields of a database file, in their order and with their element types: text as
/// uint8, a uint32 version, the `jacobian` flag as uint8, every table float32.
/// `vndf_density(x)`, `value(x, θi, k)`, `ndf(x)`, `sigma(x)` give the tables along
/// u_θ; everything is constant along u_φ.
fn database_layout(
    nt: usize,
    n: usize,
    vndf_density: impl Fn(f64) -> f64,
    value: impl Fn(f64, f64, usize) -> f64,
    ndf: impl Fn(f64) -> f64,
    sigma: impl Fn(f64) -> f64,
) -> Vec<Field> {
    database_layout_2d(
        nt,
        n,
        |x, _| vndf_density(x),
        |x, _, ti, k| value(x, ti, k),
        |x, _| ndf(x),
        |x, _| sigma(x),
    )
}

/// A `[n × n]` table over (x, y) = (u_θ, u_φ): rows along u_φ, columns along u_θ.
fn grid(n: usize, f: impl Fn(f64, f64) -> f64) -> Vec<f64> {
    let at = |j: usize| j as f64 / (n - 1) as f64;
    (0..n)
        .flat_map(|r| (0..n).map(move |c| (at(c), at(r))))
        .map(|(x, y)| f(x, y))
        .collect()
}

/// [`database_layout`] with tables over both coordinates: `vndf_density(x, y)`,
/// `value(x, y, θi, k)`, `ndf(x, y)`, `sigma(x, y)`.
fn database_layout_2d(
    nt: usize,
    n: usize,
    vndf_density: impl Fn(f64, f64) -> f64,
    value: impl Fn(f64, f64, f64, usize) -> f64,
    ndf: impl Fn(f64, f64) -> f64,
    sigma: impl Fn(f64, f64) -> f64,
) -> Vec<Field> {
    let theta_i: Vec<f64> = (0..nt).map(|j| 1.5 * j as f64 / (nt - 1) as f64).collect();
    let mut rgb = Vec::new();
    for &ti in &theta_i {
        for k in 0..3 {
            rgb.extend(grid(n, |x, y| value(x, y, ti, k)));
        }
    }
    let vndf: Vec<f64> = (0..nt).flat_map(|_| grid(n, &vndf_density)).collect();
    use ElementType::{F32, U32, U8};
    vec![
        field(
            "description",
            U8,
            &[30],
            b"test material, database layout".map(f64::from).to_vec(),
        ),
        field("version", U32, &[2], vec![1.0, 0.0]),
        field("jacobian", U8, &[1], vec![1.0]),
        field("theta_i", F32, &[nt], theta_i),
        field("phi_i", F32, &[1], vec![0.0]),
        field("ndf", F32, &[n, n], grid(n, ndf)),
        field("sigma", F32, &[n, n], grid(n, sigma)),
        field("vndf", F32, &[1, nt, n, n], vndf.clone()),
        field("luminance", F32, &[1, nt, n, n], vndf),
        field("rgb", F32, &[1, nt, 3, n, n], rgb),
    ]
}

#[test]
fn a_file_laid_out_as_the_database_reads_to_its_closed_form() {
    // VNDF density 1 + 3x (warp = its CDF); value (a_k + b_k θi)(1 + 2x); D = 2 + x;
    // σ = 1 + x/2.
    let (a, b) = ([0.30, 0.20, 0.10], [0.05, -0.04, 0.02]);
    let cdf = |x: f64| (x + 1.5 * x * x) / 2.5;
    let fields = database_layout(
        7,
        17,
        |x| 1.0 + 3.0 * x,
        |x, ti, k| (a[k] + b[k] * ti) * (1.0 + 2.0 * x),
        |x| 2.0 + x,
        |x| 1.0 + 0.5 * x,
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("material_rgb.bsdf");
    std::fs::write(&path, tensor_file(&fields)).unwrap();
    let data = read(&path, "hemi").unwrap();
    assert!(
        data.notices
            .iter()
            .any(|n| n.contains("'test material, database layout'")),
        "{:?}",
        data.notices
    );
    let mut checked = [0usize; 3];
    for s in &data.samples {
        let k = RGB_NM.iter().position(|&w| w == s.wavelength_nm).unwrap();
        let (ti, ui, um, cos_o) = sample_angles(s);
        let want = (a[k] + b[k] * ti) * (1.0 + 2.0 * cdf(um)) * (2.0 + um)
            / (4.0 * (1.0 + 0.5 * ui))
            / cos_o;
        // float32 tables: 1e-6 relative. At the mirror direction θm is 0 to rounding
        // (~1e-8 rad from acos near 1), which √ turns into ~1e-4 of u_θ: a looser bound
        // there.
        let tol = if um < 1e-3 { 1e-3 } else { 2e-5 };
        assert!(
            (s.value - want).abs() <= tol * want,
            "{} nm, θi {:.1}° θo {:.1}° Δφ {:.1}°: {} vs {want}",
            s.wavelength_nm,
            s.theta_i.to_degrees(),
            s.theta_o.to_degrees(),
            (s.phi_o - s.phi_i).to_degrees(),
            s.value
        );
        checked[k] += 1;
    }
    assert!(checked.iter().all(|&c| c > 100), "{checked:?}");
}

/// A periodic, asymmetric profile along u_φ, linear between the table's nodes (n = 17:
/// nodes at j/16, the kink at 1/4 one of them), so that bilinear interpolation reproduces
/// it: 1 at φ = ±π, 2 at y = 1/4 (φ = −π/2), back to 1 at y = 1. A φ read with the
/// wrong sign (y → 1 − y) or not relative to φi moves every value.
fn g(y: f64) -> f64 {
    if y <= 0.25 {
        1.0 + 4.0 * y
    } else {
        2.0 - (y - 0.25) * 4.0 / 3.0
    }
}

/// ∫₀^y g.
fn g_integral(y: f64) -> f64 {
    if y <= 0.25 {
        y + 2.0 * y * y
    } else {
        let t = y - 0.25;
        0.375 + 2.0 * t - 2.0 / 3.0 * t * t
    }
}

/// The isotropic closed form with tables that vary along u_φ: a VNDF density
/// p(x, y) = 1 + 3x·g(y) that is not separable, so the warp's inverse is the 2-D
/// conditional one (the row first: s_y = ∫₀^y m / ∫₀^1 m with m(y) = 1 + 1.5 g(y); then
/// s_x = (x + 1.5 g(y) x²) / (1 + 1.5 g(y)) along the row at y), a value table
/// (a_k + b_k θi)(1 + 2x)·g(y) in the warped coordinates, an NDF 2 + x·g(y) at the half
/// vector's (u_θ, u_φ) with φ relative to φi. σ is constant along u_φ, as in the
/// database's isotropic files (whose NDF and σ are the material's, the same at every
/// azimuth; renderers differ on which azimuth of ωi they look σ up at).
#[test]
fn a_database_file_varying_along_u_phi_reads_to_its_closed_form() {
    let (a, b) = ([0.30, 0.20, 0.10], [0.05, -0.04, 0.02]);
    let fields = database_layout_2d(
        7,
        17,
        |x, y| 1.0 + 3.0 * x * g(y),
        |x, y, ti, k| (a[k] + b[k] * ti) * (1.0 + 2.0 * x) * g(y),
        |x, y| 2.0 + x * g(y),
        |x, _| 1.0 + 0.5 * x,
    );
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("material_rgb.bsdf");
    std::fs::write(&path, tensor_file(&fields)).unwrap();
    // Incidence azimuths 0…150° (`azimuths`) as well as 0 (`hemi`).
    let data = read(&path, "hemi+azimuths").unwrap();
    let mut checked = [0usize; 3];
    let mut incidence_azimuths = std::collections::BTreeSet::new();
    for s in &data.samples {
        let k = RGB_NM.iter().position(|&w| w == s.wavelength_nm).unwrap();
        let (wi, wo) = (dir(s.theta_i, s.phi_i), dir(s.theta_o, s.phi_o));
        let h: Vec<f64> = (0..3).map(|c| wi[c] + wo[c]).collect();
        let len = (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt();
        let (ti, xm) = (wi[2].acos(), u_theta((h[2] / len).clamp(-1.0, 1.0).acos()));
        // At the mirror direction the half vector's azimuth is rounding noise.
        if xm < 1e-3 {
            continue;
        }
        let relative = h[1].atan2(h[0]) - s.phi_i;
        let ym = ((relative + PI) / (2.0 * PI)).rem_euclid(1.0);
        let sy = (ym + 1.5 * g_integral(ym)) / (1.0 + 1.5 * g_integral(1.0));
        let sx = (xm + 1.5 * g(ym) * xm * xm) / (1.0 + 1.5 * g(ym));
        let want = (a[k] + b[k] * ti) * (1.0 + 2.0 * sx) * g(sy) * (2.0 + xm * g(ym))
            / (4.0 * (1.0 + 0.5 * u_theta(ti)))
            / wo[2];
        assert_read_as(s, want, 2e-5);
        checked[k] += 1;
        incidence_azimuths.insert((s.phi_i.to_degrees() * 1e3).round() as i64);
    }
    eprintln!("checked {checked:?} at incidence azimuths {incidence_azimuths:?} (mdeg)");
    assert!(checked.iter().all(|&c| c > 100), "{checked:?}");
    assert!(incidence_azimuths.len() >= 6, "{incidence_azimuths:?}");
}

/// An anisotropic material laid out by hand from the format's definition: five incidence
/// azimuths over −π…0 (a half-turn symmetry: a reader folds ωi into y ≤ 0, turning ωo
/// with it), a uniform VNDF (the identity warp), `jacobian` = 0, and value tables over the
/// half vector's azimuth in the surface's frame (not relative to ωi's, as an isotropic
/// file's). Each table is (a_k + b_k θi + c_k φi)(1 + 2x)(1 + y) over (x, y) = u_m: linear
/// in every parameter, so interpolation reproduces it and the read value is the closed
/// form divided by cos θo, at every direction of a geometry whose incidence azimuths span
/// the circle.
#[test]
fn an_anisotropic_file_reads_to_its_closed_form() {
    let (n, nt) = (9, 4);
    let theta_i: Vec<f64> = (0..nt).map(|j| 1.4 * j as f64 / (nt - 1) as f64).collect();
    let phi_i: Vec<f64> = (0..5).map(|k| -PI + PI * k as f64 / 4.0).collect();
    let (a, b, c) = ([0.30, 0.20, 0.10], [0.05, -0.04, 0.02], [0.03, 0.02, -0.01]);
    let coefficient = |k: usize, ti: f64, pi: f64| a[k] + b[k] * ti + c[k] * pi;
    let mut rgb = Vec::new();
    for &pi in &phi_i {
        for &ti in &theta_i {
            for k in 0..3 {
                for row in 0..n {
                    let y = row as f64 / (n - 1) as f64;
                    for col in 0..n {
                        let x = col as f64 / (n - 1) as f64;
                        rgb.push(coefficient(k, ti, pi) * (1.0 + 2.0 * x) * (1.0 + y));
                    }
                }
            }
        }
    }
    let slices = phi_i.len() * nt;
    use ElementType::{F32, U8};
    let file = |phi: Vec<f64>| {
        tensor_file(&[
            field("description", U8, &[5], b"aniso".map(f64::from).to_vec()),
            field("jacobian", U8, &[1], vec![0.0]),
            field("theta_i", F32, &[nt], theta_i.clone()),
            field("phi_i", F32, &[phi.len()], phi),
            field("ndf", F32, &[n, n], vec![1.0; n * n]),
            field("sigma", F32, &[n, n], vec![1.0; n * n]),
            field("vndf", F32, &[5, nt, n, n], vec![1.0; slices * n * n]),
            field("luminance", F32, &[5, nt, n, n], vec![1.0; slices * n * n]),
            field("rgb", F32, &[5, nt, 3, n, n], rgb.clone()),
        ])
    };
    let dir_path = tempfile::tempdir().unwrap();
    let path = dir_path.path().join("aniso.bsdf");
    std::fs::write(&path, file(phi_i.clone())).unwrap();
    // The default geometry of an anisotropic file varies the incidence azimuth.
    let data = readers::load(
        &path,
        &ReadOptions {
            assume_uncertainty: Some((0.01, 1e-6)),
            ..Default::default()
        },
    )
    .unwrap();
    assert!(
        data.notices
            .iter()
            .any(|n| n.contains("anisotropic: 5 incidence azimuths")),
        "{:?}",
        data.notices
    );
    let azimuths: std::collections::BTreeSet<i64> = data
        .samples
        .iter()
        .map(|s| s.phi_i.to_degrees().round() as i64)
        .collect();
    assert!(azimuths.len() >= 4, "{azimuths:?}");
    let mut checked = 0;
    for s in &data.samples {
        let k = RGB_NM.iter().position(|&w| w == s.wavelength_nm).unwrap();
        let (mut wi, mut wo) = (dir(s.theta_i, s.phi_i), dir(s.theta_o, s.phi_o));
        // The fold: ωi.y ≥ 0 (+0 included) turns both directions by a half turn.
        if wi[1] >= 0.0 {
            for w in [&mut wi, &mut wo] {
                w[0] = -w[0];
                w[1] = -w[1];
            }
        }
        let (ti, pi) = (wi[2].acos(), wi[1].atan2(wi[0]));
        let h: Vec<f64> = (0..3).map(|j| wi[j] + wo[j]).collect();
        let len = (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt();
        let x = u_theta((h[2] / len).clamp(-1.0, 1.0).acos());
        let y = (h[1].atan2(h[0]) + PI) / (2.0 * PI);
        let y = y - y.floor();
        let want = coefficient(k, ti, pi) * (1.0 + 2.0 * x) * (1.0 + y) / wo[2];
        // float32 tables; near the pole u_θ carries the rounding of acos (as above).
        let tol = if x < 1e-3 { 1e-3 } else { 2e-5 };
        assert_read_as(s, want, tol);
        checked += 1;
    }
    assert!(checked > 1000, "{checked}");
    // Azimuths that span no whole fraction of the circle are refused, by name.
    let odd: Vec<f64> = (0..5).map(|k| -2.0 + 0.5 * k as f64).collect();
    std::fs::write(&path, file(odd)).unwrap();
    let e = read(&path, "azimuths").unwrap_err().to_string();
    assert!(
        e.contains("aniso.bsdf") && e.contains("phi_i") && e.contains("span"),
        "{e}"
    );
}

#[test]
fn two_equal_azimuths_are_isotropic_and_two_different_ones_are_refused() {
    let (n, nt) = (5, 3);
    let theta_i = vec![0.0, 0.7, 1.4];
    let build = |second: f64| {
        let per = |s: f64| -> Vec<f64> {
            (0..nt * 3 * n * n)
                .map(|i| s * (1.0 + (i % 7) as f64))
                .collect()
        };
        let mut rgb = per(1.0);
        rgb.extend(per(second));
        tensor_file(&[
            field("description", ElementType::U8, &[1], vec![65.0]),
            field("jacobian", ElementType::U8, &[1], vec![0.0]),
            field("theta_i", ElementType::F32, &[nt], theta_i.clone()),
            field("phi_i", ElementType::F32, &[2], vec![0.0, PI]),
            field("ndf", ElementType::F32, &[n, n], vec![1.0; n * n]),
            field("sigma", ElementType::F32, &[n, n], vec![1.0; n * n]),
            field(
                "vndf",
                ElementType::F32,
                &[2, nt, n, n],
                vec![1.0; 2 * nt * n * n],
            ),
            field(
                "luminance",
                ElementType::F32,
                &[2, nt, n, n],
                vec![1.0; 2 * nt * n * n],
            ),
            field("rgb", ElementType::F32, &[2, nt, 3, n, n], rgb),
        ])
    };
    let dir = tempfile::tempdir().unwrap();
    let same = dir.path().join("same.bsdf");
    std::fs::write(&same, build(1.0)).unwrap();
    let data = read(&same, "grid:10").unwrap();
    assert!(data.samples.iter().all(|s| s.value > 0.0));
    let differ = dir.path().join("differ.bsdf");
    std::fs::write(&differ, build(1.3)).unwrap();
    let e = read(&differ, "grid:10").unwrap_err().to_string();
    assert!(
        e.contains("differ.bsdf") && e.contains("anisotropic") && e.contains("rgb"),
        "{e}"
    );
}

#[test]
fn damaged_or_meaningless_fields_are_refused_by_name() {
    let good = || database_layout(3, 5, |_| 1.0, |_, _, k| 1.0 + k as f64, |_| 1.0, |_| 1.0);
    let dir = tempfile::tempdir().unwrap();
    let check = |name: &str, bytes: Vec<u8>, words: &[&str]| {
        let path = dir.path().join(format!("{name}.bsdf"));
        std::fs::write(&path, bytes).unwrap();
        let e = read(&path, "grid:10").unwrap_err().to_string();
        assert!(e.contains(&format!("{name}.bsdf")), "{name}: {e}");
        for w in words {
            assert!(e.contains(w), "{name}: '{w}' not in: {e}");
        }
    };
    // The undamaged file reads.
    let path = dir.path().join("good.bsdf");
    std::fs::write(&path, tensor_file(&good())).unwrap();
    read(&path, "grid:10").unwrap();

    let mut f = good();
    f[0] = field("description", ElementType::F32, &[2], vec![1.0, 2.0]);
    check(
        "text_as_float",
        tensor_file(&f),
        &["description", "float32", "text"],
    );

    let mut bytes = tensor_file(&good());
    // The first field's type code sits after magic, version, count, name length and name
    // ("description", 11 bytes) and the rank.
    let at = 12 + 2 + 4 + 2 + 11 + 2;
    assert_eq!(bytes[at], 1);
    bytes[at] = 12;
    check("unknown_type", bytes, &["description", "code 12"]);

    let bytes = tensor_file(&good());
    check(
        "truncated",
        bytes[..bytes.len() - 8].to_vec(),
        &["truncated", "rgb"],
    );

    let mut f = good();
    f[3] = field("theta_i", ElementType::F32, &[3], vec![0.0, 1.0, 0.5]);
    check("unsorted", tensor_file(&f), &["theta_i", "increase"]);

    let mut f = good();
    f.push(field("jacobian", ElementType::U8, &[1], vec![0.0]));
    check("twice", tensor_file(&f), &["jacobian", "twice"]);

    let mut f = good();
    f.retain(|x| x.name != "rgb");
    check("no_table", tensor_file(&f), &["'rgb' or 'spectra'"]);

    // Two incidence angles' tables for three angles.
    let mut f = good();
    let last = f.len() - 1;
    f[last] = field("rgb", ElementType::F32, &[1, 2, 3, 5, 5], vec![1.0; 150]);
    check(
        "shapes",
        tensor_file(&f),
        &["inconsistent shapes", "rgb [1, 2, 3, 5, 5]"],
    );
}

#[test]
fn negative_rgb_values_are_read_as_zero_with_a_notice() {
    // Channel B is negative everywhere (an out-of-gamut colour): read as 0, counted.
    let fields = database_layout(
        3,
        5,
        |_| 1.0,
        |_, _, k| [0.2, 0.1, -0.05][k],
        |_| 1.0,
        |_| 1.0,
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("vivid.bsdf");
    std::fs::write(&path, tensor_file(&fields)).unwrap();
    let data = read(&path, "grid:10").unwrap();
    let blue: Vec<f64> = data
        .samples
        .iter()
        .filter(|s| s.wavelength_nm == 450.0)
        .map(|s| s.value)
        .collect();
    assert!(!blue.is_empty() && blue.iter().all(|&v| v == 0.0));
    assert!(data
        .samples
        .iter()
        .filter(|s| s.wavelength_nm != 450.0)
        .all(|s| s.value > 0.0));
    let notice = format!(
        "{} of {} sampled values were negative",
        blue.len(),
        data.samples.len()
    );
    assert!(
        data.notices.iter().any(|n| n.contains(&notice)),
        "{notice} not in {:?}",
        data.notices
    );
}
