//! How a batch's data sets become the kernels' sample records, uploaded once per
//! evaluator: the records themselves (textures, in segments), each problem's range of
//! records and μ table (`tables`), and, kept on the host, which sample each record slot
//! holds and the loss constants in slot order (the rows of the engine's value windows).
//!
//! **Records.** One per direction, plane, inner factor a and block of up to CB channels
//! (`Record` in shaders/engine/kernel.wgsl): ωi with the record's packed word, ωo with a,
//! then per channel slot (v, w): v = y for SMAPE and g(y) otherwise, w the loss weight,
//! −1 where the slot has no sample. A thread evaluates a record's channels in one
//! unrolled call, so the compiler computes what the channels share once.
//!
//! **Textures, not storage buffers**: Mesa 22's llvmpipe (lavapipe) loads a storage
//! buffer lane by lane through the stack, about 15 cycles a scalar (perf showed 14 such
//! loads per record as the kernel's whole cost), while it fetches texels with vector
//! gathers: `lambert` 2.5e8 → 8.3e8 evaluations/s, `ggx` 1.6e8 → 3.2e8 (2-core AMD EPYC).
//! A record's fields are texels of one row (array of structures): every field of a
//! record is read together, so the layout costs nothing on a GPU either, where the
//! threads of a warp read the same record (a broadcast).
//!
//! **Segments.** A texture holds at most `max_texture_dimension_2d` rows of
//! [`wgsl::RECORDS_PER_ROW`] records (16.7 M records on lavapipe); more records go into
//! further textures, one bind group each, and a pass runs once per segment, its partial
//! results added up on the host (a test lowers the segment size to force the split).

use super::super::loss::{LossTerms, Term, NO_SAMPLE};
use super::super::reduce::RowTerms;
use super::super::wgsl;
use super::super::Problem;
use super::device::Device;
use crate::bsdf::Model;
use anyhow::Result;
use std::collections::HashMap;
use std::ops::Range;

/// The most distinct polar cosines a problem's μ table holds (`MU_TABLE_LEN` in
/// shaders/engine/kernel.wgsl); an index of this value means "not in the table".
pub const MU_TABLE_LEN: usize = 63;
/// Bits of a record's packed word (texel 0's w) holding its first scalar-view group.
pub const GROUP_BITS: u32 = 12;
/// The packed word's bits after the group: which channel slots hold a sample.
const SLOT_MASK_SHIFT: u32 = 12;
/// Where the μ indices start, and their width. Group, slot mask and μ indices fill bits
/// 0–27, so the word, read as an f32, is never a NaN whose payload a device might not
/// keep.
const MU_SHIFT: u32 = 16;
const MU_INDEX_BITS: u32 = 6;

/// Entries per row of the lookup-table texture (`LUT_WIDTH` in shaders/engine/kernel.wgsl).
const LUT_WIDTH: usize = 256;

/// One texture of records: those numbered `range` in the batch.
pub struct Segment {
    pub range: Range<u32>,
    pub view: wgpu::TextureView,
}

/// A batch's data on the device, and what the host keeps to read its value windows.
pub struct Records {
    /// CB: channel slots per record.
    pub slots: usize,
    /// Per problem, its records (numbers over the batch).
    pub problem_records: Vec<Range<u32>>,
    /// Per problem, its loss constants in slot order: row r of problem q is slot
    /// r of its records (CB per record), padding where the slot holds no sample.
    pub rows: Vec<RowTerms>,
    /// Per problem, its sample count K_q.
    pub samples: Vec<usize>,
    /// Whether every problem has a μ table.
    pub mu_tables: bool,
    pub segments: Vec<Segment>,
    pub tables: wgpu::Buffer,
    pub lut: wgpu::TextureView,
}

impl Records {
    /// Lay the problems' samples out as records and upload them, at most
    /// `segment_records` records a texture (and the device's texture limit).
    pub fn upload(
        device: &Device,
        model: &Model,
        problems: &[Problem],
        terms: &[LossTerms],
        segment_records: usize,
    ) -> Result<Records> {
        let cb = wgsl::record_channels(model);
        let floats = 4 * wgsl::record_texels(cb);
        let laid = lay_out(cb, floats, model, problems, terms)?;
        let problem_records = laid.problem_records;
        let n_records = laid.records.len() / floats;
        if n_records >= u32::MAX as usize / cb {
            return Err(crate::choice::field_error(format!(
                "{n_records} GPU records are more than one batch numbers (use {{backend=cpu}})"
            )));
        }
        let rows = problem_records
            .iter()
            .zip(terms)
            .map(|(r, t)| {
                let slots = r.start as usize * cb..r.end as usize * cb;
                RowTerms::new(t, laid.slot_sample[slots].to_vec())
            })
            .collect();
        drop(laid.slot_sample);
        let tables = table_words(&problem_records, problems, &laid.mu_tables);
        let segments = segments(device, cb, laid.records, segment_records);
        let lut = lut_texture(device, model);
        let tables = device.buffer_init(
            "tables",
            bytemuck::cast_slice(&tables),
            wgpu::BufferUsages::STORAGE,
        );
        device.check_errors()?;
        Ok(Records {
            slots: cb,
            problem_records,
            rows,
            samples: problems.iter().map(|p| p.data.len()).collect(),
            mu_tables: laid.mu_tables.iter().all(|t| !t.is_empty()),
            segments,
            tables,
            lut,
        })
    }

