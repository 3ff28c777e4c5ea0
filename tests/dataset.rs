//! The v1 dataset format (docs/conventions.md): reading, validation messages (file and line),
//! round trips, channel selection and the signed-angle convention (docs/conventions.md).

mod common;

use bsdfit::data::{geometry_key, normalise_angles, Dataset, Kind, ReadOptions};
use glam::DVec3;

const HEADER: &str = "theta_i,phi_i,theta_o,phi_o,wavelength_nm,value,uncertainty";

/// A v1 file: lines 1–4 are metadata, line 5 the header, data from line 6.
fn file(kind: &str, rows: &[&str]) -> String {
    let mut s = format!("# bsdfit dataset v1\n# material: test tile\n# kind: {kind}\n# source: unit test\n{HEADER}\n");
    for r in rows {
        s += r;
        s.push('\n');
    }
    s
}

const FIRST_DATA_LINE: usize = 6;

fn good_rows() -> Vec<&'static str> {
    vec![
        "0,0,10,0,550,0.2512,0.0031",
        "10,0,-10,0,550,0.2600,0.0031",
        "10,0,20,0,550,0.2400,0.0030",
        "30,0,-45,0,450,0.2000,0.0025",
        "30,0,-45,0,550,0.2100,0.0026",
        "30,90,60,270,650,0.1900,0.0024",
        "-20,0,35,45,650,0.1800,0.0022",
    ]
}

fn parse(text: &str) -> Result<Dataset, bsdfit::data::DataError> {
    Dataset::parse(text, "f.csv", &ReadOptions::default())
}

/// The error message for `text`, which must fail.
fn err(text: &str, opts: &ReadOptions) -> String {
    match Dataset::parse(text, "f.csv", opts) {
        Ok(d) => panic!("expected an error, got a dataset of {} samples", d.len()),
        Err(e) => e.to_string(),
    }
}

/// The error names f.csv and the given line, as `f.csv:LINE:`.
fn assert_line_error(text: &str, line: usize, needle: &str) {
    let e = err(text, &ReadOptions::default());
    assert!(
        e.contains(&format!("f.csv:{line}:")),
        "expected file and line {line} in: {e}"
    );
    assert!(
        e.to_lowercase().contains(&needle.to_lowercase()),
        "expected '{needle}' in: {e}"
    );
}

/// Replace data row `k` (0-based) of the good rows.
fn with_row(k: usize, row: &'static str) -> String {
    let mut rows = good_rows();
    rows[k] = row;
    file("brdf", &rows)
}

fn close(a: DVec3, b: DVec3) -> bool {
    (a - b).length() < 1e-12
}

#[test]
fn valid_file_reads() {
    let d = parse(&file("brdf", &good_rows())).unwrap();
    assert_eq!(d.kind, Kind::Brdf);
    assert_eq!(d.material, "test tile");
    assert_eq!(d.len(), 7);
    assert_eq!(d.channels, vec![450.0, 550.0, 650.0]);
    assert!(d.notices.is_empty(), "{:?}", d.notices);
    for (k, s) in d.samples.iter().enumerate() {
        assert_eq!(s.line as usize, FIRST_DATA_LINE + k, "line of sample {k}");
        assert_eq!(d.channels[s.channel], s.wavelength_nm);
        assert!(s.theta_i >= 0.0 && s.theta_o >= 0.0);
        assert!((s.wi().length() - 1.0).abs() < 1e-12 && (s.wo().length() - 1.0).abs() < 1e-12);
        assert!(
            s.wi().z >= 0.0 && s.wo().z >= 0.0,
            "BRDF directions in the upper hemisphere"
        );
    }
    assert_eq!(d.samples[0].value, 0.2512);
    assert_eq!(d.samples[0].uncertainty, 0.0031);
}

#[test]
fn to_csv_round_trips() {
    let d = parse(&file("brdf", &good_rows())).unwrap();
    let text = d.to_csv();
    let e = Dataset::parse(&text, "g.csv", &ReadOptions::default())
        .unwrap_or_else(|e| panic!("{e}\n{text}"));
    assert_eq!(e.kind, d.kind);
    assert_eq!(e.material, d.material);
    assert_eq!(e.channels, d.channels);
    assert_eq!(e.meta.get("source").map(String::as_str), Some("unit test"));
    assert_eq!(e.len(), d.len());
    for (a, b) in d.samples.iter().zip(&e.samples) {
        for (x, y) in [
            (a.theta_i, b.theta_i),
            (a.phi_i, b.phi_i),
            (a.theta_o, b.theta_o),
            (a.phi_o, b.phi_o),
        ] {
            assert!((x - y).abs() < 1e-12, "angle {x} vs {y}");
        }
        assert_eq!(a.wavelength_nm, b.wavelength_nm);
        assert_eq!(a.value, b.value);
        assert_eq!(a.uncertainty, b.uncertainty);
        assert_eq!(a.channel, b.channel);
        assert!(
            close(a.wi(), b.wi()) && close(a.wo(), b.wo()),
            "{:?} {:?} vs {:?} {:?}",
            a.wi(),
            a.wo(),
            b.wi(),
            b.wo()
        );
    }
    // And once more: writing is a fixed point.
    assert_eq!(
        Dataset::parse(&text, "g.csv", &ReadOptions::default())
            .unwrap()
            .to_csv(),
        text
    );
}

