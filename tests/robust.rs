//! "Nothing lost, nothing silent": a sweep folder has one owner at a time (concurrent
//! sweeps do not lose rows; stale locks are recovered), output destinations are checked
//! before the work starts and named when they fail, non-finite fits name the samples that
//! cause them, progress shows in logs, and defaults and option errors say what they mean.

use bsdfit::output::results::read_results;
use bsdfit::workflows::sweep::lock::{host_name, LOCK_FILE};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

fn bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_bsdfit"));
    c.env_remove("BSDFIT_PROGRESS_SECS");
    c
}

fn run(args: &[&str]) -> Output {
    bin().args(args).output().expect("run bsdfit")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn ok(o: &Output, what: &str) {
    assert!(
        o.status.success(),
        "{what} failed ({:?}):\n{}\n{}",
        o.status.code(),
        text(&o.stdout),
        text(&o.stderr)
    );
}

/// Exit code 1, no panic, every needle in stderr.
fn clear_error(o: &Output, needles: &[&str]) -> String {
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "stderr:\n{err}");
    assert!(!err.contains("panicked"), "{err}");
    for n in needles {
        assert!(err.contains(n), "expected '{n}' in:\n{err}");
    }
    err
}

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// A small BRDF (Oren–Nayar, inplane10) and BTDF (PTB geometry) data set.
fn data(dir: &Path) -> (PathBuf, PathBuf) {
    let brdf = dir.join("on-small.csv");
    let btdf = dir.join("tr-small.csv");
    ok(
        &run(&[
            "synth",
            "--model",
            "on",
            "--params",
            "rho=0.3:0.5:0.7,sigma=0.6",
            "--geometry",
            "inplane10",
            "--seed",
            "11",
            "--out",
            p(&brdf),
        ]),
        "synth",
    );
    ok(
        &run(&[
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
            p(&btdf),
        ]),
        "synth",
    );
    (brdf, btdf)
}

fn sweep_args<'a>(
    brdf: &'a Path,
    btdf: &'a Path,
    out: &'a Path,
    extra: &[&'a str],
) -> Vec<&'a str> {
    let mut v = vec![
        "sweep",
        p(brdf),
        p(btdf),
        "--models",
        "lambert,on,btdf(tr),btdf(tr)+scale",
        "--losses",
        "rmse,f",
        "--restarts",
        "12",
        "--backend",
        "cpu",
        "--no-pictures",
        "--out",
        p(out),
    ];
    v.extend_from_slice(extra);
    v
}

type Fit = (String, String, String, String, String);

/// The tasks a sweep would run (from `--dry-run`), as (data, model, loss, weights, optimizer).
fn planned(brdf: &Path, btdf: &Path, out: &Path, extra: &[&str]) -> BTreeSet<Fit> {
    let mut args = sweep_args(brdf, btdf, out, extra);
    args.push("--dry-run");
    let o = run(&args);
    ok(&o, "sweep --dry-run");
    text(&o.stdout)
        .lines()
        .map(|l| {
            let f: Vec<&str> = l.split('\t').collect();
            let (loss, w) = f[4].split_once('/').unwrap();
            (
                f[2].to_string(),
                f[3].to_string(),
                loss.to_string(),
                w.to_string(),
                f[5].to_string(),
            )
        })
        .collect()
}

fn fits_in(out: &Path) -> BTreeSet<Fit> {
    read_results(&out.join("results.csv"), false, &mut |m| panic!("{m}"))
        .unwrap()
        .into_iter()
        .map(|r| r.fit_key())
        .collect()
}

/// Files bsdfit leaves behind by mistake: temporaries, probes, locks.
fn leftovers(dir: &Path) -> Vec<String> {
    let mut v = Vec::new();
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let n = e.file_name().to_string_lossy().into_owned();
        if n.ends_with(".tmp") || n.ends_with(".probe") || n.starts_with(".bsdfit.lock") {
            v.push(n);
        }
    }
    v
}

