//! A GPU lost or hung in the middle of the work loses nothing (docs/reliability.md, "GPU
//! faults"): the engine reports a typed [`DeviceFault`] through `check_errors` and every
//! read-back, a timeout ends a read-back that never completes, and then `bsdfit sweep`
//! and `bsdfit fit` re-run the affected fits on the CPU reference.
//!
//! Runs on whatever Vulkan adapter exists (lavapipe here and in CI). Without one the
//! tests fail when `CI=true`, and otherwise are skipped with the reason printed.

mod common;

use bsdfit::engine::cpu::CpuBackend;
use bsdfit::engine::gpu::{device_fault, DeviceFault, GpuBackend};
use bsdfit::engine::loss::{Loss, Metric, Weights};
use bsdfit::engine::{Backend, Problem};
use bsdfit::output::results::{read_results, Row};
use common::cli::{assert_clear_error, assert_ok, bsdfit, bsdfit_env, bsdfit_env_within, p, text};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// A hundred times what any command or evaluation of these tests takes on lavapipe: one
/// still running then is hung (a read-back timeout broken), and the test fails instead
/// of waiting forever. A guard, not a measure of speed.
const WATCHDOG: Duration = Duration::from_secs(300);

/// The GPU backend with `plan` injected, or `None` (skip) where no adapter exists
/// outside CI.
fn gpu(plan: &str) -> Option<GpuBackend> {
    match GpuBackend::new() {
        Ok(g) => Some(g.with_fault(Some(plan.parse().expect("a fault plan")))),
        Err(e) => no_adapter(&e.to_string()),
    }
}

/// Whether the tests that run the command line on the GPU can run (see [`no_adapter`]).
fn have_gpu() -> bool {
    match GpuBackend::new() {
        Ok(_) => true,
        Err(e) => no_adapter::<()>(&e.to_string()).is_some(),
    }
}

fn no_adapter<T>(why: &str) -> Option<T> {
    if common::in_ci() {
        panic!("no Vulkan adapter in CI ({why}): CI installs mesa-vulkan-drivers (lavapipe) for these tests");
    }
    eprintln!("skipped: no Vulkan adapter ({why})");
    None
}

fn problem_data() -> (bsdfit::bsdf::Model, bsdfit::data::Dataset) {
    let (model, _, data) = common::synth_geometry(
        "fa(lambert)",
        "lobe.alpha=0.12,lobe.eta=1.6,lobe.ks=0.9,base.rho=0.15:0.35:0.55",
        "specular",
        &[450.0, 550.0, 650.0],
        (0.015, 1e-4),
        17,
    );
    (model, data)
}

/// `lost@2`: the first submission is answered, the second finds the device destroyed and
/// fails with a typed `Lost`, which `check_errors` reports too, and every later use of the
/// backend is refused with the same fault, an evaluator included.
#[test]
fn a_lost_device_is_a_typed_fault_that_check_errors_reports() {
    let Some(g) = gpu("lost@2") else { return };
    let (model, data) = problem_data();
    let loss = Loss::new(Metric::Rmse, Weights::Uniform);
    let problem = Problem {
        model: &model,
        data: &data,
        loss,
    };
    let point = model.from_unit(&vec![0.5; model.dim]);
    let mut eval = g.prepare(problem).expect("an evaluator");
    let first = eval.costs(&point).expect("submission 1 is answered");
    let cpu = CpuBackend::new()
        .prepare(problem)
        .unwrap()
        .costs(&point)
        .unwrap();
    assert!(
        (first[0] - cpu[0]).abs() <= 1e-4 * cpu[0].abs(),
        "{first:?} vs {cpu:?}"
    );
    assert!(g.check_errors().is_ok(), "a live device reports nothing");

    let e = eval
        .costs(&point)
        .expect_err("submission 2 meets a lost device");
    let fault = device_fault(&e)
        .unwrap_or_else(|| panic!("untyped: {e:#}"))
        .clone();
    assert!(
        matches!(fault, DeviceFault::Lost { submission: 2, .. }),
        "{fault:?}"
    );
    let checked = g.check_errors().expect_err("check_errors reports the loss");
    assert_eq!(device_fault(&checked), Some(&fault), "{checked:#}");
    assert_eq!(g.fault(), Some(fault.clone()));

    // Refused, with the same fault: no third submission, no new evaluator, no kernels.
    assert_eq!(g.submission_count(), 2);
    let again = eval.costs(&point).expect_err("refused");
    assert_eq!(device_fault(&again), Some(&fault));
    assert_eq!(
        g.submission_count(),
        2,
        "a submission begun on a lost device"
    );
    let fresh = g
        .prepare(problem)
        .err()
        .expect("no evaluator on a lost device");
    assert_eq!(device_fault(&fresh), Some(&fault), "{fresh:#}");
    assert!(device_fault(&g.prepare_kernels(&model).unwrap_err()).is_some());
}

