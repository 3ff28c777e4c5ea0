//! The device layer: opening a Vulkan adapter, catching wgpu's asynchronous errors as
//! values, noticing a device lost or hung ([`super::fault`]), and the resources every
//! other layer asks for (textures, buffers, shader modules). Nothing here knows what a
//! BSDF or a loss is.

use super::fault::{self, DeviceFault, FaultPlan, Injected};
use anyhow::{anyhow, bail, Context as _, Result};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use wgpu::util::DeviceExt;

/// An opened device, its queue and what the adapter offers.
pub struct Device {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
    pub limits: wgpu::Limits,
    /// Whether buffers the kernels write can be mapped for reading as they are (CPU
    /// devices, whose memory is the host's): read-backs then skip the copy into a
    /// staging buffer.
    pub mappable: bool,
    /// Errors wgpu reports asynchronously; [`Device::check_errors`] turns them into
    /// `Err` values instead of the default handler's panic.
    errors: Arc<Mutex<Vec<String>>>,
    /// Submissions so far and the fault that ended the device's use, shared with wgpu's
    /// device-lost callback.
    health: Arc<Health>,
    /// The fault to inject ([`fault::FAULT_VAR`]).
    plan: Option<FaultPlan>,
    /// How long a read-back waits for its submission ([`fault::TIMEOUT_VAR`]).
    timeout: Duration,
    /// The `hang@N` injection's workload, made when first needed.
    stall: std::sync::OnceLock<super::stall::Stall>,
}

/// A device that ran the `hang@N` injection's stall waits for it before it goes: wgpu
/// waits only a few seconds for a queue's work before freeing what it uses.
impl Drop for Device {
    fn drop(&mut self) {
        if self.stall.get().is_some_and(|s| s.submitted()) {
            self.device
                .poll(wgpu::PollType::Wait {
                    submission_index: None,
                    timeout: Some(Duration::from_secs(600)),
                })
                .ok();
        }
    }
}

/// What a device has been through: its submissions (numbered from 1) and its fault.
#[derive(Default)]
struct Health {
    submissions: AtomicU64,
    fault: Mutex<Option<DeviceFault>>,
}

impl Health {
    /// Record `f` unless the device already has a fault; the device's fault.
    fn set(&self, f: DeviceFault) -> DeviceFault {
        match self.fault.lock() {
            Ok(mut g) => g.get_or_insert(f).clone(),
            Err(_) => f,
        }
    }

    fn get(&self) -> Option<DeviceFault> {
        self.fault.lock().ok().and_then(|g| g.clone())
    }
}

/// Why a poll did not end in the wait's success.
enum PollFailed {
    Timeout,
    Other(String),
}

/// The process's one Vulkan instance, made on first use and kept: on an NVIDIA H200
/// (driver 580) a process that dropped its first instance found no adapter through a
/// second one ("vulkan drivers/libraries could not be loaded": `tests/gpu_records.rs`,
/// whose tests each open a device, passed its first test and failed the next three).
/// Devices opened one after another in one process (tests, the Python module) share it.
fn vulkan_instance() -> wgpu::Instance {
    static INSTANCE: std::sync::OnceLock<wgpu::Instance> = std::sync::OnceLock::new();
    INSTANCE
        .get_or_init(|| {
            wgpu::Instance::new(wgpu::InstanceDescriptor {
                backends: wgpu::Backends::VULKAN,
                ..wgpu::InstanceDescriptor::new_without_display_handle()
            })
        })
        .clone()
}

impl Device {
    /// Open the first Vulkan adapter (a discrete GPU if present, else e.g. lavapipe),
    /// asking for every limit it offers and for subgroups where it has them.
    pub fn open() -> Result<Device> {
        pollster::block_on(Self::open_async())
    }

