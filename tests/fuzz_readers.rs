//! Fuzz-style property tests of every reader: arbitrary bytes, and bytes shaped like each
//! format (v1 CSV, ALTA text, MERL tables, RGL tensor files, Zemax BSDF and ASTM E1392
//! text), must never panic, every error must name the file (the Zemax and ASTM readers:
//! `file:line:column`), and every dataset read must be well formed. About 17,000
//! cases run in CI, from fixed seeds; `cargo test --test fuzz_readers -- --ignored` runs
//! 15 × more. A failing case is saved to `tests/fuzz_readers.proptest-regressions` (commit
//! it) and replayed first on every later run.
//!
//! The same contract is checked on the coverage-guided fuzzer's seed corpus
//! (`fuzz/seeds/`) and on every crash reproducer kept in `fuzz/regressions/`
//! (docs/reliability.md): this is the slice of the fuzzing that CI runs.

/// The fuzz targets' own library (fuzz/src/lib.rs, plain Rust over bsdfit): the option
/// sets every input is read with and the contract every read is held to, shared so the
/// CI slice reads and checks as the targets do.
#[path = "../fuzz/src/lib.rs"]
#[allow(dead_code)]
mod fuzz_contract;

use bsdfit::data::readers::{self, alta, astm, merl, mueller, rgl, zemax};
use bsdfit::data::{DataError, Dataset, ReadOptions};
use fuzz_contract::{contract, located};
use proptest::prelude::*;
use proptest::test_runner::{Config, FileFailurePersistence, RngAlgorithm, TestRng, TestRunner};
use std::path::{Path, PathBuf};

use fuzz_contract::FILE;

/// Where failing cases are saved.
const REGRESSIONS: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/tests/fuzz_readers.proptest-regressions"
);

fn opts(assume: bool, allow_zero: bool) -> ReadOptions {
    ReadOptions {
        allow_zero_uncertainty: allow_zero,
        assume_uncertainty: assume.then_some((0.05, 0.001)),
        max_samples: Some(50),
        // RGL materials: a small geometry (about 50 directions) keeps cases fast.
        sample_geometry: Some("grid:30".into()),
        ..Default::default()
    }
}

/// [`check`] for the Zemax and ASTM readers: their errors also name line and column.
fn check_located(result: Result<Dataset, DataError>) -> Result<(), TestCaseError> {
    if let Err(e) = &result {
        let msg = e.to_string();
        prop_assert!(located(&msg, FILE), "error without file:line:column: {msg}");
    }
    check(result)
}

/// Run a reader and check the contract: no panic (a panic fails the property), an error
/// names the file, a dataset is well formed.
fn check(result: Result<Dataset, DataError>) -> Result<(), TestCaseError> {
    contract(result, FILE).map_err(TestCaseError::fail)
}

/// Tokens a CSV-shaped or ALTA-shaped line is made of: numbers of every kind, words of the
/// formats, and junk.
fn token() -> impl Strategy<Value = String> {
    prop_oneof![
        4 => (-200.0..200.0f64).prop_map(|v| format!("{v}")),
        2 => (0u32..4).prop_map(|k| ["0", "1", "550", "0.01"][k as usize].to_string()),
        1 => (0u32..13).prop_map(|k| [
            "nan", "NaN", "inf", "-inf", "", " ", "1e400", "1e300", "-0", "1e-320", "0x10", "١", "é",
        ][k as usize].to_string()),
        1 => (0u32..10).prop_map(|k| [
            "theta_i", "phi_i", "theta_o", "phi_o", "wavelength_nm", "value", "uncertainty",
            "\"0.5\"", "#", "# kind: brdf",
        ][k as usize].to_string()),
        1 => "[ -~]{0,6}",
    ]
}

fn csv_line() -> impl Strategy<Value = String> {
    (
        prop::collection::vec(token(), 0..9),
        prop_oneof![Just(","), Just(","), Just(";"), Just("\t")],
    )
        .prop_map(|(cells, sep)| cells.join(sep))
}

/// Text shaped like a v1 file: optional metadata, a (possibly damaged) header, rows.
fn csv_text() -> impl Strategy<Value = String> {
    (
        prop::option::of(prop_oneof![Just("# bsdfit dataset v1\n"), Just("\u{feff}# bsdfit dataset v1\n")]),
        prop_oneof![Just("# kind: brdf\n"), Just("# kind: btdf\n"), Just("# kind: x\n"), Just("")],
        prop_oneof![
            3 => Just("theta_i,phi_i,theta_o,phi_o,wavelength_nm,value,uncertainty\n".to_string()),
            1 => Just("uncertainty,value,wavelength_nm,phi_o,theta_o,phi_i,theta_i\n".to_string()),
            1 => csv_line().prop_map(|l| l + "\n"),
        ],
        prop::collection::vec(
            prop_oneof![
                6 => (0.0..90.0f64, 0.0..360.0f64, -90.0..90.0f64, 0.0..360.0f64, 400.0..700.0f64, -0.1..2.0f64, 0.0..0.1f64)
                    .prop_map(|(a, b, c, d, w, v, u)| format!("{a},{b},{c},{d},{w},{v},{u}")),
                3 => csv_line(),
                1 => Just(String::new()),
            ],
            0..12,
        ),
        prop_oneof![Just("\n"), Just("\r\n")],
    )
        .prop_map(|(marker, kind, header, rows, eol)| {
            let mut s = String::new();
            s += marker.unwrap_or("");
            s += kind;
            s += &header;
            for r in rows {
                s += &r;
                s += eol;
            }
            s
        })
}

/// Text shaped like an ALTA file: a consistent header and rows of the right width (some
/// damaged), or header lines drawn from the real keys in any order.
fn alta_text() -> impl Strategy<Value = String> {
    prop_oneof![3 => consistent_alta(), 2 => loose_alta()]
}