/// `hang@1`: the first submission is made behind device work that outlasts the timeout
/// (the injection's stall), so the device's own wait for it (the poll with its timeout)
/// ends with a typed `Hung` naming the timeout's variable, and the backend refuses
/// further work. (On a thread of its own, so that a broken timeout fails the test
/// instead of hanging it; a wait without its timeout returns once the stall is done,
/// and the test fails on the read-back that completed.)
#[test]
fn a_read_back_that_never_completes_times_out_as_a_typed_fault() {
    let Some(g) = gpu("hang@1") else { return };
    let g = g.with_timeout(Duration::from_millis(200));
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let (model, data) = problem_data();
        let problem = Problem {
            model: &model,
            data: &data,
            loss: Loss::new(Metric::Chi2, Weights::Uniform),
        };
        let point = model.from_unit(&vec![0.5; model.dim]);
        let mut eval = g.prepare(problem).expect("an evaluator");
        let first = eval
            .costs(&point)
            .map_err(|e| (device_fault(&e).cloned(), e.to_string()));
        let checked = g.check_errors().map_err(|e| device_fault(&e).cloned());
        let again = eval.costs(&point).map_err(|e| device_fault(&e).cloned());
        tx.send((first, checked, again, g.submission_count())).ok();
    });
    let (first, checked, again, submitted) = rx
        .recv_timeout(WATCHDOG)
        .expect("the read-back still waits: the timeout did not end it");
    let (fault, text) = first.expect_err("the read-back never completes");
    let hung = DeviceFault::Hung {
        submission: 1,
        seconds: 0.2,
    };
    assert_eq!(fault.as_ref(), Some(&hung), "untyped or other: {text}");
    assert!(text.contains("BSDFIT_GPU_TIMEOUT"), "{text}");
    assert_eq!(
        checked,
        Err(Some(hung.clone())),
        "check_errors reports the hang"
    );
    assert_eq!(again.map(|_| ()), Err(Some(hung)), "refused after the hang");
    assert_eq!(submitted, 1, "a submission begun on a hung device");
}

// ---- the command line: a sweep and a fit that meet a lost or hung GPU ----

fn bundled(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("data")
        .join(name)
}

/// Two bundled data sets × 3 models × 1 loss, 4 restarts: on lavapipe its stages make 3
/// (lambert), 10 (on) and 13 (fa(lambert)) GPU submissions, 26 in all; the submission
/// [`MID_SWEEP`] falls after `lambert`'s have been answered, whichever worker's turn it is.
const MODELS: &str = "lambert,on,fa(lambert)";
const MID_SWEEP: u32 = 20;

fn sweep(out: &Path, backend: &str, env: &[(&str, &str)]) -> std::process::Output {
    let (a, b) = (bundled("w80-g3.4.csv"), bundled("white-standard.csv"));
    let args = [
        "sweep",
        p(&a),
        p(&b),
        "--models",
        MODELS,
        "--losses",
        "rmse",
        "--weights",
        "uniform",
        "--restarts",
        "4",
        "--backend",
        backend,
        "--no-pictures",
        "--out",
        p(out),
    ];
    let o = bsdfit_env_within(&args, env, WATCHDOG);
    assert_ok(&o, &format!("sweep --backend {backend} with {env:?}"));
    o
}