#[test]
fn btdf_round_trips_with_lower_hemisphere() {
    let d = parse(&file(
        "btdf",
        &[
            "0,0,0,0,633,5.0,0.1",
            "0,0,-20,0,633,1.0,0.02",
            "30,0,15,90,633,2.0,0.05",
        ],
    ))
    .unwrap();
    let e = parse(&d.to_csv()).unwrap();
    assert_eq!(e.kind, Kind::Btdf);
    for (a, b) in d.samples.iter().zip(&e.samples) {
        assert!(close(a.wo(), b.wo()) && close(a.wi(), b.wi()));
        assert_eq!(a.value, b.value);
    }
}

#[test]
fn missing_column() {
    let t = "# kind: brdf\ntheta_i,phi_i,theta_o,phi_o,wavelength_nm,value\n0,0,10,0,550,0.25\n";
    assert_line_error(t, 2, "uncertainty");
}

#[test]
fn extra_column() {
    let t = "# kind: brdf\n# material: x\ntheta_i,phi_i,theta_o,phi_o,wavelength_nm,value,uncertainty,comment\n0,0,10,0,550,0.25,0.01,ok\n";
    assert_line_error(t, 3, "comment");
}

#[test]
fn wrong_cell_count() {
    assert_line_error(
        &with_row(2, "10,0,20,0,550,0.24"),
        FIRST_DATA_LINE + 2,
        "cells",
    );
    assert_line_error(
        &with_row(3, "30,0,-45,0,450,0.2,0.0025,7"),
        FIRST_DATA_LINE + 3,
        "cells",
    );
}

#[test]
fn non_numeric_cell() {
    assert_line_error(
        &with_row(4, "30,0,-45,0,550,abc,0.0026"),
        FIRST_DATA_LINE + 4,
        "value",
    );
    assert_line_error(
        &with_row(1, "10,0,-10,0,,0.26,0.0031"),
        FIRST_DATA_LINE + 1,
        "wavelength_nm",
    );
}

#[test]
fn nan_and_inf_cells() {
    for (k, row, col) in [
        (3, "30,0,-45,0,450,NaN,0.0025", "value"),
        (5, "30,90,60,270,650,0.19,nan", "uncertainty"),
        (2, "10,0,inf,0,550,0.24,0.003", "theta_o"),
        (6, "-20,0,35,45,650,-inf,0.0022", "value"),
        (0, "0,0,10,0,550,0.25,infinity", "uncertainty"),
    ] {
        assert_line_error(&with_row(k, row), FIRST_DATA_LINE + k, col);
    }
}

#[test]
fn theta_outside_range() {
    assert_line_error(
        &with_row(2, "10,0,95,0,550,0.24,0.003"),
        FIRST_DATA_LINE + 2,
        "theta_o",
    );
    assert_line_error(
        &with_row(4, "-90.5,0,-45,0,550,0.21,0.0026"),
        FIRST_DATA_LINE + 4,
        "theta_i",
    );
    // The limits themselves are accepted.
    assert!(parse(&with_row(2, "10,0,90,0,550,0.0,0.003")).is_ok());
    assert!(parse(&with_row(2, "10,0,-90,0,550,0.0,0.003")).is_ok());
}

#[test]
fn negative_value_beyond_three_uncertainties() {
    assert_line_error(
        &with_row(1, "10,0,-10,0,550,-0.0094,0.0031"),
        FIRST_DATA_LINE + 1,
        "negative",
    );
    // Within 3u it is noise, kept as written.
    let d = parse(&with_row(1, "10,0,-10,0,550,-0.0092,0.0031")).unwrap();
    assert_eq!(d.samples[1].value, -0.0092);
}

#[test]
fn negative_uncertainty() {
    assert_line_error(
        &with_row(6, "-20,0,35,45,650,0.18,-0.0022"),
        FIRST_DATA_LINE + 6,
        "uncertainty",
    );
}

#[test]
fn zero_uncertainty_is_an_error_unless_allowed() {
    let t = with_row(3, "30,0,-45,0,450,0.2,0");
    assert_line_error(&t, FIRST_DATA_LINE + 3, "uncertainty");
    let opts = ReadOptions {
        allow_zero_uncertainty: true,
        ..Default::default()
    };
    let d = Dataset::parse(&t, "f.csv", &opts).unwrap();
    let u = d.samples[3].uncertainty;
    assert!(u.is_finite() && u > 0.0, "floored uncertainty {u}");
    assert!(
        (u - 0.002).abs() < 1e-12,
        "floor max(1%·0.2, 1e-6) = 0.002, got {u}"
    );
    assert_eq!(d.notices.len(), 1, "{:?}", d.notices);
    assert!(
        d.notices[0].contains("f.csv") && d.notices[0].contains("zero uncertaint"),
        "{:?}",
        d.notices
    );
    // A zero value with zero uncertainty gets the absolute floor.
    let t = with_row(3, "30,0,-45,0,450,0,0");
    let d = Dataset::parse(&t, "f.csv", &opts).unwrap();
    assert!(d.samples[3].uncertainty > 0.0 && d.samples[3].uncertainty <= 1e-6);
}

#[test]
fn repeated_geometry_is_independent_samples() {
    // docs/conventions.md: a geometry measured twice is two independent samples, with one notice.
    let mut rows = good_rows();
    rows.push("10,0,20,0,550,0.2401,0.0030"); // the geometry of row 2, another value
    let d = parse(&file("brdf", &rows)).unwrap();
    assert_eq!(d.len(), 8);
    assert_eq!(d.samples[7].value, 0.2401);
    assert_eq!(d.samples[7].line as usize, FIRST_DATA_LINE + 7);
    assert_eq!(d.notices.len(), 1, "{:?}", d.notices);
    assert!(
        d.notices[0].contains("f.csv")
            && d.notices[0].contains("1 geometry")
            && d.notices[0].contains("2 samples"),
        "{:?}",
        d.notices
    );
    assert!(!d.notices[0].contains("warning"), "{:?}", d.notices);
}

