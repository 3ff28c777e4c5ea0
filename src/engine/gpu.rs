//! The GPU engine: wgpu compute on Vulkan, f32. One submission evaluates every candidate
//! of every restart over every sample and reduces on the device to one cost per
//! candidate (shaders/kernel.wgsl). Pipelines are compiled once per (model, loss shape)
//! and cached; the dataset is uploaded once per problem; parameter and output buffers are
//! reused across optimizer iterations and grown only when a larger batch arrives.

use super::wgsl::{compose, validate, Shape};
use super::{Backend, Evaluator, Problem};
use crate::engine::loss::{Finish, Term};
use crate::optim::NormalEquations;
use anyhow::{anyhow, bail, Context, Result};
use bytemuck::{Pod, Zeroable};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use wgpu::util::DeviceExt;

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct GpuSample {
    wi: [f32; 4],
    wo: [f32; 4],
    ext: [f32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Dims {
    n_candidates: u32,
    n_samples: u32,
    dim: u32,
    groups_x: u32,
}

struct Pipelines {
    costs: wgpu::ComputePipeline,
    values: wgpu::ComputePipeline,
}

pub struct GpuBackend {
    device: wgpu::Device,
    queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
    limits: wgpu::Limits,
    layout: wgpu::BindGroupLayout,
    pipeline_layout: wgpu::PipelineLayout,
    pipelines: Mutex<HashMap<String, Arc<Pipelines>>>,
    shape: Shape,
    /// Errors wgpu reports asynchronously; checked after each submission so they become
    /// `Err` values instead of the default handler's panic.
    errors: Arc<Mutex<Vec<String>>>,
}

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
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("bsdfit"),
                required_features: wgpu::Features::empty(),
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
                storage(1, true),
                storage(2, true),
                storage(3, true),
                storage(4, false),
                storage(5, true),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("bsdfit kernel"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let shape = if info.device_type == wgpu::DeviceType::Cpu {
            Shape::CPU_DEVICE
        } else {
            Shape::GPU_DEVICE
        };
        Ok(GpuBackend {
            shape,
            device,
            queue,
            info,
            limits,
            layout,
            pipeline_layout,
            pipelines: Mutex::default(),
            errors,
        })
    }

    /// Override the workgroup shape (benchmarks and tests of both code paths).
    pub fn with_shape(mut self, shape: Shape) -> Self {
        self.shape = shape;
        self
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

    fn pipelines(&self, problem: &Problem, term: Term, finish: Finish) -> Result<Arc<Pipelines>> {
        let key = format!(
            "{}|{}|{}|{:?}|{:?}|{:?}",
            problem.model.spec,
            problem.model.channels,
            problem.model.axes.len(),
            term,
            finish,
            self.shape
        );
        let mut cache = self
            .pipelines
            .lock()
            .map_err(|_| anyhow!("pipeline cache poisoned"))?;
        if let Some(p) = cache.get(&key) {
            return Ok(p.clone());
        }
        let source = compose(problem.model, term, finish, self.shape);
        let module = self.module(&problem.model.spec, source)?;
        let make = |entry: &str| {
            self.device
                .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(entry),
                    layout: Some(&self.pipeline_layout),
                    module: &module,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    cache: None,
                })
        };
        let p = Arc::new(Pipelines {
            costs: make("costs"),
            values: make("values"),
        });
        self.check_errors()?;
        cache.insert(key, p.clone());
        Ok(p)
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
        // is bounded by a counter compared against a host-written size, and every index
        // is either a loop counter below such a size or a slot the host computed from the
        // model layout for buffers it sized itself (`prepare`, `ensure_io`); so the
        // injected bounds checks and loop guards can be left out of the inner loop.
        Ok(unsafe {
            self.device
                .create_shader_module_trusted(desc, wgpu::ShaderRuntimeChecks::unchecked())
        })
    }

    fn max_binding(&self) -> u64 {
        self.limits
            .max_storage_buffer_binding_size
            .min(self.limits.max_buffer_size)
            .min(MAX_CHUNK_BYTES)
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
    fn prepare<'a>(&'a self, problem: Problem<'a>) -> Result<Box<dyn Evaluator + 'a>> {
        let terms = problem.loss.terms(problem.data);
        let pipes = self.pipelines(&problem, terms.term, terms.finish)?;
        let model = problem.model;
        // Sort by channel (stable) so the kernel's channel loop is outermost; the original
        // index travels with each sample for the `values` output.
        let mut order: Vec<usize> = (0..problem.data.len()).collect();
        order.sort_by_key(|&k| model.group_of(&problem.data.samples[k]));
        let samples: Vec<GpuSample> = order
            .iter()
            .map(|&k| {
                let s = &problem.data.samples[k];
                let (wi, wo) = (s.wi(), s.wo());
                GpuSample {
                    wi: [wi.x as f32, wi.y as f32, wi.z as f32, terms.w[k] as f32],
                    wo: [wo.x as f32, wo.y as f32, wo.z as f32, terms.a[k] as f32],
                    ext: [
                        s.value as f32,
                        terms.transform(k, s.value) as f32,
                        model.group_of(s) as f32,
                        f32::from_bits(k as u32),
                    ],
                }
            })
            .collect();
        let groups = model.groups();
        let mut slots = Vec::with_capacity(model.scalar_count() * groups + groups + 1);
        for g in 0..groups {
            for j in 0..model.scalar_count() {
                slots.push(model.slot(j, g) as u32);
            }
        }
        for g in 0..=groups {
            slots.push(
                problem
                    .data
                    .samples
                    .iter()
                    .filter(|s| model.group_of(s) < g)
                    .count() as u32,
            );
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
        let samples_buf = init("samples", bytemuck::cast_slice(&samples), storage);
        let slots_buf = init("slots", bytemuck::cast_slice(&slots), storage);
        let lut_buf = init("lut", bytemuck::cast_slice(&lut), storage);
        let dims_buf = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("dims"),
            size: std::mem::size_of::<Dims>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        self.check_errors()?;
        Ok(Box::new(GpuEvaluator {
            gpu: self,
            problem,
            pipes,
            samples_buf,
            slots_buf,
            lut_buf,
            dims_buf,
            io: None,
            evaluations: 0,
        }))
    }
}

/// Buffers that depend on the batch size, grown on demand.
struct IoBuffers {
    params: wgpu::Buffer,
    out: wgpu::Buffer,
    staging: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    params_cap: u64,
    out_cap: u64,
}

pub struct GpuEvaluator<'a> {
    gpu: &'a GpuBackend,
    problem: Problem<'a>,
    pipes: Arc<Pipelines>,
    samples_buf: wgpu::Buffer,
    slots_buf: wgpu::Buffer,
    lut_buf: wgpu::Buffer,
    dims_buf: wgpu::Buffer,
    io: Option<IoBuffers>,
    evaluations: u64,
}

impl GpuEvaluator<'_> {
    fn ensure_io(&mut self, params_bytes: u64, out_bytes: u64) {
        let fits = self
            .io
            .as_ref()
            .is_some_and(|io| io.params_cap >= params_bytes && io.out_cap >= out_bytes);
        if fits {
            return;
        }
        let (pc, oc) = match &self.io {
            Some(io) => (io.params_cap.max(params_bytes), io.out_cap.max(out_bytes)),
            None => (params_bytes, out_bytes),
        };
        let dev = &self.gpu.device;
        let params = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("params"),
            size: pc,
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
        let staging = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("staging"),
            size: oc,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = dev.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("bsdfit kernel"),
            layout: &self.gpu.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: self.dims_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: self.samples_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: self.slots_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: params.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: out.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: self.lut_buf.as_entire_binding(),
                },
            ],
        });
        self.io = Some(IoBuffers {
            params,
            out,
            staging,
            bind_group,
            params_cap: pc,
            out_cap: oc,
        });
    }

    /// One submission: upload `host` as the parameter buffer, run `pipeline` over `m`
    /// candidates, read back `out_len` floats (poisoned with NaN
    /// beforehand, so anything the kernel fails to write reads back as NaN).
    fn dispatch(
        &mut self,
        pipeline: &wgpu::ComputePipeline,
        host: &[f32],
        m: usize,
        out_len: usize,
    ) -> Result<Vec<f32>> {
        let p = self.problem.model.dim;
        let k = self.problem.data.len();
        let o_bytes = (out_len * 4) as u64;
        self.ensure_io((host.len() * 4) as u64, o_bytes);
        let io = self.io.as_ref().expect("io buffers allocated");
        let total_groups = (m as u32).div_ceil(self.gpu.shape.lanes);
        let groups_x = total_groups.min(MAX_GROUPS_X);
        let groups_y = total_groups.div_ceil(groups_x);
        let dims = Dims {
            n_candidates: m as u32,
            n_samples: k as u32,
            dim: p as u32,
            groups_x,
        };
        let q = &self.gpu.queue;
        q.write_buffer(&self.dims_buf, 0, bytemuck::bytes_of(&dims));
        q.write_buffer(&io.params, 0, bytemuck::cast_slice(host));
        q.write_buffer(&io.out, 0, bytemuck::cast_slice(&vec![f32::NAN; out_len]));
        let mut enc = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("bsdfit"),
            });
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("evaluate"),
                timestamp_writes: None,
            });
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &io.bind_group, &[]);
            pass.dispatch_workgroups(groups_x, groups_y, 1);
        }
        enc.copy_buffer_to_buffer(&io.out, 0, &io.staging, 0, o_bytes);
        q.submit(Some(enc.finish()));
        let slice = io.staging.slice(0..o_bytes);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            tx.send(r).ok();
        });
        self.gpu
            .device
            .poll(wgpu::PollType::wait_indefinitely())
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
        self.gpu.check_errors()?;
        Ok(data)
    }

    /// Run `pipeline` over the candidates in `params`, `per_candidate` outputs each.
    fn run(&mut self, params: &[f64], values_mode: bool) -> Result<Vec<f64>> {
        let p = self.problem.model.dim;
        anyhow::ensure!(
            p > 0 && params.len().is_multiple_of(p),
            "parameter batch of {} values is not a multiple of P = {p}",
            params.len()
        );
        let n = params.len() / p;
        let k = self.problem.data.len();
        let per = if values_mode { k } else { 1 };
        let max = self.gpu.max_binding();
        let per_cand_bytes = ((p.max(per)) * 4) as u64;
        let chunk = ((max / per_cand_bytes) as usize)
            .clamp(1, MAX_GROUPS_X as usize * MAX_GROUPS_X as usize);
        let mut result = Vec::with_capacity(n * per);
        for start in (0..n).step_by(chunk) {
            let m = chunk.min(n - start);
            let host: Vec<f32> = params[start * p..(start + m) * p]
                .iter()
                .map(|&v| v as f32)
                .collect();
            let pipes = self.pipes.clone();
            let pipeline = if values_mode {
                &pipes.values
            } else {
                &pipes.costs
            };
            let data = self.dispatch(pipeline, &host, m, m * per)?;
            result.extend(data.iter().map(|&v| v as f64));
        }
        self.evaluations += (n * k) as u64;
        Ok(result)
    }
}

impl Evaluator for GpuEvaluator<'_> {
    fn dim(&self) -> usize {
        self.problem.model.dim
    }
    fn costs(&mut self, params: &[f64]) -> Result<Vec<f64>> {
        self.run(params, false)
    }
    fn values(&mut self, params: &[f64]) -> Result<Vec<f64>> {
        self.run(params, true)
    }
    fn normal_equations(&mut self, params: &[f64], steps: &[f64]) -> Result<Vec<NormalEquations>> {
        // Model values of every candidate in one submission; the f64 reduction to JᵀJ is
        // done on the host (a device-side reduction is future work, see the README).
        let values = self.values(params)?;
        let terms = self.problem.loss.terms(self.problem.data);
        Ok(super::normal_equations_from_values(
            &values,
            &terms,
            steps,
            self.problem.model.dim,
        ))
    }

    fn evaluations(&self) -> u64 {
        self.evaluations
    }
}
