//! `bsdfit sweep` / `merge` / `render` end to end: a small sweep (2 data sets ×
//! 2 models × 1 loss × 2 weightings, few restarts, CPU backend), then resumption, shards
//! and merge, interruption, pictures and report.

use bsdfit::output::results::{read_results, Row};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bsdfit(args: &[&str]) -> Output {
    let out = Command::new(env!("CARGO_BIN_EXE_bsdfit"))
        .args(args)
        .output()
        .expect("run bsdfit");
    assert!(
        out.status.success(),
        "bsdfit {args:?} failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Two small data sets: an Oren–Nayar BRDF on the paper's in-plane geometry, and a
/// BTDF on the PTB geometry.
fn data(dir: &Path) -> (PathBuf, PathBuf) {
    let brdf = dir.join("on-small.csv");
    let btdf = dir.join("tr-small.csv");
    bsdfit(&[
        "synth",
        "--model",
        "on",
        "--params",
        "rho=0.3:0.5:0.7,sigma=0.6",
        "--geometry",
        "inplane10",
        "--noise",
        "0.015,0.0002",
        "--angular-unc",
        "0.1",
        "--seed",
        "11",
        "--out",
        brdf.to_str().unwrap(),
    ]);
    bsdfit(&[
        "synth",
        "--model",
        "btdf(tr)+scale",
        "--params",
        "alpha=0.3,eta=1.5,scale=0.8",
        "--geometry",
        "ptb5",
        "--noise",
        "0.015,0.001",
        "--seed",
        "12",
        "--out",
        btdf.to_str().unwrap(),
    ]);
    (brdf, btdf)
}

const MODELS: &str = "lambert,on,btdf(tr),btdf(tr)+scale";

fn sweep(brdf: &Path, btdf: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "sweep",
        brdf.to_str().unwrap(),
        btdf.to_str().unwrap(),
        "--models",
        MODELS,
        "--losses",
        "rmse,f",
        "--restarts",
        "3",
        "--backend",
        "cpu",
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    bsdfit(&args)
}

fn rows(dir: &Path) -> Vec<Row> {
    let mut v = read_results(&dir.join("results.csv"), false, &mut |m| panic!("{m}")).unwrap();
    v.sort_by_key(|r| {
        (
            r.data.clone(),
            r.model.clone(),
            r.loss.clone(),
            r.weights.clone(),
            r.optimizer.clone(),
        )
    });
    v
}

fn deterministic(rows: &[Row]) -> Vec<Row> {
    rows.iter().map(Row::deterministic).collect()
}

#[test]
fn sweep_resumes_shards_merge_and_reports() {
    let tmp = tempfile::tempdir().unwrap();
    let (brdf, btdf) = data(tmp.path());
    let full = tmp.path().join("full");

    // 1. The sweep: 2 data sets × 2 models × 1 loss × (uniform, uncertainty weights).
    let o = sweep(&brdf, &btdf, &full, &[]);
    let all = rows(&full);
    assert_eq!(all.len(), 8, "{}", stderr(&o));
    for r in &all {
        assert!(r.best_loss.is_finite() && r.chi2_red.is_finite(), "{r:?}");
        let expected_w = if r.kind == "brdf" {
            ["uniform", "relunc"]
        } else {
            ["uniform", "invunc"]
        };
        assert!(expected_w.contains(&r.weights.as_str()), "{r:?}");
        assert_eq!(r.loss, if r.kind == "brdf" { "rmse" } else { "f" });
        assert_eq!(r.optimizer, "lm");
        assert!(
            r.params_json()
                .contains_key(if r.kind == "brdf" { "rho" } else { "alpha" }),
            "{}",
            r.params
        );
    }
    // The true model fits its own data to within the uncertainties.
    let on = all
        .iter()
        .find(|r| r.model == "on" && r.weights == "uniform")
        .unwrap();
    assert!(on.chi2_red < 2.0, "{on:?}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(full.join("results.json")).unwrap()).unwrap();
    assert_eq!(json.as_array().unwrap().len(), 8);
    assert!(json[0]["params"].is_object() && json[0]["param_std"].is_object());
    let ranks = std::fs::read_to_string(full.join("rankings.md")).unwrap();
    assert!(
        ranks.contains("## on-small") && ranks.contains("## tr-small"),
        "{ranks}"
    );

    // 2. Pictures and report: every picture the report shows exists and is not empty.
    let report = std::fs::read_to_string(full.join("report.html")).unwrap();
    let srcs: Vec<&str> = report
        .split("src=\"")
        .skip(1)
        .map(|s| &s[..s.find('"').unwrap()])
        .collect();
    assert!(
        srcs.iter()
            .any(|s| s.starts_with("plots/") && s.ends_with(".svg")),
        "{srcs:?}"
    );
    assert!(
        srcs.iter()
            .any(|s| s.starts_with("renders/") && s.ends_with(".png")),
        "{srcs:?}"
    );
    for s in &srcs {
        let p = full.join(s);
        assert!(
            std::fs::metadata(&p)
                .map(|m| m.len() > 100)
                .unwrap_or(false),
            "{} missing or empty",
            p.display()
        );
    }
    for r in &all {
        let svg = full
            .join("plots")
            .join(&r.data)
            .join(format!("{}.svg", bsdfit::output::report::slug(r)));
        let text =
            std::fs::read_to_string(&svg).unwrap_or_else(|_| panic!("{} missing", svg.display()));
        assert!(
            text.starts_with("<svg") && text.contains("<polyline") && text.contains("<circle"),
            "{}",
            svg.display()
        );
        assert!(
            report.contains(&format!(
                "plots/{}/{}.svg",
                r.data,
                bsdfit::output::report::slug(r)
            )),
            "report does not link {}",
            svg.display()
        );
    }
    let png = std::fs::read(full.join("renders/on-small/baseline.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    for word in [
        "Effect of uncertainty weighting",
        "Ranking",
        "on-small",
        "tr-small",
    ] {
        assert!(report.contains(word), "report lacks '{word}'");
    }

    // 3. A re-run skips every fit and leaves results.csv byte-identical.
    let before = std::fs::read(full.join("results.csv")).unwrap();
    let o = sweep(&brdf, &btdf, &full, &[]);
    assert!(stderr(&o).contains("0 new fits"), "{}", stderr(&o));
    assert_eq!(
        std::fs::read(full.join("results.csv")).unwrap(),
        before,
        "re-run changed results.csv"
    );

    // 4. Shards 1/2 and 2/2, merged, equal the unsharded results (deterministic columns).
    let (a, b, merged) = (
        tmp.path().join("a"),
        tmp.path().join("b"),
        tmp.path().join("merged"),
    );
    sweep(&brdf, &btdf, &a, &["--shard", "1/2"]);
    sweep(&brdf, &btdf, &b, &["--shard", "2/2"]);
    let (ra, rb) = (rows(&a), rows(&b));
    assert!(
        !ra.is_empty() && !rb.is_empty() && ra.len() + rb.len() == 8,
        "{} + {}",
        ra.len(),
        rb.len()
    );
    assert!(!a.join("report.html").exists(), "a shard writes no report");
    bsdfit(&[
        "merge",
        a.to_str().unwrap(),
        b.to_str().unwrap(),
        "--out",
        merged.to_str().unwrap(),
        "--no-pictures",
    ]);
    assert_eq!(deterministic(&rows(&merged)), deterministic(&all));
    // Merging again adds nothing.
    let before = std::fs::read(merged.join("results.csv")).unwrap();
    bsdfit(&[
        "merge",
        a.to_str().unwrap(),
        b.to_str().unwrap(),
        "--out",
        merged.to_str().unwrap(),
        "--no-pictures",
    ]);
    assert_eq!(std::fs::read(merged.join("results.csv")).unwrap(), before);

    // 5. An interrupted run (the last row cut in the middle of its write) resumes: the
    //    partial line is dropped, that one fit is redone, the results are the same.
    let csv = full.join("results.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    let cut = text.trim_end_matches('\n').rfind('\n').unwrap() + 1 + 25;
    std::fs::write(&csv, &text[..cut]).unwrap();
    let o = sweep(&brdf, &btdf, &full, &["--no-pictures"]);
    assert!(
        stderr(&o).contains("incomplete last line") && stderr(&o).contains("1 new fit,"),
        "{}",
        stderr(&o)
    );
    assert_eq!(deterministic(&rows(&full)), deterministic(&all));
    // ... and so does one that lost whole rows (killed between fits).
    let text = std::fs::read_to_string(&csv).unwrap();
    let keep: Vec<&str> = text.lines().take(4).collect();
    std::fs::write(&csv, keep.join("\n") + "\n").unwrap();
    let o = sweep(&brdf, &btdf, &full, &["--no-pictures"]);
    assert!(stderr(&o).contains("5 new fits"), "{}", stderr(&o));
    assert_eq!(deterministic(&rows(&full)), deterministic(&all));
}

#[test]
fn unavailable_models_are_skipped_with_a_reason() {
    let tmp = tempfile::tempdir().unwrap();
    let (brdf, _) = data(tmp.path());
    let out = tmp.path().join("o");
    let o = bsdfit(&[
        "sweep",
        brdf.to_str().unwrap(),
        "--models",
        "lambert,nosuchmodel(eon)",
        "--losses",
        "rmse",
        "--weights",
        "uniform",
        "--restarts",
        "2",
        "--backend",
        "cpu",
        "--no-pictures",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        stderr(&o).contains("skipping nosuchmodel(eon)"),
        "{}",
        stderr(&o)
    );
    assert_eq!(rows(&out).len(), 1);
    let skipped: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("skipped.json")).unwrap()).unwrap();
    assert_eq!(skipped[0]["model"], "nosuchmodel(eon)");
    assert_eq!(skipped[0]["status"], "skipped");
    assert!(
        skipped[0]["reason"]
            .as_str()
            .unwrap()
            .contains("unknown model"),
        "{skipped}"
    );
}

/// A constraint is checked against the whole plan's models once, before the shards
/// split it: a shard whose own models lack the parameter (here `lambert`, without σ)
/// still runs, and its fits are unconstrained; `on`'s are held at σ = 0.3.
#[test]
fn a_shard_without_the_constrained_parameter_still_runs() {
    let tmp = tempfile::tempdir().unwrap();
    let (brdf, _) = data(tmp.path());
    let mut all = Vec::new();
    for shard in ["1/2", "2/2"] {
        let out = tmp.path().join(shard.replace('/', "-"));
        bsdfit(&[
            "sweep",
            brdf.to_str().unwrap(),
            "--models",
            "lambert,on",
            "--losses",
            "rmse",
            "--weights",
            "uniform",
            "--restarts",
            "2",
            "--backend",
            "cpu",
            "--no-pictures",
            "--fix",
            "sigma=0.3",
            "--shard",
            shard,
            "--out",
            out.to_str().unwrap(),
        ]);
        let r = rows(&out);
        assert_eq!(r.len(), 1, "{shard}: one of the two cells");
        all.extend(r);
    }
    let mut models: Vec<&str> = all.iter().map(|r| r.model.as_str()).collect();
    models.sort_unstable();
    assert_eq!(models, ["lambert", "on"]);
}

#[test]
fn render_writes_baseline_model_and_error_images() {
    let tmp = tempfile::tempdir().unwrap();
    let (brdf, _) = data(tmp.path());
    let out = tmp.path().join("r");
    let o = bsdfit(&[
        "render",
        brdf.to_str().unwrap(),
        "--model",
        "on",
        "--params",
        "rho=0.3:0.5:0.7,sigma=0.6",
        "--size",
        "64",
        "--out",
        out.to_str().unwrap(),
    ]);
    for f in ["baseline.png", "model.png", "error.png"] {
        let b = std::fs::read(out.join(f)).unwrap();
        assert!(b.len() > 100 && &b[1..4] == b"PNG", "{f}");
    }
    let stats: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("render.json")).unwrap()).unwrap();
    // The true model against its own (noisy, tabulated) data: small per-pixel error.
    let mean = stats["mean_error"].as_f64().unwrap();
    assert!(
        mean > 0.0 && mean < 0.1,
        "{stats} {}",
        String::from_utf8_lossy(&o.stdout)
    );
}