fn rows(dir: &Path) -> Vec<Row> {
    read_results(&dir.join("results.csv"), false, &mut |m| panic!("{m}")).unwrap()
}

/// A results row's JSON object of parameters (or of their σ, null where undetermined),
/// flattened in its order, arrays element by element.
fn flat_json(object: &str) -> Vec<Option<f64>> {
    let v: serde_json::Value = serde_json::from_str(object).unwrap();
    let mut out = Vec::new();
    for x in v.as_object().unwrap().values() {
        match x {
            serde_json::Value::Array(a) => out.extend(a.iter().map(|e| e.as_f64())),
            e => out.push(e.as_f64()),
        }
    }
    out
}

/// `data · model · loss/weights · optimizer`, as the sweep's notices name a fit.
fn fit_name(r: &Row) -> String {
    format!(
        "{} · {} · {}/{} · {}",
        r.data, r.model, r.loss, r.weights, r.optimizer
    )
}

/// The fits the notices say were re-run on the CPU after the fault `brief` names.
fn rerun_fits(stderr: &str, brief: &str) -> BTreeSet<String> {
    let head = format!("re-running on the CPU reference ({brief}): ");
    stderr
        .lines()
        .filter_map(|l| l.trim().strip_prefix(head.as_str()))
        .map(str::to_string)
        .collect()
}

/// A sweep that meets `fault` mid-way ends with every row a CPU-only sweep has, none
/// twice: the fits the device failed are named, re-run on the CPU (their rows the CPU
/// sweep's to the bit), the rows the GPU finished before the fault kept (within the
/// engines' stated tolerance of the CPU's). Then the same sweep, resumed in its folder,
/// has nothing to run and changes no byte.
fn sweep_survives(fault: &str, env: &[(&str, &str)], says: &[&str], brief: &str) {
    let tmp = tempfile::tempdir().unwrap();
    let (cpu_dir, dir) = (tmp.path().join("cpu"), tmp.path().join("faulted"));
    sweep(&cpu_dir, "cpu", &[]);
    let mut with = vec![("BSDFIT_GPU_FAULT", fault)];
    with.extend_from_slice(env);
    let o = sweep(&dir, "gpu", &with);
    let err = text(&o.stderr);
    assert!(!err.contains("panicked"), "{err}");
    for s in says {
        assert!(err.contains(s), "expected '{s}' in:\n{err}");
    }
    let rerun = rerun_fits(&err, brief);
    assert!(!rerun.is_empty(), "no fit named as re-run:\n{err}");

    let (cpu, got) = (rows(&cpu_dir), rows(&dir));
    let keys: BTreeSet<String> = got.iter().map(fit_name).collect();
    assert_eq!(keys.len(), got.len(), "a fit twice: {keys:?}");
    assert_eq!(keys, cpu.iter().map(fit_name).collect(), "fits missing");
    // Rows of the GPU from before the fault, or of the CPU: re-runs, and stages begun
    // after the fault (those are not named: the notice says the sweep goes on there).
    for r in &got {
        match r.backend.as_str() {
            "gpu" => {}
            "cpu" => {
                let c = cpu.iter().find(|c| c.key() == r.key());
                let c = c.unwrap_or_else(|| panic!("{}: not the CPU sweep's fit", fit_name(r)));
                assert_eq!(r.deterministic(), c.deterministic(), "{}", fit_name(r));
            }
            other => panic!("{}: backend {other}", fit_name(r)),
        }
    }
    for name in &rerun {
        let r = got.iter().find(|r| &fit_name(r) == name).unwrap();
        assert_eq!(r.backend, "cpu", "{name} was named as re-run on the CPU");
    }
    assert!(
        got.iter().any(|r| r.backend == "gpu"),
        "no row kept from before the fault: submission {fault} came earlier than this test \
         expects (see MID_SWEEP)"
    );
    let skipped = std::fs::read_to_string(dir.join("skipped.json")).unwrap();
    assert_eq!(
        skipped.trim(),
        "[]",
        "a fit recorded as failed besides its re-run"
    );
    // The rows the GPU kept, judged here against the CPU sweep's (not with the library's
    // comparator): the same optimum, its loss within 1e-3 (f32 evaluation on the device,
    // an f64 polish of the best restarts), every parameter the CPU row determines within
    // 5 % of its σ or 1 % of its value.
    for r in got.iter().filter(|r| r.backend == "gpu") {
        let c = cpu.iter().find(|c| c.key() == r.key()).unwrap();
        let name = fit_name(r);
        let rel = (r.best_loss - c.best_loss).abs() / c.best_loss.abs().max(1e-300);
        assert!(
            rel <= 1e-3,
            "{name}: loss {} on the GPU, {} on the CPU",
            r.best_loss,
            c.best_loss
        );
        let (values, sigmas) = (flat_json(&c.params), flat_json(&c.param_std));
        let gpu_values = flat_json(&r.params);
        assert_eq!(values.len(), gpu_values.len(), "{name}");
        for ((v, s), g) in values.iter().zip(&sigmas).zip(&gpu_values) {
            let (v, g) = (v.unwrap(), g.unwrap());
            let Some(s) = s else { continue };
            assert!(
                (g - v).abs() <= (0.05 * s).max(1e-2 * v.abs()),
                "{name}: a parameter {g} on the GPU, {v} ± {s} on the CPU"
            );
        }
    }

    // Resumed in the same folder (the GPU healthy now): nothing to run, nothing changed.
    let files = ["results.csv", "skipped.json", "results.json"];
    let read = |f: &str| std::fs::read(dir.join(f)).unwrap();
    let before: Vec<Vec<u8>> = files.iter().map(|f| read(f)).collect();
    let again = sweep(&dir, "gpu", &[]);
    let note = format!("{} already in", got.len());
    assert!(
        text(&again.stderr).contains(&format!("{note} {}", p(&dir.join("results.csv"))))
            && text(&again.stderr).contains("0 to run"),
        "{}",
        text(&again.stderr)
    );
    for (f, b) in files.iter().zip(before) {
        assert!(read(f) == b, "{f} changed on resuming");
    }
}