fn consistent_alta() -> impl Strategy<Value = String> {
    let params = [
        ("ISOTROPIC_TL_TV_PROJ_DPHI", 3),
        ("RUSIN_TH_TD_PD", 3),
        ("ISOTROPIC_TV_TL_DPHI", 3),
        ("RUSIN_TH_PH_TD_PD", 4),
        ("SPHERICAL_TL_PL_TV_PV", 4),
        ("CARTESIAN", 6),
    ];
    let outs = [
        ("INV_STERADIAN", 1),
        ("INV_STERADIAN_COSINE_FACTOR", 1),
        ("RGB_COLOR", 3),
    ];
    (
        0usize..6,
        0usize..3,
        0usize..3,
        prop::collection::vec((prop::collection::vec(-0.2..1.6f64, 16), 0u8..20), 1..12),
    )
        .prop_map(move |(p, o, vs, rows)| {
            let (pin, din) = params[p];
            let (pout, dout) = outs[o];
            let width = din + dout + vs * dout;
            let mut s =
                format!("#DIM {din} {dout}\n#PARAM_IN {pin}\n#PARAM_OUT {pout}\n#VS {vs}\n");
            for (vals, damage) in rows {
                let mut cols: Vec<String> = vals[..width].iter().map(|v| v.to_string()).collect();
                match damage {
                    0 => {
                        cols.pop();
                    }
                    1 => cols.push("0.5".into()),
                    2 => cols[0] = "nan".into(),
                    _ => {}
                }
                s += &cols.join(" ");
                s.push('\n');
            }
            s
        })
}

fn loose_alta() -> impl Strategy<Value = String> {
    let header_line = prop_oneof![
        (0usize..8, 0usize..5).prop_map(|(a, b)| format!("#DIM {a} {b}")),
        Just("#DIM 3".to_string()),
        (0usize..8).prop_map(|k| format!(
            "#PARAM_IN {}",
            [
                "ISOTROPIC_TL_TV_PROJ_DPHI",
                "RUSIN_TH_TD_PD",
                "CARTESIAN",
                "RUSIN_TH_PH_TD_PD",
                "SPHERICAL_TL_PL_TV_PV",
                "ISOTROPIC_TV_TL_DPHI",
                "STARK_2D",
                ""
            ][k]
        )),
        (0usize..5).prop_map(|k| format!(
            "#PARAM_OUT {}",
            [
                "INV_STERADIAN",
                "INV_STERADIAN_COSINE_FACTOR",
                "RGB_COLOR",
                "ENERGY",
                ""
            ][k]
        )),
        prop::collection::vec(0usize..4, 0..4).prop_map(|v| format!(
            "#VS {}",
            v.iter()
                .map(|x| x.to_string())
                .collect::<Vec<_>>()
                .join(" ")
        )),
        Just("#ALTA HEADER END".to_string()),
        Just("#SAMPLE \"x\"".to_string()),
        Just("# a comment".to_string()),
    ];
    (
        prop::collection::vec(header_line, 0..7),
        prop::collection::vec(
            prop_oneof![
                4 => prop::collection::vec(-2.0..2.0f64, 0..10)
                    .prop_map(|v| v.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(" ")),
                1 => prop::collection::vec(token(), 0..8).prop_map(|v| v.join(" ")),
            ],
            0..10,
        ),
    )
        .prop_map(|(h, rows)| h.join("\n") + "\n" + &rows.join("\n"))
}

/// Damage to the lines of a text file: a line dropped, repeated, replaced by junk
/// tokens, a junk line inserted, a token of a line replaced, or the file cut.
#[derive(Clone, Debug)]
enum LineDamage {
    Drop(usize),
    Repeat(usize),
    Junk(usize, Vec<String>),
    Insert(usize, Vec<String>),
    Token(usize, usize, String),
    Cut(usize),
}

fn line_damage() -> impl Strategy<Value = LineDamage> {
    let k = 0usize..64;
    prop_oneof![
        k.clone().prop_map(LineDamage::Drop),
        k.clone().prop_map(LineDamage::Repeat),
        (k.clone(), prop::collection::vec(token(), 0..6)).prop_map(|(k, t)| LineDamage::Junk(k, t)),
        (k.clone(), prop::collection::vec(token(), 0..6))
            .prop_map(|(k, t)| LineDamage::Insert(k, t)),
        (k.clone(), 0usize..12, token()).prop_map(|(k, j, t)| LineDamage::Token(k, j, t)),
        k.prop_map(LineDamage::Cut),
    ]
}

/// `lines` with up to three damages, joined with `eol`.
fn damaged(mut lines: Vec<String>, damages: Vec<LineDamage>, eol: &str, sep: char) -> String {
    for d in damages {
        let n = lines.len().max(1);
        match d {
            LineDamage::Drop(k) if !lines.is_empty() => {
                lines.remove(k % n);
            }
            LineDamage::Repeat(k) if !lines.is_empty() => {
                let l = lines[k % n].clone();
                lines.insert(k % n, l);
            }
            LineDamage::Junk(k, t) if !lines.is_empty() => lines[k % n] = t.join(" "),
            LineDamage::Insert(k, t) => lines.insert(k % (lines.len() + 1), t.join(" ")),
            LineDamage::Token(k, j, t) if !lines.is_empty() => {
                let mut cells: Vec<String> = lines[k % n].split(sep).map(str::to_string).collect();
                let c = cells.len();
                cells[j % c] = t;
                lines[k % n] = cells.join(&sep.to_string());
            }
            LineDamage::Cut(k) => lines.truncate(k % (lines.len() + 1)),
            _ => {}
        }
    }
    lines.join(eol) + eol
}

