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

/// `bsdfit args` with the environment variables `env` set (process-wide switches such as
/// `BSDFIT_GPU_FAULT`, which only a separate process can be given).
pub fn bsdfit_env(args: &[&str], env: &[(&str, &str)]) -> Output {
    Command::new(super::bin())
        .args(args)
        .envs(env.iter().copied())
        .output()
        .expect("run bsdfit")
}

/// [`bsdfit_env`], killed and failed where it still runs after `limit` (a command that
/// would otherwise wait forever: a test of a timeout that broke).
pub fn bsdfit_env_within(
    args: &[&str],
    env: &[(&str, &str)],
    limit: std::time::Duration,
) -> Output {
    use std::io::Read;
    use std::process::Stdio;
    let mut child = Command::new(super::bin())
        .args(args)
        .envs(env.iter().copied())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run bsdfit");
    // Drained as the command writes, so that it never waits on a full pipe.
    let drain = |mut r: Box<dyn Read + Send>| {
        std::thread::spawn(move || {
            let mut v = Vec::new();
            r.read_to_end(&mut v).ok();
            v
        })
    };
    let out = drain(Box::new(child.stdout.take().expect("stdout")));
    let err = drain(Box::new(child.stderr.take().expect("stderr")));
    let started = std::time::Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait for bsdfit") {
            break status;
        }
        if started.elapsed() > limit {
            child.kill().ok();
            child.wait().ok();
            let err = err.join().unwrap_or_default();
            panic!(
                "bsdfit {args:?} with {env:?} still ran after {limit:?}: hung\n{}",
                text(&err)
            );
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    };
    Output {
        status,
        stdout: out.join().unwrap_or_default(),
        stderr: err.join().unwrap_or_default(),
    }
}
