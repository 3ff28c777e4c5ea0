//! The GPU evaluator: a batch's data uploaded once ([`Records`]), and the three passes
//! the optimizers ask for, reduced over the samples without ever reading back a value
//! per candidate and sample for them:
//! - costs: a partial sum of loss terms per (candidate, tile), summed and finished on
//!   the host in f64;
//! - value windows: the model values at every record slot of a window, read back and
//!   handed to a host reduction ([`crate::engine::reduce`]) one window at a time;
//! - normal equations: on GPUs, the device's reduction of each group of P + 1 candidates
//!   to its sums per tile (normal.wgsl), the only numbers read back; on CPU devices,
//!   the host's reduction of the value windows.

use super::records::Records;
use super::runner::{Pass, ReadBack, Runner};
use super::GpuBackend;
use crate::engine::loss::LossTerms;
use crate::engine::reduce::{self, GramSums, ValueWindow, Values, WindowPart};
use crate::engine::wgsl::normal_entries;
use crate::engine::{Evaluator, Problem};
use crate::optim::NormalEquations;
use anyhow::Result;

pub struct GpuEvaluator<'a> {
    runner: Runner<'a>,
    records: Records,
    /// Model-sample evaluations per problem.
    evaluations: Vec<u64>,
}

impl<'a> GpuEvaluator<'a> {
    pub(super) fn new(gpu: &'a GpuBackend, problems: &[Problem<'a>]) -> Result<GpuEvaluator<'a>> {
        let model = problems[0].model;
        let terms: Vec<LossTerms> = problems.iter().map(|p| p.loss.terms(p.data)).collect();
        let records = Records::upload(&gpu.device, model, problems, &terms, gpu.segment_records)?;
        drop(terms);
        let shape = gpu.shape.for_batch(records.mu_tables);
        Ok(GpuEvaluator {
            runner: Runner::new(gpu, model, problems[0].loss.metric.term(), shape)?,
            evaluations: vec![0; problems.len()],
            records,
        })
    }

    fn check_batch(&self, owners: &[usize], params: &[f64]) -> Result<()> {
        let p = self.runner.dim();
        anyhow::ensure!(
            p > 0 && params.len() == owners.len() * p,
            "parameter batch of {} values is not {} candidates of P = {p}",
            params.len(),
            owners.len()
        );
        anyhow::ensure!(
            owners
                .iter()
                .all(|&q| q < self.records.problem_records.len()),
            "a candidate names a problem outside the batch's {}",
            self.records.problem_records.len()
        );
        Ok(())
    }

    /// Every window of every segment a pass over `problems` needs, `each` called with
    /// what each submission read back.
    fn for_each_submission(
        &mut self,
        pass: Pass,
        params: &[f32],
        problems: &[usize],
        each: &mut ReadBack,
    ) -> Result<()> {
        self.runner
            .for_each_submission(&self.records, pass, params, problems, each)
    }
}

impl Evaluator for GpuEvaluator<'_> {
    fn dim(&self) -> usize {
        self.runner.dim()
    }

    fn problems(&self) -> usize {
        self.records.problem_records.len()
    }

    fn samples_of(&self, q: usize) -> usize {
        self.records.samples[q]
    }

    fn costs_of(&mut self, owners: &[usize], params: &[f64]) -> Result<Vec<f64>> {
        self.check_batch(owners, params)?;
        let p = self.dim();
        let mut sums = vec![0.0f64; owners.len()];
        for run in self.runner.candidate_runs(owners.len(), 1) {
            let host: Vec<f32> = params[run.start * p..run.end * p]
                .iter()
                .map(|&v| v as f32)
                .collect();
            let first = run.start;
            self.for_each_submission(Pass::Costs, &host, &owners[run], &mut |layout, out, _| {
                // Tile after tile into one f64 sum per candidate, in record order, so
                // that the sum does not depend on how the records fall into windows.
                for (c, tiles) in out.chunks(layout.n_tiles).enumerate() {
                    for &v in tiles {
                        sums[first + c] += v as f64;
                    }
                }
                Ok(())
            })?;
        }
        for &q in owners {
            self.evaluations[q] += self.records.samples[q] as u64;
        }
        Ok(sums
            .iter()
            .zip(owners)
            .map(|(&s, &q)| self.records.rows[q].terms.finish_sum(s))
            .collect())
    }

    fn value_windows(
        &mut self,
        owners: &[usize],
        params: &[f64],
        visit: &mut dyn FnMut(&ValueWindow) -> Result<()>,
    ) -> Result<()> {
        self.check_batch(owners, params)?;
        let runs = self
            .runner
            .candidate_runs(owners.len(), owners.len().max(1));
        anyhow::ensure!(
            runs.len() <= 1,
            "{} candidates are more than one GPU submission holds; use fewer restarts",
            owners.len()
        );
        let host: Vec<f32> = params.iter().map(|&v| v as f32).collect();
        self.for_each_submission(Pass::Values, &host, owners, &mut |layout, out, records| {
            let cb = records.slots;
            let parts: Vec<WindowPart> = layout
                .records
                .iter()
                .zip(owners)
                .enumerate()
                .filter(|(_, (r, _))| !r.is_empty())
                .map(|(c, (r, &q))| {
                    let first = records.problem_records[q].start;
                    WindowPart {
                        candidate: c,
                        problem: q,
                        rows: (r.start - first) as usize * cb..(r.end - first) as usize * cb,
                        offset: layout.rows[c],
                    }
                })
                .collect();
            visit(&ValueWindow {
                parts: &parts,
                values: Values::F32(out),
                rows: &records.rows,
            })
        })?;
        for &q in owners {
            self.evaluations[q] += self.records.samples[q] as u64;
        }
        Ok(())
    }

    fn normal_equations_of(
        &mut self,
        owners: &[usize],
        params: &[f64],
        steps: &[f64],
    ) -> Result<Vec<NormalEquations>> {
        let p = self.dim();
        let m = reduce::check_groups(owners, params, steps, p)?;
        if !self.runner.device_normal() || m != p {
            return reduce::normal_equations(self, owners, params, steps);
        }
        anyhow::ensure!(
            owners.iter().all(|&q| q < self.problems()),
            "a group names a problem outside the batch's {}",
            self.problems()
        );
        let expanded: Vec<usize> = owners
            .iter()
            .flat_map(|&q| std::iter::repeat_n(q, p + 1))
            .collect();
        let host: Vec<f32> = params.iter().map(|&v| v as f32).collect();
        let groups = owners.len();
        let ne = normal_entries(p);
        let mut sums = vec![GramSums::zeros(p); groups];
        self.for_each_submission(
            Pass::Normal { groups },
            &host,
            &expanded,
            &mut |layout, out, _| {
                for (g, tiles) in out.chunks(layout.n_tiles * ne).enumerate() {
                    for tile in tiles.chunks(ne) {
                        sums[g].add_f32(tile);
                    }
                }
                Ok(())
            },
        )?;
        for &q in owners {
            self.evaluations[q] += ((p + 1) * self.records.samples[q]) as u64;
        }
        Ok(sums
            .iter()
            .zip(steps.chunks(p))
            .map(|(s, h)| s.finish(h))
            .collect())
    }

    fn evaluations_of(&self, q: usize) -> u64 {
        self.evaluations[q]
    }

    fn read_back_bytes(&self) -> u64 {
        self.runner.read_back()
    }
}