    async fn open_async() -> Result<Device> {
        let plan = FaultPlan::from_env()?;
        let timeout = fault::timeout_from_env()?;
        // Mesa's Vulkan loader prints an error when XDG_RUNTIME_DIR is unset (headless
        // machines, CI); compute never presents to a window, so any directory will do.
        if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
            std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir());
        }
        let adapter = vulkan_instance()
            .request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                ..Default::default()
            })
            .await
            .map_err(|e| {
                anyhow!("no Vulkan adapter found ({e}); install a Vulkan driver (e.g. Debian's mesa-vulkan-drivers for the lavapipe software device)")
            })?;
        let info = adapter.get_info();
        // Ask for everything the adapter offers: buffer sizes are chunked from these.
        let limits = adapter.limits();
        // Subgroups: the sample tiles of SIMD CPU devices (shaders/engine/lanes_subgroup.wgsl).
        // Mappable storage buffers on CPU devices only: elsewhere they would put the
        // kernels' outputs in memory the GPU reads slowly.
        let mut wanted = wgpu::Features::SUBGROUP;
        if info.device_type == wgpu::DeviceType::Cpu {
            wanted |= wgpu::Features::MAPPABLE_PRIMARY_BUFFERS;
        }
        let features = adapter.features() & wanted;
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
        // wgpu reports a lost device here, not to the error handler: on the poll that
        // finds it (a driver's loss), or the first poll after the queue drained
        // (`destroy`).
        let health: Arc<Health> = Arc::default();
        let watch = health.clone();
        device.set_device_lost_callback(move |reason, message| {
            let detail = match message.trim() {
                "" => format!("{reason:?}"),
                m => format!("{reason:?}: {m}"),
            };
            watch.set(DeviceFault::Lost {
                submission: watch.submissions.load(Ordering::SeqCst),
                detail,
            });
        });
        let d = Device {
            mappable: features.contains(wgpu::Features::MAPPABLE_PRIMARY_BUFFERS),
            device,
            queue,
            info,
            limits,
            errors,
            health,
            plan,
            timeout,
            stall: std::sync::OnceLock::new(),
        };
        d.prepare_plan()?;
        Ok(d)
    }

    /// A command buffer that keeps the device busy past the read-back timeout (three
    /// times as long, and a second more: a measure taken while other work ran can make it
    /// up to three times shorter): the `hang@N` injection runs it ahead of the N-th
    /// submission's work. The device waits for it before it is dropped.
    pub fn stall_past_timeout(&self) -> Result<wgpu::CommandBuffer> {
        self.stall()
            .command_buffer(self, 3.0 * self.timeout.as_secs_f64() + 1.0)
    }

    /// The hang injection's workload, made on first use.
    fn stall(&self) -> &super::stall::Stall {
        self.stall.get_or_init(|| super::stall::Stall::new(self))
    }

    /// Where a hang is planned, measure its workload now, while the device is idle (a
    /// measure taken amid other work would make the stall too short).
    fn prepare_plan(&self) -> Result<()> {
        if self.plan.is_some_and(|p| p.what == fault::Injected::Hang) {
            self.stall().calibrate(self)?;
        }
        Ok(())
    }

    /// Inject `plan` instead of what [`fault::FAULT_VAR`] says (tests).
    pub fn set_fault_plan(&mut self, plan: Option<FaultPlan>) {
        self.plan = plan;
        // A measure that fails now is tried again, and reported, at the planned hang.
        self.prepare_plan().ok();
    }

    /// Wait at most `timeout` for each read-back instead of [`fault::TIMEOUT_VAR`]'s.
    pub fn set_timeout(&mut self, timeout: Duration) {
        self.timeout = timeout;
    }

    /// The fault that ended the device's use, if any.
    pub fn fault(&self) -> Option<DeviceFault> {
        self.health.get()
    }

    /// Submissions begun so far (numbered from 1 as [`fault::FAULT_VAR`] counts them).
    pub fn submission_count(&self) -> u64 {
        self.health.submissions.load(Ordering::SeqCst)
    }

    /// `Err` (the device's fault) once the device is lost or hung: it takes no more work.
    pub fn refuse_if_faulted(&self) -> Result<()> {
        match self.fault() {
            Some(f) => Err(f.into()),
            None => Ok(()),
        }
    }

    /// Number the next submission (refused once the device has a fault), and what the
    /// fault switch does at it.
    pub fn begin_submission(&self) -> Result<(u64, Option<Injected>)> {
        self.refuse_if_faulted()?;
        let n = self.health.submissions.fetch_add(1, Ordering::SeqCst) + 1;
        let injected = self.plan.filter(|p| p.at == n).map(|p| p.what);
        if injected == Some(Injected::Lost) {
            // The genuine loss: every later use fails through wgpu's own channels.
            self.device.destroy();
        }
        Ok((n, injected))
    }

    /// Poll the device. A panic inside wgpu (its answer to a device error it cannot
    /// return, e.g. a lost device met while waiting) is caught, and the device is taken
    /// as lost.
    fn poll(&self, how: wgpu::PollType) -> std::result::Result<(), PollFailed> {
        let polled =
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| self.device.poll(how)));
        match polled {
            Ok(Ok(_)) => Ok(()),
            Ok(Err(wgpu::PollError::Timeout)) => Err(PollFailed::Timeout),
            Ok(Err(e)) => Err(PollFailed::Other(e.to_string())),
            Err(p) => {
                // wgpu could not go on with the device: it is lost, whatever it said.
                let said = p
                    .downcast_ref::<String>()
                    .map(String::as_str)
                    .or_else(|| p.downcast_ref::<&str>().copied())
                    .unwrap_or("panic");
                let f = self.health.set(DeviceFault::Lost {
                    submission: self.submission_count(),
                    detail: format!("wgpu panicked while polling it: {}", said.trim()),
                });
                Err(PollFailed::Other(f.to_string()))
            }
        }
    }

    /// Let wgpu deliver what it knows (the device-lost callback fires on a poll once the
    /// queue has drained: wait for it, within the timeout), then the device's fault.
    fn settle(&self) -> Option<DeviceFault> {
        if self.fault().is_none() {
            let _ = self.poll(wgpu::PollType::Wait {
                submission_index: None,
                timeout: Some(self.timeout),
            });
        }
        self.fault()
    }

    /// The error for a read-back that failed with `what`: the device's fault where it
    /// has one (wgpu reported the loss), else the errors wgpu reported, else `what`.
    pub fn read_back_error(&self, what: String) -> anyhow::Error {
        if let Some(f) = self.settle() {
            return f.into();
        }
        match self.check_errors() {
            Err(e) => e.context(what),
            Ok(()) => anyhow!(what),
        }
    }

    /// Wait for submission `n` (wgpu's `index`) and for its read-back's mapping,
    /// `mapped`, each at most the timeout. A timeout
    /// marks the device hung.
    pub fn wait_read_back(
        &self,
        n: u64,
        index: wgpu::SubmissionIndex,
        mapped: &Receiver<std::result::Result<(), wgpu::BufferAsyncError>>,
    ) -> Result<()> {
        let hung = || -> anyhow::Error {
            self.health
                .set(DeviceFault::Hung {
                    submission: n,
                    seconds: self.timeout.as_secs_f64(),
                })
                .into()
        };
        match self.poll(wgpu::PollType::Wait {
            submission_index: Some(index),
            timeout: Some(self.timeout),
        }) {
            Ok(()) => {}
            Err(PollFailed::Timeout) => return Err(hung()),
            Err(PollFailed::Other(e)) => {
                return Err(self.read_back_error(format!("GPU poll failed: {e}")))
            }
        }
        match mapped.recv_timeout(self.timeout) {
            Ok(Ok(())) => Ok(()),
            Ok(Err(e)) => Err(self.read_back_error(format!("GPU read-back failed: {e}"))),
            Err(RecvTimeoutError::Timeout) => Err(hung()),
            Err(RecvTimeoutError::Disconnected) => {
                Err(self.read_back_error("GPU read-back was dropped".into()))
            }
        }
    }

    /// Whether the device is a CPU (lavapipe): its memory is the host's.
    pub fn is_cpu(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    pub fn has_subgroups(&self) -> bool {
        self.device.features().contains(wgpu::Features::SUBGROUP)
    }

    pub fn adapter_name(&self) -> String {
        format!(
            "{} ({:?}, {})",
            self.info.name, self.info.device_type, self.info.driver
        )
    }

    /// The errors wgpu reported since the last call, as one `Err`: the device's fault
    /// ([`DeviceFault`], typed) once it is lost or hung, whatever else was reported.
    pub fn check_errors(&self) -> Result<()> {
        let msg = {
            let mut errs = self
                .errors
                .lock()
                .map_err(|_| anyhow!("GPU error log poisoned"))?;
            let msg = errs.join("; ");
            errs.clear();
            msg
        };
        if msg.is_empty() {
            return self.refuse_if_faulted();
        }
        // An error may be the first sign of a lost device, which wgpu reports to the
        // device-lost callback alone.
        if let Some(f) = self.settle() {
            return Err(f.into());
        }
        bail!("GPU error: {msg}")
    }

    /// A read-only 2D texture of `width` × `height` texels of `format` holding `data`.
    pub fn texture(
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

    /// A buffer holding `bytes`.
    pub fn buffer_init(
        &self,
        label: &str,
        bytes: &[u8],
        usage: wgpu::BufferUsages,
    ) -> wgpu::Buffer {
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytes,
                usage,
            })
    }

    /// An uninitialised buffer of `size` bytes.
    pub fn buffer(&self, label: &str, size: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage,
            mapped_at_creation: false,
        })
    }

    /// A buffer of `words` copies of `word`, only ever copied from (the poison the
    /// outputs are reset to before each pass).
    pub fn filled_buffer(&self, label: &str, words: usize, word: u32) -> Result<wgpu::Buffer> {
        let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: (words * 4) as u64,
            usage: wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: true,
        });
        {
            let mut view = buffer
                .slice(..)
                .get_mapped_range_mut()
                .map_err(|e| anyhow!("GPU buffer {label}: {e:?}"))?;
            view.copy_from_slice(bytemuck::cast_slice(&vec![word; words]));
        }
        buffer.unmap();
        Ok(buffer)
    }

    /// Validate a generated module with naga, then hand it to the driver.
    pub fn module(&self, label: &str, source: String) -> Result<wgpu::ShaderModule> {
        crate::engine::wgsl::validate(&source)
            .map_err(|e| anyhow!("generated WGSL for {label} does not validate:\n{e}"))?;
        let desc = wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        };
        // SAFETY: the module is generated by this crate, not user input. Every loop in it
        // is bounded by a counter compared against a host-written size (or, in `normal`,
        // the constant entry count), and every index is either a loop counter below such a
        // size or a slot the host computed from the model layout for buffers it sized
        // itself (the evaluator's passes size `out`, `normal_out` and the records for the
        // windows and tiles they dispatch); so the injected bounds checks and loop guards
        // can be left out of the inner loop.
        let module = unsafe {
            self.device
                .create_shader_module_trusted(desc, wgpu::ShaderRuntimeChecks::unchecked())
        };
        self.check_errors()?;
        Ok(module)
    }
}
