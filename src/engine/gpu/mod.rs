//! The GPU engine: wgpu compute on Vulkan, f32, in layers:
//! - [`device`]: the adapter, the device and its errors as values;
//! - [`fault`]: a device lost or hung as a typed error, the read-back timeout and the
//!   fault-injection switch;
//! - [`bindings`]: the kernels' bindings and uniform block, declared once for the Rust
//!   and the WGSL side;
//! - [`recorder`]: one submission's uploads, dispatches and read-back (no models);
//! - [`pipelines`]: the modules composed per (model, loss term shape, thread shape) and
//!   their entry points, compiled once and cached;
//! - [`records`]: a batch's data as sample records, uploaded once per evaluator;
//! - [`evaluator`]: the passes a batch needs (costs, value windows, normal equations),
//!   their windows and tiles, and the host's f64 reduction of what they return.
//!
//! **Streamed reductions.** Nothing of length candidates × samples is read back. A
//! `costs` pass returns one partial sum of loss terms per (candidate, tile of records),
//! which the host adds up and finishes per problem in f64. Levenberg–Marquardt's normal
//! equations are reduced on the device on GPUs (a `values` pass over a window of
//! records, whose values stay on the device, then the `normal` pass, one partial set of
//! sums per (group, tile)); on CPU devices (lavapipe), whose memory is the host's, the
//! values of a window are read back and reduced on the host, which measured faster
//! there. A window holds as many records as the outputs' binding allows, so memory is
//! bounded whatever the data's size.
//!
//! **Tiles.** Workgroup z of a pass works on tile z of its candidates' records (`Dims`
//! `tile`, `n_tiles`): much data spreads over many workgroups even when candidates are
//! few, and no invocation walks more than a tile. llvmpipe (lavapipe) ends every loop of
//! an invocation once all its loops together have run 65,535 iterations, silently; the
//! kernels detect it (`loops_completed`, shaders/engine/kernel.wgsl) and the engine
//! then runs that submission again with tiles a quarter as long, remembering the size
//! per model, down to [`MIN_TILE`] records, where it fails with an error naming the
//! cause.
//!
//! **Channels together, per-μ tables.** See [`records`] for the record layout (one per
//! direction and block of up to four channels, evaluated in one unrolled call), and
//! [`wgsl::Shape::mu_tables`] for the per-candidate tables of what depends on the polar
//! cosines alone (micrograin's Λ series, VMF's Legendre series, GG's Λ table): on
//! lavapipe `rmg(ggx)` went from 1.2e8 to 2.1–2.4e8 evaluations/s with them.

pub mod bindings;
pub mod device;
mod evaluator;
pub mod fault;
pub mod pipelines;
mod recorder;
pub mod records;
mod runner;
mod stall;

use super::wgsl::Shape;
use super::{Backend, Evaluator, Problem};
use crate::bsdf::Model;
use crate::engine::loss::Term;
use anyhow::{anyhow, Result};
use device::Device;
pub use evaluator::GpuEvaluator;
pub use fault::{device_fault, DeviceFault, FaultPlan};
use pipelines::{EntryPoint, PipelineCache};
use std::collections::HashMap;
use std::sync::Mutex;

/// Largest buffer the engine allocates for one binding (bytes), on CPU devices, whose
/// buffers are the host's memory (a value window of this size is read and reduced by the
/// host while still in its caches' reach), and on GPUs, where a window of model values
/// stays on the device and longer windows mean fewer submissions.
const CPU_DEVICE_CHUNK_BYTES: u64 = 64 << 20;
const GPU_CHUNK_BYTES: u64 = 1 << 30;
/// Workgroups per dispatch dimension (WebGPU's guaranteed minimum of the limit).
pub(crate) const MAX_GROUPS_X: u32 = 65535;
/// The shortest tile the engine shrinks to after loops cut short.
pub const MIN_TILE: u32 = 16;
/// The most submissions [`GpuBackend::submissions`] describes (the first ones).
const SUBMISSION_LOG_CAP: usize = 1 << 20;

