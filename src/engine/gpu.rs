//! The GPU engine: wgpu compute on Vulkan, f32. One submission evaluates every candidate
//! of every restart over every sample and reduces on the device to one sum of loss terms
//! per candidate (shaders/engine/kernel.wgsl), which the host finishes per problem in f64.
//! Pipelines are compiled once per (model, loss term shape, entry point), when first used
//! or ahead (`prepare_kernels`), and cached; the dataset is uploaded once per
//! problem; parameter and output buffers are reused across optimizer iterations and grown
//! only when a larger batch arrives.
//!
//! **Channels together, data in textures.** The samples are uploaded as records, one per
//! direction, plane and block of up to four channels ([`RecordLayout`]); a thread
//! evaluates a record's channels in one unrolled call (`eval_record`, generated in
//! [`super::wgsl::record_source`]), so the compiler computes what the channels share
//! (half vector, D, G, Fresnel…) once. The records, their sample indices and GG's lookup
//! table are sampled textures, not storage buffers: Mesa 22's llvmpipe (lavapipe) loads a
//! storage buffer lane by lane through the stack, about 15 cycles a scalar (perf showed
//! 14 such loads per record as the kernel's whole cost), while it fetches texels with
//! vector gathers. Measured on lavapipe (2-core AMD EPYC, RGB set of 1,143 rows, evals/s):
//! `lambert` 1.7e8 → 2.5e8 (channels together) → 8.3e8 (textures), `ggx` 1.2e8 → 1.6e8
//! → 3.2e8.
//!
//! **Per-μ tables.** With each problem the engine uploads its μ table, the distinct f32
//! cosines of θi and θo of its records (at most 63), and each record carries the indices
//! of its μi and μo there. Models whose per-record work includes a loop or a table
//! lookup for a function of μ alone (micrograin's Λ series, VMF's Legendre series for σ,
//! GG transmission's Λ table) evaluate it per candidate at every entry before the record
//! loop (`rmg_prepare`, `vmf_prepare`, `btdf_gg_prepare`) and look it up per record
//! (`Shape::mu_tables`): on lavapipe `rmg(ggx)` went from 1.2e8 to 2.1–2.4e8
//! evaluations/s, `vmf` from 1.6e8 to 2.7e8, `btdf(gg)` from 3.4e7 to 0.9–1.5e8, and the
//! default sweep from 4.7 s to 3.5 s.
//!
//! Levenberg–Marquardt's normal equations are reduced on the device too: one submission
//! runs the `values` pass over every group of P + 1 candidates (a restart's point and its
//! P forward-difference neighbours), whose model values stay in the `out` buffer, then the
//! `normal` pass (shaders/engine/normal.wgsl), one workgroup per group, which forms the
//! upper triangle of Σ d_a d_b, then Σ d_j r and Σ r² (d_j = h_j J_j, the residual
//! differences; compensated f32 sums): on GPUs a thread per row of that Gram matrix and
//! sample slice; on CPU devices (lavapipe), where loads are dear, a thread per sample
//! slice holding every sum, added up across threads at the end. Only those P(P + 1)/2 + P + 1 floats per group come
//! back, instead of (P + 1) × K model values; the host converts them to f64 and divides
//! by the unit-box steps, which keeps h out of f32's range. NaN and ±∞ model values
//! propagate as in the host's f64 reduction (`engine::normal_equations_of_values`, the
//! reference, tests/gpu_normal.rs); f32 sums overflow only where the moved point's cost
//! overflows in the costs pass too. A batch that needs several submissions is split
//! between groups, never inside one (a group's values must be on the device together);
//! a group whose values alone exceed a binding is reduced on the host from its values.

use super::wgsl::{self, compose, normal_entries, validate, Shape};
use super::{Backend, Evaluator, Problem};
use crate::bsdf::Model;
use crate::engine::loss::{LossTerms, Term};
use crate::optim::NormalEquations;
use anyhow::{anyhow, bail, Context, Result};
use bytemuck::{Pod, Zeroable};
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};
use wgpu::util::DeviceExt;

/// How samples become the kernels' records (`Record` in shaders/engine/kernel.wgsl):
/// one per direction, plane, inner factor a and block of up to CB channels, holding ωi,
/// the first scalar-view group, ωo, a, and per channel slot (v, w): v = y for SMAPE and
/// g(y) otherwise, w the loss weight, −1 where the slot has no sample. Beside them, per
/// slot, the sample's index in its problem or `NO_SAMPLE`.
struct RecordLayout {
    /// CB: channel slots per record.
    slots: usize,
}

const NO_SAMPLE: u32 = u32::MAX;

/// The most distinct polar cosines a problem's μ table holds (`MU_TABLE_LEN` in
/// shaders/engine/kernel.wgsl); an index of this value means "not in the table".
const MU_TABLE_LEN: usize = 63;
/// Bits of a record's packed word (texel 0's w) below its μ indices: the record's first
/// scalar-view group.
const GROUP_BITS: u32 = 16;
/// Bits of each μ index in the packed word. Group, μi and μo indices fill bits 0–27, so
/// the word, read as an f32, is never a NaN whose payload a device might not keep.
const MU_INDEX_BITS: u32 = 6;

/// Entries per row of the lookup-table texture (`LUT_WIDTH` in shaders/engine/kernel.wgsl).
const LUT_WIDTH: usize = 256;

impl RecordLayout {
    fn of(model: &Model) -> RecordLayout {
        RecordLayout {
            slots: wgsl::record_channels(model),
        }
    }

    /// f32 per record: ωi and ωo (a texel each), then two channel slots per texel.
    fn floats(&self) -> usize {
        4 * wgsl::record_texels(self.slots)
    }

    /// The records as an RGBA32F texture of `wgsl::RECORDS_PER_ROW` records per row (fewer
    /// where there are fewer), padded to whole rows: (width, height) in texels.
    fn texture_size(&self, records: usize) -> (u32, u32) {
        let texels = wgsl::record_texels(self.slots);
        let width = records.clamp(1, wgsl::RECORDS_PER_ROW) * texels;
        let height = records.div_ceil(wgsl::RECORDS_PER_ROW).max(1);
        (width as u32, height as u32)
    }