#[test]
fn repeated_geometry_written_with_signed_angles() {
    // θo = −10, φo = 0 is θo = 10, φo = 180 (docs/conventions.md).
    for extra in [
        "10,0,10,180,550,0.2601,0.0031", // row 1 (10,0,-10,0)
        "20,180,35,45,650,0.18,0.0022",  // row 6 (-20,0,35,45)
        "30,450,60,-90,650,0.19,0.0024", // row 5 (30,90,60,270), φ wrapping past 360
        "0,45,10,0,550,0.25,0.0031",     // row 0 (0,0,10,0): the azimuth at the pole
    ] {
        let mut rows = good_rows();
        rows.push(extra);
        let d = parse(&file("brdf", &rows)).unwrap_or_else(|e| panic!("{extra}: {e}"));
        assert_eq!(d.len(), 8);
        assert!(
            d.notices.len() == 1 && d.notices[0].contains("1 geometry"),
            "{extra}: {:?}",
            d.notices
        );
    }
    // Same geometry at another wavelength is not a repeat.
    let mut rows = good_rows();
    rows.push("10,0,10,180,650,0.2601,0.0031");
    let d = parse(&file("brdf", &rows)).unwrap();
    assert_eq!(d.len(), 8);
    assert!(d.notices.is_empty(), "{:?}", d.notices);
}

#[test]
fn byte_identical_repeated_row_warns() {
    let mut rows = good_rows();
    rows.push("30,0,-45,0,450,0.2000,0.0025"); // row 3, byte for byte
    rows.push("10,0,20,0,550,0.2400,0.0030"); // row 2, byte for byte
    rows.push("10,0,20,0,550,0.24,0.0030"); // row 2's geometry, other text
    let d = parse(&file("brdf", &rows)).unwrap();
    assert_eq!(d.len(), 10);
    let all = d.notices.join("\n");
    assert!(
        all.contains("2 geometries") && all.contains("5 samples"),
        "{all}"
    );
    let warn = d
        .notices
        .iter()
        .find(|n| n.contains("warning"))
        .unwrap_or_else(|| panic!("no warning in {all}"));
    assert!(warn.contains("2 rows repeated byte for byte"), "{warn}");
    assert!(
        warn.contains(&format!(
            "line {} repeats line {}",
            FIRST_DATA_LINE + 7,
            FIRST_DATA_LINE + 3
        )) && warn.contains(&format!(
            "line {} repeats line {}",
            FIRST_DATA_LINE + 8,
            FIRST_DATA_LINE + 2
        )),
        "{warn}"
    );
}

#[test]
fn two_scans_through_the_normal_give_one_sample_to_each_plane() {
    // A BTDF measured on the φt = 0° and 90° planes, the normal point in both scans.
    let d = parse(&file(
        "btdf",
        &[
            "0,0,-10,0,633,1.0,0.02",
            "0,0,0,0,633,5.0,0.1",
            "0,0,10,0,633,1.1,0.02",
            "0,0,-10,90,633,0.9,0.02",
            "0,0,0,90,633,5.1,0.1",
            "0,0,10,90,633,0.8,0.02",
        ],
    ))
    .unwrap();
    assert_eq!(d.len(), 6);
    assert_eq!(d.axes, vec![0.0, 90.0]);
    let axes: Vec<usize> = d.samples.iter().map(|s| s.axis).collect();
    assert_eq!(axes, vec![0, 0, 0, 1, 1, 1]);
    assert!(
        d.notices.len() == 1 && d.notices[0].contains("1 geometry"),
        "{:?}",
        d.notices
    );
    for s in &d.samples[1..2] {
        assert!(close(s.wo(), -DVec3::Z), "{:?}", s.wo());
    }
    assert!(close(d.samples[4].wo(), -DVec3::Z));
    // The plane survives writing and reading back.
    let e = parse(&d.to_csv()).unwrap();
    assert_eq!(
        e.samples.iter().map(|s| s.axis).collect::<Vec<_>>(),
        vec![0, 0, 0, 1, 1, 1]
    );
    // The per-plane subsets each hold both normal samples (the pole is on every plane).
    assert_eq!(d.axis_subset(1).len(), 4);
    // A normal sample whose φ is no plane of the file goes to plane 0.
    let d = parse(&file(
        "btdf",
        &["0,0,0,45,633,5.0,0.1", "0,0,10,90,633,1.0,0.02"],
    ))
    .unwrap();
    assert_eq!(d.axes, vec![90.0]);
    assert_eq!(d.samples[0].axis, 0);
}

#[test]
fn missing_kind() {
    let t = format!("# bsdfit dataset v1\n# material: x\n{HEADER}\n0,0,10,0,550,0.25,0.01\n");
    let e = err(&t, &ReadOptions::default());
    assert!(e.contains("f.csv") && e.contains("kind"), "{e}");
    let t = format!("# kind: brdff\n{HEADER}\n0,0,10,0,550,0.25,0.01\n");
    let e = err(&t, &ReadOptions::default());
    assert!(e.contains("f.csv") && e.contains("brdff"), "{e}");
}

#[test]
fn no_rows_and_no_header() {
    let e = err("# kind: brdf\n", &ReadOptions::default());
    assert!(e.contains("f.csv") && e.contains("header"), "{e}");
    let e = err(
        &format!("# kind: brdf\n{HEADER}\n"),
        &ReadOptions::default(),
    );
    assert!(e.contains("f.csv"), "{e}");
}

