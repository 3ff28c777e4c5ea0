//! The Zemax BSDF and ASTM E1392 readers on files written here from the formats'
//! definitions (docs/data-formats.md quotes them), not by bsdfit's writers: the awkward
//! parts included (CRLF, tabs, comments, degrees vs radians, sample rotations, BTDF,
//! XYZ and 31-wavelength spectra, masked and beyond-the-horizon cells). The geometry
//! oracle is built here from rotation matrices, independently of the reader's frame.

mod common;

use bsdfit::data::readers::{self, Format};
use bsdfit::data::{Dataset, Kind, ReadOptions};
use common::optical::{key, oracle, sample_key, steps, zemax_text, ZemaxSpec};
use std::collections::HashMap;
use std::f64::consts::PI;

fn assume() -> ReadOptions {
    ReadOptions {
        assume_uncertainty: Some((0.02, 1e-4)),
        ..Default::default()
    }
}

fn read(text: &str, name: &str, opts: &ReadOptions) -> Result<Dataset, String> {
    readers::parse_bytes(text.as_bytes(), name, opts).map_err(|e| e.to_string())
}

#[test]
fn a_lambertian_zemax_brdf_reads_as_rho_over_pi_where_the_oracle_puts_it() {
    let rho = 0.6;
    let z = ZemaxSpec {
        symmetry: "PlaneSymmetrical",
        spectral: "Monochrome",
        kind: "BRDF",
        rotations: vec![0.0],
        aoi: vec![0.0, 15.0, 30.0, 45.0, 60.0],
        azimuths: steps(0.0, 180.0, 10.0),
        radials: steps(0.0, 180.0, 2.5),
        eol: "\r\n",
    };
    // Every cell ρ/π, as the definition of a BSDF in sr⁻¹ gives for a Lambertian surface,
    // except one masked cell (0) above the horizon.
    let f = |_: usize, _: f64, aoi: f64, a: f64, r: f64| {
        if aoi == 30.0 && a == 40.0 && r == 20.0 {
            0.0
        } else {
            rho / PI
        }
    };
    let text = zemax_text(&z, &f, rho);
    assert_eq!(
        readers::sniff(text.as_bytes(), text.len() as u64),
        Some(Format::ZemaxBsdf)
    );
    let ds = read(&text, "lambert.bsdf", &assume()).unwrap();
    assert_eq!(ds.kind, Kind::Brdf);
    assert_eq!(ds.channels, vec![550.0]);
    assert!(ds.assumed_uncertainty.is_some());
    // The oracle's cells above the horizon, one per direction, minus the masked one.
    let mut want: HashMap<[i64; 5], f64> = HashMap::new();
    for &aoi in &z.aoi {
        for &a in &z.azimuths {
            for &r in &z.radials {
                if let Some(g) = oracle(0.0, aoi, a, r) {
                    want.insert(key(g, 550.0), f(0, 0.0, aoi, a, r));
                }
            }
        }
    }
    want.retain(|_, v| *v != 0.0);
    assert_eq!(ds.len(), want.len());
    for s in &ds.samples {
        let v = want
            .get(&sample_key(s))
            .unwrap_or_else(|| panic!("no cell at {s:?}"));
        assert!((s.value - v).abs() < 1e-6 * v, "{s:?}");
    }
    // TIS is the albedo: the table, dense and reaching the horizon, integrates to it.
    let note = ds
        .notices
        .iter()
        .find(|n| n.contains("TIS lines"))
        .expect("a TIS note");
    assert!(note.contains("0.99") || note.contains("1.00"), "{note}");
    assert!(
        ds.notices.iter().any(|n| n.contains("1 masked")),
        "{:?}",
        ds.notices
    );
    // And a fit gives back ρ = TIS.
    let model = bsdfit::bsdf::Model::for_data("lambert", &ds).unwrap();
    let r = bsdfit::inference::fit::fit(
        &model,
        &ds,
        bsdfit::engine::loss::Loss::new(
            bsdfit::engine::loss::Metric::Chi2,
            bsdfit::engine::loss::Weights::Uniform,
        ),
        &bsdfit::engine::cpu::CpuBackend::new(),
        &Default::default(),
        &mut |_| {},
    )
    .unwrap();
    assert!((r.flat_params[0] - rho).abs() < 1e-4, "{:?}", r.flat_params);
}

