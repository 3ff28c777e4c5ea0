//! Fuzz-style property tests of every reader: arbitrary bytes, and text shaped like each
//! format, must never panic, and every error must name the file. About 14,000 cases run
//! in CI (a few seconds); `cargo test --test fuzz_readers -- --ignored` runs 200,000 more.

use bsdfit::data::readers::{self, alta, merl};
use bsdfit::data::{Dataset, ReadOptions};
use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};

const FILE: &str = "fuzz-input.dat";

fn opts(assume: bool, allow_zero: bool) -> ReadOptions {
    ReadOptions {
        allow_zero_uncertainty: allow_zero,
        assume_uncertainty: assume.then_some((0.05, 0.001)),
        max_samples: Some(50),
        ..Default::default()
    }
}

/// Run `reader` and check the contract: no panic (a panic fails the property), an error
/// names the file, a dataset is well formed.
fn check(result: Result<Dataset, bsdfit::data::DataError>) -> Result<(), TestCaseError> {
    match result {
        Err(e) => {
            let msg = e.to_string();
            prop_assert!(msg.contains(FILE), "error without the file name: {msg}");
        }
        Ok(d) => {
            prop_assert!(!d.samples.is_empty());
            for s in &d.samples {
                prop_assert!(
                    s.value.is_finite() && s.uncertainty.is_finite() && s.uncertainty > 0.0
                );
                prop_assert!(s.channel < d.channels.len() && s.axis < d.axes.len());
                prop_assert!(
                    (s.wi().length() - 1.0).abs() < 1e-9 && (s.wo().length() - 1.0).abs() < 1e-9
                );
            }
        }
    }
    Ok(())
}

/// Tokens a CSV-shaped or ALTA-shaped line is made of: numbers of every kind, words of the
/// formats, and junk.
fn token() -> impl Strategy<Value = String> {
    prop_oneof![
        4 => (-200.0..200.0f64).prop_map(|v| format!("{v}")),
        2 => (0u32..4).prop_map(|k| ["0", "1", "550", "0.01"][k as usize].to_string()),
        1 => (0u32..12).prop_map(|k| [
            "nan", "NaN", "inf", "-inf", "", " ", "1e400", "-0", "1e-320", "0x10", "١", "é",
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

fn run<S: Strategy>(cases: u32, strategy: S, test: impl Fn(S::Value) -> Result<(), TestCaseError>)
where
    S::Value: std::fmt::Debug,
{
    let mut runner = TestRunner::new(Config {
        cases,
        failure_persistence: None,
        ..Config::default()
    });
    runner.run(&strategy, test).unwrap();
}

fn all_readers(bytes: &[u8], assume: bool, allow_zero: bool) -> Result<(), TestCaseError> {
    let o = opts(assume, allow_zero);
    check(readers::parse_bytes(bytes, FILE, &o))?;
    check(Dataset::parse_reader(bytes, FILE, &o, &mut |_| {}))?;
    check(alta::parse_reader(bytes, FILE, &o, &mut |_| {}))?;
    check(merl::parse(bytes, FILE, &o))?;
    Ok(())
}

fn fuzz(scale: u32) {
    use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};
    let (cases, csv_ok, alta_ok) = (
        AtomicUsize::new(0),
        AtomicUsize::new(0),
        AtomicUsize::new(0),
    );
    run(
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
    run(4000 * scale, (csv_text(), any::<bool>()), |(t, z)| {
        cases.fetch_add(1, Relaxed);
        if Dataset::parse(&t, FILE, &opts(false, z)).is_ok() {
            csv_ok.fetch_add(1, Relaxed);
        }
        all_readers(t.as_bytes(), false, z)
    });
    run(4000 * scale, (alta_text(), any::<bool>()), |(t, a)| {
        cases.fetch_add(1, Relaxed);
        if alta::parse(&t, FILE, &opts(a, false)).is_ok() {
            alta_ok.fetch_add(1, Relaxed);
        }
        all_readers(t.as_bytes(), a, false)
    });
    run(3000 * scale, merl_bytes(), |b| {
        cases.fetch_add(1, Relaxed);
        all_readers(&b, true, false)
    });
    // Every case ran, and the shaped inputs reach the readers' happy paths too.
    assert!(cases.load(Relaxed) >= 14_000 * scale as usize, "{cases:?}");
    assert!(
        csv_ok.load(Relaxed) > 100 * scale as usize,
        "v1-shaped inputs read: {csv_ok:?}"
    );
    assert!(
        alta_ok.load(Relaxed) > 10 * scale as usize,
        "ALTA-shaped inputs read: {alta_ok:?}"
    );
    eprintln!("{cases:?} cases; read without error: {csv_ok:?} v1-shaped, {alta_ok:?} ALTA-shaped");
}

/// 14,000 cases, each through all four entry points.
#[test]
fn readers_never_panic_and_name_the_file() {
    fuzz(1);
}

/// The same with 15 × more cases (about 210,000).
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
