//! The entry points any file goes through, format recognised by content: `parse_bytes`
//! (and, when the content is not recognised, under a name of each extension that picks
//! a reader then) and `load`, what the command line uses, from a file on disk (its
//! extension chosen by the input's length).
#![no_main]
use bsdfit::data::readers;
use bsdfit_fuzz::{check, option_sets};
use libfuzzer_sys::fuzz_target;
use std::path::PathBuf;
use std::sync::OnceLock;

const NAMES: [&str; 3] = ["fuzz-input.dat", "fuzz-input.binary", "fuzz-input.bsdf"];

fn folder() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let d = std::env::temp_dir().join(format!("bsdfit-fuzz-any-{}", std::process::id()));
        std::fs::create_dir_all(&d).expect("a temporary folder");
        d
    })
}

fuzz_target!(|data: &[u8]| {
    let opts = option_sets();
    let recognised = readers::sniff(data, data.len() as u64).is_some();
    for (k, name) in NAMES.into_iter().enumerate() {
        if k > 0 && recognised {
            break; // the name changes nothing but the messages
        }
        for o in &opts {
            check(readers::parse_bytes(data, name, o), name);
        }
    }
    let path = folder().join(NAMES[data.len() % 3]);
    std::fs::write(&path, data).expect("write the input");
    let file = path.display().to_string();
    for o in &opts {
        check(readers::load(&path, o), &file);
    }
});