#[test]
fn an_asymmetrical4d_btdf_puts_every_cell_where_the_oracle_does() {
    let z = ZemaxSpec {
        symmetry: "Asymmetrical4D",
        spectral: "Monochrome",
        kind: "BTDF",
        rotations: vec![0.0, 45.0, 90.0],
        aoi: vec![0.0, 20.0, 50.0],
        azimuths: steps(0.0, 330.0, 30.0),
        radials: vec![0.0, 3.0, 10.0, 25.0, 45.0, 70.0, 100.0],
        eol: "\n",
    };
    // A value that names its cell: the cell's number among the 3 × 3 × 12 × 7, an integer
    // that the file's seven significant digits hold exactly (so a permutation of any one
    // index, the radial one included, moves a value to a cell that names another). The
    // radial-0 column is one direction per table: one number for all its azimuths.
    let index = |axis: &[f64], v: f64| axis.iter().position(|&x| x == v).unwrap() as f64;
    let f = |_: usize, rot: f64, aoi: f64, a: f64, r: f64| {
        let (i, j, k, l) = (
            index(&z.rotations, rot),
            index(&z.aoi, aoi),
            if r == 0.0 { 0.0 } else { index(&z.azimuths, a) },
            index(&z.radials, r),
        );
        1.0 + l + 7.0 * (k + 12.0 * (j + 3.0 * i))
    };
    let text = zemax_text(&z, &f, 0.8);
    let ds = read(&text, "btdf.bsdf", &assume()).unwrap();
    assert_eq!(ds.kind, Kind::Btdf);
    let mut want: HashMap<[i64; 5], f64> = HashMap::new();
    for &rot in &z.rotations {
        for &aoi in &z.aoi {
            for &a in &z.azimuths {
                for &r in &z.radials {
                    if let Some(g) = oracle(rot, aoi, a, r) {
                        want.insert(key(g, 550.0), f(0, rot, aoi, a, r));
                    }
                }
            }
        }
    }
    assert_eq!(ds.len(), want.len());
    for s in &ds.samples {
        assert!(s.transmitted && s.wo().z < 0.0);
        let v = want
            .get(&sample_key(s))
            .unwrap_or_else(|| panic!("no cell at {s:?}"));
        assert!((s.value - v).abs() < 1e-9 * v, "{s:?}: {v}");
    }
    // The radial-0 column is one direction per table, read once.
    assert!(
        ds.notices.iter().any(|n| n.contains("repeat a direction")),
        "{:?}",
        ds.notices
    );
}

#[test]
fn xyz_tables_are_three_nominal_channels_and_a_wavelength_comment_labels_monochrome() {
    let z = ZemaxSpec {
        symmetry: "PlaneSymmetrical",
        spectral: "XYZ",
        kind: "BRDF",
        rotations: vec![0.0],
        aoi: vec![10.0, 30.0],
        azimuths: steps(0.0, 180.0, 45.0),
        radials: steps(0.0, 60.0, 15.0),
        eol: "\n",
    };
    let f = |c: usize, _: f64, _: f64, _: f64, _: f64| 0.1 * (c + 1) as f64;
    let ds = read(&zemax_text(&z, &f, 0.3), "xyz.bsdf", &assume()).unwrap();
    assert_eq!(ds.channels, vec![445.0, 555.0, 600.0]);
    for s in &ds.samples {
        let c = [600.0, 555.0, 445.0]
            .iter()
            .position(|w| *w == s.wavelength_nm)
            .unwrap();
        assert!((s.value - 0.1 * (c + 1) as f64).abs() < 1e-9);
    }
    let mono = ZemaxSpec {
        spectral: "Monochrome",
        ..z
    };
    let text = "# wavelength_nm: 632.8\n".to_string() + &zemax_text(&mono, &f, 0.3);
    let ds = read(&text, "he-ne.bsdf", &assume()).unwrap();
    assert_eq!(ds.channels, vec![632.8]);
}