/// `lost@N` mid-sweep: the device is destroyed at submission N.
#[test]
fn a_sweep_that_loses_its_gpu_ends_with_the_cpu_sweeps_rows() {
    if !have_gpu() {
        return;
    }
    let fault = format!("lost@{MID_SWEEP}");
    let brief = format!("GPU lost at submission {MID_SWEEP}");
    sweep_survives(
        &fault,
        &[],
        &[
            &format!("GPU fault: the GPU device was lost at submission {MID_SWEEP}"),
            "the sweep continues on the CPU reference",
        ],
        &brief,
    );
}

/// `hang@N` mid-sweep: submission N does not complete in time; a short timeout ends the wait (short
/// for a test, yet far above what this sweep's submissions take: every read-back before
/// the hang is bounded by it too).
#[test]
fn a_sweep_whose_gpu_hangs_ends_with_the_cpu_sweeps_rows() {
    if !have_gpu() {
        return;
    }
    let fault = format!("hang@{MID_SWEEP}");
    let brief = format!("GPU hung at submission {MID_SWEEP}");
    sweep_survives(
        &fault,
        &[("BSDFIT_GPU_TIMEOUT", "5")],
        &[
            &format!("GPU fault: GPU submission {MID_SWEEP} did not complete within 5 s"),
            "BSDFIT_GPU_TIMEOUT",
        ],
        &brief,
    );
}

