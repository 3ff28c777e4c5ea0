//! The workload of the `hang@N` fault injection ([`super::fault::FAULT_VAR`]): compute
//! work that keeps the device busy for longer than the read-back timeout, submitted
//! ahead of the N-th submission's own work, so that the device's wait for that
//! submission (the poll with its timeout in `Device::wait_read_back`) is what ends it, as
//! for a device that stopped answering.
//!
//! llvmpipe (lavapipe) ends an invocation's loops once they have run 65,535 iterations
//! in all (shaders/engine/kernel.wgsl, `loops_completed`), so the work is spread over
//! many invocations, each a loop within that bound. How long a workgroup adds to a pass
//! is measured on the device first, then the grid is scaled to the time wanted: the grid
//! is doubled until one pass takes a quarter of a second, and that pass's time per
//! workgroup is the measure. A GPU runs thousands of workgroups at once, so a small grid
//! takes the time of one, and a pass that short is mostly the submission's own cost and
//! noise; a quarter-second pass fills any device and leaves those out. (Two fixed passes
//! of 8 and 40 workgroups took the same time on an H200, whose stall then ended in well
//! under the read-back timeout; then a rule that stopped doubling once a pass took 1.6
//! times the last stopped, on lavapipe with another test running, at a few milliseconds,
//! where noise alone doubles a pass, and one hang test of 2 ended before its timeout.)

use super::device::Device;
use anyhow::{Context, Result};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

const SHADER: &str = include_str!("../../../shaders/engine/stall.wgsl");

/// Workgroups of the first calibration pass.
const FIRST: u64 = 8;
/// The calibration stops doubling at this many workgroups, or once a pass takes this long.
const MOST: u64 = 1 << 22;
const LONG_S: f64 = 0.25;

pub struct Stall {
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    _sink: wgpu::Buffer,
    /// Seconds one workgroup adds to a pass, measured once.
    per_group: OnceLock<f64>,
    /// Whether a stall was handed out (the device then waits for it before it goes).
    submitted: std::sync::atomic::AtomicBool,
}

impl Stall {
    pub fn new(device: &Device) -> Stall {
        let d = &device.device;
        let module = d.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("bsdfit stall (hang injection)"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let pipeline = d.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("bsdfit stall"),
            layout: None,
            module: &module,
            entry_point: Some("stall"),
            compilation_options: Default::default(),
            cache: None,
        });
        let sink = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("bsdfit stall sink"),
            size: 4 * 1024,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let bind_group = d.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("bsdfit stall"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: sink.as_entire_binding(),
            }],
        });
        Stall {
            pipeline,
            bind_group,
            _sink: sink,
            per_group: OnceLock::new(),
            submitted: Default::default(),
        }
    }

    pub fn submitted(&self) -> bool {
        self.submitted.load(std::sync::atomic::Ordering::SeqCst)
    }

    /// Measure how long a workgroup takes, once (the device should be idle: the device
    /// does it when the injection is planned, before any other work).
    pub fn calibrate(&self, device: &Device) -> Result<f64> {
        match self.per_group.get() {
            Some(&s) => Ok(s),
            None => {
                let s = self.measure(device)?;
                Ok(*self.per_group.get_or_init(|| s))
            }
        }
    }

    /// A command buffer that keeps `device` busy for about `seconds` (at least).
    pub fn command_buffer(&self, device: &Device, seconds: f64) -> Result<wgpu::CommandBuffer> {
        let per_group = self.calibrate(device)?;
        let groups = (seconds / per_group).ceil().clamp(1.0, 65_535.0 * 65_535.0) as u64;
        self.submitted
            .store(true, std::sync::atomic::Ordering::SeqCst);
        Ok(self.encode(device, grid(groups)))
    }

    fn encode(&self, device: &Device, grid: [u32; 2]) -> wgpu::CommandBuffer {
        let mut encoder = device
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("bsdfit stall"),
            });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("stall"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.bind_group, &[]);
            pass.dispatch_workgroups(grid[0], grid[1], 1);
        }
        encoder.finish()
    }

    /// Seconds per workgroup once the device is full: the grid doubled until a pass
    /// takes [`LONG_S`], each pass waited for in full, then that pass's time per
    /// workgroup (its fixed cost included, so at most a little high: the stall comes out
    /// a little shorter than asked, and it is asked for three timeouts).
    fn measure(&self, device: &Device) -> Result<f64> {
        let time = |groups: u64| -> Result<f64> {
            let t0 = Instant::now();
            let index = device.queue.submit(Some(self.encode(device, grid(groups))));
            device
                .device
                .poll(wgpu::PollType::Wait {
                    submission_index: Some(index),
                    timeout: Some(Duration::from_secs(120)),
                })
                .context("the hang injection's calibration pass did not complete")?;
            Ok(t0.elapsed().as_secs_f64())
        };
        // The least of two tries of each: work of other threads on the device can only
        // lengthen a pass, and a stall sized from a lengthened pass would be too short.
        let best = |groups: u64| -> Result<f64> { Ok(time(groups)?.min(time(groups)?)) };
        let mut groups = FIRST;
        loop {
            let t = best(groups)?;
            if t >= LONG_S || groups >= MOST {
                let [x, y] = grid(groups);
                return Ok((t / (f64::from(x) * f64::from(y))).max(1e-9));
            }
            groups *= 2;
        }
    }
}

/// A dispatch of at least `groups` workgroups within the 65,535 a dimension allows.
fn grid(groups: u64) -> [u32; 2] {
    let x = groups.clamp(1, 65_535);
    [x as u32, groups.div_ceil(x).min(65_535) as u32]
}
