//! The recording layer: one submission's uploads, output resets, compute dispatches and
//! read-back, then the wait for it. It moves bytes and runs pipelines it is given; it
//! knows nothing of models, losses or what the bytes mean.

use super::device::Device;
use super::fault::Injected;
use anyhow::Result;

/// One dispatch of a compute pass: a pipeline over a grid of workgroups.
pub struct Dispatch<'a> {
    pub pipeline: &'a wgpu::ComputePipeline,
    pub grid: [u32; 3],
}

/// A submission being recorded.
pub struct Recorder<'d> {
    device: &'d Device,
    encoder: wgpu::CommandEncoder,
}

impl<'d> Recorder<'d> {
    pub fn new(device: &'d Device) -> Recorder<'d> {
        let encoder = device
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("bsdfit"),
            });
        Recorder { device, encoder }
    }

    /// Upload `bytes` to the start of `buffer` (before anything this submission runs).
    pub fn upload(&mut self, buffer: &wgpu::Buffer, bytes: &[u8]) {
        if !bytes.is_empty() {
            self.device.queue.write_buffer(buffer, 0, bytes);
        }
    }

    /// Copy the first `bytes` of `from` over `to` (on the device, in order).
    pub fn copy(&mut self, from: &wgpu::Buffer, to: &wgpu::Buffer, bytes: u64) {
        if bytes > 0 {
            self.encoder.copy_buffer_to_buffer(from, 0, to, 0, bytes);
        }
    }

    /// One compute pass running `dispatches` in turn with `bind_group` (wgpu orders
    /// dispatches that write and then read the same buffer with a barrier between them).
    pub fn compute(&mut self, bind_group: &wgpu::BindGroup, dispatches: &[Dispatch]) {
        let mut pass = self
            .encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("evaluate"),
                timestamp_writes: None,
            });
        pass.set_bind_group(0, bind_group, &[]);
        for d in dispatches {
            pass.set_pipeline(d.pipeline);
            pass.dispatch_workgroups(d.grid[0], d.grid[1], d.grid[2]);
        }
    }

    /// Submit, wait, and hand the first `bytes` of `source` to `read`: copied into
    /// `staging` first, or mapped as they are where `staging` is `None` (a buffer
    /// created mappable, [`Device::mappable`]). The wait is bounded by the device's
    /// read-back timeout; a device lost or hung fails with its [`DeviceFault`], and so
    /// does every later submission.
    ///
    /// [`DeviceFault`]: super::fault::DeviceFault
    pub fn submit_and_read<R>(
        mut self,
        source: &wgpu::Buffer,
        staging: Option<&wgpu::Buffer>,
        bytes: u64,
        read: impl FnOnce(&[u8]) -> R,
    ) -> Result<R> {
        let (n, injected) = self.device.begin_submission()?;
        let staging = match staging {
            Some(staging) => {
                self.encoder
                    .copy_buffer_to_buffer(source, 0, staging, 0, bytes);
                staging
            }
            None => source,
        };
        let slice = staging.slice(0..bytes);
        let (tx, rx) = std::sync::mpsc::channel();
        // `hang@N` (fault::FAULT_VAR): work that outlasts the read-back timeout runs
        // ahead of this submission's own, so the wait below times out on the device, as
        // for a device that stopped answering.
        let stall = match injected {
            Some(Injected::Hang) => Some(self.device.stall_past_timeout()?),
            _ => None,
        };
        let index = self
            .device
            .queue
            .submit(stall.into_iter().chain(Some(self.encoder.finish())));
        slice.map_async(wgpu::MapMode::Read, move |r| {
            tx.send(r).ok();
        });
        self.device.wait_read_back(n, index, &rx)?;
        let out = {
            let view = slice.get_mapped_range().map_err(|e| {
                self.device
                    .read_back_error(format!("GPU read-back failed: {e:?}"))
            })?;
            read(&view)
        };
        staging.unmap();
        self.device.check_errors()?;
        Ok(out)
    }
}