fn fit_json(
    dir: &Path,
    tag: &str,
    backend: &str,
    env: &[(&str, &str)],
) -> (serde_json::Value, String) {
    let json = dir.join(format!("{tag}.json"));
    let data = bundled("w80-g3.4.csv");
    let o = bsdfit_env_within(
        &[
            "fit",
            p(&data),
            "--model",
            "fa(lambert)",
            "--restarts",
            "4",
            "--backend",
            backend,
            "--json",
            p(&json),
        ],
        env,
        WATCHDOG,
    );
    assert_ok(&o, &format!("fit {tag}"));
    let err = text(&o.stderr);
    assert!(!err.contains("panicked"), "{err}");
    let v = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    (v, err + &text(&o.stdout))
}

/// A single fit whose GPU is lost (at its first submission, or after a few) or hangs says
/// so, falls back to the CPU reference, and reports the CPU fit's parameters and backend.
#[test]
fn a_fit_whose_gpu_fails_falls_back_to_the_cpu_and_says_so() {
    if !have_gpu() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let (cpu, _) = fit_json(tmp.path(), "cpu", "cpu", &[]);
    let lost = |n: u32| format!("the GPU device was lost at submission {n} (Destroyed)");
    let hung = "GPU submission 1 did not complete within 0.5 s (the read-back timeout, \
                BSDFIT_GPU_TIMEOUT); the device is taken as hung";
    // `auto` takes a hardware GPU only: where the adapter is a software one (lavapipe, as
    // in CI) it fits on the SIMD engine, so no fault reaches it.
    let software = GpuBackend::new().is_ok_and(|g| g.is_software());
    if software {
        let (got, said) = fit_json(
            tmp.path(),
            "auto-lost1",
            "auto",
            &[("BSDFIT_GPU_FAULT", "lost@1")],
        );
        assert!(!said.contains("GPU fault"), "{said}");
        assert_eq!(got["backend"], "simd");
    }
    let auto = (!software).then(|| ("auto-lost1", "auto", "lost@1", lost(1)));
    for (tag, backend, fault, cause) in [
        ("lost1", "gpu", "lost@1", lost(1)),
        ("lost3", "gpu", "lost@3", lost(3)),
        ("hang1", "gpu", "hang@1", hung.to_string()),
    ]
    .into_iter()
    .chain(auto)
    {
        // A short timeout where the first submission hangs (none comes before it).
        let mut env = vec![("BSDFIT_GPU_FAULT", fault)];
        if fault.starts_with("hang") {
            env.push(("BSDFIT_GPU_TIMEOUT", "0.5"));
        }
        let (got, said) = fit_json(tmp.path(), tag, backend, &env);
        let line = format!("GPU fault: {cause}; the fit was re-run on the CPU reference");
        assert!(said.contains(&line), "{tag}: expected '{line}' in:\n{said}");
        assert_eq!(got["backend"], "cpu", "{tag}");
        assert!(
            got["warnings"]
                .as_array()
                .unwrap()
                .iter()
                .any(|w| w == line.as_str()),
            "{tag}: {}",
            got["warnings"]
        );
        assert_eq!(got["best"]["params"], cpu["best"]["params"], "{tag}");
        assert_eq!(got["best"]["loss"], cpu["best"]["loss"], "{tag}");
    }
}

/// The switch and the timeout are checked when the GPU opens: a value that does not
/// parse is a clear error naming its variable.
#[test]
fn a_malformed_switch_or_timeout_is_a_clear_error() {
    if !have_gpu() {
        return;
    }
    let data = bundled("w80-g3.4.csv");
    let args = ["fit", p(&data), "--model", "lambert", "--backend", "gpu"];
    let o = bsdfit_env(&args, &[("BSDFIT_GPU_FAULT", "melt@2")]);
    assert_clear_error(&o, &["BSDFIT_GPU_FAULT=melt@2", "lost@N or hang@N"]);
    let o = bsdfit_env(&args, &[("BSDFIT_GPU_TIMEOUT", "0")]);
    assert_clear_error(&o, &["BSDFIT_GPU_TIMEOUT=0", "positive"]);
    // Without the variables the same command runs.
    assert_ok(&bsdfit(&args), "fit --backend gpu");
}
