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
use std::time::Duration;

/// The GPU backend with `plan` injected, or `None` (skip) where no adapter exists
/// outside CI.
fn gpu(plan: &str) -> Option<GpuBackend> {
    match GpuBackend::new() {
        Ok(g) => Some(g.with_fault(Some(plan.parse().expect("a fault plan")))),
        Err(e) => no_adapter(&e.to_string()),
    }
}

fn no_adapter<T>(why: &str) -> Option<T> {
    if std::env::var("CI").as_deref() == Ok("true") {
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
    let again = eval.costs(&point).expect_err("refused");
    assert_eq!(device_fault(&again), Some(&fault));
    let fresh = g
        .prepare(problem)
        .err()
        .expect("no evaluator on a lost device");
    assert_eq!(device_fault(&fresh), Some(&fault), "{fresh:#}");
    assert!(device_fault(&g.prepare_kernels(&model).unwrap_err()).is_some());
}

/// `hang@1`: the first read-back never completes; the timeout ends the wait with a typed
/// `Hung` naming the timeout's variable, and the backend refuses further work.
#[test]
fn a_read_back_that_never_completes_times_out_as_a_typed_fault() {
    let Some(g) = gpu("hang@1") else { return };
    let g = g.with_timeout(Duration::from_millis(200));
    let (model, data) = problem_data();
    let problem = Problem {
        model: &model,
        data: &data,
        loss: Loss::new(Metric::Chi2, Weights::Uniform),
    };
    let point = model.from_unit(&vec![0.5; model.dim]);
    let mut eval = g.prepare(problem).expect("an evaluator");
    let e = eval
        .costs(&point)
        .expect_err("the read-back never completes");
    let fault = device_fault(&e)
        .unwrap_or_else(|| panic!("untyped: {e:#}"))
        .clone();
    assert_eq!(
        fault,
        DeviceFault::Hung {
            submission: 1,
            seconds: 0.2
        }
    );
    assert!(e.to_string().contains("BSDFIT_GPU_TIMEOUT"), "{e}");
    assert_eq!(device_fault(&g.check_errors().unwrap_err()), Some(&fault));
    let again = eval.costs(&point).expect_err("refused");
    assert_eq!(device_fault(&again), Some(&fault));
}
