//! The scheduling layer of the GPU engine: a pass (costs, values, or values and their
//! normal-equation sums) planned as submissions over windows of records, each cut into
//! tiles (workgroup z), recorded, run, and its outputs handed to the evaluator's
//! reduction while they are mapped.
//!
//! A pass covers one window of record numbers within one segment (records texture):
//! every candidate evaluates its problem's records there, tile by tile. Windows are as
//! long as the outputs' binding allows ([`Runner::plan_window`]): one window holds the
//! whole of the small data sets fits usually meet (one submission per pass); a dense
//! data set takes as many as its size needs, and memory stays one window's outputs.

use super::bindings::{self, Dim, Dims, Resource};
use super::pipelines::{EntryPoint, Pipelines};
use super::recorder::{Dispatch, Recorder};
use super::records::Records;
use super::{GpuBackend, MAX_GROUPS_X, MIN_TILE};
use crate::bsdf::Model;
use crate::engine::loss::{Term, NO_SAMPLE};
use crate::engine::wgsl::{self, normal_entries, Shape};
use anyhow::{bail, Result};
use std::ops::Range;
use std::sync::Arc;

/// The bits of the NaN that an invocation whose loops were cut short writes instead of
/// its result (`LOOPS_CUT_SHORT` in shaders/engine/kernel.wgsl).
const LOOPS_CUT_SHORT: u32 = 0x7fa1_1ed5;

/// A CPU device ended the kernel's loops early (see `LOOPS_CUT_SHORT`).
#[derive(Debug, thiserror::Error)]
#[error("the device cut the kernel's loops short")]
struct LoopsCutShort;

/// What a submission computes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Pass {
    Costs,
    Values,
    /// Values, then the normal-equation sums of `groups` groups of P + 1 candidates.
    Normal {
        groups: usize,
    },
}

/// The window a submission covered, and how its outputs are laid out.
pub(super) struct Layout {
    pub n_tiles: usize,
    /// Per candidate, its problem's records in the window.
    pub records: Vec<Range<u32>>,
    /// Per candidate, where its values start in `out` (values passes).
    pub rows: Vec<usize>,
}

/// A submission's outputs as planned: their layout, each candidate's (problem, first
/// value) for the kernels, and the sizes (4-byte words) of `out` and `normal`.
struct Outputs {
    layout: Layout,
    owners: Vec<u32>,
    /// Costs (candidate × tile) or values.
    out_len: usize,
    /// Normal-equation groups (0 but in a normal pass).
    groups: usize,
    normal_len: usize,
}

/// The (x, y) workgroup grid of `total` workgroups: at most `MAX_GROUPS_X` across.
fn grid(total: u32) -> (u32, u32) {
    let x = total.clamp(1, MAX_GROUPS_X);
    (x, total.div_ceil(x))
}

/// What receives a submission's outputs: their layout, the f32 numbers read back, and
/// the records (whose host side the reductions read).
pub(super) type ReadBack<'r> = dyn FnMut(&Layout, &[f32], &Records) -> Result<()> + 'r;

/// Buffers that depend on the batch size, grown on demand, and the bind group of each
/// segment over them.
struct Io {
    params: wgpu::Buffer,
    owners: wgpu::Buffer,
    out: wgpu::Buffer,
    normal: wgpu::Buffer,
    staging: wgpu::Buffer,
    /// `LOOPS_CUT_SHORT` NaNs, as many as the larger of `out` and `normal`, written once:
    /// each submission first copies them over its outputs on the device, so anything the
    /// kernel fails to write reads as loops cut short.
    poison: wgpu::Buffer,
    bind_groups: Vec<wgpu::BindGroup>,
    /// Bytes of params, owners, out, normal and poison.
    caps: [u64; 5],
}

/// What runs the submissions: everything of the evaluator but the records, which the
/// host reductions read while a submission's outputs are mapped.
pub(super) struct Runner<'a> {
    gpu: &'a GpuBackend,
    model: &'a Model,
    term: Term,
    shape: Shape,
    /// Records per tile.
    tile: u32,
    /// The module of the `values` entry, and the loss's own (`costs`, `normal`), the
    /// latter composed when first needed (an LM fit on a CPU device uses only `values`).
    value_pipes: Arc<Pipelines>,
    loss_pipes: Option<Arc<Pipelines>>,
    dims: wgpu::Buffer,
    io: Option<Io>,
    read_back: u64,
}