#[test]
fn concurrent_sweeps_on_one_folder_lose_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let (brdf, btdf) = data(tmp.path());
    let out = tmp.path().join("shared");
    let shard1 = planned(&brdf, &btdf, &out, &["--shard", "1/2"]);
    let shard2 = planned(&brdf, &btdf, &out, &["--shard", "2/2"]);
    assert!(!shard1.is_empty() && !shard2.is_empty());
    // Both shards started at once into the same folder (the bug: both exited 0 and the
    // last to finish rewrote results.csv with only its own rows).
    let spawn = |shard: &str| {
        bin()
            .args(sweep_args(&brdf, &btdf, &out, &["--shard", shard]))
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (a, b) = (spawn("1/2"), spawn("2/2"));
    let (a, b) = (a.wait_with_output().unwrap(), b.wait_with_output().unwrap());
    let mut expected = BTreeSet::new();
    for (o, plan) in [(&a, &shard1), (&b, &shard2)] {
        if o.status.success() {
            expected.extend(plan.iter().cloned());
        } else {
            // The loser says who holds the folder and what to do instead.
            clear_error(o, &["is in use by another bsdfit", "pid ", "bsdfit merge"]);
        }
    }
    assert!(
        a.status.success() || b.status.success(),
        "{}\n{}",
        text(&a.stderr),
        text(&b.stderr)
    );
    // Nothing lost: every row of every run that succeeded is in the final results.csv.
    let have = fits_in(&out);
    let missing: Vec<_> = expected.difference(&have).collect();
    assert!(missing.is_empty(), "lost rows: {missing:?}");
    assert!(leftovers(&out).is_empty(), "{:?}", leftovers(&out));

    // Sequentially, both shards complete the folder.
    for shard in ["1/2", "2/2"] {
        ok(
            &run(&sweep_args(&brdf, &btdf, &out, &["--shard", shard])),
            "sweep shard",
        );
    }
    let all: BTreeSet<Fit> = shard1.union(&shard2).cloned().collect();
    assert_eq!(fits_in(&out), all);
}

#[test]
fn stale_foreign_and_live_locks() {
    let tmp = tempfile::tempdir().unwrap();
    let (brdf, btdf) = data(tmp.path());
    let out = tmp.path().join("o");
    std::fs::create_dir_all(&out).unwrap();
    let lock = out.join(LOCK_FILE);
    let write_lock = |pid: u32, host: &str| {
        std::fs::write(
            &lock,
            format!("pid: {pid}\nhost: {host}\nstarted: 2024-01-01T00:00:00Z (unix 1704067200)\ncommand: sweep\ntoken: t\n"),
        )
        .unwrap()
    };
    // A live holder (this test process) on this host: refused, naming pid and host.
    write_lock(std::process::id(), &host_name());
    let o = run(&sweep_args(&brdf, &btdf, &out, &["--weights", "uniform"]));
    clear_error(
        &o,
        &[
            &format!("pid {} on host {}", std::process::id(), host_name()),
            ".bsdfit.lock",
        ],
    );
    // merge honours the lock as well.
    let o = run(&["merge", p(&out), "--out", p(&out), "--no-pictures"]);
    clear_error(&o, &[&format!("pid {}", std::process::id())]);
    // Another host: cannot be checked; the error says how to remove it.
    write_lock(12345, "some-other-host.example");
    let o = run(&sweep_args(&brdf, &btdf, &out, &["--weights", "uniform"]));
    clear_error(
        &o,
        &["some-other-host.example", &format!("rm {}", lock.display())],
    );
    // A pid that does not exist on this host: the stale lock is taken over, with a notice.
    write_lock(999_999_999, &host_name());
    let o = run(&sweep_args(&brdf, &btdf, &out, &["--weights", "uniform"]));
    ok(&o, "sweep over a stale lock");
    assert!(
        text(&o.stderr).contains("stale lock"),
        "{}",
        text(&o.stderr)
    );
    assert!(!lock.exists(), "the lock is released at exit");
    assert_eq!(fits_in(&out).len(), 4);
    // The lock is released on errors too: a results.csv of another version is an error
    // found after the lock was taken.
    std::fs::write(out.join("results.csv"), "a,b\n1,2\n").unwrap();
    let o = run(&sweep_args(&brdf, &btdf, &out, &["--weights", "uniform"]));
    clear_error(&o, &["results.csv", "columns"]);
    assert!(!lock.exists(), "the lock is released after an error");
}

