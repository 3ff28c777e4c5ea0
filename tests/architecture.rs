//! The layout rules the code keeps (docs/architecture.md), checked on the source itself so
//! that a change that breaks one fails here rather than in review.

use std::path::{Path, PathBuf};

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

fn src(sub: &str) -> Vec<PathBuf> {
    let mut files = Vec::new();
    rust_files(&Path::new(env!("CARGO_MANIFEST_DIR")).join(sub), &mut files);
    files.sort();
    assert!(!files.is_empty(), "no Rust file under {sub}");
    files
}

/// Rooms of one job: no source file over 900 lines.
#[test]
fn no_source_file_is_over_900_lines() {
    let long: Vec<String> = src("src")
        .iter()
        .map(|p| (p, std::fs::read_to_string(p).unwrap().lines().count()))
        .filter(|(_, n)| *n > 900)
        .map(|(p, n)| format!("{} ({n} lines)", p.display()))
        .collect();
    assert!(long.is_empty(), "split these: {long:?}");
}

/// The string literals of a Rust source before its `#[cfg(test)] mod tests` (a crude
/// lexer: enough for this crate's code, which has no raw strings with quotes in them).
fn literals_outside_tests(text: &str) -> Vec<(usize, String)> {
    let code = text.split("#[cfg(test)]\nmod tests").next().unwrap_or("");
    let mut out = Vec::new();
    for (i, line) in code.lines().enumerate() {
        let line = line.trim_start();
        if line.starts_with("//") {
            continue;
        }
        let mut rest = line;
        while let Some(start) = rest.find('"') {
            let after = &rest[start + 1..];
            let mut end = None;
            let mut escaped = false;
            for (k, c) in after.char_indices() {
                match c {
                    '\\' if !escaped => escaped = true,
                    '"' if !escaped => {
                        end = Some(k);
                        break;
                    }
                    _ => escaped = false,
                }
            }
            let Some(end) = end else { break };
            out.push((i + 1, after[..end].to_string()));
            rest = &after[end + 1..];
        }
    }
    out
}

/// Declarations drive diagnose: it learns which models extend which from the models'
/// declarations, so its code names no model (a spec-like literal made of registry names).
#[test]
fn diagnose_names_no_model() {
    let names: Vec<&str> = bsdfit::bsdf::registry::all()
        .iter()
        .map(|e| e.name)
        .chain(
            bsdfit::bsdf::registry::all()
                .iter()
                .flat_map(|e| e.variants.iter().copied()),
        )
        .collect();
    assert!(names.contains(&"lambert") && names.contains(&"tr"));
    let mut found = Vec::new();
    for path in src("src/workflows/diagnose") {
        let text = std::fs::read_to_string(&path).unwrap();
        for (line, lit) in literals_outside_tests(&text) {
            // Prose (with spaces) may say "on the source side"; a spec has no spaces.
            if lit.contains(char::is_whitespace) {
                continue;
            }
            if lit
                .split(['(', ')', '+', ','])
                .any(|token| names.contains(&token))
            {
                found.push(format!("{}:{line}: \"{lit}\"", path.display()));
            }
        }
    }
    assert!(found.is_empty(), "model names in diagnose: {found:?}");
    // The check itself finds a name where there is one.
    let probe = "fn f() { let s = \"fa(lambert)\"; }\n#[cfg(test)]\nmod tests { \"ggx\" }";
    let lits = literals_outside_tests(probe);
    assert_eq!(lits, vec![(1, "fa(lambert)".to_string())]);
}

/// No model family is guessed from a spec's text: a spec's kind and family come from its
/// syntax and the registry.
#[test]
fn no_spec_prefix_guesses() {
    for path in src("src") {
        let text = std::fs::read_to_string(&path).unwrap();
        for pattern in [
            "starts_with(\"btdf",
            "starts_with(\"fa(",
            "ends_with(\"+scale",
        ] {
            assert!(
                !text.contains(pattern),
                "{} guesses a model from its spec text: {pattern}",
                path.display()
            );
        }
    }
}
