//! Writing output files so that nothing is half-written and every error names its path.
//!
//! - [`write_atomic`]: every results/JSON/PNG/SVG/HTML file is written to a temporary file
//!   beside its target and renamed into place, so a reader (or a crash) never sees half a
//!   file; the temporary is removed when anything fails.
//! - [`check_writable_file`] / [`check_writable_dir`]: commands check their destinations
//!   before a long computation (create the directory, create and remove a probe file), so a
//!   typo in `--json` costs nothing.

use anyhow::{Context, Result};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

static COUNTER: AtomicU64 = AtomicU64::new(0);

/// A name beside `path` for a temporary file of this process: `.NAME.PID-N.tmp`.
fn temp_beside(path: &Path, what: &str) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    path.with_file_name(format!(".{name}.{}-{n}.{what}", std::process::id()))
}

/// The directory a file is written into ("." for a bare file name).
fn parent_dir(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// Create `dir` (and its parents), with an error that names it.
pub fn create_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))
}

/// Write `bytes` to `path` atomically: a temporary file beside it, then a rename. The
/// directory is created if needed. On failure the temporary is removed and the error
/// names `path`; an existing file at `path` is left as it was.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = parent_dir(path);
    std::fs::create_dir_all(dir).with_context(|| {
        format!(
            "cannot write {}: cannot create {}",
            path.display(),
            dir.display()
        )
    })?;
    let tmp = temp_beside(path, "tmp");
    let result = (|| -> std::io::Result<()> {
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)?;
        f.write_all(bytes)?;
        f.flush()?;
        drop(f);
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(anyhow::anyhow!("cannot write {}: {e}", path.display()));
    }
    Ok(())
}

/// Write `text` to `path` atomically ([`write_atomic`]), and only if it changes the file.
pub fn write_if_changed(path: &Path, text: &str) -> Result<bool> {
    if std::fs::read(path).ok().as_deref() == Some(text.as_bytes()) {
        return Ok(false);
    }
    write_atomic(path, text.as_bytes())?;
    Ok(true)
}

/// Create a probe file in `dir` and remove it: the directory is writable now.
fn probe(dir: &Path) -> std::io::Result<()> {
    let p = temp_beside(&dir.join("bsdfit"), "probe");
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&p)?;
    std::fs::remove_file(&p)
}

/// Check before the work starts that `path` can be written (`option` names the option it
/// came from, e.g. `--json`): its directory exists or can be created and takes a new
/// file, and `path` is not a directory.
pub fn check_writable_file(path: &Path, option: &str) -> Result<()> {
    let dir = parent_dir(path);
    std::fs::create_dir_all(dir).map_err(|e| {
        anyhow::anyhow!(
            "{option} {}: cannot create the directory {}: {e}",
            path.display(),
            dir.display()
        )
    })?;
    anyhow::ensure!(
        !path.is_dir(),
        "{option} {}: is a directory; give a file name",
        path.display()
    );
    probe(dir).map_err(|e| {
        anyhow::anyhow!(
            "{option} {}: cannot write in {}: {e}",
            path.display(),
            dir.display()
        )
    })?;
    if path.exists() {
        // Replaced by a rename, but a read-only file usually means "do not overwrite".
        let ro = std::fs::metadata(path)
            .map(|m| m.permissions().readonly())
            .unwrap_or(false);
        anyhow::ensure!(!ro, "{option} {}: the file is read-only", path.display());
    }
    Ok(())
}

/// Check before the work starts that `dir` exists or can be created and takes new files.
pub fn check_writable_dir(dir: &Path, option: &str) -> Result<()> {
    anyhow::ensure!(
        !dir.exists() || dir.is_dir(),
        "{option} {}: exists and is not a directory",
        dir.display()
    );
    std::fs::create_dir_all(dir)
        .map_err(|e| anyhow::anyhow!("{option} {}: cannot create it: {e}", dir.display()))?;
    probe(dir).map_err(|e| anyhow::anyhow!("{option} {}: cannot write in it: {e}", dir.display()))
}

/// Write a command's final result to `path`; if that fails after the work is done, keep
/// the result: print `text` to stdout (when `print_on_failure`) or write a copy to the
/// system's temporary directory, and return an error that says where it went.
pub fn write_result(path: &Path, text: &str, print_on_failure: bool) -> Result<()> {
    let Err(e) = write_atomic(path, text.as_bytes()) else {
        return Ok(());
    };
    if print_on_failure {
        println!("{text}");
        return Err(e.context("the result was printed to stdout above instead"));
    }
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "result".into());
    let fallback = std::env::temp_dir().join(format!("bsdfit-{}-{name}", std::process::id()));
    match write_atomic(&fallback, text.as_bytes()) {
        Ok(()) => Err(e.context(format!("a copy of the result is in {}", fallback.display()))),
        Err(_) => {
            println!("{text}");
            Err(e.context("the result was printed to stdout above instead"))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atomic_write_replaces_and_cleans_up() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("sub/x.json");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        let names: Vec<_> = std::fs::read_dir(d.path().join("sub"))
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names.len(), 1, "{names:?}");
        // A target that is a directory: the rename fails, the temporary is removed.
        let e = write_atomic(d.path(), b"x").unwrap_err();
        assert!(format!("{e:#}").contains(&d.path().display().to_string()));
        let left: Vec<_> = std::fs::read_dir(d.path().parent().unwrap())
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().contains(".tmp"))
            .filter(|e| {
                e.file_name()
                    .to_string_lossy()
                    .contains(&std::process::id().to_string())
            })
            .collect();
        assert!(left.is_empty());
    }

    #[test]
    fn unwritable_destinations_are_named() {
        let e = check_writable_file(Path::new("/proc/x/model.json"), "--json").unwrap_err();
        let m = format!("{e:#}");
        assert!(
            m.contains("--json /proc/x/model.json") && m.contains("/proc/x"),
            "{m}"
        );
        let e = check_writable_dir(Path::new("/proc/x"), "--out").unwrap_err();
        assert!(format!("{e:#}").contains("--out /proc/x"));
        let d = tempfile::tempdir().unwrap();
        check_writable_file(&d.path().join("a/b/c.json"), "--json").unwrap();
        assert!(d.path().join("a/b").is_dir());
        assert_eq!(std::fs::read_dir(d.path().join("a/b")).unwrap().count(), 0);
    }
}