impl<'a> Runner<'a> {
    pub(super) fn new(
        gpu: &'a GpuBackend,
        model: &'a Model,
        term: Term,
        shape: Shape,
    ) -> Result<Runner<'a>> {
        let value_pipes = gpu.value_pipelines(model, shape)?;
        let dims = gpu.device.buffer(
            "dims",
            std::mem::size_of::<Dims>() as u64,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        );
        gpu.device.check_errors()?;
        Ok(Runner {
            gpu,
            model,
            term,
            shape,
            tile: gpu.tile_for(model),
            value_pipes,
            loss_pipes: None,
            dims,
            io: None,
            read_back: 0,
        })
    }

    /// P, parameters per candidate.
    pub(super) fn dim(&self) -> usize {
        self.model.dim
    }

    /// Whether LM's normal equations are reduced on the device.
    pub(super) fn device_normal(&self) -> bool {
        self.gpu.device_normal
    }

    /// Bytes read back so far.
    pub(super) fn read_back(&self) -> u64 {
        self.read_back
    }

    /// Runs of candidates (`per_run` a multiple of their length, groups kept whole) whose
    /// parameters and owners fit a binding and a dispatch grid.
    pub(super) fn candidate_runs(&self, n: usize, per_run: usize) -> Vec<Range<usize>> {
        let max = (self.gpu.max_binding() / 4) as usize;
        let p = self.model.dim;
        let cap = (max / p.max(2))
            .min(MAX_GROUPS_X as usize * MAX_GROUPS_X as usize)
            .max(per_run)
            / per_run
            * per_run;
        (0..n.div_ceil(cap))
            .map(|i| i * cap..((i + 1) * cap).min(n))
            .collect()
    }

    /// Every window of every segment a pass over `problems` needs, `each` called with
    /// what each submission read back.
    pub(super) fn for_each_submission(
        &mut self,
        records: &Records,
        pass: Pass,
        params: &[f32],
        problems: &[usize],
        each: &mut ReadBack,
    ) -> Result<()> {
        // Only the records of these problems: skip what lies outside them.
        let lo = problems
            .iter()
            .map(|&q| records.problem_records[q].start)
            .min()
            .unwrap_or(0);
        let hi = problems
            .iter()
            .map(|&q| records.problem_records[q].end)
            .max()
            .unwrap_or(0);
        for seg in 0..records.segments.len() {
            let range = records.segments[seg].range.clone();
            let mut start = range.start.max(lo);
            let end = range.end.min(hi);
            while start < end {
                let window = self.submit(pass, seg, start..end, params, problems, records, each)?;
                start = window.end;
            }
        }
        Ok(())
    }

    /// The loss's own module (`costs`, `normal`): the module `values` uses for square
    /// terms, so that problems whose losses share a term shape share it.
    fn loss_pipes(&mut self) -> Result<Arc<Pipelines>> {
        if let Some(p) = &self.loss_pipes {
            return Ok(p.clone());
        }
        let p = self
            .gpu
            .pipelines
            .get(&self.gpu.device, self.model, self.term, self.shape)?;
        self.loss_pipes = Some(p.clone());
        Ok(p)
    }

    /// The longest window from `start` (within `room`) whose outputs fit a binding: the
    /// values of every candidate at its records, the costs or normal-equation sums of
    /// every tile, and at most `MAX_GROUPS_X` tiles.
    fn plan_window(&self, pass: Pass, room: Range<u32>, candidates: usize) -> Result<Range<u32>> {
        let max = (self.gpu.max_binding() / 4) as usize;
        let cb = wgsl::record_channels(self.model);
        let t = self.tile as usize;
        let mut w = t * MAX_GROUPS_X as usize;
        match pass {
            Pass::Costs => w = w.min(t * (max / candidates.max(1))),
            Pass::Values | Pass::Normal { .. } => w = w.min(max / (cb * candidates.max(1))),
        }
        if let Pass::Normal { groups } = pass {
            w = w.min(t * (max / (groups.max(1) * normal_entries(self.model.dim))));
        }
        anyhow::ensure!(
            w > 0,
            "{candidates} candidates are more than one GPU submission holds (at most {} \
             here); use fewer restarts",
            max / cb
        );
        // Whole tiles: a window then starts where a tile of a longer window would, so a
        // problem's tiles are the same whatever the windows (and its sums the same bits).
        if w >= t {
            w -= w % t;
        }
        Ok(room.start..room.end.min(room.start.saturating_add(w as u32)))
    }

    /// One submission of `pass` over the window from `room.start` (as long as
    /// [`Self::plan_window`] allows) of segment `seg`; `each` receives its outputs.
    /// Where a CPU device cut the loops short, the submission runs again with tiles a
    /// quarter as long. Returns the window covered.
    #[allow(clippy::too_many_arguments)]
    fn submit(
        &mut self,
        pass: Pass,
        seg: usize,
        room: Range<u32>,
        params: &[f32],
        problems: &[usize],
        records: &Records,
        each: &mut ReadBack,
    ) -> Result<Range<u32>> {
        loop {
            let window = self.plan_window(pass, room.clone(), problems.len())?;
            match self.submit_once(pass, seg, window.clone(), params, problems, records, each) {
                Err(e) if e.is::<LoopsCutShort>() => {
                    if self.tile <= MIN_TILE {
                        bail!(
                            "{} cut this evaluation short: it ends every loop of a shader \
                             invocation after 65,535 iterations in all, and evaluating `{}` \
                             takes more than that even over {MIN_TILE} records per invocation; \
                             use --backend cpu",
                            self.gpu.adapter_name(),
                            self.model.spec,
                        );
                    }
                    self.tile = (self.tile / 4).max(MIN_TILE);
                    self.gpu.shorten_tile(self.model, self.tile);
                }
                Err(e) => return Err(e),
                Ok(()) => return Ok(window),
            }
        }
    }

    /// One submission of `pass` over `window` of segment `seg` (see [`Self::submit`]),
    /// logged with its size and time.
    #[allow(clippy::too_many_arguments)]
    fn submit_once(
        &mut self,
        pass: Pass,
        seg: usize,
        window: Range<u32>,
        params: &[f32],
        problems: &[usize],
        records: &Records,
        each: &mut ReadBack,
    ) -> Result<()> {
        let started = std::time::Instant::now();
        let Some(outputs) = self.plan_outputs(pass, &window, problems, records) else {
            return Ok(());
        };
        let poisoned = if pass == Pass::Costs {
            outputs.out_len
        } else {
            0
        }
        .max(outputs.normal_len);
        self.ensure_io(
            records,
            [
                params.len(),
                outputs.owners.len(),
                outputs.out_len,
                outputs.normal_len,
                poisoned,
            ],
        )?;
        let evaluate_pipes = match pass {
            Pass::Costs => self.loss_pipes()?,
            _ => self.value_pipes.clone(),
        };
        let evaluate = self.gpu.pipelines.entry(
            &self.gpu.device,
            &evaluate_pipes,
            if pass == Pass::Costs {
                EntryPoint::Costs
            } else {
                EntryPoint::Values
            },
        )?;
        let normal_pipes = match pass {
            Pass::Normal { .. } => Some(self.loss_pipes()?),
            _ => None,
        };
        let normal = match &normal_pipes {
            Some(pipes) => Some(self.gpu.pipelines.entry(
                &self.gpu.device,
                pipes,
                EntryPoint::Normal,
            )?),
            None => None,
        };
        let n_tiles = outputs.layout.n_tiles;
        let (dims, (gx, gy), (nx, ny)) = self.dims(
            problems.len(),
            outputs.groups,
            seg,
            &window,
            n_tiles,
            records,
        );
        let mut dispatches = vec![Dispatch {
            pipeline: evaluate,
            grid: [gx, gy, n_tiles as u32],
        }];
        if let Some(normal) = normal {
            dispatches.push(Dispatch {
                pipeline: normal,
                grid: [nx, ny, n_tiles as u32],
            });
        }
        let io = self.io.as_ref().expect("io buffers allocated");
        let rec = self.record(io, pass, seg, &dims, params, &outputs, &dispatches);
        let (source, len) = match pass {
            Pass::Normal { .. } => (&io.normal, outputs.normal_len),
            _ => (&io.out, outputs.out_len),
        };
        let bytes = (len * 4) as u64;
        let staging = (!self.gpu.device.mappable).then_some(&io.staging);
        let layout = &outputs.layout;
        let result = rec.submit_and_read(source, staging, bytes, |raw| {
            let data: &[f32] = bytemuck::cast_slice(raw);
            if data.iter().any(|v| v.to_bits() == LOOPS_CUT_SHORT) {
                return Err(LoopsCutShort.into());
            }
            each(layout, data, records)
        })?;
        self.read_back += bytes;
        let evaluations: u64 = layout
            .records
            .iter()
            .zip(problems)
            .map(|(r, &q)| records.samples_in(q, r))
            .sum();
        self.gpu
            .log_submission(problems.len(), evaluations, started.elapsed().as_secs_f32());
        result
    }

    /// Where each candidate's records and outputs lie in a submission of `pass` over
    /// `window`, and the outputs' sizes; None where no problem has records there.
    fn plan_outputs(
        &self,
        pass: Pass,
        window: &Range<u32>,
        problems: &[usize],
        records: &Records,
    ) -> Option<Outputs> {
        let p = self.model.dim;
        let n = problems.len();
        let cb = records.slots;
        let in_window: Vec<Range<u32>> = problems
            .iter()
            .map(|&q| records.in_window(q, window))
            .collect();
        let longest = in_window.iter().map(|r| r.len()).max().unwrap_or(0);
        if longest == 0 {
            return None;
        }
        let n_tiles = longest.div_ceil(self.tile as usize);
        let mut rows = Vec::with_capacity(n);
        let mut owners = Vec::with_capacity(2 * n);
        let mut values_len = 0;
        for (r, &q) in in_window.iter().zip(problems) {
            rows.push(values_len);
            owners.extend([q as u32, values_len as u32]);
            values_len += r.len() * cb;
        }
        let (out_len, groups) = match pass {
            Pass::Costs => (n * n_tiles, 0),
            Pass::Values => (values_len, 0),
            Pass::Normal { groups } => (values_len, groups),
        };
        Some(Outputs {
            layout: Layout {
                n_tiles,
                records: in_window,
                rows,
            },
            owners,
            out_len,
            groups,
            normal_len: groups * n_tiles * normal_entries(p),
        })
    }

    /// The kernels' dimensions for `n` candidates and `groups` normal-equation groups
    /// over `window` of segment `seg` in `n_tiles` tiles, with the (x, y) dispatch grids
    /// of the evaluating and the normal-equation kernels.
    fn dims(
        &self,
        n: usize,
        groups: usize,
        seg: usize,
        window: &Range<u32>,
        n_tiles: usize,
        records: &Records,
    ) -> (Dims, (u32, u32), (u32, u32)) {
        let (gx, gy) = grid((n as u32).div_ceil(self.shape.candidates_per_workgroup()));
        let (nx, ny) = grid(groups as u32);
        let mut dims = Dims::default();
        dims.set(Dim::NCandidates, n as u32)
            .set(Dim::NProblems, records.problem_records.len() as u32)
            .set(Dim::Dim, self.model.dim as u32)
            .set(Dim::GroupsX, gx)
            .set(Dim::NGroups, groups as u32)
            .set(Dim::NormalGroupsX, nx)
            .set(Dim::ProbeTrips, 2)
            .set(Dim::SegFirst, records.segments[seg].range.start)
            .set(Dim::WinFirst, window.start)
            .set(Dim::WinEnd, window.end)
            .set(Dim::Tile, self.tile)
            .set(Dim::NTiles, n_tiles as u32)
            .set(Dim::OpaqueZero, 0);
        (dims, (gx, gy), (nx, ny))
    }

    /// A submission of `pass`: the dims, parameters and owners uploaded, the outputs
    /// poisoned, and `dispatches` run over segment `seg`'s bind group.
    #[allow(clippy::too_many_arguments)]
    fn record(
        &self,
        io: &Io,
        pass: Pass,
        seg: usize,
        dims: &Dims,
        params: &[f32],
        outputs: &Outputs,
        dispatches: &[Dispatch],
    ) -> Recorder<'a> {
        let mut rec = Recorder::new(&self.gpu.device);
        rec.upload(&self.dims, bytemuck::bytes_of(dims));
        rec.upload(&io.params, bytemuck::cast_slice(params));
        rec.upload(&io.owners, bytemuck::cast_slice(&outputs.owners));
        // The sums poisoned on the device, from the evaluator's poison buffer (writing them
        // from the host cost two copies of every output per submission, into wgpu's
        // staging, then into the buffer: 4 % of the default sweep's CPU time on lavapipe),
        // so that a sum a workgroup failed to write reads as loops cut short. A values
        // pass writes every slot of its window (its invocations mark their own cut-short
        // tiles): a copy of that size per window would cost as much as reading it.
        if pass == Pass::Costs {
            rec.copy(&io.poison, &io.out, (outputs.out_len * 4) as u64);
        }
        rec.copy(&io.poison, &io.normal, (outputs.normal_len * 4) as u64);
        rec.compute(&io.bind_groups[seg], dispatches);
        rec
    }

    /// Grow the buffers to hold `[params, owners, out, normal, poison]` (in 4-byte words).
    fn ensure_io(&mut self, records: &Records, words: [usize; 5]) -> Result<()> {
        // wgpu binds no empty buffer: every output exists (4 bytes at least).
        let want = words.map(|w| (w.max(1) * 4) as u64);
        if let Some(io) = &self.io {
            if io.caps.iter().zip(&want).all(|(c, w)| c >= w) {
                return Ok(());
            }
        }
        let caps = match &self.io {
            Some(io) => [0, 1, 2, 3, 4].map(|i| io.caps[i].max(want[i])),
            None => want,
        };
        let dev = &self.gpu.device;
        use wgpu::BufferUsages as U;
        let params = dev.buffer("params", caps[0], U::STORAGE | U::COPY_DST);
        let owners = dev.buffer("owners", caps[1], U::STORAGE | U::COPY_DST);
        // Outputs are read back through a staging buffer, or mapped as they are on CPU
        // devices (no staging buffer then).
        let (output, staging_bytes) = if dev.mappable {
            (U::STORAGE | U::MAP_READ | U::COPY_DST, 4)
        } else {
            (U::STORAGE | U::COPY_SRC | U::COPY_DST, caps[2].max(caps[3]))
        };
        let out = dev.buffer("out", caps[2], output);
        let normal = dev.buffer("normal", caps[3], output);
        let staging = dev.buffer("staging", staging_bytes, U::MAP_READ | U::COPY_DST);
        let poison = dev.filled_buffer("poison", (caps[4] / 4) as usize, LOOPS_CUT_SHORT)?;
        let bind_groups = records
            .segments
            .iter()
            .map(|s| {
                bindings::bind_group(
                    &dev.device,
                    self.gpu.pipelines.layout(),
                    &[
                        ("dims", Resource::Buffer(&self.dims)),
                        ("records", Resource::Texture(&s.view)),
                        ("tables", Resource::Buffer(&records.tables)),
                        ("params", Resource::Buffer(&params)),
                        ("out", Resource::Buffer(&out)),
                        ("LUT", Resource::Texture(&records.lut)),
                        ("owners", Resource::Buffer(&owners)),
                        ("normal_out", Resource::Buffer(&normal)),
                    ],
                )
            })
            .collect::<Result<Vec<_>>>()?;
        dev.check_errors()?;
        self.io = Some(Io {
            params,
            owners,
            out,
            normal,
            staging,
            poison,
            bind_groups,
            caps,
        });
        Ok(())
    }
}

impl Records {
    /// How many samples problem q has in its records `r` (slots that hold one).
    fn samples_in(&self, q: usize, r: &Range<u32>) -> u64 {
        let first = self.problem_records[q].start;
        let cb = self.slots;
        let rows = (r.start - first) as usize * cb..(r.end - first) as usize * cb;
        self.rows[q].sample[rows]
            .iter()
            .filter(|&&k| k != NO_SAMPLE)
            .count() as u64
    }
}