    /// The records of problem q in the window `window` (record numbers).
    pub fn in_window(&self, q: usize, window: &Range<u32>) -> Range<u32> {
        let r = &self.problem_records[q];
        let lo = r.start.max(window.start).min(r.end);
        lo..r.end.min(window.end).max(lo)
    }
}

/// Every problem's records, one after the other, as [`write`] lays them out.
struct LaidOut {
    /// The records (`floats` numbers each).
    records: Vec<f32>,
    /// Per record slot, the sample it holds (NO_SAMPLE for none).
    slot_sample: Vec<u32>,
    /// Per problem, its records.
    problem_records: Vec<Range<u32>>,
    /// Per problem, its μ table (empty where it has none).
    mu_tables: Vec<Vec<f32>>,
}

/// The records of every problem, in order.
fn lay_out(
    cb: usize,
    floats: usize,
    model: &Model,
    problems: &[Problem],
    terms: &[LossTerms],
) -> Result<LaidOut> {
    let mut records: Vec<f32> = Vec::new();
    let mut slot_sample: Vec<u32> = Vec::new();
    let mut problem_records = Vec::with_capacity(problems.len());
    let mut mu_tables = Vec::with_capacity(problems.len());
    for (problem, terms) in problems.iter().zip(terms) {
        let first = (records.len() / floats) as u32;
        mu_tables.push(write(
            cb,
            floats,
            model,
            problem.data,
            terms,
            &mut records,
            &mut slot_sample,
        )?);
        problem_records.push(first..(records.len() / floats) as u32);
    }
    Ok(LaidOut {
        records,
        slot_sample,
        problem_records,
        mu_tables,
    })
}

/// `tables`: 3 entries per problem, then where each problem's μ table starts; there,
/// its length, then its values (f32 bits).
fn table_words(
    problem_records: &[Range<u32>],
    problems: &[Problem],
    mu_tables: &[Vec<f32>],
) -> Vec<u32> {
    let mut tables: Vec<u32> = Vec::with_capacity(4 * problems.len());
    for (r, p) in problem_records.iter().zip(problems) {
        tables.extend([r.start, r.end, p.data.len() as u32]);
    }
    let mut at = tables.len() + problems.len();
    for table in mu_tables {
        tables.push(at as u32);
        at += 1 + table.len();
    }
    for table in mu_tables {
        tables.push(table.len() as u32);
        tables.extend(table.iter().map(|m| m.to_bits()));
    }
    tables
}

/// The records (CB channel slots each) as textures of at most `segment_records` records
/// (and the device's texture limit): whole rows of a texture each (but the last), cut
/// from the records in place: the records are padded to whole rows once, so no segment
/// is copied.
fn segments(
    device: &Device,
    cb: usize,
    mut records: Vec<f32>,
    segment_records: usize,
) -> Vec<Segment> {
    let floats = 4 * wgsl::record_texels(cb);
    let n_records = records.len() / floats;
    let rows_max = device.limits.max_texture_dimension_2d as usize;
    let per_segment = if n_records <= wgsl::RECORDS_PER_ROW {
        n_records.max(1)
    } else {
        let rows = segment_records
            .div_ceil(wgsl::RECORDS_PER_ROW)
            .clamp(1, rows_max);
        rows * wgsl::RECORDS_PER_ROW
    };
    let padded = if n_records <= wgsl::RECORDS_PER_ROW {
        n_records.max(1)
    } else {
        n_records.next_multiple_of(wgsl::RECORDS_PER_ROW)
    };
    records.resize(padded * floats, 0.0);
    let mut segments = Vec::new();
    let mut start = 0;
    loop {
        let end = (start + per_segment).min(padded);
        segments.push(Segment {
            range: start as u32..(end.min(n_records)) as u32,
            view: texture(
                device,
                cb,
                &records[start * floats..end * floats],
                end - start,
            ),
        });
        start = end;
        if start >= n_records {
            break;
        }
    }
    segments
}

