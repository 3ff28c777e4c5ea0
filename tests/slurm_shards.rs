//! Sweeps split by a Slurm job array, without a cluster: `--shard auto` reads
//! only Slurm's array variables, so setting them by hand is what a task sees. A real
//! cluster runs the same scripts in `scripts/test-slurm.sh`.

use bsdfit::output::results::{read_results, Row};
use bsdfit::workflows::sweep::slurm::shard_from_env;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const SLURM_VARS: [&str; 6] = [
    "SLURM_ARRAY_TASK_ID",
    "SLURM_ARRAY_TASK_MIN",
    "SLURM_ARRAY_TASK_MAX",
    "SLURM_ARRAY_TASK_STEP",
    "SLURM_ARRAY_TASK_COUNT",
    "SLURM_JOB_ID",
];

/// Run bsdfit with exactly these Slurm variables (the test's own environment's removed).
fn bsdfit_env(args: &[&str], env: &[(&str, String)]) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_bsdfit"));
    for v in SLURM_VARS {
        c.env_remove(v);
    }
    c.args(args).envs(env.iter().map(|(k, v)| (*k, v.as_str())));
    c.output().expect("run bsdfit")
}

fn ok(o: Output, what: &str) -> Output {
    assert!(
        o.status.success(),
        "{what} failed:\n{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Slurm's variables for task `id` of `--array=MIN-MAX:STEP`.
fn array_env(id: u64, min: u64, max: u64, step: u64) -> Vec<(&'static str, String)> {
    vec![
        ("SLURM_ARRAY_TASK_ID", id.to_string()),
        ("SLURM_ARRAY_TASK_MIN", min.to_string()),
        ("SLURM_ARRAY_TASK_MAX", max.to_string()),
        ("SLURM_ARRAY_TASK_STEP", step.to_string()),
        (
            "SLURM_ARRAY_TASK_COUNT",
            ((max - min) / step + 1).to_string(),
        ),
        ("SLURM_JOB_ID", (1000 + id).to_string()),
    ]
}

fn shard_of(vars: &[(&str, &str)]) -> anyhow::Result<(usize, usize)> {
    let map: HashMap<String, String> = vars
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    shard_from_env(&|k| map.get(k).cloned())
}

#[test]
fn array_indices_map_to_shards_for_any_base_and_step() {
    let range = |id: &str, min: &str, max: &str, step: Option<&str>, count: Option<&str>| {
        let mut v = vec![
            ("SLURM_ARRAY_TASK_ID", id),
            ("SLURM_ARRAY_TASK_MIN", min),
            ("SLURM_ARRAY_TASK_MAX", max),
        ];
        if let Some(s) = step {
            v.push(("SLURM_ARRAY_TASK_STEP", s));
        }
        if let Some(c) = count {
            v.push(("SLURM_ARRAY_TASK_COUNT", c));
        }
        shard_of(&v)
    };
    // --array=1-3
    for (id, want) in [("1", 1), ("2", 2), ("3", 3)] {
        assert_eq!(
            range(id, "1", "3", Some("1"), Some("3")).unwrap(),
            (want, 3)
        );
    }
    // --array=0-9 (0-based), no STEP or COUNT variables (older Slurm)
    assert_eq!(range("0", "0", "9", None, None).unwrap(), (1, 10));
    assert_eq!(range("9", "0", "9", None, None).unwrap(), (10, 10));
    // --array=3-9:3 (what Slurm 22.05 sets: ID 3, 6, 9; COUNT 3; STEP 3)
    assert_eq!(range("6", "3", "9", Some("3"), Some("3")).unwrap(), (2, 3));
    assert_eq!(range("9", "3", "9", Some("3"), Some("3")).unwrap(), (3, 3));
    // --array=5-5: one task
    assert_eq!(range("5", "5", "5", Some("1"), Some("1")).unwrap(), (1, 1));
    // --array=1,4,5: Slurm sets MIN 1, MAX 5, STEP 1, COUNT 3; not a range
    let e = range("4", "1", "5", Some("1"), Some("3")).unwrap_err();
    assert!(e.to_string().contains("--array=1-3"), "{e}");
    // An index off the step, or outside the range
    assert!(range("4", "3", "9", Some("3"), Some("3")).is_err());
    assert!(range("12", "3", "9", Some("3"), Some("3")).is_err());
    assert!(range("x", "1", "3", None, None)
        .unwrap_err()
        .to_string()
        .contains("SLURM_ARRAY_TASK_ID=x"));
    // Outside an array: the message says what it looked for (as the command line prints it).
    let e = bsdfit::cli::error_text(&shard_of(&[]).unwrap_err());
    for v in [
        "SLURM_ARRAY_TASK_ID",
        "SLURM_ARRAY_TASK_MIN",
        "SLURM_ARRAY_TASK_COUNT",
        "--shard I/N",
    ] {
        assert!(e.contains(v), "{e}");
    }
}

fn synth(dir: &Path) -> (PathBuf, PathBuf) {
    let a = dir.join("on.csv");
    let b = dir.join("lambert.csv");
    for (model, params, out) in [
        ("on", "rho=0.3:0.5:0.7,sigma=0.6", &a),
        ("lambert", "rho=0.2:0.3:0.4", &b),
    ] {
        ok(
            bsdfit_env(
                &[
                    "synth",
                    "--model",
                    model,
                    "--params",
                    params,
                    "--geometry",
                    "inplane10",
                    "--out",
                    out.to_str().unwrap(),
                ],
                &[],
            ),
            "synth",
        );
    }
    (a, b)
}

fn sweep_args<'a>(a: &'a Path, b: &'a Path) -> Vec<&'a str> {
    vec![
        "sweep",
        a.to_str().unwrap(),
        b.to_str().unwrap(),
        "--models",
        "lambert,on,eon",
        "--losses",
        "chi2,rmse",
        "--restarts",
        "3",
        "--backend",
        "cpu",
        "--no-pictures",
    ]
}

fn rows(csv: &Path) -> Vec<Row> {
    let mut v: Vec<Row> = read_results(csv, false, &mut |m| panic!("{m}"))
        .unwrap()
        .iter()
        .map(Row::deterministic)
        .collect();
    v.sort_by_key(|r| r.fit_key());
    v
}

/// The rows of the same sweep run in one process, outside any array.
fn unsharded_rows(dir: &Path, base: &[&str]) -> Vec<Row> {
    let one = dir.join("one");
    let mut args = base.to_vec();
    args.extend(["--out", one.to_str().unwrap()]);
    ok(bsdfit_env(&args, &[]), "unsharded sweep");
    rows(&one.join("results.csv"))
}

#[test]
fn shards_from_array_variables_merge_to_the_unsharded_rows() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = synth(tmp.path());
    let base = sweep_args(&a, &b);
    let reference = unsharded_rows(tmp.path(), &base);
    assert_eq!(
        reference.len(),
        18,
        "3 models × (chi2, rmse × 2 weightings) × 2"
    );

    // Outside an array, --shard auto says what it looked for.
    let out = tmp.path().join("sharded");
    let mut args = base.clone();
    args.extend(["--out", out.to_str().unwrap(), "--shard", "auto"]);
    let o = bsdfit_env(&args, &[]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("SLURM_ARRAY_TASK_ID is not set"),
        "{}",
        stderr(&o)
    );

    // --array=0-4:2: tasks 0, 2, 4 are shards 1, 2, 3 of 3. Task 4 first: order is free.
    for id in [4, 0] {
        ok(bsdfit_env(&args, &array_env(id, 0, 4, 2)), "shard");
    }
    assert!(out.join("plan.json").exists());
    assert!(out.join("shards/1-of-3/results.csv").exists());
    assert!(out.join("shards/3-of-3/results.csv").exists());
    // The sharded folder named as an input (without --shards): its shards are merged, and
    // the note names --shards, which checks them against the plan.
    let elsewhere = tmp.path().join("elsewhere");
    let o = ok(
        bsdfit_env(
            &[
                "merge",
                out.to_str().unwrap(),
                "--out",
                elsewhere.to_str().unwrap(),
                "--no-pictures",
            ],
            &[],
        ),
        "merge OUT --out X",
    );
    assert!(
        stderr(&o).contains("merge --shards --out"),
        "{}",
        stderr(&o)
    );
    assert_eq!(rows(&elsewhere.join("results.csv")).len(), 12);
    // Merging now names shard 2's cells and fails, after writing what it has.
    let merge = [
        "merge",
        "--shards",
        "--out",
        out.to_str().unwrap(),
        "--no-pictures",
    ];
    let o = bsdfit_env(&merge, &[]);
    assert!(
        !o.status.success(),
        "a merge with a shard missing must fail"
    );
    let e = stderr(&o);
    assert_eq!(e.matches("missing: ").count(), 6, "{e}");
    assert!(
        e.contains(", shard 2\n") && !e.contains(", shard 1\n"),
        "{e}"
    );
    assert!(e.contains("6 of the plan's 18 cells"), "{e}");
    assert_eq!(rows(&out.join("results.csv")).len(), 12);

    // The missing task runs; a re-run of a finished one runs nothing.
    ok(bsdfit_env(&args, &array_env(2, 0, 4, 2)), "shard 2");
    let again = ok(bsdfit_env(&args, &array_env(0, 0, 4, 2)), "shard 1 again");
    assert!(stderr(&again).contains(", 0 to run"), "{}", stderr(&again));
    let o = ok(bsdfit_env(&merge, &[]), "merge");
    assert!(
        stderr(&o).contains("all 18 cells of the plan are merged"),
        "{}",
        stderr(&o)
    );
    assert_eq!(rows(&out.join("results.csv")), reference);

    // Re-submitted as 2 tasks (--array=1-2): nothing runs twice, nothing is lost.
    for id in [1, 2] {
        let o = ok(bsdfit_env(&args, &array_env(id, 1, 2, 1)), "2-task shard");
        assert!(stderr(&o).contains(", 0 to run"), "{}", stderr(&o));
    }
    ok(bsdfit_env(&merge, &[]), "merge");
    assert_eq!(rows(&out.join("results.csv")), reference);

    // Another sweep into the same folder is refused by its plan.
    let mut other = args.clone();
    other[4] = "lambert";
    let o = bsdfit_env(&other, &array_env(1, 1, 2, 1));
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("holds the plan of another sweep"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn emitted_job_scripts_run_the_same_sweep() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = synth(tmp.path());
    let base = sweep_args(&a, &b);
    let reference = unsharded_rows(tmp.path(), &base);

    let out = tmp.path().join("cluster");
    let mut args = base.clone();
    args.extend(["--out", out.to_str().unwrap(), "--emit-slurm", "2"]);
    ok(bsdfit_env(&args, &[]), "emit");
    let dir = out.join("slurm");
    let array = std::fs::read_to_string(dir.join("array.sbatch")).unwrap();
    assert!(array.contains("#SBATCH --array=1-2\n"), "{array}");
    assert!(array.contains("--shard auto"), "{array}");
    // The tasks run the saved sweep, not a command line rebuilt from its options.
    let config = dir.join("sweep.json");
    assert!(
        array.contains(&format!("sweep --config {} --shard auto", config.display())),
        "{array}"
    );
    let saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&config).unwrap()).unwrap();
    assert_eq!(saved["out"], serde_json::json!(out.to_str().unwrap()));
    assert_eq!(saved["backend"], "cpu");
    assert!(!array.contains("--gres"), "no GPU asked for: {array}");
    assert!(array.contains("RAYON_NUM_THREADS=\"${SLURM_CPUS_PER_TASK:-1}\""));
    let submit = std::fs::read_to_string(dir.join("submit.sh")).unwrap();
    assert!(submit.contains("--dependency=afterany:"), "{submit}");
    assert!(
        dir.join("logs").is_dir(),
        "Slurm does not create log folders"
    );

    // The scripts are plain bash: run them as Slurm would (the #SBATCH lines are comments).
    for id in 1..=2u64 {
        let o = Command::new("bash")
            .arg(dir.join("array.sbatch"))
            .env_remove("SLURM_JOB_ID")
            .envs(array_env(id, 1, 2, 1))
            .output()
            .unwrap();
        ok(o, "array.sbatch");
    }
    let o = Command::new("bash")
        .arg(dir.join("merge.sbatch"))
        .output()
        .unwrap();
    ok(o, "merge.sbatch");
    assert_eq!(rows(&out.join("results.csv")), reference);

    // A GPU sweep asks each task for one GPU.
    let gpu_out = tmp.path().join("gpu");
    let mut args = base.clone();
    let backend = args.iter().position(|a| *a == "cpu").unwrap();
    args[backend] = "gpu";
    args.extend(["--out", gpu_out.to_str().unwrap(), "--emit-slurm", "4"]);
    ok(bsdfit_env(&args, &[]), "emit gpu");
    let array = std::fs::read_to_string(gpu_out.join("slurm/array.sbatch")).unwrap();
    assert!(array.contains("#SBATCH --gres=gpu:1\n"), "{array}");
    let saved = std::fs::read_to_string(gpu_out.join("slurm/sweep.json")).unwrap();
    assert!(saved.contains("\"backend\": \"gpu\""), "{saved}");
}