/// Text shaped like a Zemax tabular BSDF: a consistent header and tables (random
/// symmetry, spectral content, kind, lists and values), with up to three damages.
fn zemax_text() -> impl Strategy<Value = String> {
    let list = |lo: f64, hi: f64| {
        prop::collection::btree_set((lo as i64)..(hi as i64), 1..4)
            .prop_map(|s| s.into_iter().map(|x| x as f64).collect::<Vec<f64>>())
    };
    (
        (0usize..3, any::<bool>(), any::<bool>()),
        (
            list(0.0, 360.0),
            list(0.0, 91.0),
            list(0.0, 361.0),
            list(0.0, 181.0),
        ),
        prop::collection::vec(
            prop_oneof![4 => 0.0..5.0f64, 1 => Just(0.0), 1 => -0.1..0.0f64],
            64,
        ),
        prop::collection::vec(line_damage(), 0..4),
        prop_oneof![2 => Just(0usize), 1 => 1usize..4],
        prop_oneof![Just("\n"), Just("\r\n")],
    )
        .prop_map(
            |((sym, xyz, btdf), (rot, aoi, az, rad), values, damages, n, eol)| {
                let symmetry = ["PlaneSymmetrical", "Asymmetrical", "Asymmetrical4D"][sym];
                let rot = if sym == 2 { rot } else { vec![rot[0]] };
                let join = |v: &[f64]| {
                    v.iter()
                        .map(|x| x.to_string())
                        .collect::<Vec<_>>()
                        .join("\t")
                };
                let mut l: Vec<String> = vec![
                    "# shaped like a Zemax BSDF".into(),
                    "Source  Measured".into(),
                    format!("Symmetry  {symmetry}"),
                    format!(
                        "SpectralContent  {}",
                        if xyz { "XYZ" } else { "Monochrome" }
                    ),
                    format!("ScatterType  {}", if btdf { "BTDF" } else { "BRDF" }),
                ];
                for (name, v) in [
                    ("SampleRotation", &rot),
                    ("AngleOfIncidence", &aoi),
                    ("ScatterAzimuth", &az),
                    ("ScatterRadial", &rad),
                ] {
                    l.push(format!("{name} {}", v.len()));
                    l.push(join(v));
                }
                l.push(String::new());
                let sections: &[&str] = if xyz {
                    &["TristimulusX", "TristimulusY", "TristimulusZ"]
                } else {
                    &["Monochrome"]
                };
                let mut k = 0;
                for s in sections {
                    l.push(s.to_string());
                    l.push("DataBegin".into());
                    for _ in 0..rot.len() * aoi.len() {
                        l.push(format!("TIS {}", values[k % 64]));
                        for _ in 0..az.len() {
                            let row: Vec<String> = (0..rad.len())
                                .map(|_| {
                                    k += 1;
                                    format!("{:.4E}", values[k % 64])
                                })
                                .collect();
                            l.push(row.join("\t"));
                        }
                    }
                    l.push("DataEnd".into());
                }
                damaged(l, damages.into_iter().take(n).collect(), eol, '\t')
            },
        )
}

/// Text shaped like an ASTM E1392 file: header keywords, a VARS line (four or three
/// angles, wavelengths or a named value, u_ columns or not) and rows in the declared unit
/// (or radians), reflected or transmitted, with up to three damages.
fn astm_text() -> impl Strategy<Value = String> {
    (
        (
            0usize..3,
            any::<bool>(),
            0usize..3,
            any::<bool>(),
            any::<bool>(),
            0usize..3,
        ),
        prop::collection::vec(
            (
                0.0..1.0f64,
                0.0..1.0f64,
                0.0..1.0f64,
                0.0..1.0f64,
                prop::collection::vec(-0.05..3.0f64, 3),
            ),
            1..10,
        ),
        prop::collection::vec(line_damage(), 0..4),
        prop_oneof![2 => Just(0usize), 1 => 1usize..4],
        prop_oneof![Just("\n"), Just("\r\n")],
    )
        .prop_map(
            |((unit, three, values, with_u, btdf, num), rows, damages, n, eol)| {
                // unit: 0 undeclared (radians), 1 ANGLE_UNITS DEG, 2 degrees in the names.
                let scale = if unit == 0 { 1.0f64.to_radians() } else { 1.0 };
                let suffix = if unit == 2 { "[deg]" } else { "" };
                let names: Vec<&str> = match values {
                    0 => vec!["550nm"],
                    1 => vec!["450", "550", "650"],
                    _ => vec!["BRDF"],
                };
                let mut vars: Vec<String> = if three {
                    vec![
                        format!("theta_i{suffix}"),
                        format!("theta_s{suffix}"),
                        format!("phi_s{suffix}"),
                    ]
                } else {
                    ["theta_i", "phi_i", "theta_s", "phi_s"]
                        .iter()
                        .map(|a| format!("{a}{suffix}"))
                        .collect()
                };
                vars.extend(names.iter().map(|n| n.to_string()));
                if with_u {
                    vars.extend(names.iter().map(|n| format!("u_{n}")));
                }
                let mut l = vec!["SOURCE fuzz".to_string(), "SAMPLE_NAME \"shaped\"".into()];
                if unit == 1 {
                    l.push("ANGLE_UNITS DEG".into());
                }
                if num > 0 {
                    l.push(format!("NUM_POINTS {}", rows.len() + num - 1));
                }
                l.push(format!("VARS {}", vars.join(",")));
                for (ti, pi, ts, ps, v) in rows {
                    let ts = if btdf { 180.0 - 89.0 * ts } else { 89.0 * ts };
                    let mut cells: Vec<f64> = if three {
                        vec![80.0 * ti, ts, 360.0 * ps]
                    } else {
                        vec![80.0 * ti, 360.0 * pi, ts, 360.0 * ps]
                    };
                    for c in cells.iter_mut() {
                        *c *= scale;
                    }
                    cells.extend(v.iter().take(names.len()));
                    if with_u {
                        cells.extend(v.iter().take(names.len()).map(|x| 0.02 * x.abs() + 1e-4));
                    }
                    l.push(
                        cells
                            .iter()
                            .map(|c| c.to_string())
                            .collect::<Vec<_>>()
                            .join(","),
                    );
                }
                damaged(l, damages.into_iter().take(n).collect(), eol, ',')
            },
        )
}

