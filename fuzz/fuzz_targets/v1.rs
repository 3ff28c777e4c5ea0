//! The v1 CSV reader on arbitrary bytes.
#![no_main]
use bsdfit::data::Dataset;
use bsdfit_fuzz::{check, option_sets, FILE};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    for opts in option_sets() {
        check(Dataset::parse_reader(data, FILE, &opts, &mut |_| {}), FILE);
    }
});