#[test]
fn unwritable_destinations_fail_before_the_work() {
    let tmp = tempfile::tempdir().unwrap();
    let (brdf, _) = data(tmp.path());
    // A fit that would take a long time (many restarts) fails before fitting on its
    // --json: nothing of a fit is printed (a fit prints its result before writing the
    // report, so a check made after the work would leave it on stdout).
    let o = run(&[
        "fit",
        p(&brdf),
        "--model",
        "on",
        "--restarts",
        "4000",
        "--backend",
        "cpu",
        "--json",
        "/proc/x/fit.json",
    ]);
    clear_error(&o, &["--json /proc/x/fit.json", "/proc/x"]);
    assert!(
        text(&o.stdout).is_empty(),
        "no fit ran: {}",
        text(&o.stdout)
    );
    // The same for diagnose, bench and sweep.
    let o = run(&[
        "diagnose",
        p(&brdf),
        "--model",
        "lambert",
        "--backend",
        "cpu",
        "--json",
        "/proc/x/d.json",
    ]);
    clear_error(&o, &["--json /proc/x/d.json"]);
    let o = run(&[
        "diagnose",
        p(&brdf),
        "--model",
        "lambert",
        "--backend",
        "cpu",
        "--report",
        "/proc/x/rep",
    ]);
    clear_error(&o, &["--report /proc/x/rep"]);
    let o = run(&["bench", "--backend", "cpu", "--json", "/proc/x/b.json"]);
    clear_error(&o, &["--json /proc/x/b.json"]);
    let o = run(&["sweep", p(&brdf), "--backend", "cpu", "--out", "/proc/x/sw"]);
    clear_error(&o, &["--out /proc/x/sw"]);
    // render names its output folder.
    let o = run(&[
        "render",
        p(&brdf),
        "--model",
        "on",
        "--params",
        "rho=0.5,sigma=0.3",
        "--size",
        "16",
        "--out",
        "/proc/x",
    ]);
    clear_error(&o, &["/proc/x"]);
    // A --json that is a directory is named too.
    let o = run(&[
        "fit",
        p(&brdf),
        "--model",
        "lambert",
        "--backend",
        "cpu",
        "--json",
        p(tmp.path()),
    ]);
    clear_error(&o, &["is a directory"]);
}