/// Text shaped like a NIST Mueller-matrix BRDF table: a header naming the columns (in the
/// file's order or another, with Mueller columns or not) and rows of signed angles, with
/// up to three damages.
fn mueller_text() -> impl Strategy<Value = String> {
    (
        (any::<bool>(), any::<bool>()),
        prop::collection::vec(
            (
                prop_oneof![Just(0.351), Just(0.532), Just(1.064)],
                -80.0..80.0f64,
                -180.0..180.0f64,
                -85.0..85.0f64,
                -180.0..180.0f64,
                -0.01..0.7f64,
            ),
            1..10,
        ),
        prop::collection::vec(line_damage(), 0..4),
        prop_oneof![2 => Just(0usize), 1 => 1usize..4],
        prop_oneof![Just("\n"), Just("\r\n")],
    )
        .prop_map(|((reorder, mueller), rows, damages, n, eol)| {
            let mut names = vec!["lambda", "thetai", "phi", "thetar", "phir", "f_r11"];
            if mueller {
                names.extend(["f_r12/f_r11", "f_r44/f_r11"]);
            }
            let order: Vec<usize> = if reorder {
                (0..names.len()).rev().collect()
            } else {
                (0..names.len()).collect()
            };
            let mut l = vec![order
                .iter()
                .map(|&i| names[i])
                .collect::<Vec<_>>()
                .join(",")];
            for (w, ti, pi, tr, pr, f) in rows {
                let cells = [w, ti, pi, tr, pr, f, 0.01, -0.02];
                l.push(
                    order
                        .iter()
                        .map(|&i| cells[i].to_string())
                        .collect::<Vec<_>>()
                        .join(","),
                );
            }
            damaged(l, damages.into_iter().take(n).collect(), eol, ',')
        })
}

/// Byte strings that start like a MERL table: its dimensions (or others), then junk.
fn merl_bytes() -> impl Strategy<Value = Vec<u8>> {
    (
        prop_oneof![
            Just([90i32, 90, 180]),
            (any::<i32>(), any::<i32>(), any::<i32>()).prop_map(|(a, b, c)| [a, b, c]),
            (1i32..4, 1i32..4, 1i32..4).prop_map(|(a, b, c)| [a, b, c]),
        ],
        prop::collection::vec(any::<u8>(), 0..300),
    )
        .prop_map(|(d, tail)| {
            let mut v: Vec<u8> = d.iter().flat_map(|x| x.to_le_bytes()).collect();
            v.extend(tail);
            v
        })
}

/// The element types of a tensor file: code, size in bytes.
const DTYPES: [(u8, usize); 11] = [
    (1, 1),
    (2, 1),
    (3, 2),
    (4, 2),
    (5, 4),
    (6, 4),
    (7, 8),
    (8, 8),
    (9, 2),
    (10, 4),
    (11, 8),
];

/// `v` as element type `dtype` (little endian; integers rounded and saturated, f16 by
/// truncating an f32's mantissa).
fn encode(v: f64, dtype: u8) -> Vec<u8> {
    match dtype {
        1 => vec![v.round().clamp(0.0, 255.0) as u8],
        2 => vec![v.round().clamp(-128.0, 127.0) as i8 as u8],
        3 => (v.round().clamp(0.0, 65535.0) as u16)
            .to_le_bytes()
            .to_vec(),
        4 => (v.round().clamp(-32768.0, 32767.0) as i16)
            .to_le_bytes()
            .to_vec(),
        5 => (v.round().clamp(0.0, u32::MAX as f64) as u32)
            .to_le_bytes()
            .to_vec(),
        6 => (v.round() as i32).to_le_bytes().to_vec(),
        7 => (v.round().max(0.0) as u64).to_le_bytes().to_vec(),
        8 => (v.round() as i64).to_le_bytes().to_vec(),
        9 => {
            let b = (v as f32).to_bits();
            let sign = ((b >> 16) & 0x8000) as u16;
            let exp = ((b >> 23) & 0xff) as i32 - 127 + 15;
            let half = if v.is_nan() {
                0x7e00
            } else if exp >= 31 {
                sign | 0x7c00
            } else if exp <= 0 {
                sign
            } else {
                sign | ((exp as u16) << 10) | ((b >> 13) & 0x3ff) as u16
            };
            half.to_le_bytes().to_vec()
        }
        10 => (v as f32).to_le_bytes().to_vec(),
        _ => v.to_le_bytes().to_vec(),
    }
}

/// One field of a generated tensor file.
#[derive(Clone, Debug)]
struct TensorField {
    name: &'static str,
    /// The element type written in the header (the data are encoded as `encoding`).
    dtype: u8,
    encoding: u8,
    shape: Vec<u64>,
    values: Vec<f64>,
}

/// What a generated RGL material looks like before damage: incidence nodes, table size,
/// azimuths, RGB or spectral channels, `jacobian`, a `version` field (u32, as the RGL
/// database's files have), the element type of each field, a value scale.
#[derive(Clone, Debug)]
struct Material {
    nt: usize,
    n: usize,
    nphi: usize,
    spectral: Option<usize>,
    jacobian: bool,
    version: bool,
    dtypes: Vec<Option<u8>>,
    scale: f64,
}

