//! The CPU reference backend: f64, one model evaluation per (candidate, sample), rayon
//! across candidates.

use super::{Backend, Evaluator, Problem};
use crate::engine::loss::LossTerms;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};

#[derive(Debug, Default, Clone)]
pub struct CpuBackend;

impl CpuBackend {
    pub fn new() -> Self {
        CpuBackend
    }
}

impl Backend for CpuBackend {
    fn name(&self) -> String {
        format!("cpu (f64, rayon, {} threads)", rayon::current_num_threads())
    }
    fn id(&self) -> &'static str {
        "cpu"
    }
    fn prepare_many<'a>(
        &'a self,
        problems: &[Problem<'a>],
    ) -> anyhow::Result<Box<dyn Evaluator + 'a>> {
        super::check_shared(problems)?;
        Ok(Box::new(CpuEvaluator {
            parts: problems
                .iter()
                .map(|&problem| Part {
                    problem,
                    // Directions once per fit, not once per evaluation (a sample stores
                    // angles).
                    directions: problem
                        .data
                        .samples
                        .iter()
                        .map(|s| (s.wi(), s.wo()))
                        .collect(),
                    terms: problem.loss.terms(problem.data),
                    evaluations: AtomicU64::new(0),
                })
                .collect(),
        }))
    }
}

/// One problem of a batch, with what its evaluations reuse.
struct Part<'a> {
    problem: Problem<'a>,
    /// (ωi, ωo) of every sample.
    directions: Vec<(glam::DVec3, glam::DVec3)>,
    terms: LossTerms,
    evaluations: AtomicU64,
}

pub struct CpuEvaluator<'a> {
    parts: Vec<Part<'a>>,
}

impl Part<'_> {
    /// Calls `f(k, y′_k)` for every sample of one candidate.
    fn for_each_value(&self, flat: &[f64], mut f: impl FnMut(usize, f64)) {
        let model = self.problem.model;
        // Resolve the scalar view once per (plane, channel) group, not once per sample.
        let views: Vec<Vec<f64>> = (0..model.groups())
            .map(|c| {
                let mut v = Vec::new();
                model.scalars_into(flat, c, &mut v);
                v
            })
            .collect();
        let samples = self.problem.data.samples.iter().zip(&self.directions);
        for (k, (s, &(wi, wo))) in samples.enumerate() {
            f(k, model.root.eval(&views[model.group_of(s)], wi, wo));
        }
    }
}

impl CpuEvaluator<'_> {
    fn check(&self, owners: &[usize], params: &[f64]) -> anyhow::Result<()> {
        let p = self.dim();
        anyhow::ensure!(
            p > 0 && params.len() == owners.len() * p,
            "parameter batch of {} values is not {} candidates of P = {p}",
            params.len(),
            owners.len()
        );
        anyhow::ensure!(
            owners.iter().all(|&q| q < self.parts.len()),
            "a candidate names a problem outside the batch's {}",
            self.parts.len()
        );
        Ok(())
    }

    fn count(&self, owners: &[usize]) {
        for &q in owners {
            let part = &self.parts[q];
            part.evaluations
                .fetch_add(part.terms.y.len() as u64, Ordering::Relaxed);
        }
    }
}

impl Evaluator for CpuEvaluator<'_> {
    fn dim(&self) -> usize {
        self.parts[0].problem.model.dim
    }

    fn problems(&self) -> usize {
        self.parts.len()
    }

    fn samples_of(&self, q: usize) -> usize {
        self.parts[q].terms.y.len()
    }

    fn costs_of(&mut self, owners: &[usize], params: &[f64]) -> anyhow::Result<Vec<f64>> {
        self.check(owners, params)?;
        let p = self.dim();
        let out: Vec<f64> = params
            .par_chunks(p)
            .zip(owners.par_iter())
            .map(|(flat, &q)| {
                let part = &self.parts[q];
                let mut sum = 0.0;
                part.for_each_value(flat, |k, v| sum += part.terms.term_at(k, v));
                part.terms.finish_sum(sum)
            })
            .collect();
        self.count(owners);
        Ok(out)
    }

    fn values_of(&mut self, owners: &[usize], params: &[f64]) -> anyhow::Result<Vec<f64>> {
        self.check(owners, params)?;
        let p = self.dim();
        let rows: Vec<Vec<f64>> = params
            .par_chunks(p)
            .zip(owners.par_iter())
            .map(|(flat, &q)| {
                let part = &self.parts[q];
                let mut row = vec![0.0; part.terms.y.len()];
                part.for_each_value(flat, |j, v| row[j] = v);
                row
            })
            .collect();
        self.count(owners);
        Ok(rows.concat())
    }

    fn normal_equations_of(
        &mut self,
        owners: &[usize],
        params: &[f64],
        steps: &[f64],
    ) -> anyhow::Result<Vec<crate::optim::NormalEquations>> {
        let p = self.dim();
        let expanded: Vec<usize> = owners
            .iter()
            .flat_map(|&q| std::iter::repeat_n(q, p + 1))
            .collect();
        let values = self.values_of(&expanded, params)?;
        let terms: Vec<&LossTerms> = self.parts.iter().map(|x| &x.terms).collect();
        Ok(super::normal_equations_of_values(
            &values, &terms, owners, steps, p,
        ))
    }

    fn evaluations_of(&self, q: usize) -> u64 {
        self.parts[q].evaluations.load(Ordering::Relaxed)
    }
}