/// Every command refuses a bad option before its work, not after: each run below would
/// take long if it started (4,000 restarts, a 30 s bench, a 1,200-pixel render), and
/// progress lines are asked for every 0.05 s. A refusal names the option, prints nothing
/// of the work on stdout and no progress line, and leaves no output behind.
#[test]
fn bad_options_are_refused_before_the_work_in_every_command() {
    let tmp = tempfile::tempdir().unwrap();
    let (brdf, _) = data(tmp.path());
    let out = tmp.path().join("out");
    let refused = |args: &[&str], names: &[&str]| {
        let o = bin()
            .env("BSDFIT_PROGRESS_SECS", "0.05")
            .args(args)
            .output()
            .unwrap();
        let err = clear_error(&o, names);
        let what = args.join(" ");
        assert!(
            text(&o.stdout).is_empty(),
            "{what}: the work ran: {}",
            text(&o.stdout)
        );
        assert!(
            !err.lines()
                .any(|l| l.contains("elapsed") || l.contains("step 0")),
            "{what}: progress of the work:\n{err}"
        );
        assert!(!out.exists(), "{what}: left {}", out.display());
    };
    let (brdf_s, out_s) = (p(&brdf), p(&out));
    let diagnose = [
        "diagnose",
        brdf_s,
        "--model",
        "lambert",
        "--backend",
        "cpu",
        "--restarts",
        "4000",
    ];
    let bench = ["bench", "--backend", "cpu", "--seconds", "30"];
    let sweep = [
        "sweep",
        brdf_s,
        "--models",
        "lambert,on",
        "--backend",
        "cpu",
        "--restarts",
        "4000",
        "--no-pictures",
        "--out",
        out_s,
    ];
    let render = [
        "render", brdf_s, "--model", "on", "--size", "1200", "--out", out_s,
    ];
    let params = "rho=0.5,sigma=0.3";
    let cases: [(&[&str], &[&str], &[&str]); 13] = [
        (&diagnose, &["--fix", "sigmaa=1"], &["--fix", "sigmaa"]),
        (&diagnose, &["--loss", "nosuch"], &["--loss", "nosuch"]),
        (
            &diagnose,
            &["--json", "/proc/x/d.json"],
            &["--json /proc/x/d.json"],
        ),
        (
            &diagnose,
            &["--report", "/proc/x/rep"],
            &["--report /proc/x/rep"],
        ),
        (&bench, &["--models", "nosuch"], &["--models", "nosuch"]),
        (
            &bench,
            &["--json", "/proc/x/b.json"],
            &["--json /proc/x/b.json"],
        ),
        (
            &bench,
            &["--data", "/nonexistent/d.csv"],
            &["/nonexistent/d.csv"],
        ),
        (&sweep, &["--fix", "sigmaa=0.3"], &["--fix sigmaa"]),
        (
            &sweep,
            &["--losses", "rmse,nosuch"],
            &["--losses", "nosuch"],
        ),
        (&sweep, &["--shard", "3/2"], &["--shard"]),
        (
            &render,
            &["--params", "rho=0.5,sigma=0.3,bogus=1"],
            &["--params", "bogus"],
        ),
        (
            &render,
            &["--params", params, "--light", "0,0,-1"],
            &["--light"],
        ),
        (
            &render,
            &["--params", params, "--error-scale", "0"],
            &["--error-scale"],
        ),
    ];
    for (command, extra, names) in cases {
        refused(&[command, extra].concat(), names);
    }
}

#[test]
fn outputs_are_written_whole_and_leave_no_temporaries() {
    let tmp = tempfile::tempdir().unwrap();
    let (brdf, btdf) = data(tmp.path());
    let out = tmp.path().join("o");
    // A sweep with pictures: no temporary files anywhere in the folder afterwards.
    let mut args = sweep_args(&brdf, &btdf, &out, &[]);
    args.retain(|a| *a != "--no-pictures");
    let r = args.iter().position(|a| *a == "--restarts").unwrap();
    args[r + 1] = "3";
    ok(&run(&args), "sweep");
    let mut stack = vec![out.clone()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            if e.path().is_dir() {
                stack.push(e.path());
            } else {
                let n = e.file_name().to_string_lossy().into_owned();
                assert!(
                    !n.ends_with(".tmp") && !n.ends_with(".probe") && n != LOCK_FILE,
                    "left behind: {}",
                    e.path().display()
                );
            }
        }
    }
    assert!(!out.join("results.tmp").exists());
    // fit --json into a directory that does not exist yet: created, JSON complete.
    let json = tmp.path().join("new/dir/fit.json");
    let o = run(&[
        "fit",
        p(&brdf),
        "--model",
        "lambert",
        "--backend",
        "cpu",
        "--restarts",
        "2",
        "--json",
        p(&json),
    ]);
    ok(&o, "fit --json");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(v["model"], "lambert");
}