/// The fields of a material shaped like an RGL database file (small tables).
fn material_fields(m: &Material) -> Vec<TensorField> {
    let (nt, n, nphi) = (m.nt, m.n, m.nphi);
    let nc = m.spectral.unwrap_or(3);
    let grid = |f: &dyn Fn(f64, f64) -> f64| -> Vec<f64> {
        (0..n * n)
            .map(|k| {
                f(
                    (k % n) as f64 / (n - 1) as f64,
                    (k / n) as f64 / (n - 1) as f64,
                )
            })
            .collect()
    };
    let s = m.scale;
    let repeat = |v: Vec<f64>, k: usize| -> Vec<f64> { (0..k).flat_map(|_| v.clone()).collect() };
    let desc = b"generated material, shaped like an RGL database file";
    let mut fields = vec![(
        "description",
        1u8,
        vec![desc.len() as u64],
        desc.iter().map(|&b| b as f64).collect::<Vec<_>>(),
    )];
    if m.version {
        fields.push(("version", 5, vec![2], vec![1.0, 0.0]));
    }
    fields.extend([
        ("jacobian", 1, vec![1], vec![m.jacobian as u8 as f64]),
        (
            "theta_i",
            10,
            vec![nt as u64],
            (0..nt).map(|k| 1.4 * k as f64 / nt as f64).collect(),
        ),
        (
            "phi_i",
            10,
            vec![nphi as u64],
            (0..nphi).map(|k| k as f64 * std::f64::consts::PI).collect(),
        ),
        (
            "ndf",
            10,
            vec![n as u64; 2],
            grid(&|u, _| 2.0 * (-4.0 * u * u).exp() + 0.05),
        ),
        (
            "sigma",
            10,
            vec![n as u64; 2],
            grid(&|u, _| 1.0 - 0.3 * u * u),
        ),
        (
            "vndf",
            10,
            vec![nphi as u64, nt as u64, n as u64, n as u64],
            repeat(
                grid(&|u, v| 1.5 * (-3.0 * u * u).exp() + 0.1 * v),
                nphi * nt,
            ),
        ),
        (
            "luminance",
            10,
            vec![nphi as u64, nt as u64, n as u64, n as u64],
            repeat(grid(&|u, _| 0.2 + u * (1.0 - u)), nphi * nt),
        ),
    ]);
    let table = repeat(
        grid(&|u, v| s * (0.1 + 0.8 * (-6.0 * u * u).exp() + 0.1 * v)),
        nphi * nt * nc,
    );
    let table_shape = vec![nphi as u64, nt as u64, nc as u64, n as u64, n as u64];
    match m.spectral {
        None => fields.push(("rgb", 10, table_shape, table)),
        Some(_) => {
            fields.push((
                "wavelengths",
                10,
                vec![nc as u64],
                (0..nc)
                    .map(|k| 400.0 + 300.0 * k as f64 / nc as f64)
                    .collect(),
            ));
            fields.push(("spectra", 10, table_shape, table));
        }
    }
    fields
        .into_iter()
        .zip(m.dtypes.iter().chain(std::iter::repeat(&None)))
        .map(|((name, dtype, shape, values), choice)| {
            let dtype = choice.unwrap_or(dtype);
            TensorField {
                name,
                dtype,
                encoding: dtype,
                shape,
                values,
            }
        })
        .collect()
}

/// The bytes of a tensor file of `fields`, data 8-byte aligned after the header;
/// `offsets` replaces a field's data offset (data written where it says, when it can).
fn tensor_bytes(fields: &[TensorField], count: Option<u32>, offsets: &[Option<u64>]) -> Vec<u8> {
    let mut head = rgl::MAGIC.to_vec();
    head.extend_from_slice(&[1, 0]);
    head.extend_from_slice(&count.unwrap_or(fields.len() as u32).to_le_bytes());
    let header_len = head.len()
        + fields
            .iter()
            .map(|f| 2 + f.name.len() + 2 + 1 + 8 + 8 * f.shape.len())
            .sum::<usize>();
    let mut at = header_len.div_ceil(8) * 8;
    let mut body: Vec<(usize, Vec<u8>)> = Vec::new();
    for (k, f) in fields.iter().enumerate() {
        let data: Vec<u8> = f
            .values
            .iter()
            .flat_map(|&v| encode(v, f.encoding))
            .collect();
        let offset = offsets.get(k).copied().flatten().unwrap_or(at as u64);
        head.extend_from_slice(&(f.name.len() as u16).to_le_bytes());
        head.extend_from_slice(f.name.as_bytes());
        head.extend_from_slice(&(f.shape.len() as u16).to_le_bytes());
        head.push(f.dtype);
        head.extend_from_slice(&offset.to_le_bytes());
        for s in &f.shape {
            head.extend_from_slice(&s.to_le_bytes());
        }
        if offset < 1 << 16 {
            body.push((offset as usize, data.clone()));
        }
        at = (at + data.len()).div_ceil(8) * 8;
    }
    let mut out = head;
    for (offset, data) in body {
        let end = offset + data.len();
        if out.len() < end {
            out.resize(end, 0);
        }
        if offset >= header_len {
            out[offset..end].copy_from_slice(&data);
        }
    }
    out
}

/// A damage to a generated tensor file.
#[derive(Clone, Debug)]
enum Damage {
    /// Field k's header element type (the data stay encoded as before).
    Dtype(usize, u8),
    /// Field k's dimension d set to a value.
    Shape(usize, usize, u64),
    /// Field k's rank: a dimension added or removed.
    Rank(usize, bool),
    /// Field k's data offset.
    Offset(usize, u64),
    /// Field k's value j set to one of NaN, ±inf, −1, 0, 1e30.
    Value(usize, usize, u8),
    /// Field k dropped, or given twice.
    Drop(usize),
    Twice(usize),
    /// The field count in the header.
    Count(u32),
    /// The file cut at a fraction of its length, or a byte flipped.
    Cut(f64),
    Flip(f64, u8),
}

fn damage() -> impl Strategy<Value = Damage> {
    let k = 0usize..12;
    prop_oneof![
        (k.clone(), 0u8..14).prop_map(|(k, t)| Damage::Dtype(k, t)),
        (k.clone(), any::<u8>()).prop_map(|(k, t)| Damage::Dtype(k, t)),
        (
            k.clone(),
            0usize..5,
            prop_oneof![
                Just(0u64),
                Just(1),
                Just(2),
                0u64..10,
                Just(1 << 32),
                Just(1 << 61),
                Just(u64::MAX),
                any::<u64>()
            ]
        )
            .prop_map(|(k, d, v)| Damage::Shape(k, d, v)),
        (k.clone(), any::<bool>()).prop_map(|(k, b)| Damage::Rank(k, b)),
        (
            k.clone(),
            prop_oneof![
                0u64..64,
                0u64..8192,
                Just(u64::MAX),
                Just(u64::MAX - 3),
                Just(1 << 63),
                any::<u64>()
            ]
        )
            .prop_map(|(k, o)| Damage::Offset(k, o)),
        (k.clone(), any::<usize>(), 0u8..6).prop_map(|(k, j, v)| Damage::Value(k, j, v)),
        k.clone().prop_map(Damage::Drop),
        k.prop_map(Damage::Twice),
        prop_oneof![0u32..20, Just(u32::MAX), any::<u32>()].prop_map(Damage::Count),
        (0.0..1.0f64).prop_map(Damage::Cut),
        (0.0..1.0f64, any::<u8>()).prop_map(|(at, b)| Damage::Flip(at, b)),
    ]
}

