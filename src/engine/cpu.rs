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
    fn prepare<'a>(&'a self, problem: Problem<'a>) -> anyhow::Result<Box<dyn Evaluator + 'a>> {
        Ok(Box::new(CpuEvaluator {
            problem,
            // Directions once per fit, not once per evaluation (a sample stores angles).
            directions: problem
                .data
                .samples
                .iter()
                .map(|s| (s.wi(), s.wo()))
                .collect(),
            terms: problem.loss.terms(problem.data),
            evaluations: AtomicU64::new(0),
        }))
    }
}

pub struct CpuEvaluator<'a> {
    problem: Problem<'a>,
    /// (ωi, ωo) of every sample.
    directions: Vec<(glam::DVec3, glam::DVec3)>,
    terms: LossTerms,
    evaluations: AtomicU64,
}

impl CpuEvaluator<'_> {
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

    fn check(&self, params: &[f64]) -> anyhow::Result<usize> {
        let p = self.problem.model.dim;
        anyhow::ensure!(
            p > 0 && params.len().is_multiple_of(p),
            "parameter batch of {} values is not a multiple of P = {p}",
            params.len()
        );
        Ok(params.len() / p)
    }
}

impl Evaluator for CpuEvaluator<'_> {
    fn dim(&self) -> usize {
        self.problem.model.dim
    }

    fn costs(&mut self, params: &[f64]) -> anyhow::Result<Vec<f64>> {
        let n = self.check(params)?;
        let p = self.dim();
        let out: Vec<f64> = params
            .par_chunks(p)
            .map(|flat| {
                let mut sum = 0.0;
                self.for_each_value(flat, |k, v| sum += self.terms.term_at(k, v));
                self.terms.finish_sum(sum)
            })
            .collect();
        self.evaluations
            .fetch_add((n * self.problem.data.len()) as u64, Ordering::Relaxed);
        Ok(out)
    }

    fn values(&mut self, params: &[f64]) -> anyhow::Result<Vec<f64>> {
        let n = self.check(params)?;
        let p = self.dim();
        let k = self.problem.data.len();
        let mut out = vec![0.0; n * k];
        out.par_chunks_mut(k)
            .zip(params.par_chunks(p))
            .for_each(|(row, flat)| {
                self.for_each_value(flat, |j, v| row[j] = v);
            });
        self.evaluations
            .fetch_add((n * k) as u64, Ordering::Relaxed);
        Ok(out)
    }

    fn normal_equations(
        &mut self,
        params: &[f64],
        steps: &[f64],
    ) -> anyhow::Result<Vec<crate::optim::NormalEquations>> {
        let values = self.values(params)?;
        Ok(super::normal_equations_from_values(
            &values,
            &self.terms,
            steps,
            self.problem.model.dim,
        ))
    }

    fn evaluations(&self) -> u64 {
        self.evaluations.load(Ordering::Relaxed)
    }
}