/// The `shard = auto` messages name the option as each front end spells it: `--shard auto`
/// on the command line, `shard='auto'` in Python (the library error's own text).
#[test]
fn shard_auto_messages_name_the_option_per_front_end() {
    let e = shard_of(&[]).unwrap_err();
    let cli = bsdfit::cli::error_text(&e);
    assert!(
        cli.starts_with("--shard auto: SLURM_ARRAY_TASK_ID is not set")
            && cli.contains("(--shard auto reads SLURM_ARRAY_TASK_ID,")
            && cli.ends_with("or give --shard I/N"),
        "{cli}"
    );
    let python = e.to_string();
    assert!(
        python.starts_with("shard='auto': SLURM_ARRAY_TASK_ID is not set")
            && python.ends_with("or give shard='I/N'"),
        "{python}"
    );
    let e = shard_of(&[("SLURM_ARRAY_TASK_ID", "x{y}")]).unwrap_err();
    assert_eq!(
        bsdfit::cli::error_text(&e),
        "--shard auto: SLURM_ARRAY_TASK_ID=x(y) is not an index: invalid digit found in string"
    );
    let e = shard_of(&[("SLURM_ARRAY_TASK_ID", "2")]).unwrap_err();
    assert_eq!(
        e.to_string(),
        "shard='auto': SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_MIN is not"
    );
}