/// Byte-level tensor files shaped like the RGL database's: a consistent material (random
/// sizes, element types, azimuths, RGB or spectral) with up to three damages.
fn rgl_bytes() -> impl Strategy<Value = Vec<u8>> {
    let material = (
        1usize..5,
        2usize..6,
        prop_oneof![4 => Just(1usize), 2 => Just(2), 1 => Just(3)],
        prop_oneof![3 => Just(None), 1 => (1usize..6).prop_map(Some)],
        any::<bool>(),
        any::<bool>(),
        prop::collection::vec(
            prop_oneof![12 => Just(None), 1 => (0usize..11).prop_map(|i| Some(DTYPES[i].0))],
            12,
        ),
        prop_oneof![Just(1.0), 0.0..100.0f64, Just(1e-30), Just(-1.0)],
    )
        .prop_map(
            |(nt, n, nphi, spectral, jacobian, version, dtypes, scale)| Material {
                nt,
                n,
                nphi,
                spectral,
                jacobian,
                version,
                dtypes,
                scale,
            },
        );
    (
        material,
        prop::collection::vec(damage(), 0..4),
        prop_oneof![2 => Just(0usize), 1 => 1usize..4],
    )
        .prop_map(|(m, damages, n_damages)| {
            let mut fields = material_fields(&m);
            let mut offsets: Vec<Option<u64>> = vec![None; fields.len() + 1];
            let (mut count, mut cut, mut flips) = (None, None, Vec::new());
            for d in damages.into_iter().take(n_damages) {
                let nf = fields.len();
                match d {
                    Damage::Dtype(k, t) => fields[k % nf].dtype = t,
                    Damage::Shape(k, d, v) => {
                        let f = &mut fields[k % nf];
                        if !f.shape.is_empty() {
                            let d = d % f.shape.len();
                            f.shape[d] = v;
                        }
                    }
                    Damage::Rank(k, add) => {
                        let f = &mut fields[k % nf];
                        if add {
                            f.shape.insert(0, 1);
                        } else {
                            f.shape.pop();
                        }
                    }
                    Damage::Offset(k, o) => offsets[k % nf] = Some(o),
                    Damage::Value(k, j, v) => {
                        let f = &mut fields[k % nf];
                        if !f.values.is_empty() {
                            let j = j % f.values.len();
                            f.values[j] =
                                [f64::NAN, f64::INFINITY, -f64::INFINITY, -1.0, 0.0, 1e30]
                                    [v as usize];
                        }
                    }
                    Damage::Drop(k) => {
                        fields.remove(k % nf);
                    }
                    Damage::Twice(k) => fields.push(fields[k % nf].clone()),
                    Damage::Count(c) => count = Some(c),
                    Damage::Cut(at) => cut = Some(at),
                    Damage::Flip(at, b) => flips.push((at, b)),
                }
                if fields.is_empty() {
                    break;
                }
            }
            let mut bytes = tensor_bytes(&fields, count, &offsets);
            for (at, b) in flips {
                let k = (at * bytes.len() as f64) as usize;
                if let Some(x) = bytes.get_mut(k) {
                    *x ^= b | 1;
                }
            }
            if let Some(at) = cut {
                bytes.truncate((at * bytes.len() as f64) as usize);
            }
            bytes
        })
}

/// Run `cases` cases of `strategy` from the fixed seed `seed` (the same cases on every
/// run), replaying the saved failures first and saving a new one.
fn run<S: Strategy>(
    seed: u64,
    cases: u32,
    strategy: S,
    test: impl Fn(S::Value) -> Result<(), TestCaseError>,
) where
    S::Value: std::fmt::Debug,
{
    let config = Config {
        cases,
        failure_persistence: Some(Box::new(FileFailurePersistence::Direct(REGRESSIONS))),
        ..Config::default()
    };
    let mut key = [0xbfu8; 32];
    key[..8].copy_from_slice(&seed.to_le_bytes());
    let rng = TestRng::from_seed(RngAlgorithm::ChaCha, &key);
    let mut runner = TestRunner::new_with_rng(config, rng);
    if let Err(e) = runner.run(&strategy, test) {
        panic!("{e} (the case is saved in {REGRESSIONS}; commit it)");
    }
}

fn all_readers(bytes: &[u8], assume: bool, allow_zero: bool) -> Result<(), TestCaseError> {
    let o = opts(assume, allow_zero);
    check(readers::parse_bytes(bytes, FILE, &o))?;
    check(Dataset::parse_reader(bytes, FILE, &o, &mut |_| {}))?;
    check(alta::parse_reader(bytes, FILE, &o, &mut |_| {}))?;
    check(merl::parse(bytes, FILE, &o))?;
    check(rgl::parse(bytes, FILE, &o))?;
    check_located(zemax::parse_reader(bytes, FILE, &o, &mut |_| {}))?;
    check_located(astm::parse_reader(bytes, FILE, &o, &mut |_| {}))?;
    check_located(mueller::parse_reader(bytes, FILE, &o, &mut |_| {}))?;
    // The fuzz targets' lenient set: a channel selection averaged over bands.
    check(readers::parse_bytes(
        bytes,
        FILE,
        &fuzz_contract::option_sets()[2],
    ))?;
    Ok(())
}