    /// Append the records of one data set: a record per (ωi, ωo bit for bit, plane, a,
    /// channel block) in the order their first samples come in
    /// [`walk_order`](super::walk_order), and another wherever a
    /// channel is measured again at the same direction (each repeat its own record, as
    /// each is its own term of the loss).
    ///
    /// Returns the data set's μ table: the distinct f32 values of cos θi and cos θo (the
    /// records' ωi.z and ωo.z), empty where there are more than [`MU_TABLE_LEN`]. Each
    /// record's packed word holds its first scalar-view group and the indices of its μi
    /// and μo in that table, from which models compute per candidate, before the record
    /// loop, what depends on μ alone (`rmg_prepare`).
    fn write(
        &self,
        model: &Model,
        data: &crate::data::Dataset,
        terms: &LossTerms,
        records: &mut Vec<f32>,
        index: &mut Vec<u32>,
    ) -> Result<Vec<f32>> {
        let cb = self.slots;
        let first = records.len() / self.floats();
        let index_start = index.len();
        let mut mu_table: Vec<f32> = Vec::new();
        for s in &data.samples {
            for mu in [s.wi().z as f32, s.wo().z as f32] {
                if !mu_table.iter().any(|m| m.to_bits() == mu.to_bits()) {
                    mu_table.push(mu);
                }
            }
            if mu_table.len() > MU_TABLE_LEN {
                mu_table.clear();
                break;
            }
        }
        let mu_index = |mu: f64| -> u32 {
            let mu = mu as f32;
            mu_table
                .iter()
                .position(|m| m.to_bits() == mu.to_bits())
                .unwrap_or(MU_TABLE_LEN) as u32
        };
        let mut at: HashMap<([u64; 7], usize, usize), usize> = HashMap::new();
        for k in super::walk_order(data) {
            let s = &data.samples[k];
            let (wi, wo) = (s.wi(), s.wo());
            let g = model.group_of(s);
            let (plane, ch) = (g / model.channels, g % model.channels);
            let g0 = plane * model.channels + (ch / cb) * cb;
            anyhow::ensure!(
                g0 < 1 << GROUP_BITS,
                "{} scalar-view groups exceed the GPU records' {GROUP_BITS}-bit field (use \
                 --backend cpu)",
                model.groups()
            );
            let packed = g0 as u32
                | mu_index(wi.z) << GROUP_BITS
                | mu_index(wo.z) << (GROUP_BITS + MU_INDEX_BITS);
            let a = terms.a[k];
            let key = [wi.x, wi.y, wi.z, wo.x, wo.y, wo.z, a].map(f64::to_bits);
            let mut repeat = 0;
            let rec = loop {
                let r = *at.entry((key, g0, repeat)).or_insert_with(|| {
                    let r = records.len() / self.floats();
                    records.extend_from_slice(&[
                        wi.x as f32,
                        wi.y as f32,
                        wi.z as f32,
                        f32::from_bits(packed),
                        wo.x as f32,
                        wo.y as f32,
                        wo.z as f32,
                        a as f32,
                    ]);
                    let slots = records.len();
                    records.resize(slots + self.floats() - 8, 0.0);
                    for slot in 0..cb {
                        records[slots + 2 * slot + 1] = -1.0;
                    }
                    index.extend(std::iter::repeat_n(NO_SAMPLE, cb));
                    r
                });
                if index[index_start + (r - first) * cb + ch % cb] == NO_SAMPLE {
                    break r;
                }
                repeat += 1;
            };
            let slot = ch % cb;
            index[index_start + (rec - first) * cb + slot] = k as u32;
            let v = match terms.term {
                Term::AbsRatio => s.value,
                Term::Square | Term::LogSquare => terms.transform(k, s.value),
            };
            let o = rec * self.floats() + 8 + 2 * slot;
            records[o..o + 2].copy_from_slice(&[v as f32, terms.w[k] as f32]);
        }
        Ok(mu_table)
    }
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Dims {
    n_candidates: u32,
    n_problems: u32,
    dim: u32,
    groups_x: u32,
    n_groups: u32,
    normal_groups_x: u32,
    /// Always 2: the trip count of kernel.wgsl's `loops_completed` probe.
    probe_trips: u32,
    pad: u32,
}

/// A (model, loss shape)'s module and its entry points, each compiled when first used:
/// a driver compiles a pipeline when it is created (lavapipe runs LLVM then, 0.04–0.3 s a
/// pipeline for the catalogue's models), and most evaluators never use all three (on CPU
/// devices `normal` is the host's, `costs` serves only the start screening and compass).
/// On the default sweep on lavapipe, compiling all three up front took 6–10 s of its
/// ≈ 50 s of thread time, a sixth of it for `normal` alone.
struct Pipelines {
    module: wgpu::ShaderModule,
    costs: OnceLock<wgpu::ComputePipeline>,
    values: OnceLock<wgpu::ComputePipeline>,
    /// LM's normal equations from the values of groups of P + 1 candidates.
    normal: OnceLock<wgpu::ComputePipeline>,
    /// The entry point `normal` compiles (the one-slice shape is the CPU devices', see
    /// normal.wgsl for why).
    normal_entry: &'static str,
}

/// A pipeline cache entry: compiled once, by whichever evaluator asks first, while the
/// others wait on this entry alone (not on the whole cache), so workers compiling
/// different models do not queue behind each other.
type PipelinesSlot = Arc<OnceLock<std::result::Result<Arc<Pipelines>, String>>>;

pub struct GpuBackend {
    device: wgpu::Device,
    queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
    limits: wgpu::Limits,
    layout: wgpu::BindGroupLayout,
    pipeline_layout: wgpu::PipelineLayout,
    pipelines: Mutex<HashMap<String, PipelinesSlot>>,
    /// Per model spec, the fewest samples (of a batch's largest problem) with which the
    /// backend's shape had its loops cut short: later evaluators with at least as many
    /// start in `Shape::LONG_DATA` instead of paying a cut-short submission each.
    long_data_from: Mutex<HashMap<String, usize>>,
    shape: Shape,
    /// Errors wgpu reports asynchronously; checked after each submission so they become
    /// `Err` values instead of the default handler's panic.
    errors: Arc<Mutex<Vec<String>>>,
    /// Largest buffer allocated for one binding (bytes), at most the device's limits.
    chunk_bytes: u64,
    /// Whether LM's normal equations are reduced on the device (`normal.wgsl`), or from
    /// the model values read back (`normal_equations_of_values`). On CPU devices the
    /// host's: their memory is the host's, so the read-back is a copy, and the device
    /// pass cost more than it saved (lavapipe, 64-restart LM fits on W80&G3.4: fa(eon)
    /// 1.06 s → 0.57 s, rmg(eon) 1.59 s → 1.08 s with the host's).
    device_normal: bool,
    /// (candidates, evaluations, seconds) of every submission, for `bench --sweep`; at
    /// most `SUBMISSION_LOG_CAP` of them (16 bytes each).
    submission_log: Mutex<Vec<(u32, u64, f32)>>,
}

/// The most submissions [`GpuBackend::submissions`] describes (the first ones).
const SUBMISSION_LOG_CAP: usize = 1 << 20;

/// The kernels' entry points (see [`Pipelines`]).
#[derive(Clone, Copy)]
enum Entry {
    Costs,
    Values,
    Normal,
}

/// The bits of the NaN that an invocation whose loops were cut short writes instead of
/// its result (`LOOPS_CUT_SHORT` in shaders/engine/kernel.wgsl).
const LOOPS_CUT_SHORT: u32 = 0x7fa1_1ed5;

/// A CPU device ended the kernel's loops early (see `LOOPS_CUT_SHORT`).
#[derive(Debug, thiserror::Error)]
#[error("the device cut the kernel's loops short")]
struct LoopsCutShort;

/// Largest buffer the engine allocates for one binding (bytes).
const MAX_CHUNK_BYTES: u64 = 64 << 20;
/// Workgroups per dispatch dimension (WebGPU's guaranteed minimum of the limit).
const MAX_GROUPS_X: u32 = 65535;

impl GpuBackend {
    /// Open the first Vulkan adapter (a discrete GPU if present, else e.g. lavapipe).
    pub fn new() -> Result<Self> {
        pollster::block_on(Self::new_async())
    }

