//! Test datasets for the diagnose unit tests.

use crate::data::{Dataset, Kind, RawRow};

/// A dataset with the given (θi, φi, θo, φo) rows and `channels` channels, every value
/// 0.1 ± 0.01.
pub(super) fn dataset(kind: Kind, rows: &[[f64; 4]], channels: usize) -> Dataset {
    let wl = [450.0, 550.0, 650.0];
    let mut raw = Vec::new();
    for (i, r) in rows.iter().enumerate() {
        for (c, &w) in wl.iter().take(channels).enumerate() {
            raw.push((
                i * channels + c + 1,
                RawRow {
                    theta_i: r[0],
                    phi_i: r[1],
                    theta_o: r[2],
                    phi_o: r[3],
                    wavelength_nm: w,
                    value: 0.1,
                    uncertainty: 0.01,
                },
            ));
        }
    }
    Dataset::from_rows(kind, "t", &raw, "<t>", &crate::data::ReadOptions::default()).unwrap()
}
