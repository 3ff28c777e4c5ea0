//! `bsdfit diagnose FILE|DIR… --out DIR` end to end: a folder of twelve data sets in four
//! formats (written here with `synth`, `fit` and `export`, plus the vendored real files)
//! diagnosed as a collection; a run killed after its first cells and resumed without
//! redoing them; two shards merged, and a Slurm job array's tasks (`--shard auto`, run
//! here one after the other with the array's environment) merged with `merge --shards`,
//! both equal to one process's table; a data set that fails named with its error.

mod common;

use common::cli::{assert_ok, bsdfit, bsdfit_env, p, text};
use serde_json::Value;
use std::path::{Path, PathBuf};

const REAL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/real");

/// The folder of the collection: 4 v1 CSV, 2 MERL binary, 3 ASTM E1392 (2 exported, 1
/// real), 3 Zemax BSDF (1 exported, 2 real: a BRDF and a BTDF, which a BRDF start model
/// cannot diagnose), and a file of no format read.
fn collection(dir: &Path) -> PathBuf {
    let data = dir.join("data");
    std::fs::create_dir_all(&data).unwrap();
    let synth = |model: &str, params: &str, seed: &str, out: &str| {
        let mut args = vec![
            "synth",
            "--model",
            model,
            "--geometry",
            "inplane10",
            "--seed",
            seed,
        ];
        if !params.is_empty() {
            args.extend(["--params", params]);
        }
        let out = data.join(out);
        args.extend(["--out", p(&out)]);
        assert_ok(&bsdfit(&args), "synth");
    };
    synth("lambert", "", "1", "a-lambert.csv");
    synth("on", "rho=0.5,sigma=0.6", "2", "b-on.csv");
    synth("on", "rho=0.3:0.4:0.5,sigma=0.3", "3", "c-on.csv");
    synth("lambert", "rho=0.2", "4", "d-lambert.csv");
    synth("on", "rho=0.6,sigma=0.5", "5", "e-on.binary");
    synth("lambert", "rho=0.35", "6", "f-lambert.binary");
    // A fit to export: ASTM (3 channels) and Zemax (one of them).
    let fit = dir.join("on.json");
    assert_ok(
        &bsdfit(&[
            "fit",
            p(&data.join("b-on.csv")),
            "--model",
            "on",
            "--backend",
            "cpu",
            "--json",
            p(&fit),
        ]),
        "fit",
    );
    let export = |format: &str, out: &str, extra: &[&str]| {
        let mut args = vec!["export", p(&fit), "--format", format, "--out"];
        let out = data.join(out);
        args.push(p(&out));
        args.extend(extra);
        assert_ok(&bsdfit(&args), "export");
    };
    export("astm", "g-on.astm", &[]);
    export("astm", "h-on-copy.astm", &[]);
    export("zemax", "i-on.bsdf", &["--channel", "550"]);
    for f in [
        "cornell_acryl_blue.astm",
        "zemax_planesymmetric_brdf.bsdf",
        "zemax_planesymmetric_btdf.bsdf",
    ] {
        std::fs::copy(Path::new(REAL).join(f), data.join(f)).unwrap();
    }
    std::fs::write(data.join("notes.txt"), "measured on Tuesday\n").unwrap();
    data
}