#[test]
fn unknown_metadata_is_kept() {
    let t = format!("# bsdfit dataset v1\n# kind: brdf\n# operator: J. Doe\n# time: 12:30\n# thickness_mm: 2.0\n{HEADER}\n0,0,10,0,550,0.25,0.01\n");
    let d = parse(&t).unwrap();
    assert_eq!(d.meta.get("operator").map(String::as_str), Some("J. Doe"));
    assert_eq!(d.meta.get("time").map(String::as_str), Some("12:30"));
    assert_eq!(d.meta.get("thickness_mm").map(String::as_str), Some("2.0"));
    // …and written back.
    let back = parse(&d.to_csv()).unwrap();
    assert_eq!(
        back.meta.get("operator").map(String::as_str),
        Some("J. Doe")
    );
    // No material line: the file stem names the material.
    assert_eq!(d.material, "f");
}

#[test]
fn comments_and_blank_lines_keep_line_numbers() {
    let t = format!(
        "# kind: brdf\n\n{HEADER}\n0,0,10,0,550,0.25,0.01\n# a remark\n\n10,0,20,0,550,0.24,0.01\n10,0,30,0,550,oops,0.01\n"
    );
    assert_line_error(&t, 8, "value");
    // The bad row right after a remark and a blank line (csv positions point at the remark).
    let t = format!(
        "# kind: brdf\n{HEADER}\n0,0,10,0,550,0.25,0.01\n# a remark\n\n10,0,30,0,550,oops,0.01\n"
    );
    assert_line_error(&t, 6, "value");
    let t = format!(
        "# kind: brdf\n\n{HEADER}\n0,0,10,0,550,0.25,0.01\n# a remark\n\n10,0,20,0,550,0.24,0.01\n"
    );
    let d = parse(&t).unwrap();
    assert_eq!(
        d.samples.iter().map(|s| s.line).collect::<Vec<_>>(),
        vec![4, 7]
    );
}

#[test]
fn crlf_line_endings() {
    let t = file("brdf", &good_rows()).replace('\n', "\r\n");
    let d = parse(&t).unwrap_or_else(|e| panic!("CRLF file rejected: {e}"));
    assert_eq!(d.len(), 7);
    assert_eq!(d.samples[6].line as usize, FIRST_DATA_LINE + 6);
    let t = with_row(3, "30,0,-45,0,450,x,0.0025").replace('\n', "\r\n");
    assert_line_error(&t, FIRST_DATA_LINE + 3, "value");
}

// ---------------------------------------------------------------------------------------
// Channels

fn spectral() -> String {
    let mut rows = Vec::new();
    for wl in [400, 440, 550, 660, 700] {
        rows.push(format!("0,0,10,0,{wl},0.25,0.01"));
        rows.push(format!("20,0,-30,0,{wl},0.23,0.01"));
    }
    file("brdf", &rows.iter().map(String::as_str).collect::<Vec<_>>())
}

#[test]
fn wavelengths_select_nearest_in_given_order() {
    let opts = ReadOptions {
        wavelengths: Some(vec![650.0, 450.0, 550.0]),
        ..Default::default()
    };
    let d = Dataset::parse(&spectral(), "f.csv", &opts).unwrap();
    assert_eq!(d.channels, vec![660.0, 440.0, 550.0]);
    assert_eq!(d.len(), 6);
    for s in &d.samples {
        assert_eq!(d.channels[s.channel], s.wavelength_nm);
    }
    // Notices say which channel stood in for which request.
    assert!(
        d.notices
            .iter()
            .any(|n| n.contains("650") && n.contains("660")),
        "{:?}",
        d.notices
    );
    // No selection: every wavelength, sorted.
    assert_eq!(
        parse(&spectral()).unwrap().channels,
        vec![400.0, 440.0, 550.0, 660.0, 700.0]
    );
}

#[test]
fn wavelengths_mapping_to_the_same_channel_is_an_error() {
    let opts = ReadOptions {
        wavelengths: Some(vec![690.0, 720.0]),
        ..Default::default()
    };
    let e = err(&spectral(), &opts);
    assert!(e.contains("f.csv") && e.contains("700"), "{e}");
    let opts = ReadOptions {
        wavelengths: Some(vec![]),
        ..Default::default()
    };
    assert!(Dataset::parse(&spectral(), "f.csv", &opts).is_err());
}

// ---------------------------------------------------------------------------------------
// Geometry

#[test]
fn normalise_angles_folds_signed_theta() {
    assert_eq!(normalise_angles(-10.0, 0.0), (10.0, 180.0));
    assert_eq!(normalise_angles(-10.0, 270.0), (10.0, 90.0));
    assert_eq!(normalise_angles(10.0, -90.0), (10.0, 270.0));
    // At the pole the azimuth is kept (it names the plane of a normal sample)…
    assert_eq!(normalise_angles(0.0, 123.0), (0.0, 123.0));
    assert_eq!(normalise_angles(0.0, -90.0), (0.0, 270.0));
    // …but does not make a different geometry.
    assert_eq!(
        geometry_key(0.0, 45.0, 0.0, 90.0, 633.0),
        geometry_key(0.0, 0.0, 0.0, 0.0, 633.0)
    );
    assert_eq!(
        geometry_key(-10.0, 0.0, 20.0, 0.0, 550.0),
        geometry_key(10.0, 180.0, 20.0, 360.0, 550.0)
    );
    assert_ne!(
        geometry_key(10.0, 0.0, 20.0, 0.0, 550.0),
        geometry_key(10.0, 0.0, 20.0, 0.0, 551.0)
    );
    // A tiny negative azimuth does not round to 360.
    assert_eq!(normalise_angles(10.0, -1e-20).1, 0.0);
}

