//! The sweep's worker pool: cells grouped into stages that step in lockstep, one worker
//! per core, kernels compiled ahead on a thread of their own, and every finished fit
//! handed back to the calling thread (which appends it to results.csv at once).
//!
//! **A device lost or hung** ([`crate::engine::DeviceFault`]): the fits of a stage that
//! the device failed are re-run on the fallback backend (the CPU reference), and every
//! stage that starts after the fault runs there; fits the device finished before stay.

use super::Task;
use crate::bsdf::Model;
use crate::data::Dataset;
use crate::engine::loss::Loss;
use crate::engine::{device_fault, Backend, DeviceFault};
use crate::inference::fit::{fit, fit_stage, FitOptions, FitReport, PhaseSeconds};
use crate::output::results::DataFile;
use anyhow::Result;
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering::SeqCst};
use std::sync::Mutex;

/// How one fit ended: a report, an error, or a panic caught on its worker.
pub type CellOutcome = std::thread::Result<Result<FitReport>>;

/// A cell the pool can fit: its task and its model, built for the task's data.
pub type Runnable<'a> = (&'a Task, Model);

/// What the pool hands the calling thread.
pub enum PoolEvent {
    /// The device failed these cells' fits (indices into the runnable cells) with
    /// `fault`: they are being re-run on the fallback backend, their outcomes to follow.
    Rerun {
        cells: Vec<usize>,
        fault: DeviceFault,
    },
    /// A cell's fit ended (on the fallback backend where a `Rerun` named it).
    Landed(usize, Box<CellOutcome>),
}

/// What the pool needs besides its cells: the data, the backend and the fit options
/// every cell shares (each stage sets its own optimizer).
pub struct Pool<'a> {
    pub files: &'a [DataFile],
    pub backend: &'a dyn Backend,
    /// Where fits go once `backend`'s device is lost or hung (the CPU reference; `None`
    /// for a host backend).
    pub fallback: Option<&'a dyn Backend>,
    pub options: FitOptions,
}

/// What the pool measured of itself.
pub struct PoolStats {
    /// Worker threads it ran.
    pub workers: usize,
    /// Thread-seconds per phase, summed over the stages fitted together.
    pub phases: PhaseSeconds,
}