/// Every strategy with `scale` × the CI number of cases; each strategy has its own fixed
/// seed (another for each scale).
fn fuzz(scale: u32) {
    use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};
    let (cases, csv_ok, alta_ok, rgl_ok, zemax_ok, astm_ok, mueller_ok) = (
        AtomicUsize::new(0),
        AtomicUsize::new(0),
        AtomicUsize::new(0),
        AtomicUsize::new(0),
        AtomicUsize::new(0),
        AtomicUsize::new(0),
        AtomicUsize::new(0),
    );
    let seed = |k: u64| 100 * scale as u64 + k;
    run(
        seed(1),
        3000 * scale,
        (
            prop::collection::vec(any::<u8>(), 0..400),
            any::<bool>(),
            any::<bool>(),
        ),
        |(b, a, z)| {
            cases.fetch_add(1, Relaxed);
            all_readers(&b, a, z)
        },
    );
    run(
        seed(2),
        4000 * scale,
        (csv_text(), any::<bool>()),
        |(t, z)| {
            cases.fetch_add(1, Relaxed);
            if Dataset::parse(&t, FILE, &opts(false, z)).is_ok() {
                csv_ok.fetch_add(1, Relaxed);
            }
            all_readers(t.as_bytes(), false, z)
        },
    );
    run(
        seed(3),
        4000 * scale,
        (alta_text(), any::<bool>()),
        |(t, a)| {
            cases.fetch_add(1, Relaxed);
            if alta::parse(&t, FILE, &opts(a, false)).is_ok() {
                alta_ok.fetch_add(1, Relaxed);
            }
            all_readers(t.as_bytes(), a, false)
        },
    );
    run(seed(4), 3000 * scale, merl_bytes(), |b| {
        cases.fetch_add(1, Relaxed);
        all_readers(&b, true, false)
    });
    run(
        seed(5),
        3000 * scale,
        (rgl_bytes(), any::<bool>()),
        |(b, z)| {
            cases.fetch_add(1, Relaxed);
            if rgl::parse(&b, FILE, &opts(true, z)).is_ok() {
                rgl_ok.fetch_add(1, Relaxed);
            }
            all_readers(&b, true, z)
        },
    );
    run(
        seed(6),
        3000 * scale,
        (zemax_text(), any::<bool>()),
        |(t, z)| {
            cases.fetch_add(1, Relaxed);
            if zemax::parse(&t, FILE, &opts(true, z)).is_ok() {
                zemax_ok.fetch_add(1, Relaxed);
            }
            all_readers(t.as_bytes(), true, z)
        },
    );
    run(
        seed(7),
        3000 * scale,
        (astm_text(), any::<bool>(), any::<bool>()),
        |(t, a, z)| {
            cases.fetch_add(1, Relaxed);
            if astm::parse(&t, FILE, &opts(a, z)).is_ok() {
                astm_ok.fetch_add(1, Relaxed);
            }
            all_readers(t.as_bytes(), a, z)
        },
    );
    run(
        seed(8),
        3000 * scale,
        (mueller_text(), any::<bool>(), any::<bool>()),
        |(t, a, z)| {
            cases.fetch_add(1, Relaxed);
            if mueller::parse(&t, FILE, &opts(a, z)).is_ok() {
                mueller_ok.fetch_add(1, Relaxed);
            }
            all_readers(t.as_bytes(), a, z)
        },
    );
    // Every case ran, and the shaped inputs reach the readers' happy paths too.
    assert!(cases.load(Relaxed) >= 26_000 * scale as usize, "{cases:?}");
    assert!(
        mueller_ok.load(Relaxed) > 100 * scale as usize,
        "Mueller-table-shaped inputs read: {mueller_ok:?}"
    );
    assert!(
        zemax_ok.load(Relaxed) > 100 * scale as usize,
        "Zemax-shaped inputs read: {zemax_ok:?}"
    );
    assert!(
        astm_ok.load(Relaxed) > 100 * scale as usize,
        "ASTM-shaped inputs read: {astm_ok:?}"
    );
    assert!(
        csv_ok.load(Relaxed) > 100 * scale as usize,
        "v1-shaped inputs read: {csv_ok:?}"
    );
    assert!(
        alta_ok.load(Relaxed) > 10 * scale as usize,
        "ALTA-shaped inputs read: {alta_ok:?}"
    );
    assert!(
        rgl_ok.load(Relaxed) > 20 * scale as usize,
        "RGL-shaped inputs read: {rgl_ok:?}"
    );
    eprintln!(
        "{cases:?} cases; read without error: {csv_ok:?} v1-shaped, {alta_ok:?} ALTA-shaped, {rgl_ok:?} RGL-shaped, {zemax_ok:?} Zemax-shaped, {astm_ok:?} ASTM-shaped, {mueller_ok:?} Mueller-table-shaped"
    );
}

/// 26,000 cases, each through all eight readers and the sniffing entry point.
#[test]
fn readers_never_panic_and_name_the_file() {
    fuzz(1);
}

/// The same with 15 × more cases (about 390,000), from other seeds.
#[test]
#[ignore]
fn readers_never_panic_and_name_the_file_long() {
    fuzz(15);
}

