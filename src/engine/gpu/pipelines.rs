//! The pipeline layer: one WGSL module per (model, loss term shape, thread shape),
//! composed by [`wgsl::compose`], validated and compiled once, its entry points compiled
//! when first used, all cached for the backend's lifetime.

use super::bindings;
use super::device::Device;
use crate::bsdf::Model;
use crate::engine::loss::Term;
use crate::engine::wgsl::{self, Shape};
use anyhow::{anyhow, Result};
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

/// The kernels' entry points.
#[derive(Clone, Copy, Debug)]
pub enum EntryPoint {
    /// A partial sum of loss terms per (candidate, tile).
    Costs,
    /// Model values per record slot.
    Values,
    /// LM's normal-equation sums per (group, tile), from the values of a `Values` pass.
    Normal,
}

/// A module and its entry points, each compiled when first used: a driver compiles a
/// pipeline when it is created (lavapipe runs LLVM then, 0.04–0.3 s a pipeline for the
/// catalogue's models), and most evaluators never use all three (on CPU devices `normal`
/// is the host's, `costs` serves only compass search). On the default sweep on lavapipe,
/// compiling all three up front took 6–10 s of its ≈ 50 s of thread time, a sixth of it
/// for `normal` alone.
pub struct Pipelines {
    module: wgpu::ShaderModule,
    costs: OnceLock<wgpu::ComputePipeline>,
    values: OnceLock<wgpu::ComputePipeline>,
    normal: OnceLock<wgpu::ComputePipeline>,
    /// The entry point `normal` compiles: the one-slice shape is the CPU devices'
    /// (normal.wgsl says why).
    normal_entry: &'static str,
}

/// A cache entry: compiled once, by whichever evaluator asks first, while the others wait
/// on this entry alone (not on the whole cache), so workers compiling different models do
/// not queue behind each other.
type Slot = Arc<OnceLock<std::result::Result<Arc<Pipelines>, String>>>;

pub struct PipelineCache {
    layout: wgpu::BindGroupLayout,
    pipeline_layout: wgpu::PipelineLayout,
    cache: Mutex<HashMap<String, Slot>>,
}

impl PipelineCache {
    pub fn new(device: &Device) -> PipelineCache {
        let layout = device
            .device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("bsdfit kernel"),
                entries: &bindings::layout_entries(),
            });
        let pipeline_layout =
            device
                .device
                .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                    label: Some("bsdfit kernel"),
                    bind_group_layouts: &[Some(&layout)],
                    immediate_size: 0,
                });
        PipelineCache {
            layout,
            pipeline_layout,
            cache: Mutex::default(),
        }
    }

    /// The bind group layout every module's bindings follow.
    pub fn layout(&self) -> &wgpu::BindGroupLayout {
        &self.layout
    }

    /// The module of `model` for loss term shape `term` and thread shape `shape`.
    pub fn get(
        &self,
        device: &Device,
        model: &Model,
        term: Term,
        shape: Shape,
    ) -> Result<Arc<Pipelines>> {
        let key = format!(
            "{}|{}|{}|{:?}|{:?}",
            model.spec,
            model.channels,
            model.axes.len(),
            term,
            shape
        );
        let slot: Slot = self
            .cache
            .lock()
            .map_err(|_| anyhow!("pipeline cache poisoned"))?
            .entry(key)
            .or_default()
            .clone();
        slot.get_or_init(|| {
            let module = device
                .module(&model.spec, wgsl::compose(model, term, shape))
                .map_err(|e| e.to_string())?;
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

    /// One of `pipes`' entry points, compiled now if it is the first use.
    pub fn entry<'p>(
        &self,
        device: &Device,
        pipes: &'p Pipelines,
        which: EntryPoint,
    ) -> Result<&'p wgpu::ComputePipeline> {
        let (cell, name) = match which {
            EntryPoint::Costs => (&pipes.costs, "costs"),
            EntryPoint::Values => (&pipes.values, "values"),
            EntryPoint::Normal => (&pipes.normal, pipes.normal_entry),
        };
        let mut made = false;
        let pipeline = cell.get_or_init(|| {
            made = true;
            device
                .device
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
            device.check_errors()?;
        }
        Ok(pipeline)
    }
}
