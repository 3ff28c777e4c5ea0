//! Running the `bsdfit` binary from the integration tests and checking its outcome.

use std::path::Path;
use std::process::{Command, Output};

pub fn bsdfit(args: &[&str]) -> Output {
    Command::new(super::bin())
        .args(args)
        .output()
        .expect("run bsdfit")
}

pub fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

pub fn assert_ok(out: &Output, what: &str) {
    assert!(
        out.status.success(),
        "{what} failed ({:?})\nstdout:\n{}\nstderr:\n{}",
        out.status.code(),
        text(&out.stdout),
        text(&out.stderr)
    );
}

/// The command must fail with exit code 1, no panic, and a message containing every needle.
pub fn assert_clear_error(out: &Output, needles: &[&str]) -> String {
    let err = text(&out.stderr);
    assert_eq!(
        out.status.code(),
        Some(1),
        "expected exit code 1, got {:?}; stderr:\n{err}",
        out.status.code()
    );
    assert!(
        !err.contains("panicked"),
        "panic instead of an error:\n{err}"
    );
    for n in needles {
        assert!(err.contains(n), "expected '{n}' in stderr:\n{err}");
    }
    err
}

pub fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}