#[test]
fn signed_angles_give_the_right_directions() {
    let d = parse(&file(
        "brdf",
        &[
            "30,0,-45,0,550,0.2,0.01",
            "-30,0,45,0,550,0.2,0.01",
            "10,90,-20,90,550,0.2,0.01",
            "0,0,60,30,550,0.2,0.01",
        ],
    ))
    .unwrap();
    let (s30, c30) = (30f64.to_radians().sin(), 30f64.to_radians().cos());
    let (s45, c45) = (45f64.to_radians().sin(), 45f64.to_radians().cos());
    let ss = d.samples.as_slice();
    // Row 1: wi in +x, wo on the other side (−x): the in-plane mirror geometry.
    assert!(
        close(ss[0].wi(), DVec3::new(s30, 0.0, c30)),
        "{:?}",
        ss[0].wi()
    );
    assert!(
        close(ss[0].wo(), DVec3::new(-s45, 0.0, c45)),
        "{:?}",
        ss[0].wo()
    );
    assert!(
        (ss[0].theta_o - 45f64.to_radians()).abs() < 1e-12
            && (ss[0].phi_o - std::f64::consts::PI).abs() < 1e-12
    );
    // Row 2: the same pair mirrored.
    assert!(
        close(ss[1].wi(), DVec3::new(-s30, 0.0, c30)),
        "{:?}",
        ss[1].wi()
    );
    assert!(
        close(ss[1].wo(), DVec3::new(s45, 0.0, c45)),
        "{:?}",
        ss[1].wo()
    );
    // Row 3: the plane φ = 90°: wi along +y, wo along −y.
    let (s10, c10) = (10f64.to_radians().sin(), 10f64.to_radians().cos());
    let (s20, c20) = (20f64.to_radians().sin(), 20f64.to_radians().cos());
    assert!(
        close(ss[2].wi(), DVec3::new(0.0, s10, c10)),
        "{:?}",
        ss[2].wi()
    );
    assert!(
        close(ss[2].wo(), DVec3::new(0.0, -s20, c20)),
        "{:?}",
        ss[2].wo()
    );
    // Row 4: out of plane.
    let (s60, c60) = (60f64.to_radians().sin(), 60f64.to_radians().cos());
    assert!(close(ss[3].wi(), DVec3::Z));
    assert!(
        close(
            ss[3].wo(),
            DVec3::new(
                s60 * 30f64.to_radians().cos(),
                s60 * 30f64.to_radians().sin(),
                c60
            )
        ),
        "{:?}",
        ss[3].wo()
    );
}

#[test]
fn btdf_puts_wo_in_the_lower_hemisphere() {
    let d = parse(&file(
        "btdf",
        &[
            "0,0,0,0,633,5.0,0.1",
            "0,0,-20,0,633,1.0,0.02",
            "30,0,15,90,633,2.0,0.05",
        ],
    ))
    .unwrap();
    assert_eq!(d.kind, Kind::Btdf);
    let ss = d.samples.as_slice();
    // Straight through at normal incidence: θt = 0 is −n.
    assert!(
        close(ss[0].wi(), DVec3::Z) && close(ss[0].wo(), -DVec3::Z),
        "{:?}",
        ss[0].wo()
    );
    let (s20, c20) = (20f64.to_radians().sin(), 20f64.to_radians().cos());
    assert!(
        close(ss[1].wo(), DVec3::new(-s20, 0.0, -c20)),
        "{:?}",
        ss[1].wo()
    );
    let (s15, c15) = (15f64.to_radians().sin(), 15f64.to_radians().cos());
    assert!(
        close(ss[2].wo(), DVec3::new(0.0, s15, -c15)),
        "{:?}",
        ss[2].wo()
    );
    for s in ss {
        assert!(s.wi().z > 0.0 && s.wo().z < 0.0);
    }
}

// ---------------------------------------------------------------------------------------
// Robustness of the reader: encodings, delimiters, every bad row at once, sane ranges

#[test]
fn utf8_bom_is_skipped() {
    let t = format!("\u{feff}{}", file("brdf", &good_rows()));
    let d = parse(&t).unwrap_or_else(|e| panic!("BOM rejected: {e}"));
    assert_eq!(d.len(), 7);
    // Also when the BOM precedes the header itself.
    let t = format!("\u{feff}{HEADER}\n0,0,10,0,550,0.25,0.01\n");
    let e = err(&t, &ReadOptions::default());
    assert!(e.contains("kind") && !e.contains("theta_i' "), "{e}");
}

#[test]
fn tab_or_semicolon_separated_files_get_a_hint() {
    let t = file("brdf", &good_rows()).replace(',', "\t");
    assert_line_error(&t, 5, "tabs");
    let t = file("brdf", &good_rows()).replace(',', ";");
    assert_line_error(&t, 5, "comma-separated");
    // A single row with semicolons in a comma file.
    assert_line_error(
        &with_row(2, "10;0;20;0;550;0.24;0.003"),
        FIRST_DATA_LINE + 2,
        "comma-separated",
    );
}

#[test]
fn trailing_comma_is_named() {
    let t = file("brdf", &good_rows()).replace(HEADER, &format!("{HEADER},"));
    assert_line_error(&t, 5, "trailing comma");
    let t = file("brdf", &good_rows()).replace("theta_o,phi_o", "theta_o,,phi_o");
    assert_line_error(&t, 5, "empty column name");
    assert_line_error(
        &with_row(2, "10,0,20,0,550,0.24,0.003,"),
        FIRST_DATA_LINE + 2,
        "trailing comma",
    );
}