    async fn new_async() -> Result<Self> {
        // Mesa's Vulkan loader prints an error when XDG_RUNTIME_DIR is unset (headless
        // machines, CI); compute never presents to a window, so any directory will do.
        if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
            std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir());
        }
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
            backends: wgpu::Backends::VULKAN,
            ..wgpu::InstanceDescriptor::new_without_display_handle()
        });
        let adapter = instance
            .request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                ..Default::default()
            })
            .await
            .map_err(|e| {
                anyhow!("no Vulkan adapter found ({e}); install a Vulkan driver (e.g. Debian's mesa-vulkan-drivers for the lavapipe software device)")
            })?;
        let info = adapter.get_info();
        let alimits = adapter.limits();
        // Ask for everything the adapter offers: buffer sizes are chunked from these.
        let limits = alimits;
        // Subgroups: the sample tiles of SIMD CPU devices (shaders/engine/lanes_subgroup.wgsl).
        let features = adapter.features() & wgpu::Features::SUBGROUP;
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("bsdfit"),
                required_features: features,
                required_limits: limits.clone(),
                ..Default::default()
            })
            .await
            .with_context(|| format!("cannot open a device on {}", info.name))?;
        let errors: Arc<Mutex<Vec<String>>> = Arc::default();
        let sink = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e| {
            sink.lock().map(|mut v| v.push(e.to_string())).ok();
        }));
        let storage = |binding: u32, read_only: bool| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let texture = |binding: u32, sample_type| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Texture {
                sample_type,
                view_dimension: wgpu::TextureViewDimension::D2,
                multisampled: false,
            },
            count: None,
        };
        let unfilterable = wgpu::TextureSampleType::Float { filterable: false };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("bsdfit kernel"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
                // The sample records: a texture, since llvmpipe (Mesa 22) loads from a
                // storage buffer lane by lane through memory at ≈ 15 cycles a scalar
                // (measured with perf: the kernel's bound on lavapipe), while it fetches
                // texels as vectors (see the module documentation).
                texture(1, unfilterable),
                storage(2, true),
                storage(3, true),
                storage(4, false),
                texture(5, unfilterable),
                storage(6, true),
                storage(7, false),
                // Per record, the original index of each channel slot's sample.
                texture(8, wgpu::TextureSampleType::Uint),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("bsdfit kernel"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let shape = if info.device_type == wgpu::DeviceType::Cpu {
            if features.contains(wgpu::Features::SUBGROUP) {
                Shape::CPU_DEVICE_TILED
            } else {
                Shape::CPU_DEVICE
            }
        } else {
            Shape::GPU_DEVICE
        };
        let device_normal = info.device_type != wgpu::DeviceType::Cpu;
        Ok(GpuBackend {
            shape,
            device,
            queue,
            info,
            limits,
            layout,
            pipeline_layout,
            pipelines: Mutex::default(),
            long_data_from: Mutex::default(),
            errors,
            chunk_bytes: MAX_CHUNK_BYTES,
            device_normal,
            submission_log: Mutex::default(),
        })
    }

    /// Lower the largest binding the engine allocates (tests of the paths that split a
    /// batch over several submissions, or reduce normal equations on the host).
    pub fn with_max_binding(mut self, bytes: u64) -> Self {
        self.chunk_bytes = bytes.clamp(256, MAX_CHUNK_BYTES);
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

    /// Whether the device was opened with subgroup operations.
    pub fn has_subgroups(&self) -> bool {
        self.device.features().contains(wgpu::Features::SUBGROUP)
    }

    /// The workgroup shape in use.
    pub fn shape(&self) -> Shape {
        self.shape
    }

    pub fn adapter_name(&self) -> String {
        format!(
            "{} ({:?}, {})",
            self.info.name, self.info.device_type, self.info.driver
        )
    }

    fn check_errors(&self) -> Result<()> {
        let mut errs = self
            .errors
            .lock()
            .map_err(|_| anyhow!("GPU error log poisoned"))?;
        if errs.is_empty() {
            return Ok(());
        }
        let msg = errs.join("; ");
        errs.clear();
        bail!("GPU error: {msg}")
    }

    fn pipelines(&self, model: &Model, term: Term, shape: Shape) -> Result<Arc<Pipelines>> {
        let key = format!(
            "{}|{}|{}|{:?}|{:?}",
            model.spec,
            model.channels,
            model.axes.len(),
            term,
            shape
        );
        let slot: PipelinesSlot = self
            .pipelines
            .lock()
            .map_err(|_| anyhow!("pipeline cache poisoned"))?
            .entry(key)
            .or_default()
            .clone();
        slot.get_or_init(|| {
            let source = compose(model, term, shape);
            let module = self
                .module(&model.spec, source)
                .map_err(|e| e.to_string())?;
            self.check_errors().map_err(|e| e.to_string())?;
            Ok(Arc::new(Pipelines {
                module,
                costs: OnceLock::new(),
                values: OnceLock::new(),
                normal: OnceLock::new(),
                normal_entry: if shape.slices == 1 {
                    "normal_by_samples"
                } else {
                    "normal"
                },
            }))
        })
        .clone()
        .map_err(|e| anyhow!(e))
    }

    /// The pipelines whose `values` entry serves every loss of `model`: that entry writes
    /// the model values and reads no loss term, so it is composed once per model (with the
    /// square term's constant: the module the square losses' own entries use), not once
    /// per loss shape. lavapipe compiles a
    /// pipeline (NIR, then LLVM) when it is created, and NIR's passes run again even when
    /// Mesa's disk cache holds the machine code: on the default sweep that was 14 % of
    /// the GPU sweep's time, half of it for `values` entries compiled a second time.
    fn value_pipelines(&self, model: &Model, shape: Shape) -> Result<Arc<Pipelines>> {
        self.pipelines(model, Term::Square, shape)
    }

    /// One of `pipes`' entry points, compiled now if it is the first use.
    fn entry<'p>(&self, pipes: &'p Pipelines, which: Entry) -> Result<&'p wgpu::ComputePipeline> {
        let (cell, name) = match which {
            Entry::Costs => (&pipes.costs, "costs"),
            Entry::Values => (&pipes.values, "values"),
            Entry::Normal => (&pipes.normal, pipes.normal_entry),
        };
        let mut made = false;
        let pipeline = cell.get_or_init(|| {
            made = true;
            self.device
                .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(name),
                    layout: Some(&self.pipeline_layout),
                    module: &pipes.module,
                    entry_point: Some(name),
                    compilation_options: Default::default(),
                    cache: None,
                })
        });
        if made {
            self.check_errors()?;
        }
        Ok(pipeline)
    }

    /// Validate a generated module with naga, then hand it to the driver.
    fn module(&self, label: &str, source: String) -> Result<wgpu::ShaderModule> {
        validate(&source)
            .map_err(|e| anyhow!("generated WGSL for {label} does not validate:\n{e}"))?;
        let desc = wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        };
        // SAFETY: the module is generated by this crate, not user input. Every loop in it
        // is bounded by a counter compared against a host-written size (or, in `normal`,
        // the constant entry count), and every index is either a loop counter below such a
        // size or a slot the host computed from the model layout for buffers it sized
        // itself (`prepare`, `ensure_io`; `normal` reads the rows of groups whose every
        // candidate is in the submission, `normal_run`); so the injected bounds checks and
        // loop guards can be left out of the inner loop.
        Ok(unsafe {
            self.device
                .create_shader_module_trusted(desc, wgpu::ShaderRuntimeChecks::unchecked())
        })
    }

    /// A read-only 2D texture of `width` × `height` texels of `format` holding `data`.
    fn texture(
        &self,
        label: &str,
        width: usize,
        height: usize,
        format: wgpu::TextureFormat,
        data: &[u8],
    ) -> wgpu::TextureView {
        let texture = self.device.create_texture_with_data(
            &self.queue,
            &wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d {
                    width: width as u32,
                    height: height as u32,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage: wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            },
            wgpu::util::TextureDataOrder::LayerMajor,
            data,
        );
        texture.create_view(&Default::default())
    }

    fn max_binding(&self) -> u64 {
        self.limits
            .max_storage_buffer_binding_size
            .min(self.limits.max_buffer_size)
            .min(self.chunk_bytes)
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
        // A sample takes at most a record of its own; the tables an index per slot.
        let rows = self.limits.max_texture_dimension_2d as usize;
        (rows * wgsl::RECORDS_PER_ROW)
            .min((self.max_binding() / 4) as usize / wgsl::MAX_RECORD_CHANNELS)
    }
    fn submissions(&self) -> Option<super::SubmissionStats> {
        let log = self.submission_log.lock().ok()?;
        Some(super::SubmissionStats::of(&log))
    }
    fn prepare_kernels(&self, model: &Model) -> Result<()> {
        // For the usual batch: data with μ tables (a few dozen polar angles at most).
        let pipes = self.value_pipelines(model, self.shape.for_batch(true))?;
        self.entry(&pipes, Entry::Values).map(|_| ())
    }
    fn prepare_many<'a>(&'a self, problems: &[Problem<'a>]) -> Result<Box<dyn Evaluator + 'a>> {
        super::check_shared(problems)?;
        let first = problems[0];
        let model = first.model;
        let total: usize = problems.iter().map(|p| p.data.len()).sum();
        anyhow::ensure!(
            total <= self.max_batch_samples(),
            "{total} samples in one batch exceed the GPU binding limit of {} (split the problems)",
            self.max_batch_samples()
        );
        let terms: Vec<LossTerms> = problems.iter().map(|p| p.loss.terms(p.data)).collect();
        let largest = problems.iter().map(|p| p.data.len()).max().unwrap_or(0);
        let cut_short_before = self
            .long_data_from
            .lock()
            .map(|m| m.get(&model.spec).is_some_and(|&k| largest >= k))
            .unwrap_or(false);
        let layout = RecordLayout::of(model);
        let mut records: Vec<f32> = Vec::new();
        let mut ranges: Vec<u32> = Vec::with_capacity(3 * problems.len());
        let mut index: Vec<u32> = Vec::new();
        let mut mu_tables: Vec<Vec<f32>> = Vec::with_capacity(problems.len());
        for (problem, terms) in problems.iter().zip(&terms) {
            let first = (records.len() / layout.floats()) as u32;
            mu_tables.push(layout.write(model, problem.data, terms, &mut records, &mut index)?);
            ranges.extend([
                first,
                (records.len() / layout.floats()) as u32,
                problem.data.len() as u32,
            ]);
        }
        // After the 3 entries per problem, where each problem's μ table starts; there, its
        // length, then its values (f32 bits).
        let mut at = ranges.len() + problems.len();
        for table in &mu_tables {
            ranges.push(at as u32);
            at += 1 + table.len();
        }
        for table in &mu_tables {
            ranges.push(table.len() as u32);
            ranges.extend(table.iter().map(|m| m.to_bits()));
        }
        let every_problem_has_a_mu_table = mu_tables.iter().all(|t| !t.is_empty());
        let shape = if cut_short_before {
            Shape::LONG_DATA
        } else {
            self.shape
        }
        .for_batch(every_problem_has_a_mu_table);
        let value_pipes = self.value_pipelines(model, shape)?;
        let n_records = records.len() / layout.floats();
        let (width, height) = layout.texture_size(n_records);
        anyhow::ensure!(
            height <= self.limits.max_texture_dimension_2d,
            "the {total} samples of this batch take {n_records} GPU records, more than a \
             texture of {} rows holds (split the problems)",
            self.limits.max_texture_dimension_2d
        );
        records.resize((width * height * 4) as usize, 0.0);
        let tables = ranges;
        // The indices as one RGBA32U texel per record (slots past CB unused).
        let mut texels = vec![
            NO_SAMPLE;
            4 * (width / wgsl::record_texels(layout.slots) as u32 * height)
                as usize
        ];
        for (r, slots) in index.chunks(layout.slots).enumerate() {
            texels[4 * r..4 * r + layout.slots].copy_from_slice(slots);
        }
        let lut: Vec<f32> = model
            .nodes()
            .iter()
            .find_map(|n| n.bsdf.lut())
            .unwrap_or_else(|| vec![0.0]);
        let init = |label: &str, bytes: &[u8], usage: wgpu::BufferUsages| {
            self.device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some(label),
                    contents: bytes,
                    usage,
                })
        };
        let storage = wgpu::BufferUsages::STORAGE;
        let records_view = self.texture(
            "records",
            width as usize,
            height as usize,
            wgpu::TextureFormat::Rgba32Float,
            bytemuck::cast_slice(&records),
        );
        let index_view = self.texture(
            "indices",
            (width / wgsl::record_texels(layout.slots) as u32) as usize,
            height as usize,
            wgpu::TextureFormat::Rgba32Uint,
            bytemuck::cast_slice(&texels),
        );
        let tables_buf = init("tables", bytemuck::cast_slice(&tables), storage);
        let mut lut = lut;
        let lut_rows = lut.len().div_ceil(LUT_WIDTH).max(1);
        lut.resize(lut_rows * LUT_WIDTH, 0.0);
        let lut_view = self.texture(
            "lut",
            LUT_WIDTH,
            lut_rows,
            wgpu::TextureFormat::R32Float,
            bytemuck::cast_slice(&lut),
        );
        let dims_buf = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("dims"),
            size: std::mem::size_of::<Dims>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        self.check_errors()?;
        Ok(Box::new(GpuEvaluator {
            gpu: self,
            model,
            terms,
            pipes: None,
            value_pipes,
            shape,
            mu_tables: every_problem_has_a_mu_table,
            records_view,
            index_view,
            tables_buf,
            lut_view,
            dims_buf,
            io: None,
            evaluations: vec![0; problems.len()],
            read_back: 0,
        }))
    }
}