/// The model's lookup table (one entry where it has none), as rows of `LUT_WIDTH`
/// entries of an R32F texture.
fn lut_texture(device: &Device, model: &Model) -> wgpu::TextureView {
    let mut lut: Vec<f32> = model
        .nodes()
        .iter()
        .find_map(|n| n.bsdf.lut())
        .unwrap_or_else(|| vec![0.0]);
    let lut_rows = lut.len().div_ceil(LUT_WIDTH).max(1);
    lut.resize(lut_rows * LUT_WIDTH, 0.0);
    device.texture(
        "lut",
        LUT_WIDTH,
        lut_rows,
        wgpu::TextureFormat::R32Float,
        bytemuck::cast_slice(&lut),
    )
}

/// `n` records (`chunk`, whole rows of `wgsl::RECORDS_PER_ROW` records, or fewer records
/// than one row) as an RGBA32F texture.
fn texture(device: &Device, cb: usize, chunk: &[f32], n: usize) -> wgpu::TextureView {
    let texels = wgsl::record_texels(cb);
    let width = n.clamp(1, wgsl::RECORDS_PER_ROW) * texels;
    let height = n.div_ceil(wgsl::RECORDS_PER_ROW).max(1);
    debug_assert_eq!(chunk.len(), width * height * 4);
    device.texture(
        "records",
        width,
        height,
        wgpu::TextureFormat::Rgba32Float,
        bytemuck::cast_slice(chunk),
    )
}

/// Append the records of one data set: a record per (ωi, ωo bit for bit, plane, a,
/// channel block) in the order their first samples come in
/// [`walk_order`](crate::engine::walk_order), and another wherever a channel is measured
/// again at the same direction (each repeat its own record, as each is its own term of
/// the loss); and, per channel slot, the sample it holds (`slot_sample`, NO_SAMPLE for
/// none).
///
/// Returns the data set's μ table: the distinct f32 values of cos θi and cos θo (the
/// records' ωi.z and ωo.z), empty where there are more than [`MU_TABLE_LEN`]. Each
/// record's packed word holds its first scalar-view group, which of its slots hold a
/// sample, and the indices of its μi and μo in that table, from which models compute per
/// candidate, before the record loop, what depends on μ alone (`rmg_prepare`).
fn write(
    cb: usize,
    floats: usize,
    model: &Model,
    data: &crate::data::Dataset,
    terms: &LossTerms,
    records: &mut Vec<f32>,
    slot_sample: &mut Vec<u32>,
) -> Result<Vec<f32>> {
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
    anyhow::ensure!(
        model.groups() <= 1 << GROUP_BITS,
        "{} scalar-view groups (channels × planes) exceed the GPU records' {GROUP_BITS}-bit \
         field (use --backend cpu)",
        model.groups()
    );
    let mut at: HashMap<([u64; 7], usize, usize), usize> = HashMap::new();
    for k in crate::engine::walk_order(data) {
        let s = &data.samples[k];
        let (wi, wo) = (s.wi(), s.wo());
        let g = model.group_of(s);
        let (plane, ch) = (g / model.channels, g % model.channels);
        let g0 = plane * model.channels + (ch / cb) * cb;
        let packed =
            g0 as u32 | mu_index(wi.z) << MU_SHIFT | mu_index(wo.z) << (MU_SHIFT + MU_INDEX_BITS);
        let a = terms.a[k];
        let key = [wi.x, wi.y, wi.z, wo.x, wo.y, wo.z, a].map(f64::to_bits);
        let slot = ch % cb;
        let mut repeat = 0;
        let rec = loop {
            let r = *at.entry((key, g0, repeat)).or_insert_with(|| {
                let r = records.len() / floats;
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
                records.resize(slots + floats - 8, 0.0);
                for i in 0..cb {
                    records[slots + 2 * i + 1] = -1.0;
                }
                slot_sample.extend(std::iter::repeat_n(NO_SAMPLE, cb));
                r
            });
            if slot_sample[r * cb + slot] == NO_SAMPLE {
                break r;
            }
            repeat += 1;
        };
        slot_sample[rec * cb + slot] = k as u32;
        let word = &mut records[rec * floats + 3];
        *word = f32::from_bits(word.to_bits() | 1 << (SLOT_MASK_SHIFT + slot as u32));
        let v = match terms.term {
            Term::AbsRatio => s.value,
            Term::Square | Term::LogSquare => terms.transform(k, s.value),
        };
        let o = rec * floats + 8 + 2 * slot;
        records[o..o + 2].copy_from_slice(&[v as f32, terms.w[k] as f32]);
    }
    Ok(mu_table)
}