#[test]
fn latin1_bytes_are_tolerated_in_comments_only() {
    // "# opérateur" in Latin-1: é is the single byte 0xE9.
    let mut bytes =
        b"# bsdfit dataset v1\n# kind: brdf\n# op\xe9rateur: A. B\xe9n\n# remark \xe9\n".to_vec();
    bytes.extend_from_slice(format!("{HEADER}\n0,0,10,0,550,0.25,0.01\n").as_bytes());
    bytes.extend_from_slice(b"# after \xff\n");
    bytes.extend_from_slice(b"0,0,20,0,550,0.24,0.01\n");
    let d = Dataset::parse_reader(&bytes[..], "f.csv", &ReadOptions::default(), &mut |_| {})
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(d.len(), 2);
    assert!(d.meta.keys().any(|k| k.starts_with("op")), "{:?}", d.meta);
    // Elsewhere the byte is reported with its line and column.
    let mut bytes = format!("# kind: brdf\n{HEADER}\n0,0,10,0,550,0.25,0.01\n").into_bytes();
    bytes.extend_from_slice(b"0,0,20,0,550,0.2\xe9,0.01\n");
    let e = Dataset::parse_reader(&bytes[..], "f.csv", &ReadOptions::default(), &mut |_| {})
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("f.csv:4:")
            && e.contains("UTF-8")
            && e.contains("0xE9")
            && e.contains("column 17"),
        "{e}"
    );
}

#[test]
fn every_bad_row_is_reported_at_once() {
    let mut rows = good_rows();
    rows[1] = "10,0,-10,0,550,abc,0.0031";
    rows[4] = "30,0,-45,0,550,0.21,-1";
    rows[6] = "-20,0,35,45,650,0.18";
    let e = err(&file("brdf", &rows), &ReadOptions::default());
    for (k, what) in [(1, "value"), (4, "negative"), (6, "cells")] {
        assert!(
            e.contains(&format!("f.csv:{}:", FIRST_DATA_LINE + k)) && e.contains(what),
            "row {k} ({what}) missing from:\n{e}"
        );
    }
    assert!(e.starts_with("3 bad rows in f.csv"), "{e}");
    // Beyond 20, the rest are counted.
    let bad: Vec<String> = (0..45).map(|k| format!("{k},0,20,0,550,x,0.01")).collect();
    let t = file("brdf", &bad.iter().map(String::as_str).collect::<Vec<_>>());
    let e = err(&t, &ReadOptions::default());
    assert_eq!(
        e.lines().filter(|l| l.starts_with("f.csv:")).count(),
        20,
        "{e}"
    );
    assert!(
        e.contains("… and 25 more") && e.starts_with("45 bad rows"),
        "{e}"
    );
    assert!(
        e.contains(&format!("f.csv:{}:", FIRST_DATA_LINE + 19))
            && !e.contains(&format!("f.csv:{}:", FIRST_DATA_LINE + 20)),
        "{e}"
    );
}

#[test]
fn values_and_uncertainties_outside_sane_ranges() {
    // |value| > 1e7 sr⁻¹ is a unit or exponent mistake.
    assert_line_error(
        &with_row(2, "10,0,20,0,550,2e7,3e5"),
        FIRST_DATA_LINE + 2,
        "1e7",
    );
    // Vanishing uncertainties would give χ²_red = inf: errors naming the line and the
    // floor option.
    for row in ["10,0,20,0,550,0.24,1e-31", "10,0,20,0,550,0.24,1e-14"] {
        let t = with_row(2, row);
        assert_line_error(&t, FIRST_DATA_LINE + 2, "allow-zero-uncertainty");
        let e = err(&t, &ReadOptions::default());
        assert!(e.contains("1e-12") && e.contains("1e-30"), "{e}");
        let opts = ReadOptions {
            allow_zero_uncertainty: true,
            ..Default::default()
        };
        let d = Dataset::parse(&t, "f.csv", &opts).unwrap();
        assert!((d.samples[2].uncertainty - 0.0024).abs() < 1e-15);
    }
    // The limits themselves are fine.
    assert!(parse(&with_row(2, "10,0,20,0,550,1e7,1e5")).is_ok());
    assert!(parse(&with_row(2, "10,0,20,0,550,0.24,3e-13")).is_ok());
}

#[test]
fn progress_is_reported_while_streaming() {
    let rows: Vec<String> = (0..70_000)
        .map(|k| format!("{},0,{},0,550,0.25,0.01", k % 89, (k / 89) % 89))
        .collect();
    let t = file("brdf", &rows.iter().map(String::as_str).collect::<Vec<_>>());
    let mut calls = Vec::new();
    let d = Dataset::parse_reader(t.as_bytes(), "f.csv", &ReadOptions::default(), &mut |p| {
        calls.push(p)
    })
    .unwrap();
    assert_eq!(d.len(), 70_000);
    assert_eq!(calls.len(), 2, "one at 65536 lines, one at the end");
    assert_eq!(calls[1].bytes, t.len() as u64);
    assert_eq!(calls[1].rows, 70_000);
}

// ---------------------------------------------------------------------------------------
// Channel selection messages and bands

fn one_wavelength() -> String {
    file(
        "brdf",
        &["0,0,10,0,550,0.25,0.01", "0,0,20,0,550,0.24,0.01"],
    )
}