pub struct GpuBackend {
    device: Device,
    pipelines: PipelineCache,
    shape: Shape,
    /// Per model spec, the records per tile after a CPU device cut the loops of a longer
    /// tile short: later evaluators start there instead of paying a cut-short submission.
    tiles: Mutex<HashMap<String, u32>>,
    /// Largest buffer allocated for one binding (bytes), at most the device's limits.
    chunk_bytes: u64,
    /// The most records of one records texture (tests of the multi-segment path lower it).
    segment_records: usize,
    /// Records per tile to start with (`None`: the shape's default, [`Self::tile_for`]).
    first_tile: Option<u32>,
    /// Whether LM's normal equations are reduced on the device (`normal.wgsl`), or on
    /// the host from the values read back. On CPU devices the host's: their memory is the
    /// host's, so the read-back is a copy, and the device pass cost more than it saved
    /// (lavapipe, 64-restart LM fits on W80&G3.4: fa(eon) 1.06 s → 0.57 s, rmg(eon)
    /// 1.59 s → 1.08 s with the host's).
    device_normal: bool,
    /// (candidates, evaluations, seconds) of every submission, for `bench --sweep`; at
    /// most `SUBMISSION_LOG_CAP` of them (16 bytes each).
    submission_log: Mutex<Vec<(u32, u64, f32)>>,
}

impl GpuBackend {
    /// Open the first Vulkan adapter (a discrete GPU if present, else e.g. lavapipe).
    pub fn new() -> Result<Self> {
        let device = Device::open()?;
        let shape = if device.is_cpu() {
            if device.has_subgroups() {
                Shape::CPU_DEVICE_TILED
            } else {
                Shape::CPU_DEVICE
            }
        } else {
            Shape::GPU_DEVICE
        };
        Ok(GpuBackend {
            pipelines: PipelineCache::new(&device),
            shape,
            tiles: Mutex::default(),
            chunk_bytes: if device.is_cpu() {
                CPU_DEVICE_CHUNK_BYTES
            } else {
                GPU_CHUNK_BYTES
            },
            segment_records: usize::MAX,
            first_tile: None,
            device_normal: !device.is_cpu(),
            submission_log: Mutex::default(),
            device,
        })
    }

    /// Whether the adapter is a software rasterizer on the host's processor (lavapipe).
    pub fn is_software(&self) -> bool {
        self.device.is_cpu()
    }

    /// Lower the largest binding the engine allocates (tests of the paths that split a
    /// batch into several windows and submissions).
    pub fn with_max_binding(mut self, bytes: u64) -> Self {
        self.chunk_bytes = bytes.clamp(256, self.chunk_bytes);
        self
    }

    /// Put at most `records` sample records in one records texture (tests of the
    /// multi-segment path; the device's texture limit applies anyway).
    pub fn with_segment_records(mut self, records: usize) -> Self {
        self.segment_records = records.max(1);
        self
    }

    /// Start with tiles of `records` records (tests of the cut-short path: a tile longer
    /// than an invocation may walk on lavapipe).
    pub fn with_tile(mut self, records: u32) -> Self {
        self.first_tile = Some(records.max(MIN_TILE));
        self
    }

    /// Reduce LM's normal equations on the device (`true`, the default on GPUs) or on
    /// the host from the values read back (the default on CPU devices); tests of the
    /// device pass force it on.
    pub fn with_device_normal(mut self, on: bool) -> Self {
        self.device_normal = on;
        self
    }

    /// Override the workgroup shape (benchmarks and tests of every code path). Subgroup
    /// tiles are dropped on a device without subgroups.
    pub fn with_shape(mut self, mut shape: Shape) -> Self {
        shape.subgroup_tiles &= self.has_subgroups();
        self.shape = shape;
        self
    }

    /// Inject `plan` (`None`: no fault) instead of what `BSDFIT_GPU_FAULT` says (tests of
    /// the fault paths, [`fault`]).
    pub fn with_fault(mut self, plan: Option<FaultPlan>) -> Self {
        self.device.set_fault_plan(plan);
        self
    }

    /// Wait at most `timeout` for each read-back instead of `BSDFIT_GPU_TIMEOUT`'s.
    pub fn with_timeout(mut self, timeout: std::time::Duration) -> Self {
        self.device.set_timeout(timeout);
        self
    }

    /// Submissions begun so far, numbered from 1 as `BSDFIT_GPU_FAULT` counts them (a
    /// submission the device refused is not begun).
    pub fn submission_count(&self) -> u64 {
        self.device.submission_count()
    }

    /// The errors the device reported since the last check, as one `Err`; the device's
    /// [`DeviceFault`] once it is lost or hung.
    pub fn check_errors(&self) -> Result<()> {
        self.device.check_errors()
    }