/// Buffers that depend on the batch size, grown on demand.
struct IoBuffers {
    params: wgpu::Buffer,
    owners: wgpu::Buffer,
    out: wgpu::Buffer,
    /// The `normal` pass's output (NE numbers per group of P + 1 candidates).
    normal: wgpu::Buffer,
    staging: wgpu::Buffer,
    /// `LOOPS_CUT_SHORT` NaNs, as many as the larger of `out` and `normal`, written once:
    /// each submission first copies them over its outputs on the device, so anything the
    /// kernel fails to write reads as loops cut short.
    poison: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    params_cap: u64,
    out_cap: u64,
    normal_cap: u64,
}

pub struct GpuEvaluator<'a> {
    gpu: &'a GpuBackend,
    model: &'a crate::bsdf::Model,
    /// Each problem's loss constants (its sample count is `y.len()`).
    terms: Vec<LossTerms>,
    /// The pipelines of the loss's own entries (`costs`, `normal`), composed when first
    /// needed: an LM fit on a CPU device uses only `values`.
    pipes: Option<Arc<Pipelines>>,
    /// Those of the `values` entry ([`GpuBackend::value_pipelines`]).
    value_pipes: Arc<Pipelines>,
    /// The shape the pipelines were compiled for: the backend's, until a CPU device cuts its
    /// loops short (`LOOPS_CUT_SHORT`), then `Shape::LONG_DATA` (each [`Shape::for_batch`]).
    shape: Shape,
    /// Whether every problem has a μ table (`tables`, kernel.wgsl).
    mu_tables: bool,
    records_view: wgpu::TextureView,
    index_view: wgpu::TextureView,
    tables_buf: wgpu::Buffer,
    lut_view: wgpu::TextureView,
    dims_buf: wgpu::Buffer,
    io: Option<IoBuffers>,
    /// Model-sample evaluations per problem.
    evaluations: Vec<u64>,
    /// Bytes copied back from the device so far.
    read_back: u64,
}