/// (file text, the place and words its error must have).
fn zemax_refusals() -> Vec<(String, &'static str, &'static str)> {
    let good = zemax_text(
        &ZemaxSpec {
            symmetry: "PlaneSymmetrical",
            spectral: "Monochrome",
            kind: "BRDF",
            rotations: vec![0.0],
            aoi: vec![10.0, 30.0],
            azimuths: vec![0.0, 90.0, 180.0],
            radials: vec![0.0, 10.0, 20.0],
            eol: "\n",
        },
        &|_, _, _, _, _| 0.2,
        0.5,
    );
    let lines: Vec<&str> = good.lines().collect();
    let with = |n: usize, new: &str| {
        let mut l = lines.clone();
        l[n - 1] = new;
        l.join("\n") + "\n"
    };
    let without = |n: usize| {
        let mut l = lines.clone();
        l.remove(n - 1);
        l.join("\n") + "\n"
    };
    vec![
        (
            with(4, "Symmetry  Radial"),
            "x.bsdf:4:11:",
            "Symmetry 'Radial' is not PlaneSymmetrical, Asymmetrical or Asymmetrical4D",
        ),
        (
            with(5, "SpectralContent  RGB"),
            "x.bsdf:5:18:",
            "SpectralContent 'RGB' is not Monochrome or XYZ",
        ),
        (
            with(6, "ScatterType  BSDF"),
            "x.bsdf:6:14:",
            "ScatterType 'BSDF' is not BRDF or BTDF",
        ),
        (with(10, "10\t95"), "x.bsdf:10:4:", "outside [0, 90]"),
        (
            with(12, "0 90 270"),
            "x.bsdf:12:6:",
            "PlaneSymmetrical table covers azimuths 0–180°",
        ),
        (with(14, "0 10 10"), "x.bsdf:14:6:", "listed twice"),
        (
            with(8, "0 90").replace("SampleRotation  1", "SampleRotation  2"),
            "x.bsdf:7:17:",
            "need Asymmetrical4D",
        ),
        (
            with(19, "2.000000E-01\t2.0E-01"),
            "x.bsdf:19:21:",
            "expected 3 values",
        ),
        (
            with(20, "2.000000E-01\t2,0E-01\t0.2"),
            "x.bsdf:20:14:",
            "decimal mark",
        ),
        (
            without(25),
            "x.bsdf:25:1:",
            "'DataEnd' where the table of TIS line 22 expects its row 3 of 3",
        ),
        (with(22, "TIS -0.1"), "x.bsdf:22:5:", "negative"),
        (
            with(16, "TristimulusX"),
            "x.bsdf:16:1:",
            "SpectralContent (line 5) is Monochrome",
        ),
        (without(5), "x.bsdf:15:1:", "no SpectralContent"),
        (with(3, "Sauce Measured"), "x.bsdf:3:1:", "not a keyword"),
    ]
}

#[test]
fn zemax_refusals_name_file_line_and_column() {
    for (text, place, words) in zemax_refusals() {
        let e = read(&text, "x.bsdf", &assume()).unwrap_err();
        assert!(
            e.starts_with(place) && e.contains(words),
            "want {place} … {words}, got: {e}\n{text}"
        );
    }
    // Without an assumed uncertainty: refused, at the data.
    let (text, _, _) = &zemax_refusals()[0];
    let good = text.replace("Symmetry  Radial", "Symmetry  PlaneSymmetrical");
    let e = read(&good, "x.bsdf", &ReadOptions::default()).unwrap_err();
    assert!(
        e.starts_with("x.bsdf:16:1:") && e.contains("--assume-uncertainty"),
        "{e}"
    );
}

// ---------------------------------------------------------------------------------------
// ASTM E1392 files written from the definition

