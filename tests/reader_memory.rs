//! The readers stream: reading a large v1 file takes at most twice its size in memory.
//!
//! One test in its own process (an integration-test binary), so the peak resident set
//! (`VmHWM` of /proc/self/status, Linux) is this read's: the file is written first, the
//! process's resident size noted, then the file is read and the high-water mark compared.
//! Rows are shaped like a goniometer's export (six decimals, ~55 bytes a row).

mod common;

use bsdfit::data::{readers, ReadOptions};
use std::io::Write;

fn status_kib(field: &str) -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with(field))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

#[test]
fn reading_a_large_file_takes_at_most_twice_its_size() {
    if status_kib("VmHWM:").is_none() {
        common::missing("/proc/self/status (Linux), to measure the peak memory");
        return;
    }
    let rows: usize = std::env::var("BSDFIT_MEMORY_ROWS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(600_000);
    let path = std::env::temp_dir().join(format!("bsdfit-memory-{}.csv", std::process::id()));
    {
        let mut f = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        writeln!(
            f,
            "# bsdfit dataset v1\n# material: memory test\n# kind: brdf"
        )
        .unwrap();
        writeln!(
            f,
            "theta_i,phi_i,theta_o,phi_o,wavelength_nm,value,uncertainty"
        )
        .unwrap();
        // Distinct geometries over three wavelengths (no repeated-geometry notices).
        for k in 0..rows {
            let (g, c) = (k / 3, k % 3);
            let ti = (g % 89) as f64 + 0.25;
            let to = ((g / 89) % 89) as f64 + 0.5;
            let po = ((g / (89 * 89)) % 360) as f64 + 0.125;
            let v = 0.1 + 1e-7 * k as f64;
            writeln!(
                f,
                "{ti:.6},0.000000,{to:.6},{po:.6},{},{v:.6},{:.6}",
                450 + 100 * c,
                0.01 * v + 1e-4
            )
            .unwrap();
        }
    }
    let size = std::fs::metadata(&path).unwrap().len() as f64;
    let before = status_kib("VmRSS:").unwrap() as f64 * 1024.0;
    let ds = readers::load(&path, &ReadOptions::default()).unwrap();
    let peak = status_kib("VmHWM:").unwrap() as f64 * 1024.0;
    std::fs::remove_file(&path).ok();
    assert_eq!(ds.len(), rows);
    let ratio = (peak - before) / size;
    eprintln!(
        "{rows} rows, {:.1} MB file: peak +{:.1} MB while reading = {ratio:.2}× the file ({:.0} bytes a row)",
        size / 1e6,
        (peak - before) / 1e6,
        size / rows as f64
    );
    assert!(
        ratio <= 2.0,
        "reading took {ratio:.2}× the file's size (bound 2×)"
    );
}