/// One submission: the `values` (else `costs`) pipeline over `m` candidates whose
/// parameters are `host` and whose (problem, first output slot) pairs are `owners`,
/// writing `out_len` floats of `out`, and what is read back.
#[derive(Clone, Copy)]
struct Submission<'s> {
    values: bool,
    host: &'s [f32],
    owners: &'s [u32],
    m: usize,
    out_len: usize,
    output: Output,
    /// Model-sample evaluations it makes (for the submission log).
    evaluations: usize,
}

/// What one submission reads back.
#[derive(Clone, Copy)]
enum Output {
    /// `out`: one cost or K model values per candidate.
    Out,
    /// `normal`: the normal equations of `groups` groups of P + 1 candidates.
    Normal { groups: usize },
}

impl GpuEvaluator<'_> {
    fn ensure_io(&mut self, params_bytes: u64, out_bytes: u64, normal_bytes: u64) -> Result<()> {
        // wgpu binds no empty buffer: the `normal` output exists (4 bytes) in every pass.
        let normal_bytes = normal_bytes.max(4);
        let fits = self.io.as_ref().is_some_and(|io| {
            io.params_cap >= params_bytes
                && io.out_cap >= out_bytes
                && io.normal_cap >= normal_bytes
        });
        if fits {
            return Ok(());
        }
        let (pc, oc, nc) = match &self.io {
            Some(io) => (
                io.params_cap.max(params_bytes),
                io.out_cap.max(out_bytes),
                io.normal_cap.max(normal_bytes),
            ),
            None => (params_bytes, out_bytes, normal_bytes),
        };
        let dev = &self.gpu.device;
        let params = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("params"),
            size: pc,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        // Two u32 per candidate, and a candidate has at least one f32 parameter.
        let owners = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("owners"),
            size: 2 * pc,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let out = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("out"),
            size: oc,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let normal = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("normal"),
            size: nc,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let staging = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("staging"),
            size: oc.max(nc),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let poison = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("poison"),
            size: oc.max(nc),
            usage: wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: true,
        });
        {
            let mut view = poison
                .slice(..)
                .get_mapped_range_mut()
                .map_err(|e| anyhow!("GPU poison buffer: {e:?}"))?;
            let words = vec![LOOPS_CUT_SHORT; view.len() / 4];
            view.copy_from_slice(bytemuck::cast_slice(&words));
        }
        poison.unmap();
        fn entry(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
            wgpu::BindGroupEntry {
                binding,
                resource: buffer.as_entire_binding(),
            }
        }
        let bind_group = dev.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("bsdfit kernel"),
            layout: &self.gpu.layout,
            entries: &[
                entry(0, &self.dims_buf),
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(&self.records_view),
                },
                entry(2, &self.tables_buf),
                entry(3, &params),
                entry(4, &out),
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: wgpu::BindingResource::TextureView(&self.lut_view),
                },
                wgpu::BindGroupEntry {
                    binding: 8,
                    resource: wgpu::BindingResource::TextureView(&self.index_view),
                },
                entry(6, &owners),
                entry(7, &normal),
            ],
        });
        self.io = Some(IoBuffers {
            params,
            owners,
            out,
            normal,
            staging,
            poison,
            bind_group,
            params_cap: pc,
            out_cap: oc,
            normal_cap: nc,
        });
        Ok(())
    }

    /// [`Self::dispatch_once`], moved to `Shape::LONG_DATA` and run again where a CPU
    /// device cut its loops short; an error naming the cause where that shape is cut
    /// short too.
    fn dispatch(&mut self, job: &Submission) -> Result<Vec<f32>> {
        loop {
            match self.dispatch_once(job) {
                Err(e) if e.is::<LoopsCutShort>() => {
                    if self.shape.maps_like(Shape::LONG_DATA) {
                        bail!(
                            "{} cut this evaluation short: it ends every loop of a shader \
                             invocation after 65,535 iterations in all, and evaluating `{}` on \
                             the largest data set of this batch ({} samples) takes more than \
                             that even split over {} threads per candidate; use --backend cpu \
                             (or fewer samples)",
                            self.gpu.adapter_name(),
                            self.model.spec,
                            self.terms.iter().map(|t| t.y.len()).max().unwrap_or(0),
                            Shape::LONG_DATA.slices
                        );
                    }
                    self.shape = Shape::LONG_DATA.for_batch(self.mu_tables);
                    let largest = self.terms.iter().map(|t| t.y.len()).max().unwrap_or(0);
                    if let Ok(mut m) = self.gpu.long_data_from.lock() {
                        let k = m.entry(self.model.spec.clone()).or_insert(largest);
                        *k = (*k).min(largest);
                    }
                    self.pipes = None;
                    self.value_pipes = self.gpu.value_pipelines(self.model, self.shape)?;
                }
                other => return other,
            }
        }
    }

    /// Run one submission with the evaluator's shape: upload the parameters and owners,
    /// poison `out` with the `LOOPS_CUT_SHORT` NaN (so anything the kernel fails to write
    /// reads as loops cut short), evaluate, and read back `out` (`Output::Out`) or, after
    /// the `normal` pass over those values in the same submission, only its NE numbers
    /// per group, poisoned likewise (`Output::Normal`).
    fn dispatch_once(&mut self, job: &Submission) -> Result<Vec<f32>> {
        let Submission {
            values,
            host,
            owners,
            m,
            out_len,
            output,
            evaluations,
        } = *job;
        let started = std::time::Instant::now();
        let p = self.model.dim;
        let o_bytes = (out_len * 4) as u64;
        let (groups, normal_len) = match output {
            Output::Out => (0, 0),
            Output::Normal { groups } => (groups, groups * normal_entries(p)),
        };
        let n_bytes = (normal_len * 4) as u64;
        let pipes = if !values || normal_len > 0 {
            Some(self.loss_pipelines()?)
        } else {
            None
        };
        self.ensure_io((host.len() * 4) as u64, o_bytes, n_bytes)?;
        let io = self.io.as_ref().expect("io buffers allocated");
        let grid = |total: u32| {
            let x = total.clamp(1, MAX_GROUPS_X);
            (x, total.div_ceil(x))
        };
        let (groups_x, groups_y) = grid((m as u32).div_ceil(self.shape.candidates_per_workgroup()));
        let (normal_x, normal_y) = grid(groups as u32);
        let dims = Dims {
            n_candidates: m as u32,
            n_problems: self.terms.len() as u32,
            dim: p as u32,
            groups_x,
            n_groups: groups as u32,
            normal_groups_x: normal_x,
            probe_trips: 2,
            pad: 0,
        };
        let q = &self.gpu.queue;
        q.write_buffer(&self.dims_buf, 0, bytemuck::bytes_of(&dims));
        q.write_buffer(&io.params, 0, bytemuck::cast_slice(host));
        q.write_buffer(&io.owners, 0, bytemuck::cast_slice(owners));
        let evaluate = match &pipes {
            Some(pipes) if !values => self.gpu.entry(pipes, Entry::Costs)?,
            _ => self.gpu.entry(&self.value_pipes, Entry::Values)?,
        };
        let normal = match &pipes {
            Some(pipes) if normal_len > 0 => Some(self.gpu.entry(pipes, Entry::Normal)?),
            _ => None,
        };
        let mut enc = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("bsdfit"),
            });
        // The outputs poisoned on the device, from the evaluator's poison buffer: writing
        // them from the host cost two copies of every output per submission (into wgpu's
        // staging, then into the buffer), 4 % of the default sweep's CPU time on lavapipe.
        enc.copy_buffer_to_buffer(&io.poison, 0, &io.out, 0, o_bytes);
        if normal_len > 0 {
            enc.copy_buffer_to_buffer(&io.poison, 0, &io.normal, 0, n_bytes);
        }
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("evaluate"),
                timestamp_writes: None,
            });
            pass.set_pipeline(evaluate);
            pass.set_bind_group(0, &io.bind_group, &[]);
            pass.dispatch_workgroups(groups_x, groups_y, 1);
            if normal_len > 0 {
                // wgpu orders the two dispatches (the second reads what the first wrote
                // to `out`) with a barrier between them.
                pass.set_pipeline(normal.expect("compiled when normal_len > 0"));
                pass.dispatch_workgroups(normal_x, normal_y, 1);
            }
        }
        let (source, bytes) = if normal_len > 0 {
            (&io.normal, n_bytes)
        } else {
            (&io.out, o_bytes)
        };
        enc.copy_buffer_to_buffer(source, 0, &io.staging, 0, bytes);
        let index = q.submit(Some(enc.finish()));
        let slice = io.staging.slice(0..bytes);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            tx.send(r).ok();
        });
        self.gpu
            .device
            .poll(wgpu::PollType::Wait {
                submission_index: Some(index),
                timeout: None,
            })
            .map_err(|e| anyhow!("GPU poll failed: {e}"))?;
        rx.recv()
            .map_err(|_| anyhow!("GPU read-back was dropped"))?
            .map_err(|e| anyhow!("GPU read-back failed: {e}"))?;
        let data = {
            let view = slice
                .get_mapped_range()
                .map_err(|e| anyhow!("GPU read-back failed: {e:?}"))?;
            bytemuck::cast_slice::<u8, f32>(&view).to_vec()
        };
        io.staging.unmap();
        self.read_back += bytes;
        if let Ok(mut log) = self.gpu.submission_log.lock() {
            if log.len() < SUBMISSION_LOG_CAP {
                log.push((
                    m as u32,
                    evaluations as u64,
                    started.elapsed().as_secs_f32(),
                ));
            }
        }
        self.gpu.check_errors()?;
        if data.iter().any(|v| v.to_bits() == LOOPS_CUT_SHORT) {
            return Err(LoopsCutShort.into());
        }
        Ok(data)
    }

    /// The pipelines of the loss's own entries, composed on first use. Their `costs` entry
    /// returns each candidate's plain sum of terms, which the host finishes per problem
    /// ([`LossTerms::finish_sum`], in f64): so problems whose losses share a term shape
    /// (χ², RMSE, Ngan, Löw, f, cos·f: all squares) share one evaluator and one module,
    /// the one `values` uses for square terms.
    fn loss_pipelines(&mut self) -> Result<Arc<Pipelines>> {
        if let Some(p) = &self.pipes {
            return Ok(p.clone());
        }
        let p = self
            .gpu
            .pipelines(self.model, self.terms[0].term, self.shape)?;
        self.pipes = Some(p.clone());
        Ok(p)
    }

    fn check_batch(&self, owners: &[usize], params: &[f64], per_owner: usize) -> Result<()> {
        let p = self.model.dim;
        anyhow::ensure!(
            p > 0 && params.len() == owners.len() * per_owner * p,
            "parameter batch of {} values is not {} × {per_owner} candidates of P = {p}",
            params.len(),
            owners.len()
        );
        anyhow::ensure!(
            owners.iter().all(|&q| q < self.terms.len()),
            "a candidate names a problem outside the batch's {}",
            self.terms.len()
        );
        Ok(())
    }

    /// Run `pipeline` over the candidates in `params` (problem `owners[i]` each): one
    /// cost per candidate, or (`values_mode`) its problem's K model values. Batches larger
    /// than a binding go in several submissions.
    fn run(&mut self, owners: &[usize], params: &[f64], values_mode: bool) -> Result<Vec<f64>> {
        let raw = self.run_f32(owners, params, values_mode)?;
        Ok(if values_mode {
            raw.iter().map(|&v| v as f64).collect()
        } else {
            let sums = raw.iter().zip(owners);
            sums.map(|(&v, &q)| self.terms[q].finish_sum(v as f64))
                .collect()
        })
    }

    /// [`Self::run`] as the device wrote it: the f32 values, or each candidate's f32 sum
    /// of loss terms (not finished).
    fn run_f32(&mut self, owners: &[usize], params: &[f64], values_mode: bool) -> Result<Vec<f32>> {
        self.check_batch(owners, params, 1)?;
        let p = self.model.dim;
        let n = owners.len();
        let sizes: Vec<usize> = self.terms.iter().map(|t| t.y.len()).collect();
        let per = |q: usize| if values_mode { sizes[q] } else { 1 };
        let max = (self.gpu.max_binding() / 4) as usize;
        let max_candidates = MAX_GROUPS_X as usize * MAX_GROUPS_X as usize;
        let mut result = Vec::new();
        let mut start = 0;
        while start < n {
            // The largest run of candidates whose parameters and outputs fit a binding.
            let (mut end, mut outs) = (start, 0);
            while end < n
                && end - start < max_candidates
                && (end - start + 1) * p.max(2) <= max
                && outs + per(owners[end]) <= max
            {
                outs += per(owners[end]);
                end += 1;
            }
            anyhow::ensure!(end > start, "one candidate's output exceeds a GPU binding");
            let host: Vec<f32> = params[start * p..end * p]
                .iter()
                .map(|&v| v as f32)
                .collect();
            let ids = self.output_rows(&owners[start..end], per);
            let data = self.dispatch(&Submission {
                values: values_mode,
                host: &host,
                owners: &ids,
                m: end - start,
                out_len: outs,
                output: Output::Out,
                evaluations: owners[start..end].iter().map(|&q| sizes[q]).sum(),
            })?;
            if result.is_empty() {
                result = data; // the whole batch in one submission: no copy
            } else {
                result.extend_from_slice(&data);
            }
            start = end;
        }
        for &q in owners {
            self.evaluations[q] += sizes[q] as u64;
        }
        Ok(result)
    }

    /// The `owners` buffer of a run of candidates: per candidate its problem and where its
    /// `per(problem)` outputs start, one after the other.
    fn output_rows(&self, owners: &[usize], per: impl Fn(usize) -> usize) -> Vec<u32> {
        let mut ids = Vec::with_capacity(2 * owners.len());
        let mut row = 0u32;
        for &q in owners {
            ids.push(q as u32);
            ids.push(row);
            row += per(q) as u32;
        }
        ids
    }

    /// LM's normal equations of groups of P + 1 candidates, reduced on the device: each
    /// submission evaluates the model values of whole groups into `out` and the `normal`
    /// pass (shaders/engine/normal.wgsl) reduces each group to P(P + 1)/2 + P + 1 f32
    /// sums, the only numbers read back. Here they become f64 and are divided by the
    /// steps. A group whose (P + 1) × K values exceed one binding, or any group on a
    /// backend without `device_normal`, is reduced on the host from the values read back
    /// (`normal_equations_of_values`).
    fn normal_run(
        &mut self,
        owners: &[usize],
        params: &[f64],
        steps: &[f64],
    ) -> Result<Vec<NormalEquations>> {
        self.check_batch(owners, params, self.model.dim + 1)?;
        let p = self.model.dim;
        anyhow::ensure!(
            steps.len() == owners.len() * p,
            "{} steps for {} groups of P = {p}",
            steps.len(),
            owners.len()
        );
        let ne = normal_entries(p);
        let sizes: Vec<usize> = self.terms.iter().map(|t| t.y.len()).collect();
        let max = (self.gpu.max_binding() / 4) as usize;
        let fits = |q: usize| ne <= max && (p + 1) * p.max(2) <= max && (p + 1) * sizes[q] <= max;
        if !self.gpu.device_normal || !owners.iter().all(|&q| fits(q)) {
            let expanded: Vec<usize> = owners
                .iter()
                .flat_map(|&q| std::iter::repeat_n(q, p + 1))
                .collect();
            let values = self.run_f32(&expanded, params, true)?;
            let terms: Vec<&LossTerms> = self.terms.iter().collect();
            return Ok(super::normal_equations_of_values(
                &values, &terms, owners, steps, p,
            ));
        }
        let max_groups = (MAX_GROUPS_X as usize * MAX_GROUPS_X as usize) / (p + 1);
        let n = owners.len();
        let mut result = Vec::with_capacity(n);
        let mut start = 0;
        while start < n {
            // The largest run of whole groups whose parameters, values and sums each fit a
            // binding (a group's values must be on the device together).
            let (mut end, mut outs) = (start, 0);
            while end < n
                && end - start < max_groups
                && (end - start + 1) * (p + 1) * p.max(2) <= max
                && (end - start + 1) * ne <= max
                && outs + (p + 1) * sizes[owners[end]] <= max
            {
                outs += (p + 1) * sizes[owners[end]];
                end += 1;
            }
            anyhow::ensure!(end > start, "one group's values exceed a GPU binding");
            let groups = end - start;
            let host: Vec<f32> = params[start * (p + 1) * p..end * (p + 1) * p]
                .iter()
                .map(|&v| v as f32)
                .collect();
            let expanded: Vec<usize> = owners[start..end]
                .iter()
                .flat_map(|&q| std::iter::repeat_n(q, p + 1))
                .collect();
            let ids = self.output_rows(&expanded, |q| sizes[q]);
            let data = self.dispatch(&Submission {
                values: true,
                host: &host,
                owners: &ids,
                m: groups * (p + 1),
                out_len: outs,
                output: Output::Normal { groups },
                evaluations: outs,
            })?;
            for (sums, h) in data.chunks(ne).zip(steps[start * p..end * p].chunks(p)) {
                result.push(normal_from_sums(sums, h));
            }
            start = end;
        }
        for &q in owners {
            self.evaluations[q] += ((p + 1) * sizes[q]) as u64;
        }
        Ok(result)
    }
}