impl Pool<'_> {
    /// Fit every runnable cell. `each` receives every cell's outcome (by its index into
    /// `runnable`) on the calling thread, as soon as its stage ends, and the re-runs a
    /// device fault caused before their outcomes; an error from `each` stops the workers
    /// after their stages in flight and is returned.
    ///
    /// A stage is one model (same spec, channels and planes) under one optimizer and one
    /// loss term shape over every data set, loss and weighting it applies to (the default
    /// χ² and RMSE, or χ² and f, are both squares): its fits step in lockstep, so each
    /// optimizer step is one submission of all their candidates (many fits per dispatch).
    /// On lavapipe, one stage per loss instead took 4,311 submissions against 2,821, and
    /// the default sweep 3.7 s against 3.3 s. Each fit is deterministic on its own (its
    /// starts do not depend on the stage), so the outcome does not depend on the staging
    /// or on which worker finished first.
    pub fn run(
        &self,
        runnable: &[Runnable],
        each: &mut dyn FnMut(PoolEvent) -> Result<()>,
    ) -> Result<PoolStats> {
        let stages = stages_of(runnable);
        let workers = std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
            .clamp(1, stages.len().max(1));
        let next = AtomicUsize::new(0);
        let stop = AtomicBool::new(false);
        let phases = Mutex::new(PhaseSeconds::default());
        std::thread::scope(|scope| -> Result<()> {
            let (stages, stop) = (&stages, &stop);
            scope.spawn(move || self.compile_ahead(runnable, stages, stop));
            let (tx, rx) = std::sync::mpsc::channel();
            for _ in 0..workers {
                let tx = tx.clone();
                let (next, phases) = (&next, &phases);
                scope.spawn(move || loop {
                    let si = next.fetch_add(1, SeqCst);
                    if si >= stages.len() || stop.load(SeqCst) {
                        break;
                    }
                    let stage = &stages[si];
                    if !self.fit_one_stage(runnable, stage, phases, &mut |ev| tx.send(ev).is_ok()) {
                        return;
                    }
                });
            }
            drop(tx);
            for event in rx {
                if let Err(e) = each(event) {
                    stop.store(true, SeqCst);
                    return Err(e);
                }
            }
            Ok(())
        })?;
        Ok(PoolStats {
            workers,
            phases: phases.into_inner().unwrap_or_default(),
        })
    }

    /// The kernels of every stage, compiled ahead in stage order: a driver compiles when a
    /// pipeline is created (lavapipe: NIR, then LLVM, 0.01–0.1 s a model), and this thread
    /// does it while the workers wait on the device, instead of on a worker's path. A
    /// worker that needs a kernel still being compiled waits for that one alone; an error
    /// (or a panic in the driver) is left for the worker to meet and report against its
    /// fits.
    fn compile_ahead(&self, runnable: &[Runnable], stages: &[Vec<usize>], stop: &AtomicBool) {
        for stage in stages {
            if stop.load(SeqCst) {
                break;
            }
            let model = &runnable[stage[0]].1;
            let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                self.backend.prepare_kernels(model)
            }));
        }
    }

    /// Fit one stage's cells on the backend, or on the fallback once the device has a
    /// fault; the cells the device failed are fitted again on the fallback. `send` gets
    /// the events in order; false when the receiver has gone (then so does the worker).
    fn fit_one_stage(
        &self,
        runnable: &[Runnable],
        stage: &[usize],
        phases: &Mutex<PhaseSeconds>,
        send: &mut dyn FnMut(PoolEvent) -> bool,
    ) -> bool {
        // `spare`: where the cells the device fails go (none once they run there).
        let (backend, spare) = match self.fallback {
            Some(f) if self.backend.fault().is_some() => (f, None),
            spare => (self.backend, spare),
        };
        let outcomes = self.fit_cells(runnable, stage, backend, phases);
        let mut failed = Vec::new();
        let mut fault = None;
        for (&i, outcome) in stage.iter().zip(outcomes) {
            match (spare, self.device_failed(&outcome)) {
                (Some(_), Some(f)) => {
                    fault.get_or_insert(f);
                    failed.push(i);
                }
                _ => {
                    if !send(PoolEvent::Landed(i, Box::new(outcome))) {
                        return false;
                    }
                }
            }
        }
        let (Some(spare), Some(fault)) = (spare, fault) else {
            return true;
        };
        if !send(PoolEvent::Rerun {
            cells: failed.clone(),
            fault,
        }) {
            return false;
        }
        let again = self.fit_cells(runnable, &failed, spare, phases);
        failed
            .into_iter()
            .zip(again)
            .all(|(i, outcome)| send(PoolEvent::Landed(i, Box::new(outcome))))
    }

    /// The device fault behind a failed fit: its error's, or the backend's own where the
    /// fit failed (an error or a panic) after the device had one.
    fn device_failed(&self, outcome: &CellOutcome) -> Option<DeviceFault> {
        match outcome {
            Ok(Ok(_)) => None,
            Ok(Err(e)) => device_fault(e).cloned().or_else(|| self.backend.fault()),
            Err(_) => self.backend.fault(),
        }
    }

    /// Fit `cells` (one stage's) together on `backend`; if that fails (one bad fit fails
    /// the stage), fit each alone, so a failure is attributed to its own cell and the
    /// others still land. Where the device failed the stage, every cell gets its fault
    /// (alone they would be refused).
    fn fit_cells(
        &self,
        runnable: &[Runnable],
        cells: &[usize],
        backend: &dyn Backend,
        phases: &Mutex<PhaseSeconds>,
    ) -> Vec<CellOutcome> {
        let (first, model) = &runnable[cells[0]];
        let opts = FitOptions {
            optimizer: first.optimizer,
            ..self.options.clone()
        };
        let datas: Vec<&Dataset> = cells
            .iter()
            .map(|&i| &self.files[runnable[i].0.data].data)
            .collect();
        let losses: Vec<Loss> = cells
            .iter()
            .map(|&i| Loss::new(runnable[i].0.loss, runnable[i].0.weights))
            .collect();
        let together = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            fit_stage(model, &datas, &losses, backend, &opts, &mut |_| {})
        }));
        let fault = match &together {
            Ok(Err(e)) => device_fault(e).cloned(),
            _ => None,
        };
        match (together, fault) {
            (Ok(Ok((reports, spent))), _) => {
                if let Ok(mut p) = phases.lock() {
                    *p += spent;
                }
                reports.into_iter().map(|r| Ok(Ok(r))).collect()
            }
            (_, Some(f)) => cells
                .iter()
                .map(|_| Ok(Err(anyhow::Error::new(f.clone()))))
                .collect(),
            _ => cells
                .iter()
                .zip(datas.iter().zip(&losses))
                .map(|(&i, (data, &loss))| {
                    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                        fit(&runnable[i].1, data, loss, backend, &opts, &mut |_| {})
                    }))
                })
                .collect(),
        }
    }
}

/// Group cells into stages (indices into `runnable`, in cell order): same model spec,
/// channels and measurement planes, same loss term shape and optimizer.
fn stages_of(runnable: &[Runnable]) -> Vec<Vec<usize>> {
    let mut index: HashMap<String, usize> = HashMap::new();
    let mut stages: Vec<Vec<usize>> = Vec::new();
    for (i, (t, m)) in runnable.iter().enumerate() {
        let key = format!(
            "{}|{}|{:?}|{:?}|{}",
            m.spec,
            m.channels,
            m.axes,
            t.loss.term(),
            t.optimizer
        );
        let s = *index.entry(key).or_insert_with(|| {
            stages.push(Vec::new());
            stages.len() - 1
        });
        stages[s].push(i);
    }
    stages
}