/// The options of every run: a short diagnosis (one effect at most, the nominal F test)
/// that still fits every data set and adopts an effect where one is missing.
fn options(data: &Path, out: &Path) -> Vec<String> {
    [
        "diagnose",
        p(data),
        "--model",
        "lambert",
        "--out",
        p(out),
        "--max-steps",
        "1",
        "--bootstrap",
        "0",
        "--restarts",
        "2",
        "--backend",
        "cpu",
        "--wavelengths",
        "450,550,650",
        "--assume-uncertainty",
        "0.05,0.001",
        "--max-samples",
        "1500",
        "--explore",
        "1500",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect()
}

fn run(args: &[String], env: &[(&str, &str)]) -> std::process::Output {
    let a: Vec<&str> = args.iter().map(String::as_str).collect();
    bsdfit_env(&a, env)
}

/// The table of a collection folder, without the seconds (wall time differs by run).
fn table(out: &Path) -> Vec<Value> {
    let text = std::fs::read_to_string(out.join("diagnoses.json")).expect("diagnoses.json");
    let mut v: Vec<Value> = serde_json::from_str(&text).unwrap();
    for r in &mut v {
        let r = r.as_object_mut().unwrap();
        r.remove("seconds");
        if let Some(Value::Array(rounds)) = r.get_mut("rounds") {
            for round in rounds {
                round.as_object_mut().unwrap().remove("seconds");
            }
        }
    }
    v
}

#[test]
fn a_folder_of_four_formats_is_diagnosed_resumed_sharded_and_merged() {
    let tmp = tempfile::tempdir().unwrap();
    let data = collection(tmp.path());
    // One process.
    let one = tmp.path().join("one");
    let o = run(&options(&data, &one), &[]);
    let err = text(&o.stderr);
    // The BTDF file fails (a BRDF start model), so the command fails after the others.
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("1 data set of this run failed: zemax_planesymmetric_btdf.bsdf"),
        "{err}"
    );
    assert!(err.contains("not of a format read: notes.txt"), "{err}");
    let t = table(&one);
    assert_eq!(t.len(), 12, "{t:#?}");
    let by_name = |n: &str| {
        t.iter()
            .find(|r| r["data"] == n)
            .unwrap_or_else(|| panic!("{n}"))
    };
    let btdf = by_name("zemax_planesymmetric_btdf.bsdf");
    assert_eq!(btdf["status"], "failed");
    assert!(
        btdf["error"].as_str().unwrap().contains("lambert"),
        "{btdf}"
    );
    for r in t.iter().filter(|r| r["status"] == "done") {
        let start = r["start_chi2_red"].as_f64().unwrap();
        let end = r["final_chi2_red"].as_f64().unwrap();
        assert!(end <= start * (1.0 + 1e-9), "{r}");
        assert!(!r["params"].as_array().unwrap().is_empty(), "{r}");
        assert!(r["stop"].as_str().is_some_and(|s| !s.is_empty()), "{r}");
    }
    assert_eq!(t.iter().filter(|r| r["status"] == "done").count(), 11);
    // The Oren–Nayar truths get their backscatter; the Lambertian ones nothing.
    for n in ["b-on.csv", "c-on.csv", "e-on.binary", "g-on.astm"] {
        assert_eq!(
            by_name(n)["effects"],
            serde_json::json!(["backscatter"]),
            "{n}"
        );
    }
    for n in ["a-lambert.csv", "d-lambert.csv", "f-lambert.binary"] {
        assert_eq!(by_name(n)["effects"], serde_json::json!([]), "{n}");
    }
    // Sorted by final χ²_red, worst first; the CSV has a row per data set.
    let finals: Vec<f64> = t
        .iter()
        .filter_map(|r| r["final_chi2_red"].as_f64())
        .collect();
    assert!(finals.windows(2).all(|w| w[0] >= w[1]), "{finals:?}");
    let csv = std::fs::read_to_string(one.join("diagnoses.csv")).unwrap();
    assert_eq!(
        csv::Reader::from_reader(csv.as_bytes()).records().count(),
        12
    );
    // The report: the table, the effect counts, residual maps before and after.
    let html = std::fs::read_to_string(one.join("report.html")).unwrap();
    assert!(
        html.contains("Effects named across the collection"),
        "report"
    );
    assert!(
        html.contains("diagnoses/b-on.csv/residuals_1.svg"),
        "report"
    );
    assert!(one.join("diagnoses/b-on.csv/residuals_1.svg").exists());

    // Two shards into their own folders, merged: the same table.
    let (s1, s2, merged) = (
        tmp.path().join("s1"),
        tmp.path().join("s2"),
        tmp.path().join("m"),
    );
    for (s, i) in [(&s1, "1/2"), (&s2, "2/2")] {
        let mut a = options(&data, s);
        a.extend(["--shard".into(), i.into()]);
        run(&a, &[]);
    }
    assert_ok(
        &bsdfit(&["merge", p(&s1), p(&s2), "--out", p(&merged)]),
        "merge",
    );
    assert_eq!(table(&merged), t);

    // A Slurm array of 3 tasks: the emitted scripts' command, run as each task would.
    let slurm_out = tmp.path().join("slurm-run");
    let mut a = options(&data, &slurm_out);
    a.extend(["--emit-slurm".into(), "3".into()]);
    assert_ok(&run(&a, &[]), "emit-slurm");
    let array = std::fs::read_to_string(slurm_out.join("slurm/array.sbatch")).unwrap();
    assert!(array.contains("diagnose --config"), "{array}");
    let config = slurm_out.join("slurm/collection.json");
    for id in ["1", "2", "3"] {
        let env = [
            ("SLURM_ARRAY_TASK_ID", id),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_MAX", "3"),
        ];
        let o = bsdfit_env(
            &["diagnose", "--config", p(&config), "--shard", "auto"],
            &env,
        );
        assert!(
            text(&o.stderr).contains(&format!("shard {id}/3")),
            "{}",
            text(&o.stderr)
        );
    }
    assert_ok(
        &bsdfit(&["merge", "--shards", "--out", p(&slurm_out)]),
        "merge --shards",
    );
    assert_eq!(table(&slurm_out), t);
    // The merged folder is the collection's: a run into it with the same options skips
    // what the array diagnosed (and retries the data set that failed).
    let o = run(&options(&data, &slurm_out), &[]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o.stderr));
    assert!(
        text(&o.stderr).contains("11 already done"),
        "{}",
        text(&o.stderr)
    );
}