    /// Whether the device was opened with subgroup operations.
    pub fn has_subgroups(&self) -> bool {
        self.device.has_subgroups()
    }

    /// The workgroup shape in use.
    pub fn shape(&self) -> Shape {
        self.shape
    }

    pub fn adapter_name(&self) -> String {
        self.device.adapter_name()
    }

    /// Records per tile for `model`: the shape's default (one invocation walks a tile:
    /// long on CPU devices, whose threads are few, shorter on GPUs, whose threads need
    /// work spread over many workgroups), or the shorter one a cut-short pass left.
    pub fn tile_for(&self, model: &Model) -> u32 {
        let default = self
            .first_tile
            .unwrap_or(if self.shape.slices == 1 { 16384 } else { 4096 });
        self.tiles
            .lock()
            .ok()
            .and_then(|t| t.get(&model.spec).copied())
            .unwrap_or(default)
    }

    /// Remember a shorter tile for `model` (see [`Self::tile_for`]).
    fn shorten_tile(&self, model: &Model, tile: u32) {
        if let Ok(mut t) = self.tiles.lock() {
            let e = t.entry(model.spec.clone()).or_insert(tile);
            *e = (*e).min(tile);
        }
    }

    fn max_binding(&self) -> u64 {
        let l = &self.device.limits;
        l.max_storage_buffer_binding_size
            .min(l.max_buffer_size)
            .min(self.chunk_bytes)
    }

    fn log_submission(&self, candidates: usize, evaluations: u64, seconds: f32) {
        if let Ok(mut log) = self.submission_log.lock() {
            if log.len() < SUBMISSION_LOG_CAP {
                log.push((candidates as u32, evaluations, seconds));
            }
        }
    }

    /// The module whose `values` entry serves every loss of `model`: that entry writes
    /// the model values and reads no loss term, so it is composed once per model (with the
    /// square term's constant: the module the square losses' own entries use), not once
    /// per loss shape. lavapipe compiles a pipeline (NIR, then LLVM) when it is created,
    /// and NIR's passes run again even when Mesa's disk cache holds the machine code: on
    /// the default sweep that was 14 % of the GPU sweep's time, half of it for `values`
    /// entries compiled a second time.
    fn value_pipelines(
        &self,
        model: &Model,
        shape: Shape,
    ) -> Result<std::sync::Arc<pipelines::Pipelines>> {
        self.pipelines.get(&self.device, model, Term::Square, shape)
    }
}

impl Backend for GpuBackend {
    fn name(&self) -> String {
        format!("gpu (wgpu/Vulkan f32 on {})", self.adapter_name())
    }
    fn id(&self) -> &'static str {
        "gpu"
    }
    fn unit_roundoff(&self) -> f64 {
        f32::EPSILON as f64 / 2.0
    }
    fn max_batch_samples(&self) -> usize {
        // Records are numbered in u32 over a batch, CB slots each; any more samples go
        // into further textures (segments) within that.
        (u32::MAX / 8) as usize
    }
    fn submissions(&self) -> Option<super::SubmissionStats> {
        let log = self.submission_log.lock().ok()?;
        Some(super::SubmissionStats::of(&log))
    }
    fn fault(&self) -> Option<DeviceFault> {
        self.device.fault()
    }
    fn prepare_kernels(&self, model: &Model) -> Result<()> {
        self.device.refuse_if_faulted()?;
        // For the usual batch: data with μ tables (a few dozen polar angles at most).
        let pipes = self.value_pipelines(model, self.shape.for_batch(true))?;
        self.pipelines
            .entry(&self.device, &pipes, EntryPoint::Values)
            .map(|_| ())
    }
    fn prepare_many<'a>(&'a self, problems: &[Problem<'a>]) -> Result<Box<dyn Evaluator + 'a>> {
        super::check_shared(problems)?;
        self.device.refuse_if_faulted()?;
        GpuEvaluator::new(self, problems)
            .map(|e| Box::new(e) as Box<dyn Evaluator + 'a>)
            .map_err(|e| {
                // One line, the causes included; a device fault stays typed beneath it.
                let line = format!("{e:#}");
                match device_fault(&e) {
                    Some(f) => anyhow::Error::new(f.clone()).context(line),
                    None => anyhow!(line),
                }
            })
    }
}