/// A Cornell-style spectral BRDF: radians, 31 wavelengths, off-plane scatter directions.
/// Rows of a spectral file: geometry (degrees) and one value per wavelength.
type SpectralRows = Vec<([f64; 4], Vec<f64>)>;

fn astm_spectral(eol: &str) -> (String, SpectralRows) {
    let wl: Vec<f64> = (0..31).map(|k| 400.0 + 10.0 * k as f64).collect();
    let mut rows = Vec::new();
    for ti in [0.0f64, 20.0, 40.0, 60.0] {
        for ts in [10.0f64, 30.0, 50.0, 70.0] {
            // An asymmetric set of scatter azimuths, and values that change with every
            // angle (φs with its sign), so that a φs sign flip, a θi/θs swap or a lost
            // angle puts a value where another is expected.
            for ps in [-120.0f64, -90.0, -30.0, 30.0, 60.0, 150.0, 180.0] {
                let g = [ti, 0.0, ts, ps];
                let v: Vec<f64> = wl
                    .iter()
                    .map(|w| {
                        0.05 + 0.2 * (w - 400.0) / 300.0
                            + 0.001 * ts
                            + 0.0003 * ti
                            + 0.0001 * (ps + 180.0)
                    })
                    .collect();
                rows.push((g, v));
            }
        }
    }
    let mut l = vec![
        "SOURCE Test lab".to_string(),
        "MEAS_DATE 1/2/2003".into(),
        "MEAS_NAME blue paint".into(),
        "SAMPLE_NAME \"blue paint\"".into(),
        "# a comment among the header lines".into(),
        "FORMAT theta_i phi_i theta_s phi_s 31 wavelengths".into(),
        format!("NUM_POINTS {}", rows.len()),
        format!(
            "VARS theta_i,phi_i,theta_s,phi_s,{}",
            wl.iter()
                .map(|w| format!("{w}nm"))
                .collect::<Vec<_>>()
                .join(",")
        ),
    ];
    for (g, v) in &rows {
        let mut cells: Vec<String> = g.iter().map(|a| format!("{:.8}", a.to_radians())).collect();
        cells.extend(v.iter().map(|x| format!("{x:.6}")));
        l.push(cells.join(","));
    }
    (l.join(eol) + eol, rows)
}

#[test]
fn a_spectral_astm_file_in_radians_reads_with_its_31_channels_at_their_geometries() {
    let (text, rows) = astm_spectral("\r\n");
    assert_eq!(
        readers::sniff(text.as_bytes(), text.len() as u64),
        Some(Format::AstmE1392)
    );
    let ds = read(&text, "paint.astm", &assume()).unwrap();
    assert_eq!(ds.kind, Kind::Brdf);
    assert_eq!(ds.material, "blue paint");
    assert_eq!(ds.channels.len(), 31);
    assert_eq!(ds.len(), rows.len() * 31);
    let mut want = HashMap::new();
    for (g, v) in &rows {
        for (k, x) in v.iter().enumerate() {
            want.insert(key(*g, 400.0 + 10.0 * k as f64), *x);
        }
    }
    for s in &ds.samples {
        let v = want.get(&sample_key(s)).unwrap_or_else(|| panic!("{s:?}"));
        assert!((s.value - v).abs() < 1e-6, "{s:?}"); // written with 6 decimals
    }
    assert_eq!(
        ds.meta.get("astm_meas_name").map(String::as_str),
        Some("blue paint")
    );
}