/// JᵀJ, Jᵀr and Σr² of one group from the `normal` pass's sums (normal.wgsl): the upper
/// triangle of Σ d_a d_b, then Σ d_j r, then Σ r², with d_j = h_j J_j. The division by the
/// unit-box steps is done here, in f64, exactly as the host's forward differences divide.
fn normal_from_sums(sums: &[f32], h: &[f64]) -> NormalEquations {
    let p = h.len();
    let mut jtj = vec![0.0; p * p];
    let mut e = 0;
    for a in 0..p {
        for b in a..p {
            let v = sums[e] as f64 / (h[a] * h[b]);
            jtj[a * p + b] = v;
            jtj[b * p + a] = v;
            e += 1;
        }
    }
    let jtr = (0..p).map(|j| sums[e + j] as f64 / h[j]).collect();
    NormalEquations {
        jtj,
        jtr,
        ss: crate::optim::sanitize(sums[e + p] as f64),
    }
}

impl Evaluator for GpuEvaluator<'_> {
    fn dim(&self) -> usize {
        self.model.dim
    }
    fn problems(&self) -> usize {
        self.terms.len()
    }
    fn samples_of(&self, q: usize) -> usize {
        self.terms[q].y.len()
    }
    fn costs_of(&mut self, owners: &[usize], params: &[f64]) -> Result<Vec<f64>> {
        self.run(owners, params, false)
    }
    fn values_of(&mut self, owners: &[usize], params: &[f64]) -> Result<Vec<f64>> {
        self.run(owners, params, true)
    }
    fn normal_equations_of(
        &mut self,
        owners: &[usize],
        params: &[f64],
        steps: &[f64],
    ) -> Result<Vec<NormalEquations>> {
        self.normal_run(owners, params, steps)
    }

    fn evaluations_of(&self, q: usize) -> u64 {
        self.evaluations[q]
    }
    fn read_back_bytes(&self) -> u64 {
        self.read_back
    }
}