#[test]
fn fit_defaults_to_chi2_and_lm_on_any_data() {
    let tmp = tempfile::tempdir().unwrap();
    let (_, btdf) = data(tmp.path());
    let json = tmp.path().join("t.json");
    // A BTDF file with no --loss: the default (chi2) applies to it (rmse did not).
    let o = run(&[
        "fit",
        p(&btdf),
        "--model",
        "btdf(tr)+scale",
        "--backend",
        "cpu",
        "--json",
        p(&json),
    ]);
    ok(&o, "fit on BTDF data with the defaults");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(v["loss"], "chi2");
    assert_eq!(v["optimizer"], "lm");
    assert_eq!(v["restarts"], 16);
    // smape is not a sum of squares: its default optimizer is compass.
    let (brdf, _) = data(tmp.path());
    let o = run(&[
        "fit",
        p(&brdf),
        "--model",
        "lambert",
        "--loss",
        "smape",
        "--restarts",
        "2",
        "--backend",
        "cpu",
        "--json",
        p(&json),
    ]);
    ok(&o, "fit --loss smape");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(v["optimizer"], "compass");
    // The help says why.
    let h = text(&run(&["fit", "--help"]).stdout);
    assert!(
        h.contains("[default: chi2]") && h.contains("uncertainty"),
        "{h}"
    );
    let h = text(&run(&["sweep", "--help"]).stdout);
    assert!(
        h.contains("rankings changed with the seed") && h.contains("own --out"),
        "{h}"
    );
}

#[test]
fn seeds_and_restarts_say_what_they_take() {
    let tmp = tempfile::tempdir().unwrap();
    let (brdf, _) = data(tmp.path());
    for cmd in [
        vec!["fit", p(&brdf), "--model", "lambert", "--seed", "-1"],
        vec!["sweep", p(&brdf), "--seed", "-1"],
        vec!["diagnose", p(&brdf), "--model", "lambert", "--seed", "-1"],
        vec![
            "synth", "--model", "lambert", "--out", "x.csv", "--seed", "-1",
        ],
    ] {
        let o = run(&cmd);
        let err = text(&o.stderr);
        assert!(!o.status.success());
        assert!(err.contains("--seed takes a non-negative integer"), "{err}");
        assert!(!err.contains("-- -1"), "clap's misleading tip: {err}");
    }
    let o = run(&["fit", p(&brdf), "--model", "lambert", "--restarts", "0"]);
    assert!(text(&o.stderr).contains("--restarts takes a positive integer"));
    // A request that cannot fit in memory is refused up front, with a way out, and no fit
    // is printed.
    let o = run(&[
        "fit",
        p(&brdf),
        "--model",
        "on",
        "--restarts",
        "1000000",
        "--backend",
        "cpu",
    ]);
    clear_error(&o, &["--restarts 1000000", "GiB", "fewer"]);
    assert!(text(&o.stdout).is_empty(), "{}", text(&o.stdout));
}

#[test]
fn progress_lines_when_stderr_is_not_a_terminal() {
    let tmp = tempfile::tempdir().unwrap();
    let (brdf, btdf) = data(tmp.path());
    let out = tmp.path().join("o");
    // Enough restarts that the sweep outlasts the shortest interval (0.05 s) even in a
    // release build: a run shorter than the interval rightly prints no line.
    let mut args = sweep_args(&brdf, &btdf, &out, &[]);
    let at = args.iter().position(|&a| a == "--restarts").unwrap() + 1;
    args[at] = "400";
    let o = bin()
        .env("BSDFIT_PROGRESS_SECS", "0.05")
        .args(args)
        .output()
        .unwrap();
    ok(&o, "sweep");
    let err = text(&o.stderr);
    assert!(
        err.lines()
            .any(|l| l.starts_with("sweep: ") && l.contains(" fits, ") && l.contains("elapsed")),
        "{err}"
    );
    let o = bin()
        .env("BSDFIT_PROGRESS_SECS", "0.05")
        .args([
            "fit",
            p(&brdf),
            "--model",
            "on",
            "--restarts",
            "1000",
            "--optimizer",
            "compass",
            "--loss",
            "rmse",
            "--backend",
            "cpu",
        ])
        .output()
        .unwrap();
    ok(&o, "fit");
    let err = text(&o.stderr);
    assert!(
        err.lines()
            .any(|l| l.starts_with("fit: ") && l.contains("restarts converged")),
        "{err}"
    );
}