#[test]
fn astm_degrees_transmission_uncertainty_columns_and_the_short_vars_form() {
    // Degrees declared by a keyword; a BTDF (θs > 90° from the normal on the lit side);
    // signed angles; the uncertainty as a u_ column; no assumption needed.
    let text =
        "SAMPLE_NAME diffuser\nANGLE_UNITS DEG\nVARS theta_i,phi_i,theta_s,phi_s,633nm,u_633nm\n\
                0,0,180,0,2.5,0.05\n10,0,170,180,2.0,0.04\n10,0,-160,0,1.5,0.03\n";
    let ds = read(text, "d.astm", &ReadOptions::default()).unwrap();
    assert_eq!(ds.kind, Kind::Btdf);
    assert!(ds.assumed_uncertainty.is_none());
    let got: Vec<[f64; 3]> = ds
        .samples
        .iter()
        .map(|s| [s.theta_o.to_degrees(), s.phi_o.to_degrees(), s.uncertainty])
        .collect();
    // θt = 180° − θs, φt = φs; −160 at φ 0 is 160 at φ 180.
    for (g, w) in got
        .iter()
        .zip([[0.0, 0.0, 0.05], [10.0, 180.0, 0.04], [20.0, 180.0, 0.03]])
    {
        assert!(
            (g[0] - w[0]).abs() < 1e-9 && (g[2] - w[2]).abs() < 1e-12,
            "{got:?}"
        );
        if w[0] > 0.0 {
            assert!((g[1] - w[1]).abs() < 1e-9, "{got:?}");
        }
    }
    // Degrees declared in the names, three angles (φi = 0), one value column and a
    // WAVELENGTH keyword.
    let text = "WAVELENGTH 0.532 um\nVARS theta_i(deg), theta_s(deg), phi_s(deg), BRDF\n30, 30, 180, 0.3\n30, 20, 180, 0.2\n";
    let ds = read(text, "g.astm", &assume()).unwrap();
    assert_eq!(ds.channels, vec![532.0]);
    assert!((ds.samples[0].theta_o.to_degrees() - 30.0).abs() < 1e-9);
}

#[test]
fn astm_refusals_name_file_line_and_column() {
    let head = "SAMPLE_NAME s\nVARS theta_i,phi_i,theta_s,phi_s,BRDF\n";
    let cases: Vec<(String, &str, &str)> = vec![
        // Degrees that were not declared: radians are out of range, and the error says
        // how to declare degrees.
        (
            head.to_string() + "45,0,30,180,0.2\n",
            "a.astm:3:1:",
            "ANGLE_UNITS DEG",
        ),
        (
            head.to_string() + "0.1,0,0.5,3.14,0.2\n0.1,0,2.5,0,0.2\n",
            "a.astm:4:7:",
            "not both",
        ),
        (
            head.to_string() + "0.1,0,0.5,3.14\n",
            "a.astm:3:15:",
            "expected 5 cells",
        ),
        (
            head.to_string() + "0.1,0,0.5,x,0.2\n",
            "a.astm:3:11:",
            "phi_s: 'x' is not a number",
        ),
        (
            "NUM_POINTS 3\n".to_string() + &head[14..] + "0.1,0,0.5,3.14,0.2\n",
            "a.astm:1:12:",
            "NUM_POINTS 3 but the file has 1",
        ),
        (
            "VARS theta_i,phi_i,theta_s,phi_s,BTDF\n".to_string() + "0.1,0,0.5,3.14,0.2\n",
            "a.astm:1:34:",
            "ASTM E1392 measures every polar angle",
        ),
        (
            head.to_string() + "0.1,0,0.5,3.14,-5\n",
            "a.astm:3:16:",
            "negative beyond 3 uncertainties",
        ),
        (
            "SAMPLE_NAME s\n0.1,0,0.5\n".to_string(),
            "a.astm:2:1:",
            "not a header keyword",
        ),
        (
            "ANGLE_UNITS grad\nVARS theta_i,theta_s,phi_s,BRDF\n".to_string(),
            "a.astm:1:13:",
            "expected DEG or RAD",
        ),
    ];
    for (text, place, words) in cases {
        let e = readers::astm::parse(&text, "a.astm", &assume())
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with(place) && e.contains(words),
            "want {place} … {words}, got: {e}\n{text}"
        );
    }
    let e = read(
        &(head.to_string() + "0.1,0,0.5,3.14,0.2\n"),
        "a.astm",
        &ReadOptions::default(),
    )
    .unwrap_err();
    assert!(
        e.starts_with("a.astm:2:34:") && e.contains("--assume-uncertainty"),
        "{e}"
    );
}
