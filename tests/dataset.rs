//! The v1 dataset format (DESIGN §2): reading, validation messages (file and line),
//! round trips, channel selection and the signed-angle convention (DESIGN §1).

mod common;

use bsdfit::data::{normalise_angles, Dataset, Kind, ReadOptions};
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
        assert_eq!(s.line, FIRST_DATA_LINE + k, "line of sample {k}");
        assert_eq!(d.channels[s.channel], s.wavelength_nm);
        assert!(s.theta_i >= 0.0 && s.theta_o >= 0.0);
        assert!((s.wi.length() - 1.0).abs() < 1e-12 && (s.wo.length() - 1.0).abs() < 1e-12);
        assert!(
            s.wi.z >= 0.0 && s.wo.z >= 0.0,
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
            close(a.wi, b.wi) && close(a.wo, b.wo),
            "{:?} {:?} vs {:?} {:?}",
            a.wi,
            a.wo,
            b.wi,
            b.wo
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
        assert!(close(a.wo, b.wo) && close(a.wi, b.wi));
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
fn duplicate_rows() {
    let mut rows = good_rows();
    rows.push("10,0,20,0,550,0.2401,0.0030"); // same as row 2
    let e = err(&file("brdf", &rows), &ReadOptions::default());
    assert!(
        e.contains(&format!("f.csv:{}:", FIRST_DATA_LINE + 7)),
        "{e}"
    );
    assert!(
        e.contains("duplicate") && e.contains(&(FIRST_DATA_LINE + 2).to_string()),
        "{e}"
    );
}

#[test]
fn duplicate_written_with_signed_angle() {
    // θo = −10, φo = 0 is θo = 10, φo = 180 (DESIGN §1).
    let mut rows = good_rows();
    rows.push("10,0,10,180,550,0.2601,0.0031"); // same as row 1 (10,0,-10,0)
    assert_line_error(&file("brdf", &rows), FIRST_DATA_LINE + 7, "duplicate");
    // The same on the incident side, with φ wrapping past 360.
    let mut rows = good_rows();
    rows.push("20,180,35,45,650,0.18,0.0022"); // same as row 6 (-20,0,35,45)
    assert_line_error(&file("brdf", &rows), FIRST_DATA_LINE + 7, "duplicate");
    let mut rows = good_rows();
    rows.push("30,450,60,-90,650,0.19,0.0024"); // same as row 5 (30,90,60,270)
    assert_line_error(&file("brdf", &rows), FIRST_DATA_LINE + 7, "duplicate");
    // At the pole the azimuth means nothing.
    let mut rows = good_rows();
    rows.push("0,45,10,0,550,0.25,0.0031"); // same as row 0 (0,0,10,0)
    assert_line_error(&file("brdf", &rows), FIRST_DATA_LINE + 7, "duplicate");
    // Same geometry at another wavelength is not a duplicate.
    let mut rows = good_rows();
    rows.push("10,0,10,180,650,0.2601,0.0031");
    assert_eq!(parse(&file("brdf", &rows)).unwrap().len(), 8);
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
    assert_eq!(d.samples[6].line, FIRST_DATA_LINE + 6);
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
    assert_eq!(normalise_angles(0.0, 123.0), (0.0, 0.0));
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
    assert!(close(ss[0].wi, DVec3::new(s30, 0.0, c30)), "{:?}", ss[0].wi);
    assert!(
        close(ss[0].wo, DVec3::new(-s45, 0.0, c45)),
        "{:?}",
        ss[0].wo
    );
    assert!(
        (ss[0].theta_o - 45f64.to_radians()).abs() < 1e-12
            && (ss[0].phi_o - std::f64::consts::PI).abs() < 1e-12
    );
    // Row 2: the same pair mirrored.
    assert!(
        close(ss[1].wi, DVec3::new(-s30, 0.0, c30)),
        "{:?}",
        ss[1].wi
    );
    assert!(close(ss[1].wo, DVec3::new(s45, 0.0, c45)), "{:?}", ss[1].wo);
    // Row 3: the plane φ = 90°: wi along +y, wo along −y.
    let (s10, c10) = (10f64.to_radians().sin(), 10f64.to_radians().cos());
    let (s20, c20) = (20f64.to_radians().sin(), 20f64.to_radians().cos());
    assert!(close(ss[2].wi, DVec3::new(0.0, s10, c10)), "{:?}", ss[2].wi);
    assert!(
        close(ss[2].wo, DVec3::new(0.0, -s20, c20)),
        "{:?}",
        ss[2].wo
    );
    // Row 4: out of plane.
    let (s60, c60) = (60f64.to_radians().sin(), 60f64.to_radians().cos());
    assert!(close(ss[3].wi, DVec3::Z));
    assert!(
        close(
            ss[3].wo,
            DVec3::new(
                s60 * 30f64.to_radians().cos(),
                s60 * 30f64.to_radians().sin(),
                c60
            )
        ),
        "{:?}",
        ss[3].wo
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
        close(ss[0].wi, DVec3::Z) && close(ss[0].wo, -DVec3::Z),
        "{:?}",
        ss[0].wo
    );
    let (s20, c20) = (20f64.to_radians().sin(), 20f64.to_radians().cos());
    assert!(
        close(ss[1].wo, DVec3::new(-s20, 0.0, -c20)),
        "{:?}",
        ss[1].wo
    );
    let (s15, c15) = (15f64.to_radians().sin(), 15f64.to_radians().cos());
    assert!(
        close(ss[2].wo, DVec3::new(0.0, s15, -c15)),
        "{:?}",
        ss[2].wo
    );
    for s in ss {
        assert!(s.wi.z > 0.0 && s.wo.z < 0.0);
    }
}
