//! `bsdfit synth`'s dense geometries: the isotropic grid and every cell of a MERL table,
//! written as CSV or as a MERL table, read back as data.

use bsdfit::data::readers::merl;
use bsdfit::data::{Dataset, ReadOptions};
use bsdfit::math::direction;
use bsdfit::workflows::synth::geometry;
use std::process::Command;

mod common;

#[test]
fn the_grid_covers_the_isotropic_half_space_once() {
    let (_, rows) = geometry("grid:10").unwrap();
    // θi and θo in 0, 10, … 80; φo 0 … 180 by 10 (19 azimuths), one at θo = 0; the
    // retro direction (θo = θi, φo = 0) left out for θi > 0, and for θi = θo = 0 too.
    let polar = 9;
    let expected = polar * (1 + (polar - 1) * 19) - polar;
    assert_eq!(rows.len(), expected);
    let mut seen = std::collections::HashSet::new();
    for r in &rows {
        assert!(r[0] <= 85.0 && r[2] <= 85.0 && (0.0..=180.0).contains(&r[3]) && r[1] == 0.0);
        assert!(seen.insert(r.map(f64::to_bits)), "{r:?} twice");
    }
    assert_eq!(geometry("grid").unwrap().1.len(), {
        let polar = 18;
        polar * (1 + (polar - 1) * 37) - polar
    });
    assert!(geometry("grid:0").is_err() && geometry("grid:x").is_err());
}

#[test]
fn the_merl_geometry_is_every_measurable_cell_once() {
    let (_, rows) = geometry("merl").unwrap();
    let measurable = (0..merl::CELLS)
        .filter(|&i| {
            let (th, td, pd) = merl::cell_angles(i);
            merl::cell_directions(th, td, pd).is_some()
        })
        .count();
    assert!(rows.len() <= measurable && rows.len() + 1000 > measurable);
    assert!(rows.len() > 1_000_000, "{} cells", rows.len());
    // Each row lies in a cell of its own: the table's lookup of its directions finds
    // one distinct cell per row.
    let mut cells = std::collections::HashSet::new();
    for r in rows.iter().step_by(97) {
        let wi = direction(r[0].to_radians(), r[1].to_radians());
        let wo = direction(r[2].to_radians(), r[3].to_radians());
        assert!(cells.insert(merl::lookup_index(wi, wo)), "{r:?}");
    }
}

#[test]
fn synth_writes_a_merl_table_that_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("grid.binary");
    let run = Command::new(common::bin())
        .args([
            "synth",
            "--model",
            "on",
            "--params",
            "rho=0.2:0.4:0.6,sigma=0.5",
            "--geometry",
            "grid:10",
            "--noise",
            "0.01,0.0001",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let opts = ReadOptions {
        assume_uncertainty: Some((0.01, 1e-4)),
        max_samples: Some(0),
        ..Default::default()
    };
    let data = Dataset::read(&out, &opts).unwrap();
    // Every grid direction is a cell (a few share one), in three channels, and the
    // channels come back in order: R (650 nm) holds the reddest albedo.
    let (_, rows) = geometry("grid:10").unwrap();
    assert!(
        data.len().is_multiple_of(3) && data.len() / 3 > rows.len() * 9 / 10,
        "{}",
        data.len()
    );
    let mean = |c: usize| {
        let v: Vec<f64> = data
            .samples
            .iter()
            .filter(|s| s.channel == c)
            .map(|s| s.value)
            .collect();
        v.iter().sum::<f64>() / v.len() as f64
    };
    assert!(mean(0) < mean(1) && mean(1) < mean(2));
    assert!(
        (mean(2) / mean(0) - 3.0).abs() < 0.1,
        "{} {}",
        mean(0),
        mean(2)
    );
    // A BTDF cannot be a MERL table.
    let bad = Command::new(common::bin())
        .args(["synth", "--model", "btdf(tr)", "--out"])
        .arg(dir.path().join("t.binary"))
        .output()
        .unwrap();
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("MERL table holds three BRDF channels"));
}
