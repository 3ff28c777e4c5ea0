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

/// Rooms of one job: no source file over 900 lines, the crate's, the Python module's
/// native half and its Python half alike.
#[test]
fn no_source_file_is_over_900_lines() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut python: Vec<PathBuf> = std::fs::read_dir(root.join("python/bsdfit"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "py" || x == "pyi"))
        .collect();
    assert!(!python.is_empty(), "no Python file under python/bsdfit");
    python.extend(src("python/src"));
    let long: Vec<String> = src("src")
        .iter()
        .chain(&python)
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
    // A `*_tests.rs` file is a unit-test module of its own (`#[cfg(test)] #[path = …]`):
    // test code, free to name models.
    let test_module = |p: &Path| p.to_string_lossy().ends_with("_tests.rs");
    for path in src("src/workflows/diagnose")
        .into_iter()
        .filter(|p| !test_module(p))
    {
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

/// What each top-level module of `src/` may use of the crate: the layers of
/// docs/architecture.md, lowest first. A module uses itself freely; `cli` may use
/// everything, and nothing below it may use `cli`.
const ALLOWED: &[(&str, &[&str])] = &[
    ("choice", &[]),
    ("text", &[]),
    ("math", &[]),
    ("optim", &["math"]),
    ("data", &["choice", "math", "text"]),
    ("bsdf", &["choice", "data", "math", "text"]),
    (
        "engine",
        &["bsdf", "choice", "data", "math", "optim", "text"],
    ),
    (
        "inference",
        &["bsdf", "choice", "data", "engine", "math", "optim", "text"],
    ),
    (
        "output",
        &["bsdf", "choice", "data", "inference", "math", "text"],
    ),
    (
        "workflows",
        &[
            "bsdf",
            "choice",
            "data",
            "engine",
            "inference",
            "math",
            "optim",
            "output",
            "text",
        ],
    ),
    (
        "cli",
        &[
            "bsdf",
            "choice",
            "data",
            "engine",
            "inference",
            "math",
            "optim",
            "output",
            "text",
            "workflows",
        ],
    ),
];

/// The top-level modules `path` (under `src/`, or the Python crate's source) names in its
/// code: as `{root}::MODULE`, in a grouped import `{root}::{MODULE, OTHER::x}` (over
/// several lines too), and, for a file `depth` modules below the crate root, as
/// `super::…::MODULE` with as many `super`s (which names the crate root's MODULE).
/// Comment lines and `#[cfg(test)]` code (the tail of a file, and `*_tests.rs` files) are
/// left out. Each with its line.
fn modules_used(text: &str, root: &str, depth: Option<usize>) -> Vec<(usize, String)> {
    let code: String = text
        .split("#[cfg(test)]")
        .next()
        .unwrap_or("")
        .lines()
        .map(|l| {
            if l.trim_start().starts_with("//") {
                ""
            } else {
                l
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    let line_of = |at: usize| code[..at].matches('\n').count() + 1;
    let ident = |s: &str| -> String {
        s.chars()
            .take_while(|c| c.is_ascii_lowercase() || *c == '_')
            .collect()
    };
    let mut out = Vec::new();
    let mut prefixes = vec![format!("{root}::")];
    if let Some(d) = depth.filter(|&d| d > 0) {
        prefixes.push("super::".repeat(d));
    }
    for prefix in &prefixes {
        let mut from = 0;
        while let Some(found) = code[from..].find(prefix.as_str()) {
            let at = from + found;
            from = at + prefix.len();
            // `bsdfit::` inside a longer name (`_bsdfit::`), or a longer `super::` chain
            // than this one, is not the crate root.
            let before = code[..at].chars().next_back();
            if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':') {
                continue;
            }
            let rest = &code[from..];
            if rest.starts_with("super::") {
                continue;
            }
            if let Some(group) = rest.strip_prefix('{') {
                // The names at the group's first level: each item's first segment.
                let mut level = 0;
                let mut item_start = true;
                for (k, c) in group.char_indices() {
                    match c {
                        '{' => level += 1,
                        '}' if level == 0 => break,
                        '}' => level -= 1,
                        ',' if level == 0 => item_start = true,
                        c if item_start && !c.is_whitespace() => {
                            item_start = false;
                            let name = ident(&group[k..]);
                            if !name.is_empty() && name != "self" {
                                out.push((line_of(from + 1 + k), name));
                            }
                        }
                        _ => {}
                    }
                }
            } else {
                let name = ident(rest);
                if !name.is_empty() {
                    out.push((line_of(at), name));
                }
            }
        }
    }
    out.sort();
    out
}

/// How many modules below the crate root a file of `src/` is (`src/a/b.rs` and
/// `src/a/b/mod.rs`: 2), or None for the crate root itself.
fn src_depth(path: &Path) -> Option<usize> {
    let rel = path
        .strip_prefix(Path::new(env!("CARGO_MANIFEST_DIR")).join("src"))
        .ok()?;
    let parts = rel.components().count();
    let is_mod = rel.file_name().is_some_and(|f| f == "mod.rs");
    let depth = if is_mod { parts - 1 } else { parts };
    (src_module(path).is_some()).then_some(depth)
}

/// The uses of `files` that `allowed(module of the file, module used)` refuses.
fn layering_violations(
    files: &[PathBuf],
    root: &str,
    module_of: &dyn Fn(&Path) -> Option<String>,
    allowed: &dyn Fn(&str, &str) -> bool,
) -> Vec<String> {
    let mut bad = Vec::new();
    for path in files {
        if path.to_string_lossy().ends_with("_tests.rs") {
            continue;
        }
        let Some(from) = module_of(path) else {
            continue;
        };
        let text = std::fs::read_to_string(path).unwrap();
        let depth = if root == "crate" {
            src_depth(path)
        } else {
            None
        };
        for (line, to) in modules_used(&text, root, depth) {
            if to != from && !allowed(&from, &to) {
                bad.push(format!("{}:{line}: {from} uses {to}", path.display()));
            }
        }
    }
    bad
}

/// The top-level module of a file under `src/` (`None` for `lib.rs` and `main.rs`).
fn src_module(path: &Path) -> Option<String> {
    let rel = path
        .strip_prefix(Path::new(env!("CARGO_MANIFEST_DIR")).join("src"))
        .ok()?;
    let first = rel.components().next()?.as_os_str().to_string_lossy();
    let name = first.trim_end_matches(".rs").to_string();
    (name != "lib" && name != "main").then_some(name)
}

fn allowed_in_src(from: &str, to: &str) -> bool {
    ALLOWED
        .iter()
        .find(|(m, _)| *m == from)
        .is_some_and(|(_, uses)| uses.contains(&to))
}

/// Every top-level module of `src/` is in the table (a new one must be placed in a layer).
#[test]
fn every_module_has_a_layer() {
    let mut modules: Vec<String> = src("src").iter().filter_map(|p| src_module(p)).collect();
    modules.sort();
    modules.dedup();
    let missing: Vec<&String> = modules
        .iter()
        .filter(|m| !ALLOWED.iter().any(|(n, _)| n == m))
        .collect();
    assert!(missing.is_empty(), "place these in ALLOWED: {missing:?}");
}

/// Each `crate::MODULE` a file of `src/` names is one its module may use (ALLOWED).
#[test]
fn modules_use_only_the_layers_below_them() {
    let bad = layering_violations(&src("src"), "crate", &src_module, &allowed_in_src);
    assert!(
        bad.is_empty(),
        "uses against the layers:\n{}",
        bad.join("\n")
    );
}

/// The Python module uses the library as a front end beside the command line: anything
/// but `cli`, which only `console.rs` (the package's `bsdfit` command) runs, whole.
#[test]
fn the_python_module_does_not_use_the_command_line() {
    let bad = layering_violations(
        &src("python/src"),
        "bsdfit",
        &|path| {
            Some(if path.ends_with("console.rs") {
                "console".to_string()
            } else {
                "python".to_string()
            })
        },
        &|from, to| to != "cli" || from == "console",
    );
    assert!(
        bad.is_empty(),
        "uses of the command line:\n{}",
        bad.join("\n")
    );
}

/// The checker sees a planted upward use, in each form the code writes one.
#[test]
fn the_layering_check_sees_an_upward_use() {
    let planted = "use crate::data::Dataset;\nfn f() { crate::workflows::synth::geometry(\"hemi\"); }\n// crate::cli::main in a comment\n";
    assert_eq!(
        modules_used(planted, "crate", Some(1)),
        vec![(1, "data".to_string()), (2, "workflows".to_string())]
    );
    // Grouped imports, over lines and nested; `super` chains that reach the crate root
    // from a file two modules down (and not the shorter or longer ones).
    let grouped = "use crate::{\n    bsdf::Model,\n    engine::{loss::Loss, Backend},\n    self,\n};\nuse super::super::cli::Args;\nuse super::fit;\nuse super::super::super::x;\n";
    assert_eq!(
        modules_used(grouped, "crate", Some(2)),
        vec![
            (2, "bsdf".to_string()),
            (3, "engine".to_string()),
            (6, "cli".to_string())
        ]
    );
    assert_eq!(
        modules_used("pub use crate::{data, math::erf};", "crate", Some(1)),
        vec![(1, "data".to_string()), (1, "math".to_string())]
    );
    assert!(allowed_in_src("bsdf", "data"));
    assert!(!allowed_in_src("data", "workflows"));
    assert!(!allowed_in_src("workflows", "cli"));
    assert_eq!(
        modules_used(
            "use bsdfit::cli::checks;\nlet x = _bsdfit::y;",
            "bsdfit",
            None
        ),
        vec![(1, "cli".to_string())]
    );
}

/// The lines of code (not comments) of `text` that use clap.
fn clap_uses(text: &str) -> Vec<usize> {
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim_start().starts_with("//") && l.contains("clap"))
        .map(|(i, _)| i + 1)
        .collect()
}

/// What docs/architecture.md says: clap appears only in `src/cli/` (the library and the
/// Python module take options as values, not as parsed flags).
#[test]
fn clap_appears_only_in_the_command_line() {
    let cli = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/cli");
    let mut files = src("src");
    files.extend(src("python/src"));
    let bad: Vec<String> = files
        .iter()
        .filter(|p| !p.starts_with(&cli))
        .flat_map(|p| {
            let text = std::fs::read_to_string(p).unwrap();
            clap_uses(&text)
                .into_iter()
                .map(move |line| format!("{}:{line}", p.display()))
        })
        .collect();
    assert!(bad.is_empty(), "clap outside src/cli/: {bad:?}");
    assert_eq!(
        clap_uses("use clap::Args;\n// clap in a comment\n#[derive(clap::Parser)]"),
        vec![1, 3]
    );
}

/// The model files form no circle: no file of `src/bsdf/` uses another that uses it back,
/// directly or through others (the anisotropic lobes live with their isotropic parents,
/// over `stretched.rs`). Uses in a file's tests are left out.
#[test]
fn the_model_files_form_no_circle() {
    let files = src("src/bsdf");
    let name = |p: &Path| p.file_stem().unwrap().to_string_lossy().into_owned();
    let names: Vec<String> = files.iter().map(|p| name(p)).collect();
    let mut uses: std::collections::BTreeMap<String, Vec<String>> = Default::default();
    for p in &files {
        let text = std::fs::read_to_string(p).unwrap();
        let code = text.split("#[cfg(test)]\nmod tests").next().unwrap_or("");
        let mut to: Vec<String> = names
            .iter()
            .filter(|n| **n != name(p) && n.as_str() != "mod")
            .filter(|n| {
                code.lines()
                    .filter(|l| !l.trim_start().starts_with("//"))
                    .any(|l| {
                        l.contains(&format!("super::{n}::"))
                            || l.contains(&format!("super::{n}::{{"))
                    })
            })
            .cloned()
            .collect();
        to.sort();
        uses.insert(name(p), to);
    }
    // Depth-first search for a path back to the start.
    fn reaches(
        uses: &std::collections::BTreeMap<String, Vec<String>>,
        from: &str,
        goal: &str,
        seen: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        for next in uses.get(from).into_iter().flatten() {
            if next == goal {
                return Some(vec![next.clone()]);
            }
            if !seen.contains(next) {
                seen.push(next.clone());
                if let Some(mut path) = reaches(uses, next, goal, seen) {
                    path.insert(0, next.clone());
                    return Some(path);
                }
            }
        }
        None
    }
    let circles: Vec<String> = uses
        .keys()
        .filter_map(|start| {
            reaches(&uses, start, start, &mut Vec::new())
                .map(|path| format!("{start} → {}", path.join(" → ")))
        })
        .collect();
    assert!(
        circles.is_empty(),
        "circles between model files: {circles:#?}"
    );
    // The check sees a circle: aniso.rs used the lobes' files, which used it back.
    let mut planted = uses.clone();
    planted.get_mut("ggx").unwrap().push("aniso".into());
    planted.get_mut("aniso").unwrap().push("ggx".into());
    assert!(reaches(&planted, "ggx", "ggx", &mut Vec::new()).is_some());
}

/// Each package of `cargo tree`'s output with its features, `name version [f,…]`, both
/// from one command line.
fn feature_resolution(args: &[&str]) -> std::collections::BTreeMap<String, String> {
    let out = std::process::Command::new(env!("CARGO"))
        .args([
            "tree",
            "--offline",
            "--prefix",
            "none",
            "--no-dedupe",
            "-f",
            "{p} [{f}]",
        ])
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("cargo runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .filter_map(|l| {
            let mut w = l.split_whitespace();
            let (name, version) = (w.next()?, w.next()?);
            Some((format!("{name} {version}"), w.last()?.to_string()))
        })
        .collect()
}

/// The README's test command builds the tests with `--workspace` and then the Python
/// wheel (the Python package alone); the wheel reuses the tests' compiled library only if
/// every crate the two builds share is resolved with the same features. A crate whose
/// features differ recompiles with everything above it, the library included (4.5 min on
/// 2 cores). python/Cargo.toml asks for the features the library's dev-dependencies add.
#[test]
fn the_wheel_build_resolves_shared_crates_as_the_test_build() {
    let tests = feature_resolution(&["--workspace", "-e", "normal,build,dev"]);
    let wheel = feature_resolution(&["-p", "bsdfit-python", "-e", "normal,build"]);
    assert!(
        wheel.len() > 50 && wheel.keys().any(|k| k.starts_with("wgpu ")),
        "{wheel:?}"
    );
    let differ: Vec<String> = wheel
        .iter()
        .filter_map(|(k, f)| {
            let t = tests.get(k)?;
            (t != f).then(|| format!("{k}: tests {t}, wheel {f}"))
        })
        .collect();
    assert!(differ.is_empty(), "resolved differently: {differ:#?}");
}
