//! The RGL `.bsdf` (tensor file) reader on arbitrary bytes.
#![no_main]
use bsdfit::data::readers::rgl;
use bsdfit_fuzz::{check, option_sets, FILE};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    for opts in option_sets() {
        check(rgl::parse(data, FILE, &opts), FILE);
    }
});
