//! The device layer: opening a Vulkan adapter, catching wgpu's asynchronous errors as
//! values, and the resources every other layer asks for (textures, buffers, shader
//! modules). Nothing here knows what a BSDF or a loss is.

use anyhow::{anyhow, bail, Context as _, Result};
use std::sync::{Arc, Mutex};
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
}

impl Device {
    /// Open the first Vulkan adapter (a discrete GPU if present, else e.g. lavapipe),
    /// asking for every limit it offers and for subgroups where it has them.
    pub fn open() -> Result<Device> {
        pollster::block_on(Self::open_async())
    }

    async fn open_async() -> Result<Device> {
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
        Ok(Device {
            mappable: features.contains(wgpu::Features::MAPPABLE_PRIMARY_BUFFERS),
            device,
            queue,
            info,
            limits,
            errors,
        })
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

    /// The errors wgpu reported since the last call, as one `Err`.
    pub fn check_errors(&self) -> Result<()> {
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
