//! The ASTM E1392 reader on arbitrary bytes: the readers' contract, and every error
//! naming file:line:column.
#![no_main]
use bsdfit::data::readers::astm;
use bsdfit_fuzz::{check_located, option_sets, FILE};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    for opts in option_sets() {
        check_located(astm::parse_reader(data, FILE, &opts, &mut |_| {}), FILE);
    }
});