#[test]
fn asking_for_more_channels_than_the_file_has_says_so_plainly() {
    let opts = ReadOptions {
        wavelengths: Some(vec![450.0, 550.0, 650.0]),
        ..Default::default()
    };
    let e = err(&one_wavelength(), &opts);
    assert!(
        e.contains("f.csv")
            && e.contains("has only 1 wavelength: 550 nm")
            && e.contains("3 channels"),
        "{e}"
    );
    assert!(!e.contains("already selected"), "{e}");
    // Two requests near the same single channel.
    let opts = ReadOptions {
        wavelengths: Some(vec![560.0, 540.0]),
        ..Default::default()
    };
    let e = err(
        &file(
            "brdf",
            &["0,0,10,0,550,0.25,0.01", "0,0,10,0,700,0.24,0.01"],
        ),
        &opts,
    );
    assert!(
        e.contains("560 nm and 540 nm")
            && e.contains("550 nm channel")
            && e.contains("550, 700 nm"),
        "{e}"
    );
}

#[test]
fn a_wavelength_far_from_every_channel_is_an_error() {
    let opts = ReadOptions {
        wavelengths: Some(vec![480.0]),
        ..Default::default()
    };
    let e = err(&one_wavelength(), &opts);
    assert!(
        e.contains("f.csv") && e.contains("within 50 nm of 480 nm") && e.contains("550 nm"),
        "{e}"
    );
    // 50 nm away is still accepted, with a notice.
    let opts = ReadOptions {
        wavelengths: Some(vec![500.0]),
        ..Default::default()
    };
    let d = Dataset::parse(&one_wavelength(), "f.csv", &opts).unwrap();
    assert_eq!(d.channels, vec![550.0]);
    assert!(d
        .notices
        .iter()
        .any(|n| n.contains("500 nm → nearest present 550 nm")));
}

#[test]
fn band_averages_neighbouring_wavelengths() {
    // Wavelengths 540, 545, 550, 555, 560 and 650 at two geometries; the second geometry
    // lacks 560 nm.
    let mut rows = Vec::new();
    for (k, wl) in [540, 545, 550, 555, 560, 650].iter().enumerate() {
        rows.push(format!("0,0,10,0,{wl},{},0.01", 0.1 + 0.01 * k as f64));
        if *wl != 560 {
            rows.push(format!("20,0,-30,0,{wl},{},0.02", 0.2 + 0.01 * k as f64));
        }
    }
    let t = file("brdf", &rows.iter().map(String::as_str).collect::<Vec<_>>());
    let opts = ReadOptions {
        wavelengths: Some(vec![550.0, 650.0]),
        band_nm: Some(10.0),
        ..Default::default()
    };
    let d = Dataset::parse(&t, "f.csv", &opts).unwrap();
    assert_eq!(d.channels, vec![550.0, 650.0]);
    assert_eq!(d.len(), 4);
    let s = &d.samples[0]; // geometry 1, 550 nm band: values 0.10 … 0.14
    assert_eq!(s.channel, 0);
    assert!((s.value - 0.12).abs() < 1e-12, "{}", s.value);
    assert!((s.uncertainty - (5.0 * 0.01f64 * 0.01).sqrt() / 5.0).abs() < 1e-15);
    let s = &d.samples[1]; // geometry 2, 550 nm band: four values 0.20 … 0.23
    assert!((s.value - 0.215).abs() < 1e-12 && (s.uncertainty - 0.01).abs() < 1e-15);
    let s = &d.samples[2]; // geometry 1, 650 nm: one value
    assert!(s.channel == 1 && (s.value - 0.15).abs() < 1e-12 && s.uncertainty == 0.01);
    assert!(
        d.notices
            .iter()
            .any(|n| n.contains("550 nm averages 540, 545, 550, 555, 560 nm")),
        "{:?}",
        d.notices
    );
    assert!(
        d.notices.iter().any(|n| n.contains("1 to 5 samples")),
        "{:?}",
        d.notices
    );
    // Overlapping bands and a band without --wavelengths are errors.
    let opts = ReadOptions {
        wavelengths: Some(vec![540.0, 560.0]),
        band_nm: Some(15.0),
        ..Default::default()
    };
    assert!(err(&t, &opts).contains("bands of both"));
    let opts = ReadOptions {
        band_nm: Some(5.0),
        ..Default::default()
    };
    assert!(err(&t, &opts).contains("--band needs --wavelengths"));
}

/// Found by fuzzing (docs/reliability.md): a band average of finite uncertainties beyond
/// about 1e154 sr⁻¹ (a typo such as `0.003e00167`) squared them to ∞, and the dataset was
/// read with an infinite uncertainty.
#[test]
fn band_average_of_huge_uncertainties_is_finite() {
    let t = file(
        "brdf",
        &[
            "0,0,10,0,550,0.15,3e164",
            "0,0,20,0,550,0.15,1e300",
            "0,0,20,0,555,0.15,1e300",
        ],
    );
    let opts = ReadOptions {
        wavelengths: Some(vec![550.0]),
        band_nm: Some(10.0),
        ..Default::default()
    };
    let d = Dataset::parse(&t, "f.csv", &opts).unwrap();
    let u: Vec<f64> = d.samples.iter().map(|s| s.uncertainty).collect();
    assert_eq!(u.len(), 2);
    // One value: its own uncertainty; two: sqrt(2)·1e300 / 2.
    assert!((u[0] / 3e164 - 1.0).abs() < 1e-15, "{u:?}");
    assert!((u[1] / (1e300 / 2f64.sqrt()) - 1.0).abs() < 1e-15, "{u:?}");
}