#[test]
fn a_killed_collection_resumes_without_redoing_its_cells() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    std::fs::create_dir_all(&data).unwrap();
    for (i, (model, params)) in [
        ("lambert", "rho=0.4"),
        ("on", "rho=0.5,sigma=0.6"),
        ("lambert", "rho=0.2"),
        ("on", "rho=0.3,sigma=0.4"),
        ("on", "rho=0.6,sigma=0.3"),
    ]
    .iter()
    .enumerate()
    {
        let out = data.join(format!("{i}.csv"));
        let seed = (i + 1).to_string();
        assert_ok(
            &bsdfit(&[
                "synth",
                "--model",
                model,
                "--params",
                params,
                "--geometry",
                "inplane10",
                "--seed",
                &seed,
                "--out",
                p(&out),
            ]),
            "synth",
        );
    }
    let out = tmp.path().join("out");
    let args = options(&data, &out);
    let mut child = std::process::Command::new(common::bin())
        .args(&args)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let cells = out.join("cells");
    // A finished cell is a `.json`; a kill can land between a cell's temporary and its
    // rename, which leaves a hidden `.NAME.json.PID-N.tmp` that a resumed run never reads.
    let is_cell = |p: &std::path::Path| p.extension().is_some_and(|x| x == "json");
    let count = || {
        std::fs::read_dir(&cells)
            .map(|d| {
                d.filter(|e| e.as_ref().is_ok_and(|e| is_cell(&e.path())))
                    .count()
            })
            .unwrap_or(0)
    };
    let t0 = std::time::Instant::now();
    while count() < 2 && t0.elapsed().as_secs() < 300 {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    child.kill().ok();
    child.wait().unwrap();
    let listed: Vec<PathBuf> = std::fs::read_dir(&cells)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    for p in listed.iter().filter(|p| !is_cell(p)) {
        let name = p.file_name().unwrap().to_string_lossy();
        assert!(
            name.starts_with('.') && name.ends_with(".tmp"),
            "only a hidden temporary may sit beside the cells: {}",
            p.display()
        );
    }
    let kept: Vec<(PathBuf, Vec<u8>)> = listed
        .into_iter()
        .filter(|p| is_cell(p))
        .map(|p| {
            let b = std::fs::read(&p).unwrap();
            (p, b)
        })
        .collect();
    assert!(
        kept.len() >= 2,
        "the run was killed before writing two cells"
    );
    assert!(
        kept.len() < 5,
        "the run ended before it was killed: nothing was resumed"
    );
    // What a kill mid-write leaves, planted so that every run sees it: half a record in a
    // hidden temporary. The resumed run must neither count it as done nor choke on it.
    std::fs::write(cells.join(".4.csv.json.999999-0.tmp"), b"{\"data\": \"4.cs").unwrap();
    let o = run(&args, &[]);
    assert_ok(&o, "resumed diagnose");
    let err = text(&o.stderr);
    assert!(
        err.contains(&format!("{} already done", kept.len())),
        "{err}"
    );
    // The finished cells are not redone: their records are byte for byte the same.
    for (path, bytes) in &kept {
        assert_eq!(&std::fs::read(path).unwrap(), bytes, "{}", path.display());
    }
    assert_eq!(table(&out).len(), 5);
    // A second run into the folder with other options is refused before any fit.
    let mut other = args.clone();
    other[3] = "on".into();
    let o = run(&other, &[]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        text(&o.stderr).contains("other options"),
        "{}",
        text(&o.stderr)
    );
    // Folders of two different diagnoses are not merged into one table.
    let mut on = other.clone();
    let out_on = tmp.path().join("out-on");
    on[5] = p(&out_on).to_string();
    assert_ok(&run(&on, &[]), "diagnose from on");
    let both = tmp.path().join("both");
    let o = bsdfit(&["merge", p(&out), p(&out_on), "--out", p(&both)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        text(&o.stderr).contains("cannot be merged into")
            && text(&o.stderr).contains("other options"),
        "{}",
        text(&o.stderr)
    );
    // A sweep's folder is refused too: the collection's report.html would replace its own.
    let sweep = tmp.path().join("sweep");
    std::fs::create_dir_all(&sweep).unwrap();
    std::fs::write(sweep.join("results.csv"), "").unwrap();
    let mut into_sweep = args.clone();
    into_sweep[5] = p(&sweep).to_string();
    let o = run(&into_sweep, &[]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        text(&o.stderr).contains("holds a sweep"),
        "{}",
        text(&o.stderr)
    );
}
