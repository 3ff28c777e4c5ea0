//! The MERL reader on arbitrary bytes, and on full-size tables built from them.
//!
//! A MERL file is 34,992,012 bytes, far beyond what a fuzzer mutates, and the reader
//! refuses any other size (after the header check). So an input that starts with the
//! MERL header is also read as the *start of each colour block* of a full table: its
//! bytes after the header, cut into three equal runs of whole doubles, become the first
//! cells of the R, G and B blocks, every other cell holds −1 (unmeasured). The full
//! table lives in one buffer reused from input to input, and is read with two of the
//! three option sets (see below): a scan of 1.46 M cells is the cost of an input here.
#![no_main]
use bsdfit::data::readers::merl::{self, CELLS, DIMS, FILE_BYTES};
use bsdfit_fuzz::{check, option_sets, FILE};
use libfuzzer_sys::fuzz_target;
use std::sync::{Mutex, OnceLock};

fn unmeasured_table() -> Vec<u8> {
    let mut t = Vec::with_capacity(FILE_BYTES);
    for d in DIMS {
        t.extend_from_slice(&(d as i32).to_le_bytes());
    }
    for _ in 0..3 * CELLS {
        t.extend_from_slice(&(-1.0f64).to_le_bytes());
    }
    t
}

static TABLE: OnceLock<Mutex<Vec<u8>>> = OnceLock::new();

fuzz_target!(|data: &[u8]| {
    for opts in option_sets() {
        check(merl::parse(data, FILE, &opts), FILE);
    }
    let header: Vec<u8> = DIMS
        .iter()
        .flat_map(|&d| (d as i32).to_le_bytes())
        .collect();
    if data.len() == FILE_BYTES || !data.starts_with(&header) {
        return;
    }
    let payload = &data[12..];
    let n = (payload.len() / 24).min(CELLS);
    let mut table = TABLE
        .get_or_init(|| Mutex::new(unmeasured_table()))
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    for c in 0..3 {
        let at = 12 + 8 * c * CELLS;
        table[at..at + 8 * n].copy_from_slice(&payload[8 * c * n..8 * (c + 1) * n]);
    }
    // A full table takes milliseconds to scan: the strict set (refused after the layout
    // check) and one of the others, chosen by the input's length.
    let [strict, others @ ..] = option_sets();
    check(merl::parse(&table, FILE, &strict), FILE);
    let other = &others[data.len() % others.len()];
    check(merl::parse(&table, FILE, other), FILE);
    for c in 0..3 {
        let at = 12 + 8 * c * CELLS;
        for cell in table[at..at + 8 * n].chunks_exact_mut(8) {
            cell.copy_from_slice(&(-1.0f64).to_le_bytes());
        }
    }
});