#[test]
fn out_of_plane_data_is_one_plane() {
    // Up to 32 distinct azimuths are measurement planes…
    let rows: Vec<String> = (0..32)
        .map(|k| format!("10,0,40,{},550,0.2,0.01", k * 5))
        .collect();
    let d = parse(&file(
        "brdf",
        &rows.iter().map(String::as_str).collect::<Vec<_>>(),
    ))
    .unwrap();
    assert_eq!(d.axes.len(), 32);
    assert!(d.samples.iter().enumerate().all(|(k, s)| s.axis == k));
    // …more are out-of-plane data (MERL, dense ALTA scans): a single plane, said so.
    let rows: Vec<String> = (0..33)
        .map(|k| format!("10,0,40,{},550,0.2,0.01", k * 5))
        .collect();
    let d = parse(&file(
        "brdf",
        &rows.iter().map(String::as_str).collect::<Vec<_>>(),
    ))
    .unwrap();
    assert_eq!(d.axes, vec![0.0]);
    assert!(d.samples.iter().all(|s| s.axis == 0));
    assert!(
        d.notices
            .iter()
            .any(|n| n.contains("33 distinct outgoing azimuths")),
        "{:?}",
        d.notices
    );
}

/// What other tools write into a v1-shaped CSV beyond bsdfit's own files: the columns in
/// another order, capitalised names, quoted cells, spaces after the commas, every form
/// of a number's exponent and decimal point, CRLF without a final line end. Each value is
/// checked against the row it came from; a UTF-16 file is refused, naming the encoding.
#[test]
fn csv_dialects_of_other_tools_read_to_the_same_samples() {
    let text = "# kind: brdf\r\n\
                Value,phi_i,\"theta_i\",theta_o, phi_o ,Wavelength_NM,uncertainty\r\n\
                \"0.25\", 0, 10,20,0,550,2.5E-3\r\n\
                .5,0,30,40,90,550.,5e-3\r\n\
                1.25e+0,180,45,60,0,5.5e2,0.0125";
    let d = parse(text).unwrap();
    assert_eq!(d.len(), 3);
    let want = [
        (10.0, 0.0, 20.0, 0.0, 0.25, 2.5e-3),
        (30.0, 0.0, 40.0, 90.0, 0.5, 5e-3),
        (45.0, 180.0, 60.0, 0.0, 1.25, 0.0125),
    ];
    for (s, w) in d.samples.iter().zip(want) {
        let deg = |r: f64| r.to_degrees();
        assert!(
            (deg(s.theta_i) - w.0).abs() < 1e-9
                && (deg(s.phi_i) - w.1).abs() < 1e-9
                && (deg(s.theta_o) - w.2).abs() < 1e-9
                && (deg(s.phi_o) - w.3).abs() < 1e-9
                && s.value == w.4
                && s.uncertainty == w.5
                && s.wavelength_nm == 550.0,
            "{s:?} vs {w:?}"
        );
    }
    let mut utf16 = vec![0xFF, 0xFE];
    for u in
        "# kind: brdf\ntheta_i,phi_i,theta_o,phi_o,wavelength_nm,value,uncertainty\n".encode_utf16()
    {
        utf16.extend_from_slice(&u.to_le_bytes());
    }
    let e = bsdfit::data::readers::parse_bytes(&utf16, "wide.csv", &ReadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("wide.csv:1") && e.contains("UTF-8"), "{e}");
}

/// Reader options from a front end's arguments: the uncertainty to assume (text or
/// numbers) and a band are checked once, before any file, naming the option in words,
/// which the command line prints as its flag (once).
#[test]
fn read_requests_are_checked_once_naming_the_option() {
    use bsdfit::data::{AssumeArg, ReadRequest};
    let request = |assume: Option<AssumeArg>, band: Option<f64>, wavelengths: bool| ReadRequest {
        assume_uncertainty: assume,
        band_nm: band,
        wavelengths: wavelengths.then(|| vec![550.0]),
        ..Default::default()
    };
    let o = ReadOptions::from_request(request(Some(AssumeArg::Values(0.05, 0.001)), None, false))
        .unwrap();
    assert_eq!(o.assume_uncertainty, Some((0.05, 0.001)));
    assert_eq!(
        o.max_samples,
        Some(bsdfit::data::readers::merl::DEFAULT_MAX_SAMPLES)
    );
    let text = ReadOptions::from_request(request(
        Some(AssumeArg::Text("0.05, 0.001".into())),
        Some(2.0),
        true,
    ))
    .unwrap();
    assert_eq!(text.assume_uncertainty, o.assume_uncertainty);
    assert_eq!(text.band_nm, Some(2.0));
    for (r, words, flags) in [
        (
            request(Some(AssumeArg::Text("x".into())), None, false),
            "assume_uncertainty: expected REL,ABS such as 0.05,0.001",
            "--assume-uncertainty: expected REL,ABS such as 0.05,0.001",
        ),
        (
            request(Some(AssumeArg::Values(-0.1, 0.01)), None, false),
            "assume_uncertainty: (-0.1, 0.01): REL and ABS must be finite",
            "--assume-uncertainty: (-0.1, 0.01): REL and ABS must be finite",
        ),
        (
            request(None, Some(5.0), false),
            "band needs wavelengths: the centres",
            "--band needs --wavelengths: the centres",
        ),
        (
            request(None, Some(-1.0), true),
            "band=-1: expected a width ≥ 0 nm",
            "--band -1: expected a width ≥ 0 nm",
        ),
    ] {
        let e = ReadOptions::from_request(r).unwrap_err();
        assert!(e.to_string().starts_with(words), "{e}");
        assert!(bsdfit::cli::error_text(&e).starts_with(flags), "{e}");
    }
}