/// A full-size MERL table of random bytes (with the right header and size): no panic.
#[test]
fn merl_full_size_random_table() {
    use rand::{RngCore, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let mut bytes = vec![0u8; merl::FILE_BYTES];
    rng.fill_bytes(&mut bytes);
    for (k, d) in merl::DIMS.iter().enumerate() {
        bytes[4 * k..4 * k + 4].copy_from_slice(&(*d as i32).to_le_bytes());
    }
    let e = merl::parse(&bytes, FILE, &opts(true, false))
        .unwrap_err()
        .to_string();
    // Random doubles include NaNs early on: reported with their byte offset.
    assert!(e.contains(FILE) && e.contains("byte offset"), "{e}");
    // With every NaN/inf replaced, the table reads (values beyond 1e7 are errors).
    for c in bytes[12..].chunks_exact_mut(8) {
        let v = f64::from_le_bytes(c.try_into().unwrap());
        if !v.is_finite() || v.abs() > 1e9 {
            c.copy_from_slice(&(v.to_bits() as f64 / u64::MAX as f64).to_le_bytes());
        }
    }
    let r = merl::parse(&bytes, FILE, &opts(true, false));
    if let Err(e) = &r {
        assert!(e.to_string().contains(FILE));
    }
}

/// What the `merl` fuzz target also reads for an input that starts with the MERL header
/// (fuzz/fuzz_targets/merl.rs): a full-size table whose R, G and B blocks start with the
/// input's three equal runs of whole doubles after the header, every other cell −1.
fn merl_padded(bytes: &[u8]) -> Option<Vec<u8>> {
    let header: Vec<u8> = merl::DIMS
        .iter()
        .flat_map(|&d| (d as i32).to_le_bytes())
        .collect();
    if bytes.len() == merl::FILE_BYTES || !bytes.starts_with(&header) {
        return None;
    }
    let payload = &bytes[12..];
    let n = (payload.len() / 24).min(merl::CELLS);
    let mut table = header;
    for c in 0..3 {
        table.extend_from_slice(&payload[8 * c * n..8 * (c + 1) * n]);
        for _ in n..merl::CELLS {
            table.extend_from_slice(&(-1.0f64).to_le_bytes());
        }
    }
    Some(table)
}

/// Read one kept file the way fuzz target `target` does (every option set), and through
/// `readers::load` from disk; the contract must hold. Returns how many reads succeeded.
fn replay(target: &str, path: &Path) -> usize {
    let bytes = std::fs::read(path).unwrap();
    let shown = path.display().to_string();
    let mut ok = 0;
    let mut expect = |result: Result<Dataset, DataError>, file: &str| {
        ok += result.is_ok() as usize;
        if let Err(e) = contract(result, file) {
            panic!("{shown} through the {target} reader: {e}");
        }
    };
    for o in fuzz_contract::option_sets() {
        match target {
            "v1" => expect(
                Dataset::parse_reader(&bytes[..], FILE, &o, &mut |_| {}),
                FILE,
            ),
            "alta" => expect(alta::parse_reader(&bytes[..], FILE, &o, &mut |_| {}), FILE),
            "zemax" | "astm" => {
                let r = if target == "zemax" {
                    zemax::parse_reader(&bytes[..], FILE, &o, &mut |_| {})
                } else {
                    astm::parse_reader(&bytes[..], FILE, &o, &mut |_| {})
                };
                if let Err(e) = &r {
                    let msg = e.to_string();
                    assert!(
                        located(&msg, FILE),
                        "{shown} through the {target} reader: error without file:line:column: {msg}"
                    );
                }
                expect(r, FILE)
            }
            "rgl" => expect(rgl::parse(&bytes, FILE, &o), FILE),
            "merl" => {
                expect(merl::parse(&bytes, FILE, &o), FILE);
                if let Some(table) = merl_padded(&bytes) {
                    expect(merl::parse(&table, FILE, &o), FILE);
                }
            }
            "any" => {
                for name in ["fuzz-input.dat", "fuzz-input.binary", "fuzz-input.bsdf"] {
                    expect(readers::parse_bytes(&bytes, name, &o), name);
                }
            }
            _ => panic!("no fuzz target {target}"),
        }
        expect(readers::load(path, &o), &shown);
    }
    ok
}

/// The kept files of a fuzz target under `folder` (`fuzz/seeds` or `fuzz/regressions`),
/// sorted; none when the folder does not exist.
fn kept(folder: &str, target: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(folder)
        .join(target);
    let mut files: Vec<PathBuf> = match std::fs::read_dir(&dir) {
        Ok(entries) => entries.map(|e| e.unwrap().path()).collect(),
        Err(_) => Vec::new(),
    };
    files.retain(|p| p.is_file());
    files.sort();
    files
}

/// The CI slice of the coverage-guided fuzzing: every seed of the corpus and every crash
/// reproducer kept in the repository, through its target's reader(s), the sniffing entry
/// point and `readers::load`, with the targets' option sets. The seeds are shaped like
/// real files: many of them read.
#[test]
fn fuzz_corpus_and_reproducers_replay() {
    let mut report = Vec::new();
    for (target, min_seeds, min_ok) in [
        ("v1", 10, 10),
        ("alta", 10, 10),
        ("merl", 3, 2),
        ("rgl", 8, 5),
        ("zemax", 8, 6),
        ("astm", 8, 6),
        ("any", 5, 5),
    ] {
        let seeds = kept("fuzz/seeds", target);
        let reproducers = kept("fuzz/regressions", target);
        assert!(
            seeds.len() >= min_seeds,
            "fuzz/seeds/{target}: {} files (regenerate with python3 fuzz/make_seeds.py)",
            seeds.len()
        );
        let ok_seeds = seeds.iter().filter(|p| replay(target, p) > 0).count();
        for p in &reproducers {
            replay(target, p);
        }
        assert!(
            ok_seeds >= min_ok,
            "fuzz/seeds/{target}: only {ok_seeds} of {} seeds read under any option set",
            seeds.len()
        );
        report.push(format!(
            "{target}: {ok_seeds} of {} seeds read, {} reproducers",
            seeds.len(),
            reproducers.len()
        ));
    }
    eprintln!("{}", report.join("; "));
}

/// The located-error check itself: it accepts `file:line:column:` places (one, or a
/// "bad rows" list) and rejects a message without one, so the Zemax and ASTM properties
/// can fail.
#[test]
fn the_located_check_tells_a_place_from_none() {
    assert!(located(&format!("{FILE}:3:7: no DataBegin"), FILE));
    assert!(located(
        &format!("2 bad rows in {FILE}:\n{FILE}:4:1: x\n… and 1 more"),
        FILE
    ));
    assert!(!located(&format!("{FILE}: no DataBegin"), FILE));
    assert!(!located(&format!("{FILE}:3: no column"), FILE));
    assert!(!located(&format!("2 bad rows in {FILE}:\n{FILE}: x"), FILE));
    let elsewhere = DataError::File {
        file: "other.dat".into(),
        msg: "x".into(),
    };
    assert!(contract(Err(elsewhere), FILE).is_err());
}
