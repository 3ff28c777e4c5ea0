//! The Mueller-matrix BRDF CSV reader (NIST's tables, SCATMECH's column names) on
//! arbitrary bytes: the readers' contract, and every error naming file:line:column.
#![no_main]
use bsdfit::data::readers::mueller;
use bsdfit_fuzz::{check_located, option_sets, FILE};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    for opts in option_sets() {
        check_located(mueller::parse_reader(data, FILE, &opts, &mut |_| {}), FILE);
    }
});