#[test]
fn non_finite_fits_name_the_samples_that_cause_them() {
    use bsdfit::bsdf::Model;
    use bsdfit::cli::checks::{nonfinite_cause, nonfinite_message};
    use bsdfit::data::Dataset;
    use bsdfit::engine::cpu::CpuBackend;
    use bsdfit::engine::loss::{chi2, Loss, Metric, Weights};
    let tmp = tempfile::tempdir().unwrap();
    let (brdf, _) = data(tmp.path());
    let mut ds = Dataset::read(&brdf, &Default::default()).unwrap();
    // Whatever the data layer accepts, an uncertainty this small makes χ² overflow.
    ds.samples[7].uncertainty = 1e-300;
    let line = ds.samples[7].line;
    let model = Model::for_data("lambert", &ds).unwrap();
    let flat = vec![0.3; model.dim];
    let cpu = CpuBackend::new();
    let vals: Vec<f64> = ds
        .samples
        .iter()
        .map(|_| 0.3 / std::f64::consts::PI)
        .collect();
    assert!(!chi2(&ds, &vals).is_finite());
    // chi2 loss: that sample's term is infinite; it is named with its line and value ± u.
    let m = nonfinite_message(
        &model,
        &ds,
        Loss::new(Metric::Chi2, Weights::Uniform),
        &flat,
        f64::INFINITY,
        f64::INFINITY,
        &cpu,
    );
    assert!(m.contains(&format!("on-small.csv:{line}")), "{m}");
    assert!(m.contains("± 1e-300") && m.contains("1 sample"), "{m}");
    // rmse loss: every term is finite, only the χ² sum overflows: the largest are listed.
    let m = nonfinite_cause(
        &model,
        &ds,
        Loss::new(Metric::Rmse, Weights::Uniform),
        &flat,
        &cpu,
    );
    assert!(
        m.contains("overflow") && m.contains(&format!(":{line}:")),
        "{m}"
    );
    assert!(m.lines().count() <= 6, "at most 5 samples: {m}");
}

/// Help that tells the truth: every command that reads data names every format the
/// readers recognise, and every option of every command has a description (a flag line
/// followed at once by its `[default: …]` has none).
#[test]
fn every_command_names_every_format_and_every_option_has_help() {
    use bsdfit::data::readers::Format;
    let formats = [
        Format::V1Csv,
        Format::AltaText,
        Format::MerlBinary,
        Format::RglBsdf,
        Format::ZemaxBsdf,
        Format::AstmE1392,
        Format::MuellerCsv,
    ]
    .map(|f| f.to_string());
    let top = text(&run(&["--help"]).stdout);
    let commands: Vec<String> = top
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| !l.trim().is_empty())
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .filter(|c| c != "help")
        .collect();
    assert!(commands.len() >= 12, "{commands:?}");
    let mut missing = Vec::new();
    for c in &commands {
        let help = text(&run(&[c, "--help"]).stdout);
        let reads_data = [
            "fit", "diagnose", "convert", "sweep", "render", "eval", "bench",
        ];
        if reads_data.contains(&c.as_str()) {
            // Help wraps lines: compare with whitespace collapsed.
            let flat = help.split_whitespace().collect::<Vec<_>>().join(" ");
            for f in &formats {
                if !flat.contains(f.as_str()) {
                    missing.push(format!("{c}: the format '{f}' is not named"));
                }
            }
        }
        let lines: Vec<&str> = help.lines().collect();
        for (k, l) in lines.iter().enumerate() {
            let t = l.trim_start();
            if !(t.starts_with("--") || t.starts_with("-") && t.get(2..4) == Some(", ")) {
                continue;
            }
            if t.starts_with("-h, --help") || t.starts_with("-V, --version") {
                continue;
            }
            // Short help sits on the flag's line after two spaces; long help on the next.
            let same_line = t
                .split_once("  ")
                .is_some_and(|(_, h)| !h.trim().is_empty());
            let next = lines.get(k + 1).map(|n| n.trim()).unwrap_or("");
            if !same_line && (next.is_empty() || next.starts_with('[') || next.starts_with('-')) {
                missing.push(format!("{c}: {} has no help", t.split(' ').next().unwrap()));
            }
        }
    }
    assert!(missing.is_empty(), "{}", missing.join("\n"));
}
